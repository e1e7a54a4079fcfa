"""The daemon's config: defaults, every error names its key (and the file), round trip."""
from __future__ import annotations

import dataclasses
import json
import logging
import os
import re
import stat
from pathlib import Path

import pytest

from firmware_host.daemon.cli import EXAMPLE_CONFIG, check_config
from ghnerf_runtime.config import config_to_dict
from firmware_host.daemon.service import check_sink_urls
from firmware_host.sinks.usb_select import PortPath
from firmware_host.sinks.usb_sink import claimed_interface
from tests.firmware_host.fake_usb_backend import FakeBackend, two_boards
from firmware_host.daemon.config import DaemonConfig, DaemonConfigError, daemon_config_from_dict, \
    load_daemon_config

SINK = "udp://127.0.0.1:9870"
REPO_RIG = Path(__file__).resolve().parents[3] / "docs" / "examples" / "rig.json"


def _error(data: dict) -> str:
    with pytest.raises(DaemonConfigError) as e:
        daemon_config_from_dict(data)
    return str(e.value)


def test_minimal_config_takes_the_defaults():
    cfg = daemon_config_from_dict({"sinks": [SINK]})
    assert cfg.rig.url == "depthai://"
    assert cfg.sinks == (SINK,)
    assert cfg.health.status_file is None
    assert cfg.estimator.joints3d.method  # the runtime's defaults, untouched


@pytest.mark.parametrize("data, key", [
    ({"sinks": [SINK], "rig": {"ulr": "sim://"}}, "rig.ulr: unknown key"),
    ({"sinks": [SINK], "helth": {}}, "helth: unknown key"),
    ({"sinks": [SINK], "estimator": {"joints3d": {"metod": "x"}}}, "estimator.joints3d.metod: unknown key"),
    ({"sinks": [SINK], "estimator": {"session": {"threads": 0}}}, "estimator.session.threads"),
    ({"sinks": [SINK], "rig": {"read_timeout_s": -1}}, "rig.read_timeout_s: must be a number of seconds"),
    ({"sinks": [SINK], "rig": {"read_timeout_s": float("nan")}}, "rig.read_timeout_s"),
    ({"sinks": [SINK], "rig": {"read_timeout_s": True}}, "rig.read_timeout_s"),
    ({"sinks": [SINK], "rig": {"read_timeout_s": 5, "stall_s": 2}}, "rig.stall_s: must be at least read_timeout_s"),
    ({"sinks": [SINK], "rig": {"reopen_min_s": 5, "reopen_max_s": 1}}, "rig.reopen_max_s"),
    ({"sinks": [SINK], "rig": {"url": "depthai"}}, "rig.url: must be a rig URL"),
    ({"sinks": [SINK], "rig": {"exit_at_end": "yes"}}, "rig.exit_at_end: must be true or false"),
    ({"sinks": [SINK], "rig": []}, "rig: must be a mapping"),
    ({"sinks": [SINK], "health": {"status_file": ""}}, "health.status_file"),
    ({"sinks": [SINK], "log_level": "loud"}, "log_level: must be one of"),
    ({}, "sinks: must be a non-empty list"),
    ({"sinks": []}, "sinks: must be a non-empty list"),
    ({"sinks": SINK}, "sinks: must be a non-empty list"),
    ({"sinks": [SINK, 3]}, "sinks[1]: must be a sink URL"),
    ({"sinks": [SINK, SINK]}, "sinks: lists a URL twice"),
    ({"sinks": [SINK], "rig": {"url": "record+sim://?out=/tmp/x"}}, "rig.url: record+ is not supported"),
    ({"sinks": [SINK], "rig": {"read_timeout_s": 12, "stall_s": 20}},
     "health.loop_allowance_s: must be at least rig.read_timeout_s"),
    ({"sinks": [SINK], "health": {"loop_allowance_s": 5}}, "health.loop_allowance_s: must be at least"),
    ({"sinks": [SINK], "rig": {"stall_s": 10 ** 400}}, "rig.stall_s: must be a number of seconds"),
    # was "estimator.EstimatorConfig: ...": the runtime keyed its root by its class name
    ({"sinks": [SINK], "estimator": []}, "estimator: must be a mapping (JSON object), got list"),
    ({"sinks": [SINK], "estimator": None}, "estimator: must be a mapping (JSON object), got NoneType"),
    # one destination twice, its URLs told apart by their options, case or spelling: each frame went out twice
    ({"sinks": [SINK, SINK + "?queue=8"]}, f"sinks[1]: sends where sinks[0] ({SINK!r}) does"),
    ({"sinks": [SINK, "UDP://127.0.0.1:9870"]}, "sinks[1]: sends where sinks[0]"),
    # the udp sink takes a lone '/' as no path: one port, each frame sent twice (kept apart until session 63's review)
    ({"sinks": [SINK, "udp://127.0.0.1:9870/"]}, "sinks[1]: sends where sinks[0]"),
    ({"sinks": ["vmc://127.0.0.1:9870/", "vmc://127.0.0.1:9870"]}, "sinks[1]: sends where sinks[0]"),
    ({"sinks": ["file:///tmp/j.jsonl", SINK, "file:///tmp//j.jsonl?queue=9"]}, "sinks[2]: sends where sinks[0]"),
    ({"sinks": ["file:///tmp/a%20b.jsonl", "file:///tmp/a b.jsonl"]}, "sinks[1]: sends where sinks[0]"),
    ({"sinks": ["serial:///dev/ttyACM0", "serial:///dev/ttyACM0?baud=115200"]}, "sinks[1]: sends where sinks[0]"),
    ({"sinks": ["file:///tmp/a%2Eb", "file:///tmp/./a.b/"]}, "sinks[1]: sends where sinks[0]"),
    ({"sinks": ["serial:///dev/tty%41CM0", "serial:///dev//ttyACM0"]}, "sinks[1]: sends where sinks[0]"),
    # decoded as the sinks decode it: unquote made %FF and %FE both U+FFFD, "sinks[1]: sends where sinks[0]"
    ({"sinks": ["file:///tmp/a%FFb.jsonl", "file:///tmp/a%FEb.jsonl"]},
     "sinks[0]: /tmp/a%FFb.jsonl: is not UTF-8 (give the path in UTF-8, or rename the file)"),
])
def test_errors_name_the_key(data, key):
    assert _error(data).startswith(key)


