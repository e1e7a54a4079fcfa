"""``ghnerf-listen``: the receiving end, over a real UDP socket and a real pty, fed by the real sinks."""
from __future__ import annotations

import errno
import io
import os
import socket
import threading
import time

import pytest

from firmware_host import listen
from firmware_host.sinks import open_sink
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame


def test_udp_summary_counts_what_the_sink_sent():
    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)
    host, number = port.address
    out = io.StringIO()
    result: list = []
    thread = threading.Thread(target=lambda: result.append(listen.listen(port, seconds=1.5, as_json=False, out=out,
                                                                         every_s=0.5)))
    thread.start()
    try:
        with open_sink(f"udp://{host}:{number}?status_s=0.2&queue=16", backoff=FAST_BACKOFF, rig_id="bench",
                       cameras=("left", "right")) as sink:
            for seq in (0, 1, 2, 5, 6):  # 3 and 4 skipped by the sender
                sink.send(make_frame(seq))
        thread.join(timeout=10)
    finally:
        port.close()
    tally = result[0]
    assert tally.total_joints == 5 and tally.total_gaps == 2
    assert tally.hello is not None and tally.hello.rig_id == "bench" and tally.hello.cameras == ("left", "right")
    text = out.getvalue()
    assert "JOINTS/s" in text and "25.0 joints present" in text and "rig 'bench'" in text


def test_serial_device_path_is_percent_decoded_as_the_sink_decodes_it(tmp_path):
    """A udev by-id name with a '#' is written %23 in a URL; the listener opens the decoded path."""
    master, slave = os.openpty()
    link = tmp_path / "usb-Robot#1-if00"
    link.symlink_to(os.ttyname(slave))
    port = listen.open_port(f"serial://{str(tmp_path)}/usb-Robot%231-if00?baud=115200")
    try:
        assert port.port.port == str(link)
    finally:
        port.close()
        os.close(master)
        os.close(slave)


def test_a_baud_termios_cannot_take_is_refused_on_a_real_tty(capsys):
    """On a tty (not /dev/null, which fails to open anyway) a baud past 2**31 - 1 reached pyserial's
    OverflowError: a traceback and exit 1 instead of the one-line exit 2 the sink's bounds give."""
    master, slave = os.openpty()
    try:
        assert listen.main([f"serial://{os.ttyname(slave)}?baud={2**31}", "--seconds", "0.1"]) == 2
    finally:
        os.close(master)
        os.close(slave)
    err = capsys.readouterr().err.strip()
    assert err.startswith("ghnerf-listen: error: ") and "baud must be in [50, 2147483647]" in err


def test_serial_json_lines_over_a_pty():
    master, slave = os.openpty()
    name = os.ttyname(slave)
    port = listen.open_port(f"serial://{name}?baud=115200")
    sink = open_sink("memory://", rig_id="pty")
    try:
        sink.send(make_frame(7))
        sink.close()
        os.write(master, b"\x00garbage\x00" + sink.read())  # line noise first: it is counted, then skipped
        out = io.StringIO()
        tally = listen.listen(port, seconds=0.5, as_json=True, out=out)
    finally:
        port.close()
        os.close(master)
        os.close(slave)
    lines = out.getvalue().splitlines()
    assert any('"type": "JOINTS"' in line and '"seq": 7' in line for line in lines)
    assert any('"error"' in line for line in lines)
    assert tally.total_joints == 1


