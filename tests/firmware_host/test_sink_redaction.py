"""A sink shows its own URL without the passwords it may carry (review 52): its log lines, thread name, repr, its
errors' messages (which the daemon logs, and the status file's ``last_error`` holds) and a refused URL's message.
What was given stays on the objects (``sink.url``, ``error.url``, ``error.value``) for callers that need it."""
from __future__ import annotations

import logging
import threading

import pytest

from firmware_host.errors import SinkClosedError, SinkConfigError, SinkUnavailableError, SinkWriteError
from firmware_host.sinks import Sink, SinkOptions, open_sink
from firmware_host.protocol import JointFrame
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, wait_until

SECRET = "s3cret"


class _DownSink(Sink):
    """A link that is never there: its connect fails, as an unplugged one's does."""

    def __init__(self, url: str) -> None:
        super().__init__(url, SinkOptions(backoff=FAST_BACKOFF))
        self.tries = 0

    def _connect(self) -> None:
        self.tries += 1
        if self.tries == 1:
            raise RuntimeError("a backend bug")  # logged once with its traceback
        raise SinkUnavailableError(self.url, "not plugged in")

    def _disconnect(self) -> None:
        pass

    def _deliver(self, frame: JointFrame, flags: int) -> None:
        raise AssertionError("never connected")


def test_a_sink_logs_and_names_itself_without_its_password(caplog):
    url = f"scripted://viewer:{SECRET}@here?token=abc"
    with caplog.at_level(logging.DEBUG, logger="firmware_host.sinks"):
        sink = _DownSink(url).start()
        wait_until(lambda: sink.tries >= 3, what="three connect attempts")
        names = [t.name for t in threading.enumerate() if t.name.startswith("sink ")]
        shown = repr(sink)
        stats = sink.close()
    assert sink.url == url  # kept as given
    assert "scripted://viewer:***@here?token=***" in caplog.text
    assert "viewer:***@here" in shown and "sink scripted://viewer:***@here?token=***" in names
    assert SECRET not in caplog.text and "abc" not in caplog.text and SECRET not in shown
    assert SECRET not in (stats.last_error or "") and "not plugged in" in stats.last_error
    with pytest.raises(SinkClosedError) as closed:
        sink.send(make_frame(0))
    assert SECRET not in str(closed.value) and "viewer:***@here" in str(closed.value)


def test_a_memory_sink_s_dropped_frame_is_reported_without_its_password():
    sink = open_sink(f"memory://viewer:{SECRET}@here?max_bytes=16")
    try:
        sink.send(make_frame(0))  # larger than 16 bytes: a write error, the frame dropped
        wait_until(lambda: sink.stats().dropped_error == 1, what="the dropped frame")
    finally:
        stats = sink.close()
    assert "memory://viewer:***@here" in stats.last_error and SECRET not in stats.last_error


@pytest.mark.parametrize("error", [SinkUnavailableError, SinkWriteError])
def test_a_link_error_names_the_url_without_its_password(error):
    e = error(f"udp://viewer:{SECRET}@127.0.0.1:9000?api_key={SECRET}", "gone")
    assert str(e).startswith("udp://viewer:***@127.0.0.1:9000?api_key=***: ") and SECRET not in str(e)
    assert SECRET in e.url  # kept as given


@pytest.mark.parametrize("url, field", [
    (f"udp://viewer:{SECRET}@127.0.0.1:9000", "user info"),  # refused: user info
    (f"file://viewer:{SECRET}@host/tmp/joints.jsonl", "host"),  # refused: a host
    (f"memory://here?password={SECRET}", "password"),  # an unknown parameter, a secret one
    (f"udp://viewer:{SECRET}@[::1:9000", "url"),  # cannot be parsed: the whole URL is the value
])
def test_a_refused_sink_url_is_named_without_its_password(url, field):
    with pytest.raises(SinkConfigError) as refused:
        open_sink(url).close()
    e = refused.value
    assert e.field == field and e.url == url and SECRET in repr(e.value)  # kept as given
    assert SECRET not in str(e) and "***" in str(e)
    assert str(e).startswith(url.replace(SECRET, "***").split("?")[0])  # the URL, its user and host kept


class _StallingSink(Sink):
    """A link that stays open while its receiver does not read: every write fails until ``reading`` is set."""

    def __init__(self, url: str) -> None:
        super().__init__(url, SinkOptions(backoff=FAST_BACKOFF, queue=1, stall_s=0.1))
        self.reading = threading.Event()

    def _connect(self) -> None:
        pass

    def _disconnect(self) -> None:
        pass

    def _deliver(self, frame: JointFrame, flags: int) -> None:
        if not self.reading.is_set():
            raise SinkWriteError(self.url, "write timed out")