def test_a_recorder_inside_another_wrapper_is_refused_too(monkeypatch):
    """The daemon refused a rig URL starting with ``record+``: one whose recorder sat inside another wrapper of the
    registry (``spy+record+...``) passed, to fail at the second open on the take folder the first one filled."""
    from drivers import wrappers

    monkeypatch.setitem(wrappers.WRAPPERS, "spy+", wrappers.WRAPPERS[wrappers.RECORD_PREFIX])
    assert _error({"sinks": [SINK], "rig": {"url": "spy+record+sim://?out=/tmp/x"}}).startswith(
        "rig.url: record+ is not supported")
    assert daemon_config_from_dict({"sinks": [SINK], "rig": {"url": "replay:///tmp/record+x"}})  # not a prefix


@pytest.mark.parametrize("sinks, said", [
    (["memory://viewer:hunter2@here", "memory://viewer:hunter2@here"],
     "sinks: lists a URL twice, got ['memory://viewer:***@here', 'memory://viewer:***@here']"),
    (["udp://viewer:hunter2@127.0.0.1:9870?token=hunter2"] * 2, "sinks: lists a URL twice, got "
     "['udp://viewer:***@127.0.0.1:9870?token=***', 'udp://viewer:***@127.0.0.1:9870?token=***']"),
    (["memory://viewer:hunter2@here", "memory://viewer:hunter2@here?max_bytes=16"],
     "sinks[1]: sends where sinks[0] ('memory://viewer:***@here') does: one URL per destination, with all its "
     "options, got 'memory://viewer:***@here?max_bytes=16'"),
])
def test_a_sink_url_refused_for_its_duplicate_is_shown_without_its_password(sinks, said):
    """As the sinks show their URLs (``redact_url``): these two errors printed them as configured, password and
    all, to the journal and to ``--validate-config``'s output."""
    assert _error({"sinks": sinks}) == said


@pytest.mark.parametrize("sinks", [
    ["memory://?status_s=0.05", "memory://?status_s=0.06"],  # in-process buffers: each sink is its own
    ["serial:///dev/ttyACM0", "serial:///dev/ttyACM1"],
    [SINK, "udp://127.0.0.1:9871", "vmc://127.0.0.1:9870"],  # another port; another scheme (the receiver's choice)
    ["file:///tmp/a.jsonl", "file:///tmp/b.jsonl"],
])
def test_sinks_to_different_destinations_are_kept(sinks):
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)


def test_a_file_sink_through_a_link_and_up_is_the_file_it_reaches(tmp_path):
    """``link/../j.jsonl`` is ``j.jsonl`` beside the link's target, not beside the link: ``posixpath.normpath``
    made it the other sink's file and refused two sinks that write two files."""
    (tmp_path / "elsewhere" / "in").mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "elsewhere" / "in")
    sinks = [f"file://{tmp_path}/j.jsonl", f"file://{tmp_path}/link/../j.jsonl"]
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)
    (tmp_path / "plain").mkdir()  # through a folder, one file: refused, naming the other sink
    with pytest.raises(DaemonConfigError, match=r"^sinks\[1\]: is where sinks\[0\] writes too"):
        daemon_config_from_dict({"sinks": [sinks[0], f"file://{tmp_path}/plain/../j.jsonl"]})


@pytest.mark.parametrize("sinks", [
    # two identical boards, each named (docs/protocol.md, "Two boards of one VID:PID"): refused as one destination,
    # the options that tell them apart dropped
    ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&serial=XYZ789"],
    ["usb://1209:0001?ep=0x01&port=1-1.4", "usb://1209:0001?ep=0x01&port=1-2"],
    ["usb://1209:0001?ep=0x01&interface=0", "usb://1209:0001?ep=0x02&interface=1"],  # one board, two interfaces
    ["usb://1209:0001?ep=0x01", "usb://1209:0002?ep=0x01&serial=ABC123"],  # another PID
])
def test_usb_sinks_that_claim_different_interfaces_are_kept(sinks):
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)


@pytest.mark.parametrize("sinks, said", [
    # one VID:PID spelled two ways, told apart only by the endpoint: the second claim of the interface fails
    (["usb://1209:1?ep=0x01", "usb://0x1209:0x0001?ep=0x02"],
     "sinks[1]: sends where sinks[0] ('usb://1209:1?ep=0x01') does (both claim interface 0 of the 1209:0001 board "
     "listed first): one URL per destination"),
    (["usb://1209:0001?ep=0x01&port=1-1.4", "usb://1209:0001?ep=0x01&port=1-01.4&queue=8"],
     "sinks[1]: sends where sinks[0] ('usb://1209:0001?ep=0x01&port=1-1.4') does (both claim interface 0 of the "
     "1209:0001 board with port=1-1.4)"),
    # no selector takes the board libusb lists first: it may be the named one
    (["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01"],
     "sinks[1]: sends where sinks[0] ('usb://1209:0001?ep=0x01&serial=ABC123') does (both claim interface 0 of "
     "1209:0001, and the one with no serial= or port= takes the board listed first, which may be serial='ABC123': "
     "name each sink's board)"),
])
def test_usb_sinks_that_may_claim_one_interface_are_refused(sinks, said):
    assert _error({"sinks": sinks}).startswith(said)


@pytest.mark.parametrize("url, board", [
    ("usb://1209:1?ep=0x01&serial=ABC123", ("serial", "ABC123", "serial='ABC123'")),
    ("usb://1209:1?ep=0x01&port=1-01.4", ("port", PortPath(1, (1, 4)), "port=1-1.4")),
    # a serial that reads like a port is still a serial: the kind is the claim's, not its text's
    ("usb://1209:1?ep=0x01&serial=port%3D1-1.4", ("serial", "port=1-1.4", "serial='port=1-1.4'")),
])
def test_a_usb_claim_says_which_kind_of_name_chose_its_board(url, board):
    """The config check tells a ``serial=`` from a ``port=`` by the claim's :class:`BoardName` (it read the prefix of
    the claim's own text before the session-65 review); the text is the one its errors show."""
    claim = claimed_interface(url)
    assert (claim.vid_pid, claim.interface) == ("1209:0001", 0)
    assert (claim.board.by, claim.board.value, str(claim.board)) == board
    assert claimed_interface("usb://1209:1?ep=0x01").board is None  # the first board libusb lists
    assert claimed_interface("usb://1209:1") is None  # no ep=: the sink's own check says why


