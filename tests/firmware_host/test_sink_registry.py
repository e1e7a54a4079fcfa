"""open_sink(): scheme registry, lazy imports, typed configuration errors."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from firmware_host.errors import SinkConfigError
from firmware_host.sinks import BACKENDS, Sink, check_sink_url, open_sink, sink_class
from firmware_host.sinks.registry import STAND_IN_CAMERAS


def test_every_scheme_resolves_to_its_backend() -> None:
    for scheme in BACKENDS:
        assert sink_class(f"{scheme}://x").scheme == scheme


def test_importing_sinks_loads_no_backend_library() -> None:
    code = (
        "import sys, firmware_host.sinks, firmware_host.protocol;"
        "print(sorted(m for m in ('serial', 'usb', 'pythonosc', 'libusb_package') if m in sys.modules))"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root).stdout
    assert out.strip() == "[]"


@pytest.mark.parametrize(
    ("url", "kw", "field", "value"),
    [
        ("ftp://host", {}, "scheme", "ftp"),
        ("joints", {}, "scheme", ""),
        ("serial:///dev/ttyACM0?baud=fast", {}, "baud", "fast"),
        ("serial:///dev/ttyACM0?baud=-9600", {}, "baud", "-9600"),
        ("serial:///dev/ttyACM0?bauds=9600", {}, "bauds", "9600"),
        ("serial:///dev/ttyACM0?baud=1&baud=2", {}, "baud", ["1", "2"]),
        ("serial://", {}, "port", ""),
        ("usb://1209:0001", {}, "ep", None),
        ("usb://1209:0001?ep=0x81", {}, "ep", "0x81"),
        ("usb://12345", {"ep": 1}, "VID:PID", "12345"),
        ("udp://127.0.0.1", {}, "port", ""),  # the port as written (the whole location before session 58)
        ("udp://:9000", {}, "host", ""),
        ("memory://?queue=0", {}, "queue", "0"),
        ("memory://", {"rig_id": "caf\u00e9"}, "rig_id", "caf\u00e9"),
        ("memory://", {"colour": "red"}, "colour", "red"),
        ("memory://?send_2d=maybe", {}, "send_2d", "maybe"),
        ("serial:///dev/ttyACM0", {"baud": 0}, "baud", 0),
        ("memory://", {"max_fps": -1.0}, "max_fps", -1.0),
        # inf overflowed the STATUS deadline in the worker, and 1e12 passed threading's longest wait:
        # the sink never connected, or its worker died with frames queued
        ("memory://?status_s=inf", {}, "status_s", "inf"),
        ("memory://?status_s=1e12", {}, "status_s", 1e12),
        # no floor: an idle sink sent ~1000 HELLO + STATUS a second; no ceiling: the queue grew through an outage
        ("memory://?status_s=1e-300", {}, "status_s", 1e-300),
        ("memory://?status_s=0.0099", {}, "status_s", 0.0099),
        ("memory://?queue=100000000000000000000000", {}, "queue", 10**23),
        ("memory://", {"queue": 4097}, "queue", 4097),
        ("memory://?fps=nan", {}, "fps", "nan"),
        ("udp://[::1:9870", {}, "url", "udp://[::1:9870"),
        # a fragment was dropped: the file went to /tmp/run; a host made a relative path of localhost/...
        ("file:///tmp/run#2/joints.jsonl", {}, "fragment", "2/joints.jsonl"),
        ("udp://127.0.0.1:9870#robot", {}, "fragment", "robot"),
        ("file://robot/var/joints.jsonl", {}, "host", "robot"),
        ("file://", {}, "path", ""),
        # vmc:// has no HELLO, STATUS or JOINTS_2D: these were accepted and ignored
        ("vmc://127.0.0.1?send_2d=1&cameras=left,right", {}, "cameras", "left,right"),
        ("vmc://127.0.0.1?status_s=5", {}, "status_s", "5"),
        ("vmc://127.0.0.1?rig_id=stage", {}, "rig_id", "stage"),
        ("vmc://127.0.0.1?joint_count=25", {}, "joint_count", "25"),
        # the avatar's view: a word from its list, exactly; yes/no for mirror; neither on other sinks
        ("vmc://127.0.0.1?facing=front", {}, "facing", "front"),
        ("vmc://127.0.0.1?facing=Camera", {}, "facing", "Camera"),
        ("vmc://127.0.0.1?facing=", {}, "facing", ""),
        ("vmc://127.0.0.1", {"facing": True}, "facing", True),
        ("vmc://127.0.0.1?mirror=maybe", {}, "mirror", "maybe"),
        ("vmc://127.0.0.1?mirror=1&facing=camera", {"mirror": "2"}, "mirror", "2"),
        ("udp://127.0.0.1:9870?mirror=1", {}, "mirror", "1"),
        ("vmc://127.0.0.1?calibration_flag=maybe", {}, "calibration_flag", "maybe"),
        ("udp://127.0.0.1:9870?calibration_flag=0", {}, "calibration_flag", "0"),
        ("memory://?facing=camera", {}, "facing", "camera"),
        # given empty or with an empty item, read without a word: cameras=a,,b dropped the empty name (b announced
        # as camera 1, not 2), rig_id= and cameras= read as left out; a name twice sent the second camera as the first
        ("memory://?cameras=a,,b", {}, "cameras", "a,,b"),
        ("memory://?cameras=left,", {}, "cameras", "left,"),
        ("memory://?cameras=", {}, "cameras", ""),
        ("memory://?cameras", {}, "cameras", ""),
        ("memory://?send_2d=1&cameras=left,left", {}, "cameras", "left,left"),
        ("memory://?cameras=left,%20right", {}, "cameras", "left, right"),
        ("memory://", {"cameras": ("left", "")}, "cameras", ("left", "")),
        ("memory://", {"cameras": ("left", "left")}, "cameras", ("left", "left")),
        ("memory://?rig_id=", {}, "rig_id", ""),
        ("memory://?rig_id", {}, "rig_id", ""),
        ("memory://", {"rig_id": ""}, "rig_id", ""),
    ],
)
def test_config_errors_name_url_field_and_value(url: str, kw: dict, field: str, value: object) -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink(url, **kw)
    err = info.value
    assert isinstance(err, ValueError)
    assert (err.url, err.field, err.value) == (url, field, value)
    assert url in str(err) and field in str(err)


def test_the_bounds_of_status_s_and_queue_are_named_and_their_ends_accepted() -> None:
    from firmware_host.sinks.options import MAX_QUEUE, MAX_STATUS_S, MIN_STATUS_S

    with pytest.raises(SinkConfigError, match=r"status_s=1e-300: must be in \[0\.01, 3600\] seconds"):
        open_sink("memory://?status_s=1e-300")
    with pytest.raises(SinkConfigError, match=rf"queue=4097: must be in \[1, {MAX_QUEUE}\] frames"):
        open_sink("memory://?queue=4097")
    for url in (f"memory://?status_s={MIN_STATUS_S}&queue={MAX_QUEUE}", f"memory://?status_s={MAX_STATUS_S}&queue=1"):
        open_sink(url).close()


@pytest.mark.parametrize("url, field, value, says", [
    ("memory://?queue=08", "queue", "08", "decimal digits expected, without a leading zero (write 8;"),
    ("memory://?queue=010", "queue", "010", "(write 10;"),
    ("memory://?joint_count=025", "joint_count", "025", "(write 25;"),
    ("memory://?joint_count=-025", "joint_count", "-025", "without a sign"),
    ("usb://1209:0001?ep=01", "ep", "01", "without a leading zero (write 1; hex as 0x..)"),
    ("memory://?queue=1e3", "queue", "1e3", "expected a whole number: decimal digits, or hex as 0x.."),
])
def test_an_integer_that_does_not_parse_says_what_is_expected(url: str, field: str, value: str, says: str) -> None:
    """queue=08 said "invalid literal for int() with base 0: '08'" (Python refuses a leading zero there)."""
    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert (info.value.field, info.value.value) == (field, value)
    assert says in str(info.value) and "base 0" not in str(info.value)


@pytest.mark.parametrize("url, says", [
    ("memory://?cameras=a,,b", "camera 1 has an empty name"),
    ("memory://?cameras=", "empty: give the camera names in index order"),
    ("memory://?cameras=left,left", "camera name 'left' is given twice"),
    ("memory://?cameras=left,%20right", "name ' right' has spaces around it"),
    ("memory://?rig_id=", "empty: give the id HELLO announces, or leave rig_id out"),
])
def test_an_empty_or_malformed_name_says_what_is_wrong(url: str, says: str) -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert says in str(info.value)


def test_camera_names_and_rig_id_given_well_are_taken_in_order() -> None:
    """The refusals above leave names as they were: in order, a space inside a name kept."""
    sink = open_sink("memory://?send_2d=1&cameras=left,cam%202,right&rig_id=bench%201")
    try:
        assert sink.options.cameras == ("left", "cam 2", "right")
        assert sink.options.rig_id == "bench 1"
    finally:
        sink.close()
    # a keyword's names (the rig's own, as the daemon passes them) are taken as named, spaces and all
    sink = open_sink("memory://", cameras=(" left", "right"))
    try:
        assert sink.options.cameras == (" left", "right")
    finally:
        sink.close()


def test_a_full_queue_stays_within_its_memory_bound() -> None:
    """MAX_QUEUE frames of the largest kind (64 joints, both cameras' 2D joints, float64) held as a sink's queue
    holds them: the figure docs/protocol.md quotes for a long outage (~11 MiB for BODY_25, ~23 MiB at 64)."""
    import tracemalloc
    from collections import deque

    import numpy as np

    from firmware_host.protocol.messages import JointFrame
    from firmware_host.sinks.options import MAX_QUEUE

    used = {}
    for joints in (25, 64):
        tracemalloc.start()
        try:
            queue = deque([JointFrame(k, k, 0, np.zeros((joints, 4)), {0: np.zeros((joints, 3)),
                                                                      1: np.zeros((joints, 3))}), 0]
                          for k in range(MAX_QUEUE))
            used[joints] = tracemalloc.get_traced_memory()[0] / (1 << 20)
        finally:
            tracemalloc.stop()
        assert len(queue) == MAX_QUEUE
    assert used[25] < 12 and used[64] < 24, used  # measured 11.1 and 23.2 MiB (numpy 2, CPython 3.11)


def test_keywords_override_the_query() -> None:
    sink = open_sink("serial:///dev/null-not-a-port?baud=9600", baud=921600)
    try:
        assert sink.baud == 921600  # type: ignore[attr-defined]
    finally:
        sink.close()


def test_vmc_default_port() -> None:
    sink = open_sink("vmc://127.0.0.1")
    try:
        assert sink._link.port == 39539  # type: ignore[attr-defined]
    finally:
        sink.close()


def test_vmc_takes_the_rig_s_id_and_cameras_as_keywords() -> None:
    # the daemon hands every sink the rig's id and camera names; vmc:// just does not use them
    sink = open_sink("vmc://127.0.0.1?max_fps=60", rig_id="stage", cameras=("left", "right"))
    try:
        assert sink.scheme == "vmc"
    finally:
        sink.close()


def test_vmc_names_every_protocol_option_it_refuses() -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink("vmc://127.0.0.1?send_2d=1&status_s=5")
    assert "send_2d, status_s" in str(info.value)


@pytest.mark.parametrize("url, kw, facing, mirror", [
    ("vmc://127.0.0.1", {}, "away", False),  # the defaults: what vmc:// sent before the options existed
    ("vmc://127.0.0.1?facing=camera&mirror=1", {}, "camera", True),
    ("vmc://127.0.0.1?mirror=on&facing=away", {}, "away", True),
    ("vmc://127.0.0.1?mirror=1", {"mirror": False, "facing": "camera"}, "camera", False),  # keywords win
])
def test_vmc_takes_facing_and_mirror(url: str, kw: dict, facing: str, mirror: bool) -> None:
    from firmware_host.sinks.vmc_view import AvatarView

    sink = open_sink(url, **kw)
    try:
        assert sink.view == AvatarView(facing=facing, mirror=mirror)  # type: ignore[attr-defined]
    finally:
        sink.close()


@pytest.mark.parametrize(("url", "said"), [
    # urlsplit removes a tab, CR or LF from anywhere in a URL: another file written, another rate or port used
    ("file:///tmp/a\tb.jsonl", "holds a tab at character 14, which URL parsing drops; remove it, or write it as %09"),
    ("serial:///dev/ttyACM0?baud=96\n00", "holds a line feed at character 30"),
    ("udp://127.0.0.1:98\r70", "holds a carriage return at character 19"),
    ("memory://?queue=8\n", "holds a line feed at character 18"),
])
def test_a_tab_or_line_break_that_url_parsing_drops_is_refused_as_rig_urls_refuse_it(url: str, said: str) -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert (info.value.field, info.value.value) == ("url", url) and said in str(info.value)


@pytest.mark.parametrize(("url", "said"), [
    # kept by urlsplit, each reached the daemon's STATUS line and status-file keys raw (session 74)
    ("file:///tmp/a\x1b]0;x\x07b.jsonl", "holds a control character (U+001B) at character 14, which logs and "
                                        "terminals would act on or hide; remove it, or write it as %1B"),
    ("memory://a\x0bb", "(U+000B) at character 11"),
    ("udp://127.0.0.1:90\x1b[2J00", "(U+001B) at character 19"),  # its [ was read as a broken IPv6 host
    ("udp://127.0.0.1:9000?x=\x00", "(U+0000) at character 24"),
    ("serial:///dev/ttyACM0\x7f", "(U+007F) at character 22"),
    ("udp://127.0.0.1:9000\x9b", "(U+009B) at character 21, which logs and terminals would act on or hide; remove "
                                 "it, or write it as %C2%9B"),
])
def test_every_other_control_character_is_refused_as_rig_urls_refuse_it(url: str, said: str) -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert (info.value.field, info.value.value) == ("url", url) and said in str(info.value), str(info.value)
    assert str(info.value).startswith(repr(url) + ": invalid url=")  # escaped, on one line


@pytest.mark.parametrize(("url", "said"), [
    # no C0/C1 control, so taken before: the STATUS line and logs broke at the separator, or showed the bidi
    # control's path in another order than the file written
    ("file:///tmp/a\u2028b.jsonl", "holds a line separator (U+2028) at character 14, which logs and editors break "
                                   "the line at; remove it, or write it as %E2%80%A8"),
    ("udp://127.0.0.1:9000?x=\u2029", "holds a paragraph separator (U+2029) at character 24"),
    ("file:///tmp/\u202elmth.jsonl", "holds a bidirectional-text control (U+202E) at character 13"),
    ("memory://a\u2066b", "holds a bidirectional-text control (U+2066) at character 11"),
    ("serial:///dev/ttyACM0\u200f", "holds a bidirectional-text control (U+200F) at character 22"),
])
def test_a_line_separator_or_bidi_control_is_refused_as_rig_urls_refuse_it(url: str, said: str) -> None:
    with pytest.raises(SinkConfigError) as info:
        open_sink(url)
    assert (info.value.field, info.value.value) == ("url", url) and said in str(info.value), str(info.value)
    assert str(info.value).startswith(repr(url) + ": invalid url=")  # escaped, on one line


@pytest.mark.parametrize("url", ["serial:///dev/ghnerf-no-such-port?baud=921600", "udp://127.0.0.1:9870",
                                 "file:///nonexistent-folder/j.jsonl", "usb://1209:0001?ep=0x01"])
def test_check_sink_url_passes_a_good_url_opening_nothing(url, monkeypatch) -> None:
    """The config check (daemon, demo) builds the sink without starting it: a port not there or busy yet passes."""
    def never(self):
        raise AssertionError(f"{url} was started by the check")

    monkeypatch.setattr(Sink, "start", never)
    assert check_sink_url(url, cameras=STAND_IN_CAMERAS) is None


@pytest.mark.parametrize(("url", "field"), [("bogus://x", "scheme"), ("udp://", "host"),
                                            ("serial:///dev/ttyS0?baud=fast", "baud"),
                                            ("memory://?colour=red", "colour")])
def test_check_sink_url_refuses_what_open_sink_refuses(url, field) -> None:
    with pytest.raises(SinkConfigError) as e:
        check_sink_url(url)
    assert e.value.field == field and str(e.value).startswith(f"{url}: invalid {field}=")
