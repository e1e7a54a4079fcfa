"""file:// holds an exclusive claim on its file: a second writer is down, naming the file and the holder.

Two daemons on a sim:// or replay:// rig, with their own status files and one file:// sink, both appended: their
HELLOs, STATUS lines and frames interleaved in one file.
"""
from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
from pathlib import Path

from firmware_host.sinks import open_sink
from firmware_host.sinks.base import Sink
from firmware_host.sinks.file_claim import holder_pid, holder_text
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, wait_until

_REPO = Path(__file__).resolve().parents[2]


def _hellos(path: Path) -> int:
    return sum(json.loads(line)["type"] == "HELLO" for line in path.read_text().splitlines())


def _refused(sink: Sink) -> str:
    wait_until(lambda: sink.stats().connect_failures >= 2, what="the second sink refused, and retried")
    stats = sink.stats()
    assert stats.state == "down" and not stats.connected and stats.connects == 0
    return stats.last_error or ""


def test_a_second_sink_on_one_file_is_down_naming_it_until_the_first_lets_go(tmp_path: Path) -> None:
    path = tmp_path / "joints.jsonl"
    first = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    second = None
    try:
        assert first.wait_connected(5)
        second = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
        error = _refused(second)
        assert f"{path} is being written by another sink of this process (pid {os.getpid()})" in error
        assert "interleave" in error and "retried until that one lets go" in error
        second.send(make_frame(7))
        first.send(make_frame(0))
        assert first.wait_drained(5)
        assert _hellos(path) == 1 and '"seq":7' not in path.read_text()  # nothing of the second's
        first.close()
        assert second.wait_connected(5)  # the claim went with the first's descriptor
        second.send(make_frame(8))
        assert second.wait_drained(5)
    finally:
        first.close()
        if second is not None:
            second.close()
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    # the second's queued frame and the next follow the first's lines, after its own HELLO
    assert [ln.get("seq") for ln in lines if ln["type"] == "JOINTS"] == [0, 7, 8] and _hellos(path) == 2


_HOLD_UNTIL_STDIN_CLOSES = """
import sys
from firmware_host.sinks import open_sink
from firmware_host.sinks.base import Sink
sink = open_sink("file://" + sys.argv[1] + "?status_s=3600")
assert sink.wait_connected(5)
print("holding", flush=True)
sys.stdin.read()
sink.close()
"""


def test_a_sink_of_another_process_is_named_by_its_pid(tmp_path: Path) -> None:
    path = tmp_path / "joints.jsonl"
    env = {**os.environ, "PYTHONPATH": str(_REPO)}
    proc = subprocess.Popen([sys.executable, "-c", _HOLD_UNTIL_STDIN_CLOSES, str(path)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, env=env, text=True)
    sink = None
    try:
        assert proc.stdout is not None and proc.stdout.readline() == "holding\n"
        sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
        error = _refused(sink)
        assert f"{path} is being written by pid {proc.pid} (" in error
        assert proc.stdin is not None
        proc.stdin.close()  # the other lets go
        assert proc.wait(10) == 0
        assert sink.wait_connected(5)
    finally:
        proc.kill()
        if sink is not None:
            sink.close()
    assert _hellos(path) == 2


def test_a_holder_whose_name_holds_a_control_character_is_named_escaped() -> None:
    """A program names itself (/proc/PID/comm): an ESC sequence in that name reached the log and the daemon's STATUS
    line raw through the sink's error (session 74)."""
    script = "import sys, time; open('/proc/self/comm', 'w').write('ev\\x1b[2Jil'); print(flush=True); time.sleep(30)"
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE)
    try:
        assert child.stdout is not None and child.stdout.readline() == b"\n"
        assert holder_text(child.pid) == f"pid {child.pid} ('ev\\x1b[2Jil')"
    finally:
        child.kill()
        child.wait()
    assert holder_text(os.getpid()).startswith("another sink of this process")


def test_the_claim_holds_through_copytruncate_and_moves_with_a_rename(tmp_path: Path) -> None:
    path = tmp_path / "joints.jsonl"
    sink = open_sink(path.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        sink.send(make_frame(0))
        assert sink.wait_drained(5)
        path.write_bytes(b"")  # logrotate's copytruncate: the same file, still claimed
        assert _claimed(path)
        path.rename(tmp_path / "joints.jsonl.1")  # logrotate's default: the sink opens a new file at the path ...
        sink.send(make_frame(1))
        wait_until(lambda: sink.stats().connects == 2, what="the new file opened")
        assert _claimed(path)  # ... and claims it,
        assert not _claimed(tmp_path / "joints.jsonl.1")  # letting the old one go (compress may take it)
    finally:
        sink.close()
    assert not _claimed(path)


def _claimed(path: Path) -> bool:
    """Whether another open file holds a flock on ``path`` (probed without taking it for long)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        st = os.fstat(fd)
        assert holder_pid(st.st_dev, st.st_ino) == os.getpid()
        return True
    finally:
        os.close(fd)
    return False


def test_a_named_pipe_is_not_claimed(tmp_path: Path) -> None:
    # its reader takes whatever is written; /dev/stdout on a terminal is shared by whatever that shell started
    fifo = tmp_path / "joints.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    sinks = [open_sink(fifo.as_uri() + "?status_s=3600", backoff=FAST_BACKOFF) for _ in range(2)]
    try:
        assert all(sink.wait_connected(5) for sink in sinks)
    finally:
        for sink in sinks:
            sink.close()
        os.close(reader)