@pytest.fixture
def boards_on_the_bus(monkeypatch):
    """Plug simulated boards in where the usb:// sink's own backend looks (libusb_package's libusb): the config
    check enumerates through the sink, as the daemon does at load."""
    import libusb_package

    def plug(*boards):  # none: no libusb on this machine (get_libusb1_backend's None)
        monkeypatch.setattr(libusb_package, "get_libusb1_backend", lambda: FakeBackend(*boards) if boards else None)
        return boards
    return plug


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_one_usb_board_named_by_its_serial_and_by_its_port_is_one_destination(boards_on_the_bus, order):
    """One board chosen once by ``serial=`` and once by ``port=``: both loaded, and the second sink waited at connect
    for ever behind the first one's claim (session 65). Refused at load when the board is plugged in, naming both
    sinks and the port; nothing on the board configured, claimed, detached or left open."""
    board, = boards_on_the_bus(two_boards()[0])
    named = ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:1?ep=0x02&port=1-1.4"]
    sinks = [named[k] for k in order]
    whichs = ["serial='ABC123'", "port=1-1.4"]
    assert _error({"sinks": sinks}) == (
        f"sinks[1]: sends where sinks[0] ({sinks[0]!r}) does (both claim interface 0 of the 1209:0001 board at port "
        f"1-1.4, named {whichs[order[0]]} and {whichs[order[1]]}): one URL per destination, with all its options, "
        f"got {sinks[1]!r}")
    assert (board.configuration, board.claimed, board.detaches, board.open_handles) == (0, set(), 0, 0)