@pytest.mark.parametrize("url, message", [
    ("udp://127.0.0.1", "give the port"),
    ("tcp://x:1", "reads udp:// or serial://"),
    ("serial://", "give the device"),
    ("serial:///dev/nonexistent-ghnerf?baud=9600", "cannot open"),
    ("serial:///dev/null?baud=fast", "baud must be"),
    # the serial sink's bounds: past 2**31 - 1 pyserial raised OverflowError (a traceback, exit 1); 0 opened
    ("serial:///dev/null?baud=2147483648", "baud must be in [50, 2147483647]"),
    ("serial:///dev/null?baud=0", "baud must be in [50, 2147483647]"),
    # ignored: the port opened at 115200, the user believing 921600
    ("serial:///dev/null?baudrate=921600", "unknown parameter baudrate; it takes baud"),
    ("udp://127.0.0.1:0?baud=9600&x=", "unknown parameter baud, x; it takes none"),
    # a fragment was dropped, and what followed it: /dev/null opened at 115200 for ?baud=9600, and a by-id
    # name's '#' cut the device path short (the sinks refuse it too)
    ("serial:///dev/null#1?baud=9600", "a '#' ends the URL (the rest, '1?baud=9600', would be ignored)"),
    ("udp://127.0.0.1:9870#robot", "write a '#' in a device path as %23"),
    # decoded to U+FFFD, the listener opened /dev/tty\ufffd, and "cannot open" named a device never given
    ("serial:///dev/tty%FF?baud=9600", "the device /dev/tty%FF holds %FF, which is not UTF-8"),
    # pyserial's ValueError ("embedded null byte") was caught as "cannot open": refused as other odd paths are
    ("serial:///dev/tty%00", "the device '/dev/tty\\x00': holds a NUL byte"),
    ("serial:///dev/" + "t" * 256, "has a name of 256 bytes; a file or folder name has at most 255"),
    # urlsplit drops a tab, CR or LF: udp://...:98<LF>70 listened on 9870 without a word (the sinks' rule, shown
    # escaped: the URL as written split the one-line error)
    ("udp://127.0.0.1:98\n70", "'udp://127.0.0.1:98\\n70': holds a line feed at character 19, which URL parsing "
                                "drops; remove it, or write it as %0A"),
    ("serial:///dev/null?baud=96\t00", "holds a tab at character 27"),
    ("udp://viewer:s3cret@127.0.0.1:98\r70", "'udp://viewer:***@127.0.0.1:98\\r70': holds a carriage return"),
    # urlsplit reads past the tab to a password: hidden in the refusal too (redact_url matched '://' as written)
    ("udp:/\t/viewer:s3cret@127.0.0.1:9870", "'udp:/\\t/viewer:***@127.0.0.1:9870': holds a tab at character 6"),
    # any other control character: kept by urlsplit, printed raw (an ESC sequence rewrote the terminal; session 74)
    ("udp://127.0.0.1:98\x1b[2J70", "'udp://127.0.0.1:98\\x1b[2J70': holds a control character (U+001B) at "
                                    "character 19, which logs and terminals would act on or hide"),
    ("serial:///dev/null\x85?baud=9600", "'serial:///dev/null\\x85?baud=9600': holds a control character (U+0085)"),
    # no C0/C1 control, so taken before: the separator broke the line, the bidi control reordered it
    ("udp://127.0.0.1:98\u202870", "'udp://127.0.0.1:98\\u202870': holds a line separator (U+2028) at character 19"),
    ("serial:///dev/null\u202e?baud=9600", "'serial:///dev/null\\u202e?baud=9600': holds a bidirectional-text "
                                           "control (U+202E) at character 19"),
    # written as %1B: decoded, the device (and pyserial's words quoting it) reached the terminal raw at the open
    ("serial:///dev/ghnerf-none%1B%5B2J?baud=9600", "serial://'/dev/ghnerf-none\\x1b[2J': cannot open: "),
])
def test_bad_urls_are_one_line_exit_2(url, message, capsys):
    assert listen.main([url, "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("ghnerf-listen: error: ") and message in err and "\n" not in err and "\r" not in err
    assert "\x1b" not in err and "\x85" not in err and "\u2028" not in err and "\u202e" not in err
    assert "s3cret" not in err


def test_sequence_numbers_wrap_and_errors_are_per_line():
    from firmware_host.protocol.messages import Joints, make_header
    from firmware_host.protocol.constants import MsgType
    import numpy as np

    tally = listen.Tally()

    def joints(seq: int) -> Joints:
        return Joints(make_header(MsgType.JOINTS, seq, 0, 1000), 0, np.zeros((25, 3), np.int16),
                      np.zeros(25, np.uint8), np.zeros(25, bool))

    for seq in (2**32 - 2, 2**32 - 1, 1):  # 0 skipped across the wrap
        tally.add(joints(seq))
    assert tally.total_gaps == 1
    tally.add(joints(5))
    tally.add(joints(3))  # a step back (reordering, a sender restart) is not 4 billion gaps; 3 came late after all
    assert tally.total_gaps == 3 and tally.total_late == 1
    tally.add(joints(6))  # 5 was the newest: 3 arrived late, so 3 -> 6 is no second gap of 4 and 5
    assert tally.total_gaps == 3
    restarted = listen.Tally()
    for seq in (500, 501, 0, 1, 3):  # a sender that restarted: its numbering is followed from there
        restarted.add(joints(seq))
    assert restarted.total_gaps == 1 and restarted.last_seq == 3
    first = tally.line(1.0, {"crc": 2, "cobs": 0})
    second = tally.line(1.0, {"crc": 2, "cobs": 0})
    assert "decode errors {'crc': 2}" in first and "decode errors" not in second


def _joints(seq: int):
    from firmware_host.protocol.constants import MsgType
    from firmware_host.protocol.messages import Joints, make_header
    import numpy as np

    return Joints(make_header(MsgType.JOINTS, seq, 0, 1000), 0, np.zeros((25, 3), np.int16), np.zeros(25, np.uint8),
                  np.zeros(25, bool))


def test_a_late_datagram_is_counted_late_and_takes_its_gap_out_of_the_loss():
    tally = listen.Tally()
    for seq in (0, 1, 3):
        tally.add(_joints(seq))
    first = tally.line(1.0, {})  # 2 is missing at the end of this second
    for seq in (2, 4, 4):  # 2 arrives late (reordered on the link), 4 twice
        tally.add(_joints(seq))
    second = tally.line(1.0, {})
    assert "1 seq gaps" in first and "late (" not in first
    assert "0 seq gaps; 1 late (reordered); 1 duplicate" in second
    assert (tally.total_gaps, tally.total_late, tally.total_duplicates, tally.last_seq) == (0, 1, 1, 4)
    tally.add(_joints(7))
    tally.add(_joints(6))  # within one summary: skipped and back, no gap in its line either
    assert "1 seq gaps; 1 late (reordered)" in tally.line(1.0, {}) and tally.total_gaps == 1


def test_the_late_window_bounds_what_counts_late():
    tally = listen.Tally()
    for seq in (100, 99):  # sent before the first seq heard: late, never counted lost
        tally.add(_joints(seq))
    assert (tally.total_gaps, tally.total_late) == (0, 1)
    tally.add(_joints(100 + 1 + 50))  # 50 lost
    tally.add(_joints(151 - listen.LATE_WINDOW))  # the oldest seq that can still come late
    assert (tally.total_gaps, tally.total_late, tally.last_seq) == (49, 2, 151)
    tally.add(_joints(151 - listen.LATE_WINDOW - 1))  # further back: a sender that restarted, followed from there
    assert (tally.total_gaps, tally.total_late, tally.last_seq) == (49, 2, 151 - listen.LATE_WINDOW - 1)
    wrap = listen.Tally()
    for seq in (2**32 - 2, 1, 2**32 - 1, 0):  # across the wrap, both skipped seqs arrive late
        wrap.add(_joints(seq))
    assert (wrap.total_gaps, wrap.total_late, wrap.last_seq) == (0, 2, 1)


def _hello(seq: int):
    from firmware_host.protocol.constants import CoordFrame, JointSet, MsgType, PROTOCOL_VERSION, Units
    from firmware_host.protocol.messages import Hello, make_header

    return Hello(make_header(MsgType.HELLO, seq, 0, 1000), PROTOCOL_VERSION, int(JointSet.BODY_25), 25,
                 int(Units.MILLIMETRES), int(CoordFrame.RIG), "rig", ("left", "right"))


def test_a_hello_of_a_sender_with_no_frame_yet_starts_a_new_numbering():
    from firmware_host.protocol.constants import NO_FRAME_SEQ

    restarted = listen.Tally()
    for seq in (28, 29, 30):
        restarted.add(_joints(seq))
    restarted.add(_hello(NO_FRAME_SEQ))  # a new process, within LATE_WINDOW of the old seq
    for seq in (0, 1, 2, 5):
        restarted.add(_joints(seq))
    assert (restarted.total_gaps, restarted.total_late, restarted.last_seq) == (2, 0, 5)
    first_lost = listen.Tally()  # heard from its HELLO on: a first JOINTS of 3 means 0, 1 and 2 were lost
    first_lost.add(_hello(NO_FRAME_SEQ))
    first_lost.add(_joints(3))
    first_lost.add(_joints(1))  # one of them late after all
    assert (first_lost.total_gaps, first_lost.total_late, first_lost.last_seq) == (2, 1, 3)
    reopened = listen.Tally()  # an output reopened by the same sender: its HELLO carries the last frame, no reset
    for seq in (28, 30):
        reopened.add(_joints(seq))
    reopened.add(_hello(30))
    reopened.add(_joints(29))
    assert (reopened.total_gaps, reopened.total_late, reopened.last_seq) == (0, 1, 30)


def test_a_stray_datagram_without_delimiter_costs_only_itself():
    from firmware_host.protocol import decode_stream, encode
    from firmware_host.protocol.messages import Joints, make_header
    from firmware_host.protocol.constants import MsgType
    import numpy as np

    msg = Joints(make_header(MsgType.JOINTS, 7, 0, 1000), 0, np.zeros((25, 3), np.int16),
                 np.zeros(25, np.uint8), np.zeros(25, bool))
    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(b"/VMC/Ext/OK,i\x01", port.address)  # e.g. a VMC sender pointed at this port
            tx.sendto(encode(msg), port.address)
        events, stats = decode_stream(port.read(2.0) + port.read(2.0))
    finally:
        port.close()
    # it was glued to the JOINTS datagram behind it: one crc error, and the frame lost with it
    assert [e.to_json().get("type") for e in events] == [None, "JOINTS"] and stats.messages == 1


def _datagram_reaches(port, family: int, address: str) -> bool:
    """Send one datagram from a ``family`` socket to ``address`` and the port's number; True if it is read."""
    with socket.socket(family, socket.SOCK_DGRAM) as tx:
        tx.sendto(b"\x00ping\x00", (address, port.address[1]))
    return port.read(2.0) == b"\x00ping\x00"


def test_udp_on_every_interface_hears_ipv4_and_ipv6_senders():
    # udp://localhost sinks used to send to ::1 (glibc's first answer on many hosts) and nobody heard them
    port = listen.open_port("udp://:0", ephemeral=True)
    try:
        if port.sock.family == socket.AF_INET6:
            assert port.sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY) == 0
            assert _datagram_reaches(port, socket.AF_INET6, "::1")
        assert _datagram_reaches(port, socket.AF_INET, "127.0.0.1")
    finally:
        port.close()
    if not socket.has_ipv6:
        pytest.skip("no IPv6 here: only the IPv4 fallback was checked")
    assert port.sock.family == socket.AF_INET6


def test_udp_on_every_interface_falls_back_to_ipv4_without_ipv6(monkeypatch):
    real_socket = socket.socket

    def no_ipv6(family=socket.AF_INET, *args, **kwargs):
        if family == socket.AF_INET6:
            raise OSError(errno.EAFNOSUPPORT, "Address family not supported by protocol")
        return real_socket(family, *args, **kwargs)

    monkeypatch.setattr(listen.socket, "socket", no_ipv6)
    port = listen.open_port("udp://:0", ephemeral=True)
    try:
        assert port.sock.family == socket.AF_INET and port.address[0] == "0.0.0.0"
        assert _datagram_reaches(port, socket.AF_INET, "127.0.0.1")
    finally:
        port.close()


def test_udp_on_an_ipv6_literal():
    if not socket.has_ipv6:
        pytest.skip("no IPv6 here")
    port = listen.open_port("udp://[::1]:0", ephemeral=True)
    try:
        assert port.sock.family == socket.AF_INET6 and _datagram_reaches(port, socket.AF_INET6, "::1")
    finally:
        port.close()


def test_the_listener_and_the_udp_sink_pick_a_name_s_address_by_one_rule(monkeypatch: pytest.MonkeyPatch) -> None:
    from firmware_host import addresses
    from firmware_host.sinks import udp_sink

    v6, v4 = ("::1", 9870, 0, 0), ("127.0.0.1", 9870)
    infos = [(socket.AF_INET6, socket.SOCK_DGRAM, 17, "", v6), (socket.AF_INET, socket.SOCK_DGRAM, 17, "", v4)]
    assert addresses.ipv4_first(infos) == (socket.AF_INET, v4)
    assert addresses.ipv4_first(infos[:1]) == (socket.AF_INET6, v6)
    used: list[object] = []

    def spy(answer, *keep):
        used.append(answer)
        return addresses.ipv4_first(answer, *keep)

    monkeypatch.setattr(listen, "ipv4_first", spy)
    monkeypatch.setattr(udp_sink, "ipv4_first", spy)
    udp_sink.resolve("udp://localhost:0", "localhost", 0)
    listen._bind("127.0.0.1", 0).close()
    assert len(used) == 2  # both went through the shared rule


def test_the_scheme_is_case_insensitive():
    port = listen.open_port("UDP://127.0.0.1:0", ephemeral=True)
    try:
        host, number = port.address
        assert host == "127.0.0.1" and number > 0  # bound as udp://, the system's port read back
    finally:
        port.close()


@pytest.mark.parametrize("group", ["239.255.77.1", "[ff05::77]"])
def test_udp_on_a_multicast_group_joins_it(group):
    # A socket bound to a group's address, without joining it, heard nothing a udp:// sink sent to the group.
    family = socket.AF_INET6 if ":" in group else socket.AF_INET
    try:
        port = listen.open_port(f"udp://{group}:0", ephemeral=True)
    except listen.ListenError as e:
        pytest.skip(f"no multicast here: {e}")
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as probe:
            try:
                probe.sendto(b"", (group.strip("[]"), 9))
            except OSError as e:  # no route for multicast on this host (a bare container)
                pytest.skip(f"cannot send multicast here: {e}")
        assert _datagram_reaches(port, family, group.strip("[]"))
    finally:
        port.close()


def test_the_help_names_the_counters_in_the_words_the_line_prints(capsys):
    """``--help`` says what each counter of the per-second line is, as docs/daemon.md does (it said nothing)."""
    with pytest.raises(SystemExit) as e:
        listen.main(["--help"])
    assert e.value.code == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps anywhere
    tally = listen.Tally()
    for seq in (0, 2, 1, 1):  # a gap, the late frame that fills it, a duplicate
        tally.add(_joints(seq))
    tally.add(_joints(4))
    line = tally.line(1.0, {})
    for label in ("seq gaps", "late (reordered)", "duplicate"):
        assert label in line and f"'N {label}'" in text, label
    assert f"up to {listen.LATE_WINDOW} behind the newest" in text


def _port_reading(data: bytes, *, then: BaseException):
    """A port for :func:`listen.main` that reads ``data`` once, then raises ``then`` (an unplugged serial port's
    ListenError, a Ctrl-C's KeyboardInterrupt)."""
    class Port:
        reads = [data]

        def read(self, timeout_s: float) -> bytes:
            if self.reads:
                return self.reads.pop()
            raise then

        def close(self) -> None:
            pass
    return Port()


def test_a_port_that_fails_while_read_still_ends_with_the_totals(monkeypatch, capsys):
    # an unplugged serial port: the error, exit 2, and nothing of what had arrived (the totals were lost)
    sink = open_sink("memory://", rig_id="pty")
    for seq in (0, 1, 3):
        sink.send(make_frame(seq))
    sink.close()
    unplugged = _port_reading(sink.read(), then=listen.ListenError(
        "serial:///dev/ttyACM0: read failed: [Errno 5] Input/output error"))
    monkeypatch.setattr(listen, "open_port", lambda url: unplugged)
    assert listen.main(["serial:///dev/ttyACM0", "--json"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["ghnerf-listen: error: serial:///dev/ttyACM0: read failed: [Errno 5] Input/output error",
                   "3 JOINTS messages, 1 sequence gaps (lost), 0 late (reordered), 0 duplicate"]


def test_the_line_counts_scene_flags_and_the_calibration_suspicion_a_sink_sends():
    """What the daemon's JSON says of a frame reaches the receiver: a real memory sink's frames flagged two people
    / single view, its STATUS flagged CALIBRATION_SUSPECT, its HELLO announcing the scene flags. The line used to
    say none of it, so a person at the robot could not see why it stopped."""
    from dataclasses import replace

    from firmware_host.protocol.constants import SCENE_FLAGS, Flags
    from firmware_host.protocol.decoder import decode_stream

    from firmware_host.sinks.memory_sink import MemorySink

    sink = MemorySink.from_url("memory://", rig_id="arm")
    sink.set_calibration_suspect(True)  # before start, as the daemon does: its first STATUS says so
    sink.start()
    for seq, flags in ((0, 0), (1, Flags.SEVERAL_PEOPLE), (2, Flags.SEVERAL_PEOPLE | Flags.CALIBRATION_SUSPECT),
                       (3, Flags.SINGLE_VIEW)):
        sink.send(replace(make_frame(seq), scene_flags=int(flags)))
    sink.close()
    events, _ = decode_stream(sink.read())
    tally = listen.Tally()
    for event in events:
        tally.add(event.message)
    assert tally.hello is not None and tally.hello.header.flags == SCENE_FLAGS
    assert tally.status is not None and tally.status.header.flags == Flags.CALIBRATION_SUSPECT
    line = tally.line(1.0, {})
    assert "2 several people; 1 single view; 1 calibration suspect" in line, line
    assert "sender fault OK, CALIBRATION SUSPECT, dropped 0" in line, line
    assert "(sends no scene flags)" not in line
    assert "several people" not in tally.line(1.0, {})  # counted per interval


def test_the_line_says_when_a_sender_cannot_report_scene_flags():
    """An older sender's HELLO has flags 0: no SEVERAL_PEOPLE from it means nothing, and the line says so."""
    from firmware_host.protocol.constants import MsgType
    from firmware_host.protocol.messages import Hello, make_header

    tally = listen.Tally()
    tally.add(Hello(make_header(MsgType.HELLO, 0, 0, 0), 1, 0, 25, 0, 0, "old", ("left", "right")))
    assert "rig 'old' cameras ['left', 'right'] (sends no scene flags)" in tally.line(1.0, {})


def test_sigterm_ends_the_listener_with_the_totals_as_ctrl_c_does():
    """``timeout 10 ghnerf-listen ...`` or a supervisor on the robot stops it with SIGTERM: its default action killed
    the process with no totals (status -15), where Ctrl-C printed them and exited 0."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    number = probe.getsockname()[1]
    probe.close()  # the listener binds it next (a free port picked the only way a subprocess can be told it)
    proc = subprocess.Popen([sys.executable, "-m", "firmware_host.listen", f"udp://127.0.0.1:{number}"], cwd=repo,
                            env={**os.environ, "PYTHONPATH": str(repo)}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert "JOINTS/s" in _line_within(proc.stdout, 60).decode()  # its first summary: listening, handler installed
        with open_sink(f"udp://127.0.0.1:{number}?queue=16", backoff=FAST_BACKOFF, rig_id="bench") as sink:
            for seq in (0, 1, 3):
                sink.send(make_frame(seq))
        # not a fixed 0.5 s: the summary that counts the gap seq 3 leaves says the last datagram was read
        deadline = time.monotonic() + 60
        while "; 1 seq gaps" not in (line := _line_within(proc.stdout, 60).decode()):
            assert line and time.monotonic() < deadline, f"no summary counted the gap before seq 3 (last {line!r})"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert err.splitlines()[-1] == "3 JOINTS messages, 1 sequence gaps (lost), 0 late (reordered), 0 duplicate"


def test_the_readme_s_python_receiver_decodes_what_a_udp_sink_sends(monkeypatch):
    """The README's receiver for a robot's Linux computer, run as written on the datagrams a sink sends (one frame
    each, a cut one among them), its socket a stand-in that ends the endless loop once they are read."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "StreamDecoder" in b)
    sink = open_sink("memory://", rig_id="bench", cameras=("left", "right"))
    for seq in (0, 1):
        sink.send(make_frame(seq))
    sink.close()
    frames = [f + b"\x00" for f in sink.read().split(b"\x00") if f]
    datagrams = frames[:1] + [frames[1][:-9]] + frames[1:]  # a datagram cut short before a whole one

    class _Read(Exception):
        pass

    class _Socket:
        def __init__(self, *args) -> None:
            self.bound = None

        def bind(self, address) -> None:
            self.bound = address

        def recv(self, size: int) -> bytes:
            if not datagrams:
                raise _Read
            return datagrams.pop(0)

    monkeypatch.setattr(socket, "socket", _Socket)
    names: dict = {}
    with pytest.raises(_Read):
        exec(block, names)
    assert names["sock"].bound == ("", 9870)
    assert names["xyz_mm"].shape == (25, 3) and names["missing"].shape == (25,) and not names["missing"].any()
    stats = names["decoder"].stats
    assert stats.messages == len(frames) and sum(stats.errors.values()) == 1  # the cut datagram, and only it


def test_the_readme_s_sink_example_runs_as_written(monkeypatch):
    """The README's sender, run as written (its udp:// sink aimed at a port of this host): it used a ``joints_xyzc``
    it never made, a NameError for whoever pasted it."""
    import re
    from pathlib import Path

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "open_sink(" in b)
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(5)
    port = receiver.getsockname()[1]
    names: dict = {}
    with receiver:
        exec(block.replace("udp://127.0.0.1:9000", f"udp://127.0.0.1:{port}"), names)
        assert names["sink"].stats().sent == 1
        assert receiver.recv(2048)  # HELLO first, as every sink sends

def test_the_readme_s_receiver_names_the_ipv6_socket_a_udp_sink_to_an_ipv6_host_needs():
    """The README's receiver binds IPv4 only, which hears nothing from a udp:// sink to an IPv6 literal (or an
    IPv6-only host), and did not say so; its comment's variant, run on a real socket, hears that sink."""
    import re
    from pathlib import Path

    from firmware_host.protocol.decoder import StreamDecoder
    from firmware_host.protocol.messages import Joints

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "StreamDecoder" in b)
    assert re.search(r"^# IPv4 only: .*IPv6", block, re.M), "the receiver does not say it binds IPv4 only"
    variant = re.search(r"socket\.(AF_INET6) and bind\(\(\"(::)\", 9870\)\)", block)
    assert variant, "the receiver's comment names no IPv6 variant"
    if not socket.has_ipv6:
        pytest.skip("no IPv6 here: the variant cannot be run")
    try:
        rx = socket.socket(getattr(socket, variant[1]), socket.SOCK_DGRAM)
    except OSError as e:
        pytest.skip(f"no IPv6 socket here: {e}")
    with rx:
        try:
            rx.bind((variant[2], 0))  # the README's port, 9870, may be taken on this machine
        except OSError as e:
            pytest.skip(f"cannot bind IPv6 here: {e}")
        rx.settimeout(5.0)
        with open_sink(f"udp://[::1]:{rx.getsockname()[1]}", rig_id="bench", cameras=("left", "right")) as sink:
            sink.send(make_frame(0))
        decoder, joints = StreamDecoder(), []
        while not joints:
            joints = [e.message for e in decoder.feed(rx.recv(2048) + b"\0") if isinstance(e.message, Joints)]
    assert joints[0].xyz_mm.shape == (25, 3)


_LISTEN_INTO_A_STALLED_PIPE = """
import os, select, sys
from firmware_host import listen
from firmware_host.sinks import open_sink
from ghnerf_runtime.cli.sigterm import sigterm_as_interrupt
from tests.firmware_host.joint_stream_helpers import make_frame

class Port:  # a frame on every read: the pipe fills at once and the listener blocks in a write
    seq, said = 0, False
    def read(self, timeout):
        if not self.said and not select.select([], [sys.stdout], [], 0)[1]:
            # said from inside listen(): the stop handlers are in place and a write is about to block
            print("full", file=sys.stderr, flush=True)
            self.said = True
        sink = open_sink("memory://", rig_id="pipe")
        sink.send(make_frame(self.seq))
        sink.close()
        self.seq += 1
        return sink.read()

with sigterm_as_interrupt():
    listen.listen(Port(), seconds=None, as_json=True, out=sys.stdout)
print("stopped", file=sys.stderr, flush=True)
if sys.argv[1] == "killed":  # as SIGKILL would after the stop: the exit's flush of the line held back never runs
    os._exit(0)
"""


def _line_within(pipe, seconds: float) -> bytes:
    """The next line a child writes to the unbuffered ``pipe``, or what came of it in ``seconds``: a child that
    never says it fails the test instead of hanging it."""
    import select
    import time

    line, deadline = b"", time.monotonic() + seconds
    while not line.endswith(b"\n"):
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([pipe], [], [], left)[0]:
            break
        byte = os.read(pipe.fileno(), 1)  # one at a time: the next line stays in the pipe for the next call
        if not byte:
            break
        line += byte
    return line


def _wait_blocked_in_a_pipe_write(pid: int, seconds: float) -> None:
    """Until ``pid`` sleeps in a write to a full pipe, as Linux's /proc/PID/wchan names it (pipe_write,
    anon_pipe_write). A kernel that hides wchan (it reads "0") leaves the process state: asleep for a whole second
    after its word that the pipe is full, the write is what it sleeps in; where there is no /proc that word is all."""
    import time

    deadline, asleep_since = time.monotonic() + seconds, None
    while True:
        try:
            with open(f"/proc/{pid}/wchan") as f:
                wchan = f.read()
            with open(f"/proc/{pid}/stat") as f:
                state = f.read().rsplit(")", 1)[1].split()[0]
        except FileNotFoundError:
            return
        if "pipe" in wchan:
            return
        now = time.monotonic()
        asleep_since = (asleep_since or now) if wchan in ("", "0") and state == "S" else None
        if asleep_since is not None and now - asleep_since >= 1.0:
            return
        assert now < deadline, f"the listener never blocked in a write to its pipe (wchan {wchan!r}, state {state})"
        time.sleep(0.01)


@pytest.mark.parametrize("end", ["exits", "killed"])
@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_a_stop_inside_a_write_blocked_on_a_full_pipe_leaves_no_half_json_line(signum, end):
    """Review 63: could a first Ctrl-C (or SIGTERM) landing in a write blocked on a full pipe leave half a JSON
    line? No: each line is flushed alone and is shorter than PIPE_BUF, so the pipe takes it whole or not at all;
    the one the stop interrupted stays in Python's buffer and the exit's flush writes it whole, or (killed before)
    nothing of it. Pinned here with a reader that stalls, then reads everything."""
    import json
    import select
    import signal
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-c", _LISTEN_INTO_A_STALLED_PIPE, end], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, cwd=os.getcwd(), bufsize=0)
    try:
        # not a fixed sleep: on a loaded host the child was still importing when the signal came (SIGTERM's
        # default action killed it, SIGINT's KeyboardInterrupt ended it with a traceback)
        assert _line_within(child.stderr, 60) == b"full\n"
        _wait_blocked_in_a_pipe_write(child.pid, 60)
        child.send_signal(getattr(signal, signum))
        assert _line_within(child.stderr, 60) == b"stopped\n"  # the stop came while its write was blocked
        data = child.stdout.read()
    finally:
        child.kill()
        child.wait()
    lines = data.split(b"\n")
    assert lines[-1] == b"" and len(lines) > 2  # ends at a line's end
    assert all(len(line) < select.PIPE_BUF for line in lines)
    assert [json.loads(line)["type"] for line in lines[:-1]][:3] == ["HELLO", "STATUS", "JOINTS"]


def test_the_line_says_when_the_hello_announces_joints_other_than_body25_mm_in_the_rig_frame():
    """Version 1 defines only joint set 0, units 0 and frame 0, and the decoders pass another value through, so a
    receiver checks them itself (docs/protocol.md, HELLO). The listener, the reference receiver, printed such a
    HELLO as any other: an integrator read millimetres in the rig frame off a stream that said otherwise."""
    from firmware_host.protocol.constants import SCENE_FLAGS, MsgType
    from firmware_host.protocol.messages import Hello, make_header

    expected = listen.Tally()
    expected.add(_hello(0))
    assert "not BODY_25" not in expected.line(1.0, {})
    other = listen.Tally()
    other.add(Hello(make_header(MsgType.HELLO, 0, 0, 0, SCENE_FLAGS), 1, 3, 25, 1, 2, "arm", ("left", "right")))
    line = other.line(1.0, {})
    assert "rig 'arm' cameras ['left', 'right'] (not BODY_25 in mm in the rig frame: joint_set 3, units 1, frame 2)" \
        in line, line
    units_only = listen.Tally()
    units_only.add(Hello(make_header(MsgType.HELLO, 0, 0, 0, SCENE_FLAGS), 1, 0, 25, 1, 0, "arm", ("left",)))
    assert "(not BODY_25 in mm in the rig frame: units 1)" in units_only.line(1.0, {})


def _joints_of_set(seq: int, joint_set: int, count: int, missing: int = 0):
    """A JOINTS of ``joint_set`` with ``count`` joints, the first ``missing`` of them missing."""
    from dataclasses import replace

    import numpy as np

    flags = np.arange(count) < missing
    return replace(_joints(seq), joint_set=joint_set, xyz_mm=np.zeros((count, 3), np.int16),
                   conf=np.where(flags, 0, 200).astype(np.uint8), missing=flags)


def test_joints_of_an_unknown_joint_set_are_counted_apart_from_the_joints_present():
    """Version 1 defines BODY_25 alone, and a receiver that reads it ignores JOINTS of another set (docs/protocol.md,
    HELLO). The line averaged their joints into 'joints present' (25 and 10 read '17.5 joints present', a BODY_25
    person short of joints) and said nothing else of them: only the HELLO's part warned, and only once a HELLO came.
    They are counted by their set now, each JOINTS by its own joint_set; the rate, latency and sequence, which are
    their headers', still count them."""
    tally = listen.Tally()
    for seq, message in enumerate((_joints_of_set(0, 0, 25, missing=1), _joints_of_set(1, 7, 10),
                                   _joints_of_set(2, 7, 10), _joints_of_set(3, 9, 64))):
        assert message.header.seq == seq
        tally.add(message)
    line = tally.line(1.0, {})
    assert line.startswith("4.0 JOINTS/s; 24.0 joints present; 2 JOINTS of joint_set 7 (unknown: left out of joints "
                           "present); 1 JOINTS of joint_set 9 (unknown: left out of joints present); latency "), line
    assert "0 seq gaps" in line
    alone = listen.Tally()  # none of BODY_25: no 'joints present' at all, the latency still said
    alone.add(_joints_of_set(0, 7, 10))
    line = alone.line(1.0, {})
    assert "joints present;" not in line and "1 JOINTS of joint_set 7 (unknown" in line and "latency 1.0 ms" in line
    assert "joint_set" not in alone.line(1.0, {})  # counted per interval
    assert alone.total_unknown_sets == {7: 1} and tally.total_unknown_sets == {7: 2, 9: 1}


def test_the_totals_count_joints_of_an_unknown_joint_set(monkeypatch, capsys):
    from firmware_host.protocol.encoder import encode

    port = _port_reading(b"".join(encode(m) for m in (_joints_of_set(0, 0, 25), _joints_of_set(1, 7, 10))),
                         then=KeyboardInterrupt())
    monkeypatch.setattr(listen, "open_port", lambda url: port)
    assert listen.main(["udp://:9870", "--json"]) == 0
    assert capsys.readouterr().err.splitlines() == [
        "2 JOINTS messages, 0 sequence gaps (lost), 0 late (reordered), 0 duplicate, 1 of joint_set 7 (unknown)"]


def test_the_help_names_the_unknown_joint_set_counts(capsys):
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'N JOINTS of joint_set K (unknown: left out of joints present)'" in text, text
    assert "'N of joint_set K (unknown)'" in text, text


def test_the_help_names_every_scene_flag_s_count_and_both_hello_notes(capsys):
    """The line counts every scene flag (``ALL_SCENE_FLAGS``), and ``--help`` names each count and both HELLO notes
    in the line's words: session 65 added ``someone else`` and ``(scans for someone else)`` to the line, not to the
    help."""
    from firmware_host.protocol import ALL_SCENE_FLAGS

    assert sum(int(flag) for flag, _ in listen.SCENE_WORDS) == ALL_SCENE_FLAGS
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    for _, word in listen.SCENE_WORDS:
        assert f"'N {word}'" in text, word
    assert "'(sends no scene flags)'" in text and "'(scans for someone else)'" in text, text


def test_the_json_help_names_the_joints_units_and_frame(capsys):
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "x, y, z in mm (rig frame: x right, y down, z away from the cameras)" in text, text


def _at(seq: int, msg_type: str, send_us: int):
    """A JOINTS or HELLO of ``seq`` written at ``send_us`` on the sender's monotonic clock."""
    from dataclasses import replace

    message = _joints(seq) if msg_type == "JOINTS" else _hello(seq)
    return replace(message, header=replace(message.header, send_us=send_us))


def test_a_duplicated_or_reordered_hello_of_a_new_sender_does_not_restart_its_numbering():
    """On UDP the HELLO a new process sends before its first frame can come twice, or after its first JOINTS.
    Taken for another new process, it counted the frames that had arrived since as lost: 0 and 1 here."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ

    period = 33_333
    start = 50_000_000
    duplicated = listen.Tally()
    hello = _at(NO_FRAME_SEQ, "HELLO", start)
    for message in (hello, _at(0, "JOINTS", start + period), _at(1, "JOINTS", start + 2 * period), hello,
                    _at(2, "JOINTS", start + 3 * period)):
        duplicated.add(message)
    assert (duplicated.total_gaps, duplicated.total_late, duplicated.last_seq) == (0, 0, 2)
    reordered = listen.Tally()  # the periodic HELLO written just before frame 0 arrives after it
    for message in (_at(NO_FRAME_SEQ, "HELLO", start), _at(0, "JOINTS", start + 2 * period),
                    _at(NO_FRAME_SEQ, "HELLO", start + period), _at(1, "JOINTS", start + 3 * period)):
        reordered.add(message)
    assert (reordered.total_gaps, reordered.last_seq) == (0, 1)


def test_a_hello_written_after_the_frames_or_long_before_them_is_a_new_process():
    """A restarted process writes its HELLO after its predecessor's frames; a device that rebooted writes it on a
    clock that started again, long before the old frames' times: both begin a new numbering."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ

    period = 33_333
    for hello_us in (50_000_000 + 40 * period, 20_000_000):  # restarted after the frames; rebooted, uptime 20 s
        tally = listen.Tally()
        tally.add(_at(NO_FRAME_SEQ, "HELLO", 50_000_000))
        for seq in range(30):
            tally.add(_at(seq, "JOINTS", 50_000_000 + (seq + 1) * period))
        tally.add(_at(NO_FRAME_SEQ, "HELLO", hello_us))
        tally.add(_at(2, "JOINTS", hello_us + period))  # its frames 0 and 1 lost
        assert (tally.total_gaps, tally.total_late, tally.last_seq) == (2, 0, 2), hello_us


def test_version_errors_say_the_sender_speaks_another_protocol_version():
    """A listener older than its sender gets a ``version`` error on every frame (docs/protocol.md, section 4); the
    line said only "decode errors {'version': 5}", which reads like line noise."""
    tally = listen.Tally()
    line = tally.line(1.0, {"version": 5, "crc": 0})
    assert "decode errors {'version': 5} (version: whole frames of a protocol version other than 1" in line, line
    assert "newer ghnerf-listen" in line
    assert "(version:" not in tally.line(1.0, {"version": 5, "crc": 1})  # a crc error alone: no such hint


def test_the_help_names_the_hello_s_layout_warning_and_the_version_errors(capsys):
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "'(not BODY_25 in mm in the rig frame: ...)'" in text and "'version': a sender of a newer protocol" in text


def test_a_new_sender_s_hello_reordered_behind_its_first_frames_counts_none_of_them_lost():
    """A numbering begun by a JOINTS (the listener started after the HELLO, or a sender restarted far from its old
    seq) has no HELLO of its own; the new sender's HELLO that UDP delivers after its first frames was taken for yet
    another new process, and the frames that had arrived (0 and 1 here) were counted lost."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ

    period = 33_333
    start = 50_000_000
    for old_seqs in ((), tuple(range(100, 140))):  # the listener's first message; a restart from seq 139
        tally = listen.Tally()
        for seq in old_seqs:
            tally.add(_at(seq, "JOINTS", start - 10_000_000 + seq * period))
        for message in (_at(0, "JOINTS", start + period), _at(1, "JOINTS", start + 2 * period),
                        _at(NO_FRAME_SEQ, "HELLO", start), _at(2, "JOINTS", start + 3 * period)):
            tally.add(message)
        assert (tally.total_gaps, tally.total_late, tally.last_seq) == (0, 0, 2), old_seqs


def _status(seq: int, send_us: int, fault: int, dropped: int):
    """A STATUS of ``seq`` written at ``send_us`` on the sender's clock, saying ``fault`` and ``dropped`` frames."""
    from firmware_host.protocol.constants import MsgType
    from firmware_host.protocol.messages import Status, make_header

    return Status(make_header(MsgType.STATUS, seq, send_us, send_us), 3000, 0, dropped, 0, fault)


def _shown_status(tally: "listen.Tally") -> tuple[int, int]:
    assert tally.status is not None
    return tally.status.fault, tally.status.dropped


def test_a_status_reordered_behind_a_newer_one_is_not_shown():
    """Over UDP an older STATUS can arrive after a newer one; shown as it arrived, the line said the sender's state
    of a second before (QUEUE_OVERFLOW, 4 dropped) after it had reported OK with 9. By the sender's clock, across a
    seq wrap and for a stalled sender whose STATUS all carry one seq, the newest written is shown."""
    from firmware_host.protocol.constants import Fault

    for old_seq, new_seq in ((40, 70), (2**32 - 2, 1), (70, 70)):  # frames sent between; across the wrap; none
        tally = listen.Tally()
        tally.add(_status(new_seq, 61_000_000, int(Fault.OK), 9))
        tally.add(_status(old_seq, 60_000_000, int(Fault.QUEUE_OVERFLOW), 4))  # written first, arrived last
        assert _shown_status(tally) == (int(Fault.OK), 9), (old_seq, new_seq)
        assert "sender fault OK, dropped 9" in tally.line(1.0, {})
        tally.add(_status(new_seq, 61_000_000, int(Fault.OK), 9))  # a duplicate changes nothing either
        tally.add(_status(new_seq + 1, 62_000_000, int(Fault.LINK_ERRORS), 12))  # a newer one is shown
        assert _shown_status(tally) == (int(Fault.LINK_ERRORS), 12), (old_seq, new_seq)


def test_a_restarted_sender_s_status_is_shown_whatever_its_time():
    """A rebooted device's clock starts again: its STATUS, written "before" the old one's, is the newest. Over 1 s
    before (STALE_STATUS_US), it is taken for a reboot; nearer, after a HELLO or JOINTS that begins a new numbering
    (the restart listen counts frames by). A stale HELLO of the old sender begins none, and keeps the order."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ, Fault

    period = 33_333
    start = 100_000_000

    def old_sender() -> "listen.Tally":
        tally = listen.Tally()
        tally.add(_at(NO_FRAME_SEQ, "HELLO", start))
        for seq in range(100, 130):
            tally.add(_at(seq, "JOINTS", start + (seq - 99) * period))
        tally.add(_status(129, start + 31 * period, int(Fault.CAMERA_FAULT), 3))
        return tally

    rebooted = old_sender()  # its HELLO lost: the STATUS alone, from a clock at 20 s
    rebooted.add(_status(NO_FRAME_SEQ, 20_000_000, int(Fault.OK), 0))
    assert _shown_status(rebooted) == (int(Fault.OK), 0)
    near = start + 31 * period - 500_000  # rebooted, its clock by chance half a second behind the old STATUS
    for begin in (_at(NO_FRAME_SEQ, "HELLO", start + 31 * period + 1), _at(0, "JOINTS", near - period)):
        restarted = old_sender()
        restarted.add(begin)  # a HELLO written after the old frames; a JOINTS far behind the old seq
        restarted.add(_status(0, near, int(Fault.OK), 0))
        assert _shown_status(restarted) == (int(Fault.OK), 0), begin
    stale = old_sender()  # the old sender's HELLO, duplicated, arrives late: the same numbering, the same order
    stale.add(_at(NO_FRAME_SEQ, "HELLO", start))
    stale.add(_status(129, start + 31 * period - 1, int(Fault.OK), 2))
    assert _shown_status(stale) == (int(Fault.CAMERA_FAULT), 3)


def test_the_listener_shows_the_newest_of_reordered_status_datagrams(monkeypatch, capsys):
    """End to end: the datagrams a udp:// port hands over, the newer STATUS first, then the older."""
    from firmware_host.protocol.constants import Fault
    from firmware_host.protocol.encoder import encode

    data = encode(_status(80, 5_000_000, int(Fault.OK), 7)) + encode(_status(50, 4_000_000, int(Fault.RATE_LIMITED), 6))
    out = io.StringIO()
    listen.listen(_port_reading(data, then=KeyboardInterrupt()), seconds=None, as_json=False, out=out, every_s=0.0)
    assert "sender fault OK, dropped 7" in out.getvalue(), out.getvalue()


def _hello_of(rig_id: str, seq: int, send_us: int):
    """A HELLO of ``rig_id`` and ``seq`` written at ``send_us`` on the sender's clock."""
    from dataclasses import replace

    hello = _at(seq, "HELLO", send_us)
    return replace(hello, rig_id=rig_id)


def test_a_hello_reordered_behind_a_newer_one_is_not_shown():
    """A reload that opens another rig sends a HELLO with the new rig id; over UDP the old rig's HELLO written just
    before can arrive after it, and the line said the old rig until the next HELLO. As for STATUS, the newest by the
    sender's clock is shown; a rebooted or restarted sender's HELLO is shown whatever its time."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ

    start = 100_000_000
    tally = listen.Tally()
    for seq in range(10, 20):
        tally.add(_at(seq, "JOINTS", start + seq * 33_333))
    tally.add(_hello_of("new", 19, start + 700_000))
    tally.add(_hello_of("old", 19, start + 600_000))  # written first, arrived last
    assert tally.hello is not None and tally.hello.rig_id == "new"
    assert "rig 'new'" in tally.line(1.0, {})
    tally.add(_hello_of("later", 19, start + 800_000))
    assert tally.hello.rig_id == "later"
    rebooted = listen.Tally()  # its clock started again: over 1 s before, it is not the old sender's
    rebooted.add(_hello_of("old", 19, start))
    rebooted.add(_hello_of("rebooted", 19, 20_000_000))
    assert rebooted.hello is not None and rebooted.hello.rig_id == "rebooted"
    restarted = listen.Tally()  # a new process (seq 2**32 - 1) of a device rebooted, its clock 0.5 s behind
    restarted.add(_hello_of("old", 19, start + 700_000))
    restarted.add(_hello_of("new", NO_FRAME_SEQ, start + 200_000))
    assert restarted.hello is not None and restarted.hello.rig_id == "new"
    followed = listen.Tally()  # a restart followed from its frames (its first HELLO lost): its next HELLO is shown
    for seq in range(100, 110):
        followed.add(_at(seq, "JOINTS", start + seq * 33_333))
    followed.add(_hello_of("old", 109, start + 110 * 33_333))
    followed.add(_at(0, "JOINTS", start + 500_000))  # far behind the old seq, on a clock 3.2 s behind the HELLO
    followed.add(_hello_of("new", 0, start + 3_000_000))  # ... 0.7 s behind
    assert followed.hello is not None and followed.hello.rig_id == "new"


class _Senders:
    """A udp:// port for :func:`listen.listen`: scripted datagrams, each with its sender's address, then a Ctrl-C.
    A datagram is a message, encoded here, or bytes sent as they are."""

    def __init__(self, datagrams) -> None:
        self.datagrams = list(datagrams)

    def read_from(self, timeout_s: float):
        from firmware_host.protocol.encoder import encode

        if not self.datagrams:
            raise KeyboardInterrupt
        source, message = self.datagrams.pop(0)
        return (message if isinstance(message, bytes) else encode(message)), source

    def close(self) -> None:
        pass


_A, _B = "127.0.0.1:40000", "127.0.0.2:40001"


def _two_rigs():
    """Two senders on one port, interleaved: A's frames 0-5 and OK STATUS; B's, on a clock 0.4 s behind A's, with 4
    lost and 3 ahead of 2 (reordered), and a CAMERA_FAULT STATUS; each a HELLO of its rig first."""
    from firmware_host.protocol.constants import NO_FRAME_SEQ, Fault

    period, a_start, b_start = 33_333, 50_000_000, 49_600_000
    a = [_hello_of("rig-a", NO_FRAME_SEQ, a_start)]
    a += [_at(seq, "JOINTS", a_start + (seq + 1) * period) for seq in range(6)]
    a.append(_status(5, a_start + 7 * period, int(Fault.OK), 0))
    b = [_hello_of("rig-b", NO_FRAME_SEQ, b_start)]
    b += [_at(seq, "JOINTS", b_start + (seq + 1) * period) for seq in (0, 1, 3, 2, 5)]
    b.append(_status(5, b_start + 7 * period, int(Fault.CAMERA_FAULT), 2))
    datagrams = []
    for k in range(max(len(a), len(b))):
        datagrams += [(_A, a[k])] if k < len(a) else []
        datagrams += [(_B, b[k])] if k < len(b) else []
    return datagrams


def test_two_senders_on_one_port_are_counted_apart():
    """Until session 75 one tally took both: B's frames read as A's duplicates (5; the totals said 11 JOINTS, 0 lost),
    B's loss and reordering went unseen, and B's STATUS, written on a clock 0.4 s behind A's, was never shown."""
    heard, notes = listen.Heard(), io.StringIO()
    listen.listen(_Senders(_two_rigs()), seconds=None, as_json=True, out=io.StringIO(), heard=heard, notes=notes)
    a, b = heard.producers[_A].tally, heard.producers[_B].tally
    assert list(heard.producers) == [_A, _B]
    assert (a.total_joints, a.total_gaps, a.total_late, a.last_seq) == (6, 0, 0, 5)
    assert (b.total_joints, b.total_gaps, b.total_late, b.last_seq) == (5, 1, 1, 5)
    assert _shown_status(a) == (0, 0) and _shown_status(b) == (5, 2)
    assert a.hello is not None and a.hello.rig_id == "rig-a" and b.hello is not None and b.hello.rig_id == "rig-b"
    lines = heard.lines(1.0, time.monotonic())
    assert len(lines) == 2 and lines[0].startswith(f"{_A}: 6.0 JOINTS/s;") and "rig 'rig-a'" in lines[0], lines
    assert lines[1].startswith(f"{_B}: 5.0 JOINTS/s;") and "1 seq gaps; 1 late (reordered)" in lines[1], lines
    assert "sender fault CAMERA_FAULT, dropped 2" in lines[1] and "rig 'rig-b'" in lines[1], lines
    said = notes.getvalue()
    assert said.startswith(f"ghnerf-listen: another sender on this port: {_B}, besides {_A} (heard ") and (
        said.count("\n") == 1), said


def _json_lines(port) -> list[dict]:
    import json

    out = io.StringIO()
    listen.listen(port, seconds=None, as_json=True, out=out, notes=io.StringIO())
    return [json.loads(line) for line in out.getvalue().splitlines()]


def test_json_lines_from_a_udp_port_name_their_sender_first():
    """Before, --json lines from two senders on one port were the canonical JSON alone: a reader could not tell whose
    frame, STATUS or decode error each was (A's and B's seqs interleaved read as duplicates and gaps). Each line from
    a udp:// port now carries its sender's address first, from the first line and with one sender too; past it, the
    line is the message's canonical JSON, unchanged."""
    lines = _json_lines(_Senders(_two_rigs() + [("192.0.2.9:5353", b"\x07stray\x00")]))
    assert [line[listen.SENDER_KEY] for line in lines] == [source for source, _ in _two_rigs()] + ["192.0.2.9:5353"]
    assert all(next(iter(line)) == listen.SENDER_KEY for line in lines)  # first: seen at the start of a long JOINTS
    for sender in (_A, _B):
        canonical = [{k: v for k, v in line.items() if k != listen.SENDER_KEY} for line in lines
                     if line[listen.SENDER_KEY] == sender]
        assert canonical == [message.to_json() for source, message in _two_rigs() if source == sender]
    assert set(lines[-1]) == {listen.SENDER_KEY, "error"}  # a stray datagram's decode error says where it came from
    alone = _json_lines(_Senders([(_A, message) for source, message in _two_rigs() if source == _A]))
    assert len(alone) == 8 and all(line[listen.SENDER_KEY] == _A for line in alone)


def test_json_lines_of_a_real_udp_port_name_the_socket_that_sent_them():
    from firmware_host.protocol.encoder import encode

    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)

    class FirstTwo:  # the real port, ended as Ctrl-C ends it once its two datagrams were read
        left = 2

        def read_from(self, timeout_s: float):
            if self.left == 0:
                raise KeyboardInterrupt
            data, source = port.read_from(5.0)
            assert data, "a datagram sent over loopback did not arrive"
            self.left -= 1
            return data, source

    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.bind(("127.0.0.1", 0))
            for message in (_hello(0), _joints(1)):
                tx.sendto(encode(message), port.address)
            lines = _json_lines(FirstTwo())
            sender = f"127.0.0.1:{tx.getsockname()[1]}"
    finally:
        port.close()
    assert [(line[listen.SENDER_KEY], line["type"]) for line in lines] == [(sender, "HELLO"), (sender, "JOINTS")]