def test_a_stalled_sink_logs_its_stall_and_its_end_without_its_password(caplog):
    # the stall watch (session 53) and the redaction (session 53) came from two branches: the stall's WARNING and
    # INFO named the sink by its URL as given, password and all
    url = f"scripted://viewer:{SECRET}@here?token=abc"
    sink = _StallingSink(url).start()
    with caplog.at_level(logging.INFO, logger="firmware_host.sinks"):
        try:
            seq = 0

            def logged(words: str) -> bool:
                nonlocal seq
                sink.send(make_frame(seq))
                seq += 1
                sink.wait_drained(5)
                return any(words in r.getMessage() for r in caplog.records)

            wait_until(lambda: logged("stalled: no frame got through"), what="the stall logged")
            sink.reading.set()
            wait_until(lambda: logged("get through again"), what="the stall's end logged")
        finally:
            sink.close()
    stall_lines = [r.getMessage() for r in caplog.records if "stall" in r.getMessage()]
    assert len(stall_lines) >= 2 and all("scripted://viewer:***@here?token=***" in m for m in stall_lines)
    assert SECRET not in caplog.text and "abc" not in caplog.text


@pytest.mark.parametrize("url", [
    f"udp://viewer:{SECRET}@127.0.0.1:90\n00",  # refused: a line feed (URL parsing drops it)
    f"file:///tmp/a\r\nb.jsonl?token={SECRET}",
    f"memory://a\x0bb?password={SECRET}",  # a vertical tab, which URL parsing keeps: an unknown (secret) parameter
])
def test_a_refused_sink_url_with_a_line_break_is_named_on_one_line_without_its_password(url):
    """A log line per error: the URL as written split it (a line feed, a vertical tab), the rest of the message
    on a line of its own; it is shown escaped now, as a rig URL's message shows it (``drivers.url.shown_url``)."""
    with pytest.raises(SinkConfigError) as refused:
        open_sink(url).close()
    text = str(refused.value)
    assert len(text.splitlines()) == 1 and SECRET not in text, text
    assert text.startswith(repr(url.replace(SECRET, "***")) + ": invalid "), text


@pytest.mark.parametrize("error, said", [(SinkUnavailableError, "unavailable"), (SinkWriteError, "write failed")])
def test_a_link_error_names_a_url_with_a_control_character_on_one_line(error, said):
    e = error(f"scripted://viewer:{SECRET}@here\x0b2?token={SECRET}", "gone")
    assert str(e) == f"'scripted://viewer:***@here\\x0b2?token=***': {said}: gone", str(e)


def test_a_sink_names_itself_on_one_line_where_its_url_holds_a_control_character():
    sink = _DownSink(f"scripted://viewer:{SECRET}@here\x0b2")
    assert repr(sink) == "<_DownSink 'scripted://viewer:***@here\\x0b2'>"


def test_the_status_line_gives_a_down_sink_s_reason_without_its_url_where_the_url_holds_a_control_character():
    """The daemon's status line names the sink, then its error less the URL the error starts with: the one the
    errors show (escaped), or the URL came twice."""
    from firmware_host.daemon.health import Health

    url = f"memory://viewer:{SECRET}@a\x0bb"
    line = Health(rig_url="sim://").status_line({url: {"state": "down",
                                                       "last_error": str(SinkUnavailableError(url, "gone"))}})
    assert line.endswith(" down: gone"), line


@pytest.mark.parametrize("url", [
    f"udp:/\t/viewer:{SECRET}@127.0.0.1:9000",  # urlsplit drops the tab: a password it reads, refused for the tab
    f"udp://127.0.0.1:9000?pass\nword={SECRET}",
])
def test_a_sink_url_refused_for_a_dropped_character_hides_the_secret_url_parsing_reads_past_it(url):
    with pytest.raises(SinkConfigError) as refused:
        open_sink(url).close()
    assert SECRET not in str(refused.value) and "***" in str(refused.value), str(refused.value)


def test_a_down_file_sink_names_its_decoded_path_escaped(tmp_path):
    """The URL's %1B, decoded into the path, reached the log's "link lost (...)" and the status line raw through the
    open's reason ("cannot open <path>"): an ESC sequence rewrote the terminal (the URL itself refuses a raw one)."""
    from firmware_host.sinks.file_sink import FileSink

    sink = FileSink.from_url(f"file://{tmp_path}/x%1B%5B2J/j.jsonl")
    with pytest.raises(SinkUnavailableError) as down:
        sink._connect()
    assert f"cannot open '{tmp_path}/x\\x1b[2J/j.jsonl': [Errno 2]" in down.value.reason, down.value.reason
    assert "\x1b" not in down.value.reason and "\x1b" not in str(down.value), str(down.value)


@pytest.mark.parametrize("error", [SinkUnavailableError, SinkWriteError])
def test_a_link_error_s_reason_holding_a_control_character_is_escaped(error):
    # a device's or pyserial's words may quote a decoded path: "could not open port /dev/x<ESC>..."
    e = error("serial:///dev/x%1B", "could not open port /dev/x\x1b[2J: [Errno 2]")
    assert str(e).endswith(": 'could not open port /dev/x\\x1b[2J: [Errno 2]'"), str(e)