@pytest.mark.parametrize("boards, sinks", [
    # no board at load: the spellings stand (a board unplugged at boot is no error), as before session 65
    ((dataclasses.replace(two_boards()[0], present=False),),
     ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&port=1-1.4"]),
    ((), ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&port=1-1.4"]),  # no libusb at all
    # the serial's board is in another socket: two boards
    (two_boards(),
     ["usb://1209:0001?ep=0x01&serial=XYZ789", "usb://1209:0001?ep=0x01&port=1-1.4"]),
    # one board, two interfaces
    ((two_boards()[0],),
     ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x02&port=1-1.4&interface=1"]),
    # its serial unreadable (no udev rule): which board it names is not known, the spellings stand
    ((dataclasses.replace(two_boards()[0], access_denied=True),),
     ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&port=1-1.4"]),
])
def test_usb_sinks_naming_boards_apart_on_the_bus_are_kept(boards_on_the_bus, boards, sinks):
    boards_on_the_bus(*boards)
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)


def test_a_config_with_no_serial_and_port_pair_reads_nothing_from_the_bus(monkeypatch):
    """Only a ``serial=`` and ``port=`` pair of one VID:PID and interface is looked for on the bus: two boards named
    by two serials load without a libusb call, so no device is opened at load."""
    import libusb_package

    def no_libusb():
        raise AssertionError("libusb asked")
    monkeypatch.setattr(libusb_package, "get_libusb1_backend", no_libusb)
    sinks = ["usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&serial=XYZ789",
             "usb://1209:0001?ep=0x01&port=1-1.4&interface=1"]
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)


@pytest.fixture
def pty_slave():
    """A pty's slave path (a character device, as /dev/ttyACM0 is), open while the test runs."""
    master, slave = os.openpty()
    yield os.ttyname(slave)
    os.close(slave)
    os.close(master)


def test_two_serial_sinks_on_one_device_by_two_names_are_refused(tmp_path, pty_slave):
    """``/dev/serial/by-id/...`` is a link to ``/dev/ttyACM0``: the second sink sat behind the first one's lock
    for ever, retrying, as the spellings were all that was compared."""
    (tmp_path / "by-id").mkdir()
    (tmp_path / "by-id" / "usb-Foo-if00").symlink_to(pty_slave)
    sinks = [f"serial://{pty_slave}", f"serial://{tmp_path}/by-id/usb-Foo-if00?baud=921600"]
    number = os.stat(pty_slave).st_rdev
    assert _error({"sinks": sinks}) == (
        f"sinks[1]: sends where sinks[0] ('serial://{pty_slave}') does (both paths lead to character device "
        f"{os.major(number)}:{os.minor(number)}): one URL per destination, with all its options, got '{sinks[1]}'")


def test_a_second_node_of_one_serial_device_is_one_destination(tmp_path, pty_slave):
    """Two nodes of one device (a second /dev) do not share pyserial's flock, which is the node's: the device's
    number is compared, not the node's inode."""
    try:
        os.mknod(tmp_path / "ttyCopy", stat.S_IFCHR | 0o600, os.stat(pty_slave).st_rdev)
    except PermissionError:
        pytest.skip("mknod needs CAP_MKNOD")
    with pytest.raises(DaemonConfigError, match=r"^sinks\[1\]: sends where sinks\[0\]"):
        daemon_config_from_dict({"sinks": [f"serial://{pty_slave}", f"serial://{tmp_path}/ttyCopy"]})


def test_serial_ports_not_there_at_load_are_told_apart_by_their_spelling(tmp_path, pty_slave):
    """A by-id port not plugged in at boot (its link missing, or left leading nowhere) is no error: the config loads
    and the sink waits for it."""
    (tmp_path / "usb-Gone-if00").symlink_to(tmp_path / "ttyACM9")
    sinks = [f"serial://{pty_slave}", f"serial://{tmp_path}/usb-Foo-if00", f"serial://{tmp_path}/usb-Gone-if00"]
    assert daemon_config_from_dict({"sinks": sinks}).sinks == tuple(sinks)


def test_a_file_sink_through_a_link_to_another_sinks_file_is_refused(tmp_path):
    """Two ``file://`` names of one file are the outputs-apart check's (``realpath``), not told twice."""
    (tmp_path / "j.jsonl").touch()
    (tmp_path / "link.jsonl").symlink_to(tmp_path / "j.jsonl")
    with pytest.raises(DaemonConfigError, match=r"^sinks\[1\]: is where sinks\[0\] writes too"):
        daemon_config_from_dict({"sinks": [f"file://{tmp_path}/j.jsonl", f"file://{tmp_path}/link.jsonl"]})


@pytest.mark.parametrize("change, said", [
    # the status file is replaced whole at every beat: the calibration became a health report
    (lambda d, t: d["health"].update(status_file=f"{t}/rig.json"),
     "health.status_file: is rig.url's rig= file ({t}/rig.json), which the daemon reads"),
    (lambda d, t: d["health"].update(status_file=f"{t}/sub/../rig.json"),  # one file, spelled another way
     "health.status_file: is rig.url's rig= file ({t}/rig.json), which the daemon reads"),
    # a file:// sink appends joint lines to it
    (lambda d, t: d.update(sinks=[f"file://{t}/rig.json"]), "sinks[0]: is rig.url's rig= file ({t}/rig.json)"),
    (lambda d, t: d.update(sinks=[SINK, f"file://{t}/status.json"]),
     "sinks[1]: is where health.status_file writes too: two writers would mix in one file"),
    (lambda d, t: d.update(sinks=[f"file://{t}/j.jsonl", f"file://localhost{t}/j.jsonl?write_timeout_ms=5"]),
     "sinks[1]: is where sinks[0] writes too"),
])
def test_a_file_the_daemon_writes_is_no_file_it_reads_or_writes_otherwise(tmp_path, change, said):
    data = {"rig": {"url": f"opencv://?first=0&second=1&rig={tmp_path}/rig.json"}, "sinks": [SINK],
            "health": {"status_file": str(tmp_path / "status.json")}}
    change(data, tmp_path)
    assert said.format(t=tmp_path) in _error(data)


def test_the_status_file_or_a_file_sink_is_not_the_config_file(tmp_path):
    """The first status beat replaced the config with a health report (the next start failed); a file:// sink
    appended joint lines to it."""
    path = tmp_path / "ghnerf.json"
    for change in ({"health": {"status_file": "ghnerf.json"}}, {"sinks": [f"file://{path}"]}):
        path.write_text(json.dumps({"rig": {"url": "sim://"}, "sinks": [SINK], **change}))
        with pytest.raises(DaemonConfigError) as e:
            load_daemon_config(path)
        assert f"is the config file itself ({path}), which the daemon reads" in str(e.value)
        assert str(e.value).startswith(str(path))
    path.write_text(json.dumps({"rig": {"url": "sim://"}, "sinks": [SINK], "health": {"status_file": "status.json"}}))
    assert load_daemon_config(path).health.status_file == str(tmp_path / "status.json")  # beside it: fine


def test_a_status_file_or_file_sink_that_is_a_folder_is_refused_naming_the_key(tmp_path):
    """Accepted before session 75, every write failed (a warning at each start and reload). A file sink's folder
    not there yet is still fine (a USB stick mounted later); a path that is a folder now is a mistake."""
    (tmp_path / "run").mkdir()
    path = tmp_path / "ghnerf.json"
    for change, key in (({"health": {"status_file": "run"}}, "health.status_file"),
                        ({"sinks": [SINK, f"file://{tmp_path}/run/"]}, "sinks[1]"),
                        ({"sinks": [f"file://localhost{tmp_path}/run"]}, "sinks[0]")):
        path.write_text(json.dumps({"rig": {"url": "sim://"}, "sinks": [SINK], **change}))
        with pytest.raises(DaemonConfigError) as e:
            load_daemon_config(path)
        assert f"{path}: {key}: is a folder, not a file; name the file to write in it" in str(e.value)
        assert f"{tmp_path}/run" in str(e.value)
    path.write_text(json.dumps({"rig": {"url": "sim://"}, "health": {"status_file": "run/status.json"},
                                "sinks": [f"file://{tmp_path}/usb/joints.jsonl"]}))  # a folder not there yet
    assert load_daemon_config(path).health.status_file == str(tmp_path / "run" / "status.json")


@pytest.mark.parametrize("change, said", [
    # opened sim:// (URL parsing drops it), but a relative replay:// take was not read from the file's folder
    ({"rig": {"url": " sim://"}}, "rig.url: starts with a space"),
    ({"rig": {"url": "sim://?fps=30\u00a0"}}, "rig.url: ends with a space"),
    ({"sinks": [" udp://127.0.0.1:9870"]}, "sinks[0]: starts with a space"),
    ({"sinks": [SINK, "file:///tmp/j.jsonl "]}, "sinks[1]: ends with a space"),  # wrote another file
])
def test_a_url_with_a_space_before_or_after_it_is_refused_naming_the_key(change, said):
    assert said + ", which is no part of the URL; remove it" in _error({"sinks": [SINK], **change})


@pytest.mark.parametrize("sinks, said", [
    ([SINK, "file:///tmp/j.jsonl\u2028"], "sinks[1]: 'file:///tmp/j.jsonl\\u2028': invalid url='file:///tmp/j.jsonl"
                                          "\\u2028': holds a line separator (U+2028) at character 20"),
    (["\u2029udp://127.0.0.1:9870"], "sinks[0]: '\\u2029udp://127.0.0.1:9870': invalid url="),
])
def test_a_url_with_a_line_separator_at_an_end_is_refused_naming_it_not_as_a_space(sinks, said):
    """U+2028 and U+2029 are whitespace to ``str.isspace``: the sinks' own check names them, as it names a tab."""
    config = daemon_config_from_dict({"sinks": sinks})
    with pytest.raises(DaemonConfigError) as e:
        check_sink_urls(config.sinks)
    assert said in str(e.value), str(e.value)


def test_round_trip_and_example_is_valid():
    cfg = daemon_config_from_dict(EXAMPLE_CONFIG)
    assert daemon_config_from_dict(json.loads(json.dumps(config_to_dict(cfg)))) == cfg
    assert isinstance(cfg, DaemonConfig)


def test_file_errors_name_the_file(tmp_path):
    missing = tmp_path / "nope.json"
    with pytest.raises(DaemonConfigError, match=f"^{missing}: cannot read"):
        load_daemon_config(missing)
    bad = tmp_path / "bad.json"
    bad.write_text('{"sinks": [\n  "udp://h:1",\n}')
    with pytest.raises(DaemonConfigError, match=rf"^{bad}: not valid JSON \(line 3"):
        load_daemon_config(bad)
    latin = tmp_path / "latin.json"
    latin.write_bytes(b'{"sinks": ["udp://caf\xe9:1"]}')
    with pytest.raises(DaemonConfigError, match=f"^{latin}: not UTF-8"):
        load_daemon_config(latin)
    for content in (b"", b"\n \r\n", b"\xef\xbb\xbf"):  # was "not valid JSON (line 1, column 1: Expecting value)"
        empty = tmp_path / "empty.json"
        empty.write_bytes(content)
        with pytest.raises(DaemonConfigError, match=f"^{empty}: the config file is empty$"):
            load_daemon_config(empty)
    typo = tmp_path / "typo.json"
    typo.write_text(json.dumps({"sinks": [SINK], "rig": {"urll": "sim://"}}))
    with pytest.raises(DaemonConfigError, match=f"^{typo}: rig.urll: unknown key"):
        load_daemon_config(typo)


def test_the_check_of_rig_url_leaves_the_rig_s_warnings_to_its_open(tmp_path, caplog):
    """The daemon checks its config at the start and at every reload (``check_config``), and the check read a take's
    manifest (twice: the source it creates, the nominal-rig check) and a ``rig=`` file with their warnings: the
    journal repeated a narrow pair's at every reload, and at the start before the open said it. The open logs them,
    once per ``rig.url``; ``--validate-config``, which opens no rig, asks for them (``warn_of_rig``), once."""
    import drivers
    from drivers.sim import RigPlacement
    from ghnerf_runtime.rig_file import save_rig

    models = tmp_path / "models"
    models.mkdir()
    (models / "x.onnx").write_bytes(b"not checked here")
    take, narrow = tmp_path / "take", tmp_path / "narrow.json"
    url = f"sim://?width=40&height=30&baseline=0.05&policy=all&cache={tmp_path / 'cache'}"
    with drivers.open_rig(f"record+{url}&out={take}") as rig:
        rig.read(timeout_s=5)
    save_rig(RigPlacement(width=40, height=30, baseline_m=0.05).build("narrow"), narrow)
    for rig_url in (f"replay://{take}", f"opencv://?first=0&second=1&rig={narrow}"):
        config = daemon_config_from_dict({"rig": {"url": rig_url}, "sinks": [SINK],
                                          "estimator": {"session": {"model_dir": str(models)}}})
        caplog.clear()
        with caplog.at_level(logging.WARNING):
            check_config(config)
            assert [r for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()] == [], caplog.text
            check_config(config, warn_of_rig=True)
            asked = [r.getMessage() for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
        assert len(asked) == 1, (rig_url, caplog.text)


def test_check_config_names_bad_urls_and_models(tmp_path, monkeypatch):
    models = tmp_path / "models"
    models.mkdir()
    (models / "x.onnx").write_bytes(b"not checked here")

    def cfg(**over):
        data = {"rig": {"url": "sim://?fps=30"}, "sinks": [SINK],
                "estimator": {"session": {"model_dir": str(models)}}}
        data.update(over)
        return daemon_config_from_dict(data)

    check_config(cfg())  # passes: URLs parse, the folder holds a graph
    with pytest.raises(DaemonConfigError, match=r"^rig\.url: .*fps"):
        check_config(cfg(rig={"url": "sim://?fps=-3"}))
    with pytest.raises(DaemonConfigError, match=r"^rig\.url: .*nosuch"):
        check_config(cfg(rig={"url": "nosuch://"}))
    with pytest.raises(DaemonConfigError, match=r"^sinks\[1\]: .*baud"):
        check_config(cfg(sinks=[SINK, "serial:///dev/ttyUSB9?baud=fast"]))
    with pytest.raises(DaemonConfigError, match=r"^sinks\[0\]: .*cameras="):
        check_config(cfg(sinks=[SINK + "?send_2d=1&cameras=a,b"]))
    check_config(cfg(sinks=[SINK + "?send_2d=1"]))  # the daemon fills in the camera names
    # rig_id= given empty kept the daemon from adding the rig's id: HELLO announced none, without a word
    with pytest.raises(DaemonConfigError, match=r"^sinks\[0\]: .*invalid rig_id='': empty"):
        check_config(cfg(sinks=[SINK + "?rig_id="]))
    check_config(cfg(rig={"url": f"replay://{tmp_path / 'later'}"}))  # a recording the daemon will wait for
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DaemonConfigError, match=r"^estimator\.session\.model_dir: .*no \*\.onnx"):
        check_config(cfg(estimator={"session": {"model_dir": str(empty)}}))
    # a relative folder that is not there: said "holds no *.onnx graphs (make model builds ./models)"
    # where the example config was run from outside the repository, whose models/ it names
    monkeypatch.chdir(tmp_path)
    where = f"estimator.session.model_dir: nowhere: no such folder, read from the current directory {tmp_path}:"
    with pytest.raises(DaemonConfigError, match=re.escape(where)) as e:
        check_config(cfg(estimator={"session": {"model_dir": "nowhere"}}))
    assert "make model" not in str(e.value)


def test_check_config_reads_a_rig_file_named_in_the_url(tmp_path):
    from ghnerf_runtime.geometry.rig import Rig
    from ghnerf_runtime.rig_file import load_rig, save_rig

    models = tmp_path / "models"
    models.mkdir()
    (models / "x.onnx").write_bytes(b"")
    rig = load_rig(REPO_RIG)
    long_id = tmp_path / "rig.json"
    save_rig(Rig(rig.cameras, rig.volume, rig_id="a rig id far longer than the streams 32 characters"), long_id)

    def cfg(url):
        return daemon_config_from_dict({"rig": {"url": url}, "sinks": [SINK],
                                        "estimator": {"session": {"model_dir": str(models)}}})

    size = f"width={rig.pair[0].width}&height={rig.pair[0].height}"
    check_config(cfg(f"depthai://?rig={REPO_RIG}&{size}"))
    with pytest.raises(DaemonConfigError, match=r"^rig\.url: .*rig id 'a rig id far longer"):
        check_config(cfg(f"depthai://?rig={long_id}&{size}"))
    with pytest.raises(DaemonConfigError, match=r"^rig\.url: .*missing\.json"):
        check_config(cfg(f"depthai://?rig={tmp_path / 'missing.json'}&{size}"))
    # Webcams: only with their calibration (without one their rig is a nominal stand-in, for ghcal capture).
    check_config(cfg(f"opencv://?first=0&second=1&rig={REPO_RIG}"))
    with pytest.raises(DaemonConfigError, match=r"^rig\.url: opencv:// cameras need their calibration: add rig="):
        check_config(cfg("opencv://?first=0&second=1"))


@pytest.mark.parametrize("doc", ["docs/daemon.md", "README.md", "systemd/daemon.json"])
def test_the_configs_in_the_docs_are_valid(doc):
    """Every daemon config a reader may copy (the JSON blocks with a "sinks" key) loads as it is."""
    import re

    text = (REPO_RIG.parents[2] / doc).read_text()
    blocks = [text] if doc.endswith(".json") else re.findall(r"```json\n(.*?)```", text, re.S)
    configs = [json.loads(b) for b in blocks if '"sinks"' in b]
    assert configs, f"no daemon config in {doc}"
    for data in configs:
        daemon_config_from_dict(data)


def test_check_config_refuses_a_take_of_uncalibrated_webcams(tmp_path):
    # the nominal rig of opencv:// without rig= went into the take, and replay:// of it passed as a calibration
    from drivers.backends.opencv import NOMINAL_RIG_ID
    from drivers.backends.recording_format import Manifest, write_manifest
    from ghnerf_runtime.geometry.rig import Rig
    from ghnerf_runtime.rig_file import load_rig

    models = tmp_path / "models"
    models.mkdir()
    (models / "x.onnx").write_bytes(b"")
    rig = load_rig(REPO_RIG)

    def cfg(url):
        return daemon_config_from_dict({"rig": {"url": url}, "sinks": [SINK],
                                        "estimator": {"session": {"model_dir": str(models)}}})

    for name, take_rig in (("marked", Rig(rig.cameras, rig.volume, "webcams", metadata={"uncalibrated": True})),
                           ("old", Rig(rig.cameras, rig.volume, NOMINAL_RIG_ID))):
        (tmp_path / name).mkdir()
        write_manifest(tmp_path / name, Manifest(rig=take_rig, complete=True))
        with pytest.raises(DaemonConfigError, match=r"^rig\.url: .*manifest\.json: the take was recorded from "
                                                    r"opencv:// cameras without their calibration"):
            check_config(cfg(f"replay://{tmp_path / name}"))
    (tmp_path / "calibrated").mkdir()
    write_manifest(tmp_path / "calibrated", Manifest(rig=rig, complete=True))
    check_config(cfg(f"replay://{tmp_path / 'calibrated'}"))


def test_the_nominal_webcam_rig_is_marked():
    from drivers.backends.opencv import OpenCVRigSource, is_nominal_rig
    from drivers.url import RigUrl

    source = OpenCVRigSource.from_url(RigUrl.parse("opencv://?first=0&second=1"))
    rig = source._nominal_rig([(640, 480), (640, 480)])
    assert rig.metadata["uncalibrated"] is True and is_nominal_rig(rig)


def test_relative_paths_in_the_file_are_read_from_its_folder(tmp_path, monkeypatch):
    """As systemd drop-ins and docker compose read theirs: the same file works from any current directory."""
    folder = tmp_path / "etc" / "ghnerf"
    folder.mkdir(parents=True)
    path = folder / "daemon.json"
    path.write_text(json.dumps({"sinks": ["udp://127.0.0.1:9870"],
                                "estimator": {"session": {"model_dir": "../models"}},
                                "health": {"status_file": "run/status.json"}}))
    monkeypatch.chdir(tmp_path)
    config = load_daemon_config("etc/ghnerf/daemon.json")  # a relative --config: its folder, made absolute
    assert config.estimator.session.model_dir == str(folder / "../models")
    assert config.health.status_file == str(folder / "run/status.json")
    # absolute paths are kept; a key the file leaves out keeps its default (relative to the current directory,
    # where the unit's WorkingDirectory=/opt/ghnerf finds /opt/ghnerf/models)
    path.write_text(json.dumps({"sinks": ["udp://127.0.0.1:9870"], "health": {"status_file": "/run/g.json"}}))
    config = load_daemon_config(path)
    assert config.estimator.session.model_dir == "models" and config.health.status_file == "/run/g.json"
    # a value of the wrong type is still the validation's to report, by its key
    path.write_text(json.dumps({"sinks": ["udp://127.0.0.1:9870"], "health": {"status_file": 3}}))
    with pytest.raises(DaemonConfigError, match=r"health\.status_file: must be a file path or null"):
        load_daemon_config(path)


def test_relative_files_in_the_rig_url_are_read_from_the_files_folder(tmp_path, monkeypatch):
    """As the plain path keys: a take, a rig file, a video named relative in rig.url (the daemon runs in '/')."""
    from drivers.url import RigUrl

    folder = tmp_path / "etc" / "my ghnerf#2"  # a space and a '#': percent-encoded in the URL, read back as such
    folder.mkdir(parents=True)
    path = folder / "daemon.json"
    sink = "file:///var/log/joints%231.jsonl"

    def load(url: str) -> RigUrl:
        path.write_text(json.dumps({"rig": {"url": url}, "sinks": [sink]}))
        config = load_daemon_config("etc/my ghnerf#2/daemon.json")  # a relative --config: its folder, absolute
        assert config.sinks == (sink,)  # sinks take absolute paths only: as written
        return RigUrl.parse(config.rig.url)

    monkeypatch.chdir(tmp_path)
    assert load("replay://takes/walk%2301?loop=1").target == str(folder / "takes/walk#01")
    assert load("opencv://?first=takes/left.mp4&second=/dev/video2&rig=rigs/rig%20a+b.json").options == {
        "first": str(folder / "takes/left.mp4"), "second": "/dev/video2", "rig": str(folder / "rigs/rig a+b.json")}
    assert load("sim://?bvh=walk.bvh&cache=off").options == {"bvh": str(folder / "walk.bvh"), "cache": "off"}
    assert load("replay:///data/take1").target == "/data/take1"  # absolute: kept
    # not from a file (a command line, code): relative to the current directory, as the backends read it
    assert daemon_config_from_dict({"rig": {"url": "replay://takes/walk"}, "sinks": [sink]}).rig.url \
        == "replay://takes/walk"


def test_a_missing_file_in_the_rig_url_names_its_resolved_path_and_the_config_file(tmp_path, monkeypatch):
    from firmware_host.daemon.cli import read_checked_config

    folder = tmp_path / "etc"
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "x.onnx").write_bytes(b"")
    (folder / "rigs").mkdir()
    (folder / "rigs" / "rig+1.json").write_bytes(REPO_RIG.read_bytes())
    path = folder / "daemon.json"
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # where a relative path used to be read

    def write(rig_file: str) -> None:
        path.write_text(json.dumps({"rig": {"url": f"opencv://?first=0&second=2&rig={rig_file}"},
                                    "sinks": [SINK], "estimator": {"session": {"model_dir": "models"}}}))

    write("rigs/rig%2B1.json")
    read_checked_config(str(path))  # found beside the file
    write("rigs/missing.json")
    with pytest.raises(DaemonConfigError) as e:
        read_checked_config(str(path))
    assert str(e.value).startswith(f"{path}: rig.url: ")
    assert f"file {folder / 'rigs' / 'missing.json'}: cannot read rig file" in str(e.value)
    assert str(e.value).endswith(f" (a relative path in {path} is read from its folder, {folder})")


def test_the_relative_path_note_comes_only_where_the_failing_value_was_written_relative(tmp_path, monkeypatch):
    """A config under /etc/ghnerf written with absolute paths was told "(a relative path in ... is read from its
    folder ...)" for a missing model folder or rig file in that folder: the note went by the folder a path is in, not
    by how it was written. Now it comes where the value that fails was relative in the file; a rig URL's message
    quotes the whole URL (with its other paths), which does not count."""
    from firmware_host.daemon.cli import read_checked_config

    folder = tmp_path / "etc"
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "x.onnx").write_bytes(b"")
    (folder / "left.avi").write_bytes(b"")
    path = folder / "daemon.json"
    monkeypatch.chdir(tmp_path)
    note = f" (a relative path in {path} is read from its folder, {folder})"

    def error(url: str, model_dir: str) -> str:
        path.write_text(json.dumps({"rig": {"url": url}, "sinks": [SINK],
                                    "estimator": {"session": {"model_dir": model_dir}}}))
        with pytest.raises(DaemonConfigError) as e:
            read_checked_config(str(path))
        return str(e.value)

    sim = "sim://?fps=30"
    assert error(sim, str(folder / "nomodels")) == f"{path}: estimator.session.model_dir: {folder / 'nomodels'}: " \
                                                   f"no such folder"
    assert error(sim, "nomodels").endswith(f"{folder / 'nomodels'}: no such folder{note}")
    missing = folder / "missing.json"
    said = error(f"opencv://?first=left.avi&second=1&rig={missing}", "models")  # the video relative, the rig not
    assert f"file {missing}: cannot read rig file" in said and f"first={folder / 'left.avi'}" in said
    assert not said.endswith(note), said
    assert error("opencv://?first=0&second=1&rig=missing.json", "models").endswith(note)