def test_json_lines_of_a_serial_link_are_the_canonical_json_alone():
    """A serial link has one sender and no address: its lines stay what the file:// sink writes and the test vectors
    list (docs/protocol.md, section 9)."""
    from firmware_host.protocol.encoder import encode

    messages = [_hello(0), _joints(1)]
    lines = _json_lines(_port_reading(b"".join(encode(m) for m in messages) + b"\x07noise\x00",
                                      then=KeyboardInterrupt()))
    assert lines == [m.to_json() for m in messages] + [{"error": lines[-1]["error"]}]


def test_the_help_says_json_lines_name_their_sender(capsys):
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f'from a udp:// port each line starts with its sender\'s address, "{listen.SENDER_KEY}": "HOST:PORT"' \
        in text, text


def test_the_totals_name_each_sender_and_the_second_is_announced(monkeypatch, capsys):
    monkeypatch.setattr(listen, "open_port", lambda url: _Senders(_two_rigs()))
    assert listen.main(["udp://:9870"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"ghnerf-listen: another sender on this port: {_B}, besides {_A}"), err
    assert err[1:] == [f"{_A}: 6 JOINTS messages, 0 sequence gaps (lost), 0 late (reordered), 0 duplicate",
                       f"{_B}: 5 JOINTS messages, 1 sequence gaps (lost), 1 late (reordered), 0 duplicate"], err


def test_one_sender_or_one_that_reopened_its_socket_reads_as_before(monkeypatch, capsys):
    """One address: the line and totals as before there were several. A sender heard from a new address after its
    old one fell quiet (QUIET_S; a udp:// sink that reconnected sends from another port) replaces it unannounced."""
    alone = [(source, message) for source, message in _two_rigs() if source == _A]
    monkeypatch.setattr(listen, "open_port", lambda url: _Senders(alone))
    assert listen.main(["udp://:9870"]) == 0
    assert capsys.readouterr().err.splitlines() == ["6 JOINTS messages, 0 sequence gaps (lost), 0 late (reordered), "
                                                    "0 duplicate"]
    monkeypatch.setattr(listen, "QUIET_S", 0.0)  # A quiet since its last datagram
    reopened = [(_B if k >= 4 else _A, message) for k, (_, message) in enumerate(alone)]
    heard, notes = listen.Heard(), io.StringIO()
    listen.listen(_Senders(reopened), seconds=None, as_json=True, out=io.StringIO(), heard=heard, notes=notes)
    lines = heard.lines(1.0, time.monotonic())
    assert notes.getvalue() == "" and len(lines) == 1 and lines[0].startswith("3.0 JOINTS/s;"), lines


def test_a_udp_port_names_each_datagram_s_sender():
    from firmware_host.protocol.encoder import encode

    port = listen.open_port("udp://127.0.0.1:0", ephemeral=True)
    try:
        names = []
        for host in ("127.0.0.1", "127.0.0.2"):  # two senders on this machine: the loopback is all of 127/8
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
                tx.bind((host, 0))
                tx.sendto(encode(_joints(1)), port.address)
                names.append(f"{host}:{tx.getsockname()[1]}")
        assert [port.read_from(2.0)[1] for _ in names] == names
    finally:
        port.close()
    both = listen.open_port("udp://:0", ephemeral=True)  # dual-stack where the machine has IPv6
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            tx.sendto(encode(_joints(1)), ("127.0.0.1", both.address[1]))
            assert both.read_from(2.0)[1] == f"127.0.0.1:{tx.getsockname()[1]}"  # not ::ffff:127.0.0.1
    finally:
        both.close()
    assert listen.source_name(("::ffff:192.0.2.7", 40123, 0, 0)) == "192.0.2.7:40123"  # on the dual-stack socket
    assert listen.source_name(("2001:db8::7", 40123, 0, 0)) == "[2001:db8::7]:40123"
    assert listen.source_name(("fe80::1%eth0", 40123, 0, 2)) == "[fe80::1%eth0]:40123"
    assert listen.source_name(("::ffff:0:192.0.2.7", 40123, 0, 0)) == "[::ffff:0:192.0.2.7]:40123"  # not mapped
    assert listen.source_name(("192.0.2.7", 40123)) == "192.0.2.7:40123"  # an IPv4 socket's


def test_the_help_says_several_senders_are_counted_apart(capsys):
    with pytest.raises(SystemExit):
        listen.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Several senders on a udp:// port: each counted apart" in text and "newest HELLO" in text, text


def test_the_senders_kept_are_bounded_the_longest_quiet_forgotten_and_counted(monkeypatch, capsys):
    """A sink that reconnects often sends from a new port each time, and stray datagrams come from random ports:
    until session 75 each address was kept for good, the table (and its lines and totals) growing without limit."""
    heard, notes = listen.Heard(), io.StringIO()
    heard.producer(_A, 0.0, notes).tally.add(_joints(1))
    for k in range(3 * listen.MAX_PRODUCERS):  # A heard again after each newcomer: never the longest quiet
        heard.producer(f"192.0.2.1:{1024 + k}", 1.0 + k, notes).tally.add(_joints(1))
        heard.producer(_A, 1.5 + k, notes)
    assert len(heard.producers) == listen.MAX_PRODUCERS and _A in heard.producers
    assert f"192.0.2.1:{1024 + 3 * listen.MAX_PRODUCERS - 1}" in heard.producers  # the newest kept
    assert "192.0.2.1:1024" not in heard.producers  # the oldest forgotten
    forgotten = 3 * listen.MAX_PRODUCERS + 1 - listen.MAX_PRODUCERS
    totals = heard.totals()
    assert len(totals) == listen.MAX_PRODUCERS + 1 and totals[0].startswith(f"{_A}: 1 JOINTS messages"), totals
    assert totals[-1] == (f"{forgotten} more senders forgotten (the longest quiet, past {listen.MAX_PRODUCERS} "
                          f"kept): {forgotten} JOINTS messages from them"), totals[-1]
    # through the command: the one sender left after another was forgotten is still named, the forgotten said
    monkeypatch.setattr(listen, "MAX_PRODUCERS", 1)
    rigs = _two_rigs()
    monkeypatch.setattr(listen, "open_port", lambda url: _Senders([d for d in rigs if d[0] == _A] +
                                                                  [d for d in rigs if d[0] == _B]))
    assert listen.main(["udp://:9870"]) == 0
    assert capsys.readouterr().err.splitlines()[-2:] == [
        f"{_B}: 5 JOINTS messages, 1 sequence gaps (lost), 1 late (reordered), 0 duplicate",
        "1 more senders forgotten (the longest quiet, past 1 kept): 6 JOINTS messages from them"]


def test_new_senders_are_said_at_most_once_per_quiet_spell_the_unsaid_counted_in_the_next_note():
    """Until session 75 every stray datagram from a new port printed its own "another sender" line while a real
    sender streamed: a port scan or a sink reconnecting in a loop filled the terminal."""
    heard, notes = listen.Heard(), io.StringIO()
    heard.producer(_A, 0.0, notes)
    for k in range(5):
        heard.producer(f"192.0.2.1:{2000 + k}", 1.0 + 0.1 * k, notes)
        heard.producer(_A, 1.05 + 0.1 * k, notes)
    said = notes.getvalue().splitlines()
    assert len(said) == 1 and said[0].startswith(
        f"ghnerf-listen: another sender on this port: 192.0.2.1:2000, besides {_A} (heard "), said
    heard.producer(f"192.0.2.1:{3000}", 1.0 + listen.QUIET_S, notes)
    said = notes.getvalue().splitlines()
    assert len(said) == 2 and "192.0.2.1:3000" in said[1] and "(4 more new senders since the last such note)" in said[1]
