"""Two daemons on one status file: the second is refused, naming the file and the first one's pid.

Before session 63 two daemons given one ``health.status_file`` (the service, and one started by hand on its config)
replaced each other's report at every beat, and neither said so.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from firmware_host.daemon import Daemon, DaemonConfigError, DaemonStartError, daemon_config_from_dict
from firmware_host.daemon.notify import SystemdNotifier
from firmware_host.daemon.status_claim import StatusFileClaim, StatusFileTaken

REPO = Path(__file__).resolve().parents[3]

_HOLD = """
import sys, time
from firmware_host.daemon.status_claim import StatusFileClaim
claim = StatusFileClaim.take(sys.argv[1])
print("held", flush=True)
sys.stdin.readline()
"""


class _OtherProcess:
    """Another process holding the claim on ``path`` until the context ends."""

    def __init__(self, path: Path) -> None:
        self.proc = subprocess.Popen([sys.executable, "-c", _HOLD, str(path)], cwd=REPO, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(REPO)})

    def __enter__(self) -> "_OtherProcess":
        assert self.proc.stdout.readline().strip() == "held"
        return self

    def __exit__(self, *exc) -> None:
        self.proc.stdin.close()
        self.proc.wait(10)


def test_a_claimed_status_file_is_refused_naming_the_holders_pid(tmp_path):
    status = tmp_path / "status.json"
    with _OtherProcess(status) as other:
        with pytest.raises(StatusFileTaken) as taken:
            StatusFileClaim.take(str(status))
        StatusFileClaim.take(str(tmp_path / "other.json")).release()  # another file in the folder is free
    assert taken.value.pid == other.proc.pid
    assert str(status) in str(taken.value) and f"pid {other.proc.pid}" in str(taken.value)
    StatusFileClaim.take(str(status)).release()  # the holder ended: its claim went with it


def test_the_same_file_named_another_way_is_the_same_claim(tmp_path):
    (tmp_path / "run").mkdir()
    os.symlink(tmp_path / "run", tmp_path / "link")
    claim = StatusFileClaim.take(str(tmp_path / "run" / "status.json"))
    try:
        with pytest.raises(StatusFileTaken):
            StatusFileClaim.take(str(tmp_path / "link" / "status.json"))
    finally:
        claim.release()


def _config(tmp_path: Path, status: Path):
    return daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                    "estimator": {"session": {"model_dir": str(tmp_path / "no-models")}},
                                    "health": {"status_file": str(status)}})


def test_a_second_daemon_on_a_status_file_another_writes_does_not_start_nor_write_it(tmp_path):
    status = tmp_path / "status.json"
    status.write_text('{"pid": 1}\n')  # the first daemon's report
    with _OtherProcess(status) as other:
        with pytest.raises(DaemonStartError) as refused:
            Daemon(_config(tmp_path, status), notifier=SystemdNotifier({})).run(threading.Event())
    assert str(refused.value).startswith(f"health.status_file: {status} is written by another ghnerf-daemon "
                                         f"(pid {other.proc.pid})")
    assert json.loads(status.read_text()) == {"pid": 1}  # untouched: no "stopping" of the refused one


def test_the_claim_is_let_go_when_the_start_fails_otherwise(tmp_path):
    status = tmp_path / "status.json"
    with pytest.raises(DaemonStartError, match="no-models"):  # the model folder is missing
        Daemon(_config(tmp_path, status), notifier=SystemdNotifier({})).run(threading.Event())
    StatusFileClaim.take(str(status)).release()


def test_a_reload_onto_a_status_file_another_writes_is_refused(tmp_path, monkeypatch):
    status, other_file = tmp_path / "status.json", tmp_path / "other.json"
    daemon = Daemon(_config(tmp_path, status), notifier=SystemdNotifier({}),
                    reload_config=lambda: _config(tmp_path, other_file))
    daemon._status_claim = StatusFileClaim.take(str(status))
    try:
        with _OtherProcess(other_file) as other:
            with pytest.raises(DaemonConfigError) as refused:
                daemon._reload(None)
        assert refused.value.key == "health.status_file" and f"pid {other.proc.pid}" in str(refused.value)
        assert daemon.config.health.status_file == str(status)
        with pytest.raises(StatusFileTaken):  # still this daemon's
            StatusFileClaim.take(str(status))
    finally:
        daemon._status_claim.release()


def test_a_reload_onto_a_free_status_file_moves_the_claim(tmp_path):
    status, moved = tmp_path / "status.json", tmp_path / "moved.json"
    daemon = Daemon(_config(tmp_path, status), notifier=SystemdNotifier({}),
                    reload_config=lambda: _config(tmp_path, moved))
    daemon._status_claim = StatusFileClaim.take(str(status))
    try:
        assert "health" in daemon._reload(None)
        with pytest.raises(StatusFileTaken):
            StatusFileClaim.take(str(moved))
        StatusFileClaim.take(str(status)).release()  # the old file is free again
    finally:
        daemon._status_claim.release()


def test_a_reload_onto_the_same_status_file_spelled_another_way_keeps_the_claim(tmp_path):
    # the claim is the file's, however spelled (a link to its folder): taken again, the daemon's own claim refused
    # the reload as another daemon's, naming this daemon's pid; and the old spelling's file was removed
    (tmp_path / "run").mkdir()
    os.symlink(tmp_path / "run", tmp_path / "link")
    status = tmp_path / "run" / "status.json"
    status.write_text('{"pid": 1}\n')
    daemon = Daemon(_config(tmp_path, status), notifier=SystemdNotifier({}),
                    reload_config=lambda: _config(tmp_path, tmp_path / "link" / "status.json"))
    daemon._status_claim = StatusFileClaim.take(str(status))
    try:
        assert "health" in daemon._reload(None)
        assert daemon.config.health.status_file == str(tmp_path / "link" / "status.json")
        assert status.exists()  # the file this daemon still writes, not an old one to remove
        with pytest.raises(StatusFileTaken):  # still held
            StatusFileClaim.take(str(status))
    finally:
        daemon._status_claim.release()
    StatusFileClaim.take(str(status)).release()


def test_every_refused_start_learns_the_holders_pid_however_many_there_were(tmp_path):
    # each refused start's connection (asking for the pid) stayed queued at the holder, never accepted: from the
    # tenth on (the listen backlog full) the refusal named no pid. The daemon's status writes let them go.
    status = tmp_path / "status.json"
    daemon = Daemon(_config(tmp_path, status), notifier=SystemdNotifier({}))
    daemon._status_claim = StatusFileClaim.take(str(status))
    try:
        for _ in range(12):
            with pytest.raises(StatusFileTaken) as taken:
                StatusFileClaim.take(str(status))
            assert taken.value.pid == os.getpid()
            daemon._tick(force=True)
    finally:
        daemon._status_claim.release()