def test_the_relative_path_note_does_not_come_for_an_option_s_error_in_a_url_its_message_escapes(tmp_path):
    """The note looked for a relative path in the message less the URL as written; the message quotes it as repr
    does, a backslash doubled, so the URL stayed, and with it the path: fps=3\\0 was told of relative paths."""
    from firmware_host.daemon.cli import read_checked_config

    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "x.onnx").write_bytes(b"")
    (tmp_path / "walk.bvh").write_bytes(b"")
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({"rig": {"url": "sim://?bvh=walk.bvh&fps=3\\0"}, "sinks": [SINK],
                                "estimator": {"session": {"model_dir": "models"}}}))
    with pytest.raises(DaemonConfigError) as e:
        read_checked_config(str(path))
    assert "option fps='3\\\\0' must be a number" in str(e.value) and "relative path" not in str(e.value), str(e.value)


@pytest.mark.parametrize("written", ["takes/wa\tlk", "takes/wa\x1b[2Jlk", "takes/wa\x85lk"])
def test_a_control_character_in_a_relative_path_of_the_config_s_rig_url_is_refused(tmp_path, written):
    """Made absolute, the path was percent-encoded, the raw character with it: a tab or ESC the command line refuses
    passed as %09 or %1B, and the daemon looked for a folder named with it (session 74)."""
    from firmware_host.daemon.cli import read_checked_config

    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "x.onnx").write_bytes(b"")
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({"rig": {"url": f"replay://{written}"}, "sinks": [SINK],
                                "estimator": {"session": {"model_dir": "models"}}}))
    with pytest.raises(DaemonConfigError) as e:
        read_checked_config(str(path))
    said = str(e.value)
    assert f"rig.url: rig URL {'replay://' + written!r}: holds a " in said and "at character 18" in said, said
    assert "relative path" not in said and len(said.splitlines()) == 1


def test_check_config_reads_a_plus_in_the_rig_file_as_the_backend_does(tmp_path):
    # parse_qs read rig=/etc/rig+1.json as '/etc/rig 1.json', which the backend (a '+' is a plus) never opens
    models = tmp_path / "models"
    models.mkdir()
    (models / "x.onnx").write_bytes(b"")
    (tmp_path / "rig+1.json").write_bytes(REPO_RIG.read_bytes())
    check_config(daemon_config_from_dict({"rig": {"url": f"opencv://?first=0&second=2&rig={tmp_path}/rig+1.json"},
                                          "sinks": [SINK], "estimator": {"session": {"model_dir": str(models)}}}))


def _doc_value(text: str):
    """A cell of the defaults column as JSON reads it (`depthai://` -> 'depthai://', 1.0, true, null)."""
    text = text.strip()
    return text.strip("`") if text.startswith("`") else json.loads(text)


def test_the_defaults_table_in_the_docs_is_the_config():
    """docs/daemon.md's table of keys and defaults names every field of ``rig`` and ``health`` with the dataclasses'
    default (nothing checked it: a changed default would have left the doc stating the old one)."""
    from dataclasses import fields

    from firmware_host.daemon.config import HealthConfig, RigConfig

    text = (REPO_RIG.parents[2] / "docs" / "daemon.md").read_text()
    table = text.split("| key | default | meaning |\n|---|---|---|\n", 1)[1].split("\n\n", 1)[0]
    documented = {}
    for row in table.splitlines():
        keys, defaults = row.split(" | ")[0].lstrip("| "), row.split(" | ")[1]
        keys = [k.strip(" `") for k in keys.split(",")]
        values = [defaults] if len(keys) == 1 else defaults.split(",")
        assert len(values) == len(keys), row
        documented.update(zip(keys, values))
    defaults = DaemonConfig(sinks=(SINK,))
    for section, cls in (("rig", RigConfig), ("health", HealthConfig)):
        for f in fields(cls):
            key = f"{section}.{f.name}"
            assert key in documented, f"docs/daemon.md's table leaves out {key}"
            assert _doc_value(documented[key]) == getattr(getattr(defaults, section), f.name), key
    assert _doc_value(documented["log_level"]) == defaults.log_level
    assert documented["sinks"].strip() == "(required)"


def test_check_config_wants_the_files_of_a_part_turned_on(tmp_path):
    """``joints3d.skeleton_prior`` / ``novel_view.painter`` ``"on"`` without their file in the model folder: the
    estimator refuses it, but it is built once the rig opens, so such a config passed ``--validate-config``, loaded
    its model and exited 2 when the camera came (or waited for ever for an absent one)."""
    models = tmp_path / "models"
    models.mkdir()
    (models / "human.onnx").write_bytes(b"not checked here")

    def cfg(**estimator):
        return daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": [SINK],
                                        "estimator": {"session": {"model_dir": str(models)}, **estimator}})

    check_config(cfg(joints3d={"skeleton_prior": "auto"}, novel_view={"enabled": True}))  # auto: used if there
    check_config(cfg(novel_view={"painter": "on"}))  # no novel view: the painter is never asked for
    with pytest.raises(DaemonConfigError, match=r"^estimator\.joints3d\.skeleton_prior: 'on', but .* has no "
                                                r"skeleton_prior\.onnx"):
        check_config(cfg(joints3d={"skeleton_prior": "on"}))
    with pytest.raises(DaemonConfigError, match=r"^estimator\.novel_view\.painter: 'on' with novel_view\.enabled, "
                                                r"but .* has no novel_painter\.onnx"):
        check_config(cfg(novel_view={"enabled": True, "painter": "on"}))
    (models / "skeleton_prior.onnx").write_bytes(b"")
    (models / "novel_painter.onnx").write_bytes(b"")
    check_config(cfg(joints3d={"skeleton_prior": "on"}, novel_view={"enabled": True, "painter": "on"}))
    # fp32 asks for the fp32 painter, as the session loads it (NovelPainter.find)
    (models / "novel_painter.onnx").unlink()
    (models / "novel_painter.int8.onnx").write_bytes(b"")
    check_config(cfg(novel_view={"enabled": True, "painter": "on"}))
    with pytest.raises(DaemonConfigError, match=r"^estimator\.novel_view\.painter"):
        check_config(cfg(session={"model_dir": str(models), "precision": "fp32"},
                         novel_view={"enabled": True, "painter": "on"}))


_LOAD_UNDER_A_MEMORY_CAP = """
import resource, sys
from firmware_host.daemon.config import DaemonConfigError, load_daemon_config
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))  # a device's memory, and this host's kept safe
try:
    load_daemon_config(sys.argv[1])
except DaemonConfigError as e:
    print(e)
"""


@pytest.mark.parametrize("what", ["big file", "device"])
def test_a_file_far_bigger_than_a_config_or_a_device_is_refused_unread(tmp_path, what):
    """Another file given as the config (a take's frames, /dev/zero) was read whole, at the start and at every reload:
    the memory ran out (MemoryError, exit 1: restarted into the same read) or, a device, the read never ended. As
    a rig file, a config file holds at most 1 MiB; the size is known before the read."""
    import subprocess
    import sys

    path = tmp_path / "frames.jsonl"
    if what == "big file":
        with open(path, "wb") as fh:
            fh.truncate(4 << 30)  # sparse: no disk written
    else:
        path = Path("/dev/zero")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    done = subprocess.run([sys.executable, "-c", _LOAD_UNDER_A_MEMORY_CAP, str(path)], capture_output=True,
                          text=True, timeout=120, env=env, cwd=Path(__file__).resolve().parents[3])
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr[-2000:]
    assert done.stdout.startswith(f"{path}: ") and ("1 MiB" in done.stdout or "device" in done.stdout), done.stdout


def test_the_size_cap_reads_the_file_a_link_names_and_leaves_a_pipe_to_the_read(tmp_path):
    """The cap is the named file's, through a symlink (a link's own size is its target's name); a pipe
    (``--config <(...)``), which has no size, is read as before, as docs/daemon.md says."""
    import threading

    big = tmp_path / "frames.jsonl"
    with open(big, "wb") as fh:
        fh.truncate(2 << 20)  # sparse: read whole, it would be "not valid JSON", not refused for its size
    link = tmp_path / "daemon.json"
    link.symlink_to(big)
    with pytest.raises(DaemonConfigError, match=r"holds 2097152 bytes, over the 1048576 \(1 MiB"):
        load_daemon_config(link)
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    writer = threading.Thread(target=fifo.write_text, args=('{"sinks": ["memory://"]}',), daemon=True)
    writer.start()
    assert load_daemon_config(fifo).sinks == ("memory://",)
    writer.join(timeout=10)


def test_a_pipe_longer_than_a_config_is_refused_after_a_bounded_read(tmp_path):
    """A pipe has no size for the stat check: one that carries more than a config may (another program's output
    given as ``--config <(...)``) is refused after reading one character past the cap, not read whole."""
    import threading

    from firmware_host.daemon.config import MAX_CONFIG_FILE_BYTES

    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    written = []

    def write_far_past_the_cap() -> None:
        try:
            with open(fifo, "w") as fh:
                for _ in range(8):  # 8 MiB in all, if the reader took it
                    fh.write(" " * MAX_CONFIG_FILE_BYTES)
                    written.append(MAX_CONFIG_FILE_BYTES)
        except BrokenPipeError:  # the reader stopped: what it did not take was never read
            pass

    writer = threading.Thread(target=write_far_past_the_cap, daemon=True)
    writer.start()
    with pytest.raises(DaemonConfigError, match=rf"holds over {MAX_CONFIG_FILE_BYTES} characters") as caught:
        load_daemon_config(fifo)
    assert str(caught.value).startswith(f"{fifo}: ")
    writer.join(timeout=30)
    assert not writer.is_alive() and sum(written) < 8 * MAX_CONFIG_FILE_BYTES
