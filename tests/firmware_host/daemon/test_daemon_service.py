"""The daemon's main loop on the simulated rig with the shipped model, end to end in process.

What each test shows: pairs flow from ``sim://`` through the estimator to a ``memory://`` sink
(the real protocol bytes, decoded back); a camera that vanishes is reopened and the sinks flag
CAMERA_FAULT meanwhile; a rig that is absent at start is waited for with backoff; a recording
that ends stops the daemon; systemd hears READY, STATUS and STOPPING; the status file is
complete, valid JSON. They run in real time (the daemon reads the rig at its frame rate) and wait
for events, never asserting how long something took.
"""
from __future__ import annotations

import dataclasses
import gc
import json
import logging
import os
import shutil
import socket
import stat
import threading
import time
import weakref
from pathlib import Path
from typing import Callable, Optional

import numpy as np
import pytest

import drivers
from firmware_host.daemon import Daemon, DaemonConfigError, DaemonStartError, daemon_config_from_dict
from firmware_host.daemon.health import State
from firmware_host.daemon.notify import SystemdNotifier
from firmware_host.listen import Tally
from firmware_host.protocol.constants import Fault, Flags
from firmware_host.protocol.messages import Hello, Joints, Status
from tests.firmware_host.daemon.test_daemon_memory import glibc_only_reason, probe_big_block
from tests.firmware_host.joint_stream_helpers import (FAST_BACKOFF, messages_of, queued_datagrams, record_take,
                                                    wait_until)

REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"
pytestmark = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                reason="no trained model yet: models/model_card.json does not exist")


@pytest.fixture(scope="module")
def sim_url(tmp_path_factory) -> str:
    cache = tmp_path_factory.mktemp("sim-cache")
    return f"sim://?fps=30&seed=0&motion=wave&width=320&height=240&cache={cache}"


def _config(rig: dict, tmp_path: Path, sinks=("memory://?status_s=0.05",), **health) -> object:
    return daemon_config_from_dict({
        "rig": rig,
        "sinks": list(sinks),
        "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
        "health": {"status_file": str(tmp_path / "status.json"), "status_every_s": 0.05, **health},
    })


class _Running:
    """A daemon on a thread, with a notify socket systemd would own."""

    def __init__(self, config, tmp_path: Path, **kw) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(str(tmp_path / "notify.sock"))
        self.sock.settimeout(0.05)
        self.listening = True
        self.listener = threading.Thread(target=self._listen, daemon=True)  # systemd reads all the time
        self.daemon = Daemon(config, notifier=SystemdNotifier({"NOTIFY_SOCKET": str(tmp_path / "notify.sock")}),
                             sink_kwargs={"backoff": FAST_BACKOFF}, **kw)
        self.stop = threading.Event()
        self.rc: list[object] = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.notes: list[dict[str, str]] = []

    def _run(self) -> None:
        try:
            self.rc.append(self.daemon.run(self.stop))
        except BaseException as e:  # surfaced by finish()
            self.rc.append(e)

    def __enter__(self) -> "_Running":
        self.listener.start()
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(timeout=30)
        self.listening = False
        self.listener.join(timeout=5)
        self.sock.close()

    def finish(self) -> object:
        self.stop.set()
        self.thread.join(timeout=30)
        assert not self.thread.is_alive(), "the daemon did not stop"
        self.listening = False
        self.listener.join(timeout=5)
        return self.rc[0]

    def _listen(self) -> None:
        while self.listening:
            try:
                data = self.sock.recv(4096).decode()
            except socket.timeout:
                continue
            except OSError:
                return
            self.notes.append(dict(line.split("=", 1) for line in data.splitlines()))


def test_pairs_stream_to_the_sink_and_systemd_hears_it(sim_url, tmp_path):
    cfg = _config({"url": sim_url}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 15, timeout=60, what="15 estimated pairs")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        assert run.finish() == 0
    messages = messages_of(sink.read())
    hello = [m for m in messages if isinstance(m, Hello)]
    joints = [m for m in messages if isinstance(m, Joints)]
    assert hello and hello[0].cameras == ("left", "right") and hello[0].rig_id
    assert len(joints) == run.daemon.health.pairs_estimated
    # The shipped model finds the simulated person: most joints present, within the room.
    found = ~np.stack([j.missing for j in joints])
    xyz_m = np.stack([j.xyz_mm for j in joints]) / 1000.0
    assert found.mean() > 0.8
    depth = xyz_m[found][:, 2]
    assert np.all((depth > 1.5) & (depth < 4.5))  # the simulated person stands 3 m in front of the rig
    assert stat.S_IMODE(os.stat(tmp_path / "status.json").st_mode) == 0o644  # operators may read it
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["state"] == State.STOPPING
    assert report["pairs"]["estimated"] == len(joints)
    assert report["sinks"]["memory://?status_s=0.05"]["sent"] == len(joints)
    assert report["rig"]["opens"] == 1 and report["rig"]["lost"] == 0
    assert report["estimator"]["latency_ms_median"] > 0
    keys = [set(n) for n in run.notes]
    assert "READY" in keys[0] and run.notes[0]["MAINPID"].isdigit()
    assert any(n.get("STATUS", "").startswith("running:") for n in run.notes)
    assert "STOPPING" in keys[-1]


def test_a_udp_sink_whose_host_does_not_resolve_yet_does_not_hold_up_the_start(sim_url, tmp_path, monkeypatch):
    """Why the unit is not ordered after network-online.target (which held every boot without a link up to the
    wait-online timeout, a serial-only rig too): a boot before the network is up. The UDP sink's host does not
    resolve (EAI_AGAIN, as with no name server reachable), yet the daemon starts, says READY and streams to its
    other sink; once the name resolves (the network came up) the UDP sink delivers too, with no restart."""
    from firmware_host.sinks import udp_sink

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.05)
    network_up = threading.Event()
    real_getaddrinfo = socket.getaddrinfo

    def getaddrinfo(host, port, *args, **kwargs):
        if host != "robot.test":
            return real_getaddrinfo(host, port, *args, **kwargs)
        if not network_up.is_set():
            raise socket.gaierror(socket.EAI_AGAIN, "Temporary failure in name resolution")
        return [(socket.AF_INET, socket.SOCK_DGRAM, 17, "", rx.getsockname())]

    monkeypatch.setattr(udp_sink.socket, "getaddrinfo", getaddrinfo)
    udp = f"udp://robot.test:{rx.getsockname()[1]}"
    cfg = _config({"url": sim_url}, tmp_path, sinks=("memory://?status_s=0.05", udp))
    try:
        with _Running(cfg, tmp_path) as run:
            wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
            assert any(n.get("READY") == "1" for n in run.notes)
            down = run.daemon.sinks[udp].stats()  # still no network: the sink retries in its own thread
            assert not down.connected and "cannot resolve robot.test" in (down.last_error or ""), down

            network_up.set()
            received = []

            def got_datagram() -> bool:
                try:
                    received.append(rx.recv(65536))
                except socket.timeout:
                    pass
                return bool(received)

            wait_until(got_datagram, timeout=30, what="a datagram once the name resolves")
            assert run.finish() == 0
    finally:
        rx.close()


def test_a_vanished_camera_is_reopened_and_flagged(sim_url, tmp_path):
    cfg = _config({"url": f"{sim_url}&unplug_after_s=0.6", "reopen_min_s": 0.01}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_lost >= 2 and run.daemon.health.rig_opens >= 3,
                   timeout=60, what="two unplugs and reopens")
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 3, timeout=60, what="pairs after a reopen")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        assert run.finish() == 0
    assert "unplugged" in run.daemon.health.last_error
    messages = messages_of(sink.read())
    first_joints = next(k for k, m in enumerate(messages) if isinstance(m, Joints))
    # After pairs first flowed (before them the rig was still opening, a camera fault too):
    faults = [m.fault for m in messages[first_joints:] if isinstance(m, Status)]
    assert Fault.CAMERA_FAULT in faults  # flagged while the camera was away
    assert faults.index(Fault.CAMERA_FAULT) < len(faults) - 1 - faults[::-1].index(Fault.OK)  # and cleared
    _assert_seqs_number_the_frames_sent(messages, sink)


def _assert_seqs_number_the_frames_sent(messages: list, sink) -> None:
    """The JOINTS seqs are 0, 1, 2... (docs/protocol.md section 3): every gap is flagged as the sink's own
    drop, and the gaps add up to what the sink dropped; nothing the daemon did not send takes a number."""
    joints = [m for m in messages if isinstance(m, Joints)]
    seqs = [m.header.seq for m in joints]
    assert seqs and seqs[0] == 0, seqs[:5]
    steps = np.diff(seqs)
    assert np.all(steps >= 1), f"the seq went back: {seqs}"
    unflagged = [(seqs[k], seqs[k + 1]) for k in np.flatnonzero(steps > 1)
                 if not joints[k + 1].header.flags & (Flags.DROPPED | Flags.DECIMATED)]
    assert unflagged == [], f"gaps a receiver would count as lost on the link: {unflagged}"
    stats = sink.stats()
    assert len(seqs) == stats.sent and seqs[-1] < stats.submitted  # numbers of frames handed to the sink
    assert int(np.sum(steps - 1)) <= stats.submitted - stats.sent


class _CountingEstimator:
    """Stands in for the model: every third pair rejected (FrameError), the others all joints found."""

    def __init__(self, session, rig, config, **options) -> None:
        self.rig, self.calls, self.sequences = rig, 0, []

    def estimate(self, images, *, sequence: int, timestamp_s: float):
        from ghnerf_runtime.body25 import JOINT_NAMES
        from ghnerf_runtime.errors import FrameError
        from ghnerf_runtime.estimator import PairResult

        self.calls += 1
        self.sequences.append(sequence)  # the driver's pair number: still the estimator's
        if self.calls % 3 == 0:
            raise FrameError("a frame of the wrong shape")
        names = [c.name for c in self.rig.pair]
        n = len(JOINT_NAMES)
        return PairResult(sequence, tuple(JOINT_NAMES), np.full((n, 3), 1.0), np.full(n, 0.9), np.zeros(n, bool),
                          {c: np.full((n, 2), 10.0) for c in names}, {c: np.full(n, 0.9) for c in names},
                          {c: np.zeros(n, bool) for c in names}, {"total": 1.0}, False, {c: True for c in names},
                          {}, "stub")

    def reset(self) -> None:
        pass

    def close(self) -> None:
        pass


def test_a_rig_warning_is_logged_once_through_reopens(sim_url, tmp_path, caplog):
    """A narrow pair (``baseline=0.05``) is warned of at the rig's open; the daemon reopens its rig after each lost
    camera, and each reopen logged the same warning again (session 65's follow-up): once per daemon run now."""
    cfg = _config({"url": f"{sim_url}&baseline=0.05&unplug_after_s=0.4", "reopen_min_s": 0.01}, tmp_path)
    with caplog.at_level(logging.WARNING, logger="drivers"):
        with _Running(cfg, tmp_path) as run:
            wait_until(lambda: run.daemon.health.rig_opens >= 3, timeout=60, what="two reopens")
            assert run.finish() == 0
    narrow = [r.getMessage() for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
    assert len(narrow) == 1, narrow


def test_a_take_s_rig_warning_is_logged_once_through_reopens(sim_url, tmp_path, caplog):
    """``replay://`` warned of its take's rig (a narrow pair, read from the manifest) each time the daemon created
    its source: at each start over of a take played with ``exit_at_end`` false, as at each reopen after a fault
    (session 66). Once per ``rig.url`` now, as a rig file named in ``opencv://`` is."""
    take = tmp_path / "take"
    with drivers.open_rig(f"record+{sim_url}&baseline=0.05&policy=all&out={take}") as rig:
        for _ in range(6):
            rig.read(timeout_s=5)
    cfg = _config({"url": f"replay://{take}", "exit_at_end": False, "reopen_min_s": 0.01}, tmp_path)
    caplog.clear()  # (the recording's sim:// warned of the rig it built)
    with caplog.at_level(logging.WARNING, logger="drivers"):
        with _Running(cfg, tmp_path) as run:
            wait_until(lambda: run.daemon.health.rig_opens >= 3, timeout=60, what="the take started over twice")
            assert run.finish() == 0
    narrow = [r.getMessage() for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
    assert len(narrow) == 1 and narrow[0].startswith(f"{take}/manifest.json: cameras"), narrow


def test_a_reload_back_to_a_rig_seen_earlier_warns_of_it_again(sim_url, tmp_path, caplog):
    """Reloaded from a narrow pair (``baseline=0.05``) to another rig.url and back, the daemon runs the first rig
    again: its warning was not logged again, so the journal since the last reload said nothing of the rig in use
    (session 66). Reopens of one rig.url still log it once."""
    narrow = {"url": f"{sim_url}&baseline=0.05", "reopen_min_s": 0.01}
    other = {"url": f"{sim_url}&baseline=1.2", "reopen_min_s": 0.01}  # no warning
    configs = _Configs()
    with caplog.at_level(logging.WARNING, logger="drivers"):
        with _Running(_config(narrow, tmp_path), tmp_path, reload_config=configs) as run:
            for reloads, rig in enumerate((other, narrow), start=1):
                wait_until(lambda: run.daemon.health.rig_opens == reloads, timeout=60, what=f"open {reloads}")
                configs.next = _config(rig, tmp_path)
                run.daemon.request_reload()
                wait_until(lambda: run.daemon.health.reloads == reloads, timeout=60, what=f"reload {reloads}")
            wait_until(lambda: run.daemon.health.rig_opens == 3, timeout=60, what="the first rig opened again")
            assert run.finish() == 0
    warned = [r.getMessage() for r in caplog.records if "MIN_PAIR_ANGLE_DEG" in r.getMessage()]
    assert len(warned) == 2 and all("are 50 mm apart" in m for m in warned), warned


def test_seqs_stay_contiguous_through_reopens_and_rejected_pairs(sim_url, tmp_path, monkeypatch):
    """Each reopen starts the driver's pair numbers at 0 again and a rejected pair sends nothing: neither
    shows on the wire, where seq counts the frames the daemon sent (a gap: lost after the daemon)."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    cfg = _config({"url": f"{sim_url}&unplug_after_s=0.4", "reopen_min_s": 0.01}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_opens >= 3 and run.daemon.health.pairs_estimated >= 20,
                   timeout=60, what="pairs from three opens of the rig")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        assert run.finish() == 0
    health = run.daemon.health
    assert health.estimate_errors > 0 and health.rig_lost >= 2
    messages = messages_of(sink.read())
    _assert_seqs_number_the_frames_sent(messages, sink)
    assert sink.stats().submitted == health.pairs_estimated  # one frame, one number, per estimated pair
    report = json.loads((tmp_path / "status.json").read_text())  # what the daemon did not send, counted
    assert report["pairs"]["estimate_errors"] == health.estimate_errors
    assert report["pairs"]["read"] == health.pairs_estimated + health.estimate_errors


class _ScriptedEstimator(_CountingEstimator):
    """No rejected pairs; each pair's result is the parent's with :meth:`_figures` of its number ``n`` (counting
    from 0) replaced: what a test scripts, pair by pair."""

    def estimate(self, images, *, sequence: int, timestamp_s: float):
        from dataclasses import replace

        self.n = getattr(self, "n", -1) + 1
        self.calls = 0  # the parent's third call is a FrameError: never reached
        result = super().estimate(images, sequence=sequence, timestamp_s=timestamp_s)
        return replace(result, **self._figures(self.n))

    def _figures(self, n: int) -> dict:
        raise NotImplementedError


class _SceneEstimator(_ScriptedEstimator):
    """Pairs 2, 3 (counting from 0) with two people in view, pair 4 a prior fallback, and from pair 6 on views 3 px
    apart (a camera moved: the median of the calibration check's window of 3 passes 1 px at pair 7)."""

    def _figures(self, n: int) -> dict:
        return dict(several_people=n in (2, 3), prior_fallback=n == 4, reprojection_px_median=3.0 if n >= 6 else 0.2)


def _flags_on_the_link(estimator, sim_url, tmp_path, monkeypatch, **health):
    """Run the daemon on ``estimator`` (calibration window 3, 1 px; ``health``: other health settings) for 14 pairs;
    its memory sink's messages and the JOINTS' scene flags by sequence number (seq k is the k-th estimate, no pair
    rejected: keyed by it, a frame the sink dropped cannot shift the rest)."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", estimator)
    cfg = _config({"url": sim_url}, tmp_path, **{"calibration_window": 3, "calibration_max_px": 1.0, **health})
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 14, timeout=60, what="14 estimated pairs")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        assert run.finish() == 0
    messages = messages_of(sink.read())
    flags = {m.header.seq: m.header.flags & ~(Flags.DROPPED | Flags.DECIMATED)
             for m in messages if isinstance(m, Joints)}
    assert set(range(10)) <= set(flags), sorted(flags)
    return run, messages, flags


def test_what_the_status_file_says_of_a_frame_reaches_the_receiver(sim_url, tmp_path, monkeypatch):
    """A robot reads only the joint stream: the pairs with two people in view or a prior fallback reach it as
    JOINTS flagged SEVERAL_PEOPLE / PRIOR_FALLBACK, the suspect calibration as CALIBRATION_SUSPECT on the JOINTS
    and on every STATUS from then on, and HELLO announces the flags (docs/protocol.md section 3). Nothing of it
    left the daemon: the flags were 0."""
    run, messages, flags = _flags_on_the_link(_SceneEstimator, sim_url, tmp_path, monkeypatch)
    expected = {2: Flags.SEVERAL_PEOPLE, 3: Flags.SEVERAL_PEOPLE, 4: Flags.PRIOR_FALLBACK}
    assert all(f & ~Flags.CALIBRATION_SUSPECT == expected.get(seq, 0) for seq, f in flags.items()), flags
    suspect = {seq: bool(f & Flags.CALIBRATION_SUSPECT) for seq, f in flags.items()}
    assert suspect == {seq: seq >= 7 for seq in flags}, flags  # 2 of 3 px in the window of 3: median 3 px
    assert run.daemon.health.calibration.suspect
    statuses = [m for m in messages if isinstance(m, Status)]
    assert not statuses[0].header.flags & Flags.CALIBRATION_SUSPECT
    assert statuses[-1].header.flags == Flags.CALIBRATION_SUSPECT  # the link says so while no frame flows too
    assert {m.header.flags for m in messages if isinstance(m, Hello)} == {0x3C}  # SCENE_FLAGS: the sender says them
    # and the status file counts them over its window (docs/daemon.md; until session 64 it said none of them,
    # though docs/daemon.md had it call the pairs several_people, prior_fallback or single_view)
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["estimator"]["flagged"] == {"several_people": 2, "prior_fallback": 1, "single_view": 0}


class _PannedEstimator(_ScriptedEstimator):
    """Views that always meet (0.2 px), no feet in view for pairs 0-2, feet on the floor for 3-5 and 0.3 m below
    it from pair 6 on (a camera panned: the median of the floor check's window of 3 passes 0.05 m at pair 7)."""

    def _figures(self, n: int) -> dict:
        return dict(reprojection_px_median=0.2, lowest_foot_m=None if n < 3 else -0.3 if n >= 6 else 0.02)


def test_feet_off_the_floor_flag_the_calibration_on_the_link(sim_url, tmp_path, monkeypatch):
    """A panned camera: the views still meet, but the feet sink below the floor. The pairs without feet do not
    count; once the floor check's window of 3 has its median 0.3 m below the floor the JOINTS and every STATUS
    carry CALIBRATION_SUSPECT, and the status file says which symptom (docs/protocol.md, docs/daemon.md)."""
    run, messages, flags = _flags_on_the_link(_PannedEstimator, sim_url, tmp_path, monkeypatch)
    assert {seq: bool(f & Flags.CALIBRATION_SUSPECT) for seq, f in flags.items()} == {seq: seq >= 7 for seq in flags}
    assert [m for m in messages if isinstance(m, Status)][-1].header.flags == Flags.CALIBRATION_SUSPECT
    calibration = run.daemon.health.report()["calibration"]
    assert calibration["suspect"] and calibration["floor_suspect"] and not calibration["px_suspect"]
    assert calibration["lowest_foot_m_median"] == -0.3 and calibration["floor_pairs"] == 3
    assert "feet 0.30 m below the floor > 0.05 m" in run.daemon.health.status_line()


def test_a_vmc_receiver_hears_the_suspect_calibration_too(sim_url, tmp_path, monkeypatch):
    """vmc:// has no header flags: a game heard /VMC/Ext/OK "calibrated" from a rig the daemon flagged suspect. The
    daemon's frames reach it with /ghnerf/calibration_suspect from the pair the check turns suspect on (pair 7, as on
    the binary link), and without it before (docs/protocol.md section 8)."""
    import firmware_host.daemon.service as service

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    vmc_url = f"vmc://127.0.0.1:{rx.getsockname()[1]}?queue=64"
    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _SceneEstimator)
    cfg = _config({"url": sim_url}, tmp_path, sinks=(vmc_url,), calibration_window=3, calibration_max_px=1.0)
    try:
        with _Running(cfg, tmp_path) as run:
            wait_until(lambda: run.daemon.health.pairs_estimated >= 10, timeout=60, what="10 estimated pairs")
            sink = run.daemon.sinks[vmc_url]
            assert run.finish() == 0
        stats = sink.stats()
        dgrams = queued_datagrams(rx)
    finally:
        rx.close()
    assert stats.dropped == stats.decimated == 0, stats  # so the k-th frame heard is the k-th estimate
    firsts = [d for d in dgrams if b"/VMC/Ext/OK\0" in d]  # each frame's first datagram
    assert len(firsts) == stats.sent >= 10
    heard = [b"/ghnerf/calibration_suspect\0" in d for d in firsts]
    assert heard == [k >= 7 for k in range(len(firsts))], heard


class _FailingRunsEstimator(_CountingEstimator):
    """onnxruntime failing (ModelRunError) on the 4th pair, and on every pair from the 10th on if ``always``;
    the others all joints found (no FrameError)."""

    always = False

    def estimate(self, images, *, sequence: int, timestamp_s: float):
        from ghnerf_runtime.errors import ModelRunError

        self.n = getattr(self, "n", 0) + 1
        if self.n == 4 or (self.always and self.n >= 10):
            raise ModelRunError("graph 'human' failed: RuntimeException: out of memory", path="human.onnx")
        self.calls = 0  # the parent's third call is a FrameError: never reached
        return super().estimate(images, sequence=sequence, timestamp_s=timestamp_s)


def test_the_model_failing_on_one_pair_skips_it(sim_url, tmp_path, monkeypatch):
    """One pair onnxruntime fails on is counted and skipped, like a rejected one (it stopped the daemon)."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _FailingRunsEstimator)
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 8 or run.rc, timeout=30, what="pairs after it")
        assert run.finish() == 0
    assert run.daemon.health.estimate_errors == 1
    assert "the model failed" in run.daemon.health.last_error and "out of memory" in run.daemon.health.last_error


def test_the_model_failing_on_every_pair_stops_the_daemon_saying_why(sim_url, tmp_path, monkeypatch):
    """MAX_FAILED_RUNS failures in a row stop it (exit 1 in the CLI: systemd restarts it), and the status
    file, which outlives the process, says why."""
    import firmware_host.daemon.service as service
    from ghnerf_runtime.errors import ModelRunError

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", type("Always", (_FailingRunsEstimator,), {"always": True}))
    monkeypatch.setattr(service, "MAX_FAILED_RUNS", 5)
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path) as run:
        run.thread.join(timeout=30)
        assert not run.thread.is_alive()
    assert isinstance(run.rc[0], ModelRunError)
    assert run.daemon.health.estimate_errors == 6  # the 4th pair, then the 10th to the 14th
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["state"] == State.STOPPING
    assert report["last_error"].startswith("stopped by ModelRunError: human.onnx: graph 'human' failed")


def test_a_take_s_negative_capture_times_kept_are_rejected_pairs_not_a_crash(sim_url, tmp_path, monkeypatch, caplog):
    """The recording format allows negative stamps (signed 64-bit), and ``keep_time=1`` delivers them, but the
    stream's capture times are unsigned microseconds: the first such pair failed in ``JointFrame`` with a bare
    ``ValueError`` and stopped the daemon (exit 1: a restart, then the same). Each is a rejected pair now, counted
    and logged before the model runs on it; the take plays to its end."""
    import firmware_host.daemon.service as service

    take = tmp_path / "take"
    # stamps from -1 s, 1/30 s apart: every one negative
    record_take(f"record+{sim_url}&policy=all&out={take}", drivers.ManualClock(-10**9), 6)
    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    with caplog.at_level(logging.WARNING, logger="ghnerf.daemon"):
        with _Running(_config({"url": f"replay://{take}?keep_time=1&speed=free"}, tmp_path), tmp_path) as run:
            run.thread.join(timeout=60)  # rig.exit_at_end: the daemon stops by itself
            assert not run.thread.is_alive()
    assert run.rc == [0]
    health = run.daemon.health
    assert health.estimate_errors == health.pairs_read == 6 and health.pairs_estimated == 0
    rejected = [r.getMessage() for r in caplog.records if "rejected" in r.getMessage()]
    assert len(rejected) == 1 and "frame 0 was captured at timestamp_ns=-1000000000" in rejected[0], rejected
    assert "keep_time=1" in rejected[0]
    assert run.daemon._estimator.calls == 0


def test_an_absent_rig_is_waited_for_then_a_recording_plays_to_its_end(sim_url, tmp_path):
    take = tmp_path / "take"
    with drivers.open_rig(f"record+{sim_url}&policy=all&out={tmp_path / 'made'}") as rig:
        for _ in range(12):
            rig.read(timeout_s=5)
    cfg = _config({"url": f"replay://{take}", "reopen_min_s": 0.02, "reopen_max_s": 0.1}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_open_failures >= 3, timeout=30, what="failed opens")
        report = json.loads((tmp_path / "status.json").read_text())
        assert report["state"] in (State.WAITING, State.OPENING)
        assert str(take) in report["last_error"]
        assert run.daemon.sinks == {}  # nothing to announce until the rig (its camera names) is known
        shutil.copytree(tmp_path / "made", take)  # the recording appears
        run.thread.join(timeout=60)  # rig.exit_at_end: the daemon stops by itself
        assert not run.thread.is_alive()
        assert run.rc == [0]
    assert run.daemon.health.pairs_estimated >= 10
    assert run.daemon.health.rig_opens == 1


@pytest.mark.parametrize("damage", ["garbage", "header cut short"])
def test_a_corrupt_frame_in_a_recording_is_skipped_and_the_recording_plays_to_its_end(sim_url, tmp_path, damage):
    """A frame a backend cannot deliver is raised once and the next read goes on (RigSource.read): the
    daemon counts it and reads on. (It took it for a failed rig: the replay was reopened from its start,
    hit the same frame, and played its first pairs for ever, never reaching the end.) An image whose header is cut
    short is such a frame: no size at open, not a take of another size than its rig. (An image of another size
    was one too, until the open measured every image: test_a_take_of_another_size_than_its_rig_stops_the_daemon.)"""
    take = tmp_path / "take"
    with drivers.open_rig(f"record+{sim_url}&policy=all&out={take}") as rig:
        for _ in range(16):
            rig.read(timeout_s=5)
    corrupt = sorted((take / "images" / "left").iterdir())[5]
    if damage == "garbage":
        corrupt.write_bytes(b"not a png")
    else:
        corrupt.write_bytes(corrupt.read_bytes()[:12])
    cfg = _config({"url": f"replay://{take}", "reopen_min_s": 0.01, "reopen_max_s": 0.01}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        run.thread.join(timeout=20)  # rig.exit_at_end: the daemon stops by itself at the recording's end
        assert not run.thread.is_alive(), f"still running after {run.daemon.health.rig_opens} opens"
        assert run.rc == [0]
    health = run.daemon.health
    assert health.rig_opens == 1 and health.rig_lost == 0
    assert health.read_errors == 1 and health.pairs_estimated >= 12
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["pairs"]["read_errors"] == 1


def test_a_take_of_another_size_than_its_rig_stops_the_daemon_naming_it(sim_url, tmp_path):
    """Every image of a camera resized (320x240 recorded, 160x120 now): each read failed on the image, two before a
    pair were taken for a failed rig, and the take was reopened from its start for ever (state waiting). Its open
    refuses it now (drivers.FrameSizeError), and three such opens stop the daemon (exit 2), as for cameras that never
    deliver their rig file's size, blaming the take."""
    import cv2

    take = tmp_path / "take"
    with drivers.open_rig(f"record+{sim_url}&policy=all&out={take}") as rig:
        for _ in range(8):
            rig.read(timeout_s=5)
    for path in sorted((take / "images" / "left").iterdir()):
        cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), (160, 120)))
    cfg = _config({"url": f"replay://{take}", "reopen_min_s": 0.01, "reopen_max_s": 0.01}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        run.thread.join(timeout=20)
        assert not run.thread.is_alive(), f"still reopening the take after {run.daemon.health.rig_lost} losses"
    error = run.rc[0]
    assert isinstance(error, DaemonStartError)
    message = str(error)
    assert message.startswith(f"rig.url 'replay://{take}': recording {take}: camera 'left': ")
    assert " images are 160x120 (images/left/" in message
    assert f"but its rig camera in {take / 'manifest.json'} is 320x240" in message
    assert message.endswith("(the same on 3 opens in a row, the cameras never having delivered the rig's size: a take "
                            "whose images are not the size of the rig in its manifest, which no restart fixes)")
    assert run.daemon.health.rig_open_failures == 3 and run.daemon.health.rig_opens == 0


def test_a_replay_streams_capture_times_on_the_daemons_clock(sim_url, tmp_path):
    """A take recorded on another clock (here three days ahead, a device with a longer uptime) streamed its
    recorded stamps as capture times: a receiver's latency (send - capture) was minus three days. Replayed,
    the frames are stamped on the daemon's clock with the recorded spacing."""
    take = tmp_path / "take"
    ahead = drivers.ManualClock(time.monotonic_ns() + 3 * 86_400 * 10**9)
    with drivers.open_rig(f"record+{sim_url}&policy=all&out={take}&lossless=1", clock=ahead) as rig:
        recorded = [rig.read(timeout_s=5).frames[0].timestamp_ns for _ in range(12)]
    cfg = _config({"url": f"replay://{take}"}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.sinks, timeout=30, what="the sink opened")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        run.thread.join(timeout=60)  # rig.exit_at_end: the daemon stops by itself at the recording's end
        assert not run.thread.is_alive() and run.rc == [0]
    joints = [m for m in messages_of(sink.read()) if isinstance(m, Joints)]
    assert len(joints) == len(recorded)
    tally = Tally()  # what ghnerf-listen computes
    for message in joints:
        tally.add(message)
    assert all(0 <= ms < 5000 for ms in tally.latency_ms), tally.latency_ms  # the estimate's time, not days
    sent = [m.header.capture_us for m in joints]
    assert all(abs((s - sent[0]) - (t - recorded[0]) // 1000) <= 1 for s, t in zip(sent, recorded))


def test_a_rig_whose_reads_keep_failing_is_reopened(sim_url, tmp_path, monkeypatch):
    """A failure raised again on the next read (an opencv:// capture thread that died) is the rig's: reopened."""
    def fail(self, timeout_s):
        raise drivers.RigOperationError("capture thread died")

    monkeypatch.setattr(type(drivers.create_rig_source(sim_url)), "_read_frame", fail)
    cfg = _config({"url": sim_url, "reopen_min_s": 0.01, "reopen_max_s": 0.01}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_lost >= 2, timeout=30, what="two reopens")
        assert run.finish() == 0
    assert "capture thread died" in run.daemon.health.last_error


def test_stop_while_waiting_is_prompt(tmp_path):
    cfg = _config({"url": f"replay://{tmp_path / 'never'}", "reopen_min_s": 30, "reopen_max_s": 30}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_open_failures >= 1, timeout=30, what="a failed open")
        t0 = time.monotonic()
        assert run.finish() == 0
        assert time.monotonic() - t0 < 5.0  # not after the 30 s backoff: the wait watches the stop event


class _GatedOpens:
    """``drivers.create_rig_source`` for the daemon: the sources after the first ``free`` ones block in their open
    until ``release`` is set (an OAK's open, which may take longer than systemd's TimeoutStopSec)."""

    def __init__(self, real: Callable, free: int = 1) -> None:
        self._real, self._free = real, free
        self.release, self.entered = threading.Event(), threading.Event()
        self.sources: list = []

    def __call__(self, url: str, **kw):
        source = self._real(url, **kw)
        if len(self.sources) >= self._free:
            opener = source._open

            def gated() -> None:
                self.entered.set()
                self.release.wait()
                opener()

            source._open = gated
        self.sources.append(source)
        return source


def test_a_stop_during_an_open_does_not_wait_for_it(sim_url, tmp_path, monkeypatch):
    """A stop while the rig reopens ends the daemon without waiting for the open (up to health.open_allowance_s,
    60 s, while systemd SIGKILLs after TimeoutStopSec=20): the sinks are closed with what was sent, STOPPING and the
    status file's last report written, exit 0. The stop closes the source at once, before the open returns (until
    now the open's thread closed it once the open returned, the device held meanwhile), and the open, completing
    later in its abandoned thread, releases what it made: no device is left claimed."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    opens = _GatedOpens(drivers.create_rig_source)
    monkeypatch.setattr(service.drivers, "create_rig_source", opens)
    cfg = _config({"url": f"{sim_url}&unplug_after_s=0.6", "reopen_min_s": 0.01}, tmp_path)
    run = _Running(cfg, tmp_path)
    try:
        with run:
            assert opens.entered.wait(60), "the rig was never reopened"
            sink = run.daemon.sinks["memory://?status_s=0.05"]
            run.stop.set()
            run.thread.join(timeout=15)
            assert not run.thread.is_alive(), "the stop waited for the open"
            assert not opens.release.is_set() and run.rc == [0]
            assert opens.sources[-1]._closed  # closed by the stop, its open still held back
        assert sink.stats().state == "closed"
        joints = [m for m in messages_of(sink.read()) if isinstance(m, Joints)]
        assert joints and len(joints) == sink.stats().sent
        report = json.loads((tmp_path / "status.json").read_text())
        assert report["state"] == State.STOPPING and report["rig"]["opens"] == 1
        assert "STOPPING" in run.notes[-1]
    finally:
        opens.release.set()
    late = opens.sources[-1]
    # closed and released: close() marks a source closed before it releases it (an open() finishing meanwhile
    # must see the close), so "closed" alone can be read while the release still runs
    wait_until(lambda: late._closed and not late.is_open, timeout=30, what="the abandoned open closing its source")


def test_a_model_that_does_not_load_stops_the_start(tmp_path):
    broken = tmp_path / "models"
    broken.mkdir()
    (broken / "encoder.onnx").write_bytes(b"\x08\x07garbage")
    cfg = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                   "estimator": {"session": {"model_dir": str(broken)}}})
    with pytest.raises(DaemonStartError, match=str(broken)):
        Daemon(cfg, notifier=SystemdNotifier({})).run(threading.Event())


class _RecordingNotifier(SystemdNotifier):
    """What the daemon tells systemd, kept (no socket)."""

    def __init__(self) -> None:
        super().__init__({})
        self.notes: list[dict] = []

    def notify(self, **fields: object) -> bool:
        self.notes.append(fields)
        return True


BASELINE = MODELS / "baseline"  # a model without encoder heatmaps (docs/runtime.md, "Heatmap sources")


@pytest.mark.skipif(not BASELINE.is_dir(), reason="no models/baseline")
def test_settings_the_model_cannot_serve_stop_the_start_before_ready(tmp_path):
    """heatmaps.source 'encoder' (the default) with the baseline, which has no encoder heatmaps: the estimator
    refused it only once built, when the rig opened, so the daemon loaded the model, sent READY and exited 2 when
    the camera came, or waited for ever for one that never did (as here). It is refused now, before READY."""
    cfg = daemon_config_from_dict({"rig": {"url": f"replay://{tmp_path / 'never'}"}, "sinks": ["memory://"],
                                   "estimator": {"session": {"model_dir": str(BASELINE), "warmup": False}}})
    notifier, stop = _RecordingNotifier(), threading.Event()
    timer = threading.Timer(15.0, stop.set)  # the old code waits for the rig: stopped, it returned 0
    timer.start()
    try:
        with pytest.raises(DaemonStartError, match=r"^estimator: .*heatmaps\.source = 'encoder' needs a model "
                                                   r"exported with encoder heatmaps"):
            Daemon(cfg, notifier=notifier).run(stop)
    finally:
        timer.cancel()
    assert not stop.is_set(), "refused only after the wait for the rig"
    assert not any("ready" in note for note in notifier.notes)  # systemd never heard READY


@pytest.mark.skipif(not BASELINE.is_dir(), reason="no models/baseline")
def test_the_start_check_passes_settings_the_model_serves(tmp_path):
    """The same baseline with the heatmaps it has passes the stand-in check (the real rig's estimator is built
    when it opens)."""
    cfg = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                   "estimator": {"session": {"model_dir": str(BASELINE), "warmup": False},
                                                 "heatmaps": {"source": "rendered"}}})
    daemon = Daemon(cfg, notifier=SystemdNotifier({}))
    daemon._load_model()
    daemon._check_estimator()
    assert daemon._estimator is None  # the stand-in's is not kept


def test_a_bad_rig_url_stops_the_start(tmp_path):
    cfg = _config({"url": "sim://?fps=-1"}, tmp_path)
    with pytest.raises(DaemonStartError, match=r"rig\.url .*fps"):
        Daemon(cfg, notifier=SystemdNotifier({})).run(threading.Event())


def test_a_bad_sink_url_stops_the_start_without_a_rig(tmp_path):
    cfg = _config({"url": f"replay://{tmp_path / 'not-yet'}"}, tmp_path, sinks=["udp://127.0.0.1:9870?fps=fast"])
    with pytest.raises(DaemonStartError, match=r"sinks\[0\]: .*fps"):
        Daemon(cfg, notifier=SystemdNotifier({})).run(threading.Event())


class _StopWhileLoading(threading.Event):
    """A SIGTERM that arrives while the model loads: clear at the start's first look (a stop set before it loads no
    model), set from the next on."""

    def __init__(self) -> None:
        super().__init__()
        self.looks = 0

    def is_set(self) -> bool:
        self.looks += 1
        return self.looks > 1 or super().is_set()


def test_stopped_while_loading_never_reports_ready(tmp_path):
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(tmp_path / "n.sock"))
    sock.settimeout(0.5)
    stop = _StopWhileLoading()
    cfg = _config({"url": "sim://"}, tmp_path)
    try:
        assert Daemon(cfg, notifier=SystemdNotifier({"NOTIFY_SOCKET": str(tmp_path / "n.sock")})).run(stop) == 0
        assert sock.recv(4096) == b"STOPPING=1"
    finally:
        sock.close()


_PREVIOUS_RUN = {"state": "running", "pid": 1, "last_error": None}  # a run killed by the watchdog left this


def test_a_start_that_fails_before_the_loop_says_why_in_the_status_file(tmp_path):
    """The status file outlives the process (RuntimeDirectoryPreserve=yes) to say what happened; a start that exited 2
    before the loop (a model that does not load) left the previous run's report there, "running" under a dead pid."""
    broken = tmp_path / "models"
    broken.mkdir()
    (broken / "encoder.onnx").write_bytes(b"\x08\x07garbage")
    status = tmp_path / "status.json"
    status.write_text(json.dumps(_PREVIOUS_RUN))
    cfg = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                   "estimator": {"session": {"model_dir": str(broken)}},
                                   "health": {"status_file": str(status)}})
    with pytest.raises(DaemonStartError):
        Daemon(cfg, notifier=SystemdNotifier({})).run(threading.Event())
    report = json.loads(status.read_text())
    assert report["pid"] == os.getpid() and report["state"] == "stopping"
    assert report["last_error"].startswith("stopped by DaemonStartError: ") and str(broken) in report["last_error"]


def test_a_stop_while_loading_leaves_this_runs_report(tmp_path):
    status = tmp_path / "status.json"
    status.write_text(json.dumps(_PREVIOUS_RUN))
    stop = _StopWhileLoading()
    assert Daemon(_config({"url": "sim://"}, tmp_path), notifier=SystemdNotifier({})).run(stop) == 0
    report = json.loads(status.read_text())
    assert report["pid"] == os.getpid() and report["state"] == "stopping" and report["last_error"] is None
    assert report["rig"]["opens"] == 0


class _StopWhenReady(SystemdNotifier):
    """Sets ``stop`` as the daemon reports ready: it logs its start, then stops without opening the rig."""

    def __init__(self, stop: threading.Event) -> None:
        super().__init__({})
        self.stop = stop

    def notify(self, **fields: object) -> bool:
        if "ready" in fields:
            self.stop.set()
        return True


def test_the_start_log_line_shows_sink_urls_without_their_passwords(tmp_path, caplog):
    secret = "memory://viewer:s3cret@here?status_s=0.05"  # memory:// takes any location, user info too
    cfg = _config({"url": "sim://"}, tmp_path, sinks=[secret])
    stop = threading.Event()
    with caplog.at_level(logging.INFO, logger="ghnerf.daemon"):
        assert Daemon(cfg, notifier=_StopWhenReady(stop)).run(stop) == 0
    started = [r.getMessage() for r in caplog.records if r.getMessage().startswith("started:")]
    assert started and "memory://viewer:***@here?status_s=0.05" in started[0]
    assert "s3cret" not in caplog.text


def test_a_sink_that_fails_to_close_is_logged_without_its_password(tmp_path, caplog):
    from firmware_host.sinks import open_sink

    url = "memory://viewer:s3cret@here?status_s=0.01"
    daemon = Daemon(_config({"url": "sim://"}, tmp_path), notifier=SystemdNotifier({}))
    sink = open_sink(url)

    def fail() -> None:
        raise OSError("the link is gone")

    daemon._sinks[url] = sink
    sink_close, sink.close = sink.close, fail
    try:
        with caplog.at_level(logging.WARNING, logger="ghnerf.daemon"):
            daemon._close_sink(url)
    finally:
        sink_close()
    assert "closing sink memory://viewer:***@here?status_s=0.01: the link is gone" in caplog.text
    assert "s3cret" not in caplog.text


def test_the_status_file_names_sinks_without_their_passwords(tmp_path):
    """The status file (0644: operators read it) keyed ``sinks`` by the URLs as configured, so a ``memory://``
    sink's password was there. Now redacted; two URLs differing only in their password are told apart by ``#2``
    in the config's order, whatever order the sinks were opened in, and a sink a reload removed comes after."""
    from firmware_host.sinks import open_sink

    urls = ["memory://viewer:s3cret@here?status_s=0.01", "memory://viewer:hunter2@here?status_s=0.01", "memory://"]
    removed = "memory://viewer:t0ken@here?status_s=0.01"
    daemon = Daemon(_config({"url": "sim://"}, tmp_path, sinks=urls), notifier=SystemdNotifier({}))
    daemon._sinks[removed] = open_sink(removed)
    daemon._close_sink(removed)  # its last counters stay in the report, as after a reload that removed it
    for url in reversed(urls):  # opened in the other order than the config's
        daemon._sinks[url] = open_sink(url)
    try:
        daemon._tick(force=True, tell_systemd=False)
    finally:
        for url in urls:
            daemon._close_sink(url)
    text = (tmp_path / "status.json").read_text()
    assert list(json.loads(text)["sinks"]) == ["memory://viewer:***@here?status_s=0.01",
                                               "memory://viewer:***@here?status_s=0.01#2", "memory://",
                                               "memory://viewer:***@here?status_s=0.01#3"]
    assert not any(secret in text for secret in ("s3cret", "hunter2", "t0ken"))


def test_a_stuck_estimate_is_flagged_while_it_runs(tmp_path):
    from firmware_host.sinks import open_sink

    cfg = _config({"url": "sim://"}, tmp_path, slow_estimate_s=0.5)
    daemon = Daemon(cfg, notifier=SystemdNotifier({}))
    sink = open_sink("memory://?status_s=0.01")
    daemon._sinks["memory://"] = sink  # as _open_sinks leaves it (what a rig being open would do)
    try:
        daemon._on_watchdog_tick("estimating a pair", 0.2)
        assert not daemon.health.estimator_stalled
        daemon._on_watchdog_tick("reading a pair", 3.0)  # a slow read is the camera's, not the estimator's
        assert not daemon.health.estimator_stalled
        daemon._on_watchdog_tick("estimating a pair", 0.8)  # the watchdog's thread, mid-estimate
        assert daemon.health.estimator_stalled
        wait_until(lambda: any(isinstance(m, Status) and m.fault == Fault.ESTIMATOR_STALLED
                               for m in messages_of(sink.read())), timeout=10, what="a STATUS with the fault")
    finally:
        sink.close()


def test_on_the_depthai_backend(tmp_path):
    """The daemon on ``depthai://``'s real backend (calibration, Sync stage, queues), on a host-only depthai
    pipeline standing in for the device (tests/drivers/depthai_host.py): the frames show no person, so
    this is about the plumbing: pairs read and estimated, sinks fed, a prompt stop."""
    from tests.drivers.depthai_host import HostPipelineLink

    cfg = _config({"url": "depthai://?width=160&height=100&mount_height=1.2&fps=30"}, tmp_path)
    with _Running(cfg, tmp_path, rig_kwargs={"link_factory": HostPipelineLink}) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 10, timeout=60, what="10 estimated pairs")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        t0 = time.monotonic()
        assert run.finish() == 0
        assert time.monotonic() - t0 < 10.0
    joints = [m for m in messages_of(sink.read()) if isinstance(m, Joints)]
    assert len(joints) == run.daemon.health.pairs_estimated >= 10
    assert run.daemon.health.rig_lost == 0


@pytest.mark.hardware
@pytest.mark.skipif(os.environ.get("GHNERF_TEST_DEPTHAI") != "1",
                    reason="needs an OAK device; set GHNERF_TEST_DEPTHAI=1 (and GHNERF_DEPTHAI_ID) to run")
def test_on_an_oak(tmp_path):
    url = f"depthai://{os.environ.get('GHNERF_DEPTHAI_ID', '')}?fps=30&width=640&height=400&mount_height=1.2"
    cfg = _config({"url": url}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 30, timeout=90, what="30 estimated pairs")
        assert run.finish() == 0
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["rig"]["opens"] == 1 and report["pairs"]["estimated"] >= 30


def test_the_watchdog_wakes_within_the_slow_estimate_threshold(tmp_path):
    cfg = _config({"url": "sim://"}, tmp_path, slow_estimate_s=1.0)
    daemon = Daemon(cfg, notifier=SystemdNotifier({"NOTIFY_SOCKET": "/nonexistent", "WATCHDOG_USEC": "30000000"}))
    assert daemon.watchdog._interval <= 0.5  # not systemd's 15 s


def test_a_sink_url_with_camera_names_is_refused_at_start(tmp_path):
    cfg = _config({"url": "sim://"}, tmp_path, sinks=["memory://?cameras=a,b"])
    with pytest.raises(DaemonStartError, match=r"sinks\[0\]: .*cameras="):
        Daemon(cfg, notifier=SystemdNotifier({})).run(threading.Event())


# ---------------------------------------------------------------- reloading the config (SIGHUP)
class _ScanningEstimator(_ScriptedEstimator):
    """With ``presence.scan_every_s`` set, every other pair's (held) scan answer says someone else is near, and
    without it there is no answer (``someone_else`` None), as the estimator's."""

    def __init__(self, session, rig, config, **options) -> None:
        super().__init__(session, rig, config, **options)
        self.scans = config.presence.scan_every_s > 0

    def _figures(self, n: int) -> dict:
        return dict(someone_else=(n % 2 == 1) if self.scans else None)


def test_someone_else_reaches_the_link_and_hello_says_whether_the_scan_runs(sim_url, tmp_path, monkeypatch):
    """A robot that slows down when someone else is near reads SOMEONE_ELSE on the frames (bit 6) while the
    estimator's scan for others runs, announced in HELLO (0x7C); a reload that turns the scan off announces 0x3C
    from then on, and no frame carries the bit (docs/protocol.md, "Scene flags"). Before session 65 the answer was
    in ghnerf-run's JSON only, and HELLO said 0x3C either way."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _ScanningEstimator)
    data = _config_dict(sim_url, tmp_path)
    data["estimator"]["presence"] = {"scan_every_s": 0.5}
    configs = _Configs()
    with _Running(daemon_config_from_dict(data), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 6, timeout=60, what="6 estimated pairs")
        del data["estimator"]["presence"]
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=60, what="the reload")
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 4, timeout=60, what="pairs after the reload")
        sink = run.daemon.sinks["memory://?status_s=0.05"]
        assert run.finish() == 0
    messages = messages_of(sink.read())
    hellos = [k for k, m in enumerate(messages) if isinstance(m, Hello)]
    off = next(k for k in hellos if messages[k].header.flags == 0x3C)  # SCENE_FLAGS: the scan no longer runs
    assert {messages[k].header.flags for k in hellos if k < off} == {0x7C}  # ALL_SCENE_FLAGS: it runs
    assert {messages[k].header.flags for k in hellos if k > off} == {0x3C}
    someone = [bool(m.header.flags & Flags.SOMEONE_ELSE) for m in messages[:off] if isinstance(m, Joints)]
    assert True in someone and False in someone, someone
    assert not any(m.header.flags & Flags.SOMEONE_ELSE for m in messages[off:] if isinstance(m, Joints))
    assert any(isinstance(m, Joints) for m in messages[off:])


class _Configs:
    """What ``reload_config`` returns next: a config, or the error a bad file raises."""

    def __init__(self) -> None:
        self.next: object = None

    def __call__(self):
        if isinstance(self.next, Exception):
            raise self.next
        return self.next


def _notes_after(notes: list[dict[str, str]], key: str) -> list[dict[str, str]]:
    k = next(i for i, n in enumerate(notes) if key in n)
    return notes[k:]


def test_a_reload_adds_and_removes_sinks_while_the_others_stream_on(sim_url, tmp_path):
    first, second = "memory://?status_s=0.05", "memory://?status_s=0.06"
    configs = _Configs()
    with _Running(_config({"url": sim_url}, tmp_path, sinks=[first]), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
        kept = run.daemon.sinks[first]
        configs.next = _config({"url": sim_url}, tmp_path, sinks=[first, second])
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=30, what="the reload")
        added = run.daemon.sinks[second]
        assert run.daemon.sinks[first] is kept  # not reopened: its client sees no gap and no new HELLO
        sent = kept.stats().sent
        wait_until(lambda: added.stats().sent >= 5 and kept.stats().sent >= sent + 5, timeout=60,
                   what="joints on the added sink and on the kept one")
        configs.next = _config({"url": sim_url}, tmp_path, sinks=[second])
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 2, timeout=30, what="the second reload")
        assert list(run.daemon.sinks) == [second]
        assert run.finish() == 0
    # One stream on the kept sink from start to stop (its messages decode as one, every estimate in it).
    assert sum(isinstance(m, Joints) for m in messages_of(kept.read())) == kept.stats().sent >= 10
    assert any(isinstance(m, Hello) for m in messages_of(added.read()))
    assert run.daemon.health.rig_opens == 1 and run.daemon.health.reload_failures == 0
    reloading = _notes_after(run.notes, "RELOADING")
    assert reloading[0]["MONOTONIC_USEC"].isdigit()
    assert any("READY" in n for n in reloading[1:])  # systemd's reload job completes
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["config"] == {"reloads": 2, "reload_failures": 0, "reload_error": None}
    assert report["sinks"][first]["sent"] == kept.stats().sent  # a removed sink's counters stay in the report


def test_a_bad_reload_is_refused_and_the_daemon_runs_on_unchanged(sim_url, tmp_path):
    broken = tmp_path / "broken-models"
    broken.mkdir()
    (broken / "encoder.onnx").write_bytes(b"\x08\x07garbage")
    configs = _Configs()
    cfg = _config({"url": sim_url}, tmp_path)
    with _Running(cfg, tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
        estimator, sinks = run.daemon._estimator, run.daemon.sinks
        configs.next = DaemonConfigError("unknown key", key="daemon.json: rig.ulr")  # what a typo'd file raises
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reload_failures == 1, timeout=30, what="the first refusal")
        assert "rig.ulr" in run.daemon.health.reload_error
        bad_model = daemon_config_from_dict({**_config_dict(sim_url, tmp_path),
                                             "estimator": {"session": {"model_dir": str(broken)}}})
        configs.next = bad_model
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reload_failures == 2, timeout=60, what="the second refusal")
        assert run.daemon.health.reload_error.startswith("reload refused: estimator: does not load")
        assert str(broken) in run.daemon.health.reload_error
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 5, timeout=60, what="pairs after the refusals")
        assert run.daemon.config is cfg and run.daemon._estimator is estimator and run.daemon.sinks == sinks
        report = json.loads((tmp_path / "status.json").read_text())
        assert report["config"]["reload_failures"] == 2 and str(broken) in report["config"]["reload_error"]
        assert run.finish() == 0
    refused = [n for n in run.notes if "READY" in n and "reload refused: " in n.get("STATUS", "")]
    assert len(refused) == 2 and all(n.get("READY") == "1" for n in refused)
    assert run.daemon.health.reloads == 0 and run.daemon.health.rig_opens == 1


def _config_dict(url: str, tmp_path: Path) -> dict:
    return {"rig": {"url": url}, "sinks": ["memory://?status_s=0.05"],
            "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
            "health": {"status_file": str(tmp_path / "status.json"), "status_every_s": 0.05}}


def test_a_reload_of_the_estimator_and_health_keeps_the_rig_open(sim_url, tmp_path):
    configs = _Configs()
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
        before = run.daemon._estimator
        data = _config_dict(sim_url, tmp_path)
        data["estimator"]["smoothing"] = {"beta": 3.0}
        data["health"]["slow_estimate_s"] = 0.4
        data["health"]["status_file"] = str(tmp_path / "moved.json")
        assert (tmp_path / "status.json").exists()
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=60, what="the reload")
        # the old report is removed, not left saying "running" for ever
        wait_until(lambda: (tmp_path / "moved.json").exists(), timeout=60, what="the moved status file")
        assert not (tmp_path / "status.json").exists()
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 5, timeout=60, what="pairs after the reload")
        after = run.daemon._estimator
        assert after is not before and after.config.smoothing.beta == 3.0
        assert run.daemon.watchdog._interval <= 0.2  # woken often enough for the new slow_estimate_s
        assert run.finish() == 0
    assert run.daemon.health.rig_opens == 1 and run.daemon.health.rig_lost == 0


class _ShodEstimator(_CountingEstimator):
    """Someone in 6 cm soles: the foot joints' median 0.1 m up, every pair's floor figure that less the configured
    ``joints3d.foot_standing_m`` (0.06 m at the default 0.04: past the 0.05 m limit), the views meeting."""

    def __init__(self, session, rig, config, **options) -> None:
        super().__init__(session, rig, config, **options)
        self.standing = config.joints3d.foot_standing_m

    def estimate(self, images, *, sequence: int, timestamp_s: float):
        from dataclasses import replace

        self.calls = 0  # the parent's third call is a FrameError: never reached
        result = super().estimate(images, sequence=sequence, timestamp_s=timestamp_s)
        return replace(result, reprojection_px_median=0.2, lowest_foot_m=round(0.1 - self.standing, 6))


def test_a_reload_that_sets_the_standing_foot_starts_the_floor_check_afresh(sim_url, tmp_path, monkeypatch):
    """``ghnerf-daemon --measure-floor`` says which ``estimator.joints3d.foot_standing_m`` to set, and
    docs/calibration.md says to reload: the floor check's window, of figures taken with the old standing foot,
    starts afresh with the new estimator (not a window mixing both, nor a false alarm held until it fills again)."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _ShodEstimator)
    configs, at_reload = _Configs(), []
    with _Running(_config({"url": sim_url}, tmp_path, calibration_window=3), tmp_path, reload_config=configs,
                  on_reload=lambda new: at_reload.append(list(run.daemon.health.floor.values))) as run:
        floor = run.daemon.health.floor
        wait_until(lambda: floor.suspect, timeout=60, what="the soles read 0.06 m above the floor")
        data = _config_dict(sim_url, tmp_path)
        data["health"]["calibration_window"] = 3
        data["estimator"]["joints3d"] = {"foot_standing_m": 0.1}
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=60, what="the reload")
        assert at_reload == [[]]  # (taken on the daemon's thread as the reload was applied)
        wait_until(lambda: len(floor.values) == 3, timeout=60, what="a window of the new figures")
        assert run.finish() == 0
    assert list(floor.values) == [0.0, 0.0, 0.0] and not floor.suspect


def test_a_reload_that_loads_the_model_again_hands_the_old_ones_pages_back(sim_url, tmp_path, monkeypatch):
    """A reload that replaces the session trims the heap once (each left the daemon megabytes larger:
    docs/daemon.md, "Reloaded again and again"); one that keeps it does not."""
    import firmware_host.daemon.service as service

    trims = []
    monkeypatch.setattr(service, "return_freed_memory", lambda: trims.append(1) or True)
    configs = _Configs()
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 3, timeout=60, what="3 estimated pairs")
        data = _config_dict(sim_url, tmp_path)
        data["estimator"]["smoothing"] = {"beta": 3.0}  # the same session
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=60, what="the first reload")
        assert trims == []
        first = run.daemon._session
        data["estimator"].setdefault("session", {})["threads"] = 1  # the model loaded again
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 2, timeout=120, what="the second reload")
        assert run.daemon._session is not first and trims == [1]
        assert run.finish() == 0


def test_a_reload_that_loads_the_model_again_trims_after_the_old_sessions_are_freed(sim_url, tmp_path, monkeypatch):
    """The trim hands back the replaced model's pages only once nothing holds its sessions: the streaming loop
    kept the old estimator (and through it the old sessions) in a local until the pair after the reload, so
    the trim ran while they were alive and their pages were freed after it, left to the next reload's trim."""
    import firmware_host.daemon.service as service

    replaced: list[weakref.ref] = []  # weak: this test must not be what keeps them
    freed_at_trim = []

    def trim() -> bool:
        gc.collect()  # as return_freed_memory does first
        freed_at_trim.append([ref() is None for ref in replaced])
        return True

    monkeypatch.setattr(service, "return_freed_memory", trim)
    configs = _Configs()
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 3, timeout=60, what="3 estimated pairs")
        old = run.daemon._session
        replaced.extend([weakref.ref(old), *(weakref.ref(sess) for sess in old._sessions.values())])
        del old
        data = _config_dict(sim_url, tmp_path)
        data["estimator"]["session"]["threads"] = 1  # the model loaded again
        configs.next = daemon_config_from_dict(data)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.reloads == 1, timeout=120, what="the reload")
        assert run.finish() == 0
    assert freed_at_trim == [[True] * len(replaced)]


def test_the_daemon_keeps_the_models_big_blocks_out_of_the_heap():
    """After the daemon has loaded its model, a big block freed does not send the next model's into the heap
    (where each reload that loads the model left the daemon megabytes larger: docs/daemon.md, "Reloaded
    again and again"; firmware_host.daemon.memory)."""
    if glibc_only_reason():
        pytest.skip(glibc_only_reason())
    cfg = {"rig": {"url": "sim://"}, "sinks": ["memory://"], "estimator": {"session": {"model_dir": str(MODELS)}}}
    started = "\n".join([
        "import threading",
        "from firmware_host.daemon import Daemon, daemon_config_from_dict",
        "from firmware_host.daemon.notify import SystemdNotifier",
        "class Stop(threading.Event):",
        "    looks = 0",
        "    def is_set(self):  # clear at the start's first look (a stop set before it loads no model), then set",
        "        self.looks += 1",
        "        return self.looks > 1",
        "stop = Stop()  # the model loaded, then stopped before the rig",
        f"assert Daemon(daemon_config_from_dict({cfg!r}), notifier=SystemdNotifier({{}})).run(stop) == 0"])
    assert probe_big_block(started) == "mapped"


def test_a_reload_with_another_rig_url_opens_it(sim_url, tmp_path):
    configs = _Configs()
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
        other = sim_url.replace("width=320&height=240", "width=256&height=192")
        configs.next = _config({"url": other}, tmp_path)
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.rig_opens == 2, timeout=60, what="the new rig opened")
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 5, timeout=60, what="pairs from the new rig")
        assert run.daemon._estimator.rig.pair[0].width == 256  # rebuilt for the new calibration
        assert run.finish() == 0
    assert run.daemon.health.rig_lost == 0 and run.daemon.health.rig_url == other


def test_a_fill_not_the_models_is_logged_once_at_the_start_and_once_by_a_reload_that_changes_it(sim_url, tmp_path,
                                                                                                 caplog):
    """The start built two estimators (its settings check's on a stand-in rig, then the rig's) and each logged
    the fill line, so the journal said it twice; a reload that also changed rig.url did the same (its check on a
    stand-in, then the new rig's). Said by the check, once per config that sets it."""
    def fill_lines(fill: str) -> int:
        return sum(1 for r in caplog.records if r.getMessage().startswith(f"roi.pad_fill {fill!r} as configured"))

    def with_fill(url: str, fill: str):
        data = _config_dict(url, tmp_path)
        data["estimator"]["roi"] = {"pad_fill": fill}  # the shipped model's own is 'fade'
        return daemon_config_from_dict(data)

    configs = _Configs()
    with caplog.at_level(logging.INFO, logger="ghnerf_runtime.estimator"), \
            _Running(with_fill(sim_url, "black"), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 3, timeout=60, what="3 estimated pairs")
        assert run.daemon._estimator.config.roi.pad_fill == "black"
        assert fill_lines("black") == 1
        other = sim_url.replace("width=320&height=240", "width=256&height=192")
        configs.next = with_fill(other, "edge")
        run.daemon.request_reload()
        wait_until(lambda: run.daemon.health.rig_opens == 2, timeout=60, what="the new rig opened")
        seen = run.daemon.health.pairs_estimated
        wait_until(lambda: run.daemon.health.pairs_estimated > seen + 2, timeout=60, what="pairs from the new rig")
        assert run.daemon._estimator.config.roi.pad_fill == "edge"  # the new rig's estimator runs the new fill
        assert run.finish() == 0
    assert (fill_lines("black"), fill_lines("edge")) == (1, 1)


def test_a_reload_while_waiting_for_an_absent_rig_opens_the_new_one(sim_url, tmp_path):
    configs = _Configs()
    absent = {"url": f"replay://{tmp_path / 'never'}", "reopen_min_s": 30, "reopen_max_s": 30}
    with _Running(_config(absent, tmp_path), tmp_path, reload_config=configs) as run:
        wait_until(lambda: run.daemon.health.rig_open_failures >= 1, timeout=30, what="a failed open")
        configs.next = _config({"url": sim_url}, tmp_path)
        run.daemon.request_reload()  # not after the 30 s backoff: the wait watches for a reload too
        wait_until(lambda: run.daemon.health.pairs_estimated >= 3, timeout=20, what="pairs from the reloaded rig")
        assert run.finish() == 0
    assert run.daemon.health.rig_opens == 1


# The reload's own logic, on a daemon that is not running (no model: the estimator and session are stand-ins).
class _StubEstimator:
    def __init__(self, rig) -> None:
        self.rig, self.closed = rig, False

    def close(self) -> None:
        self.closed = True


def _idle_daemon(tmp_path: Path, sinks: list[str], configs: _Configs, rig) -> Daemon:
    from firmware_host.sinks import open_sink

    daemon = Daemon(_config({"url": "sim://"}, tmp_path, sinks=sinks), notifier=SystemdNotifier({}),
                    reload_config=configs)
    daemon._session, daemon._estimator = object(), _StubEstimator(rig)
    key = (rig.rig_id, tuple(c.name for c in rig.pair))
    for url in sinks:  # as _open_sinks leaves them for this rig
        daemon._sinks[url] = open_sink(url, cameras=key[1], **({} if "rig_id" in url else {"rig_id": key[0]}))
    daemon._sinks_for = key
    return daemon


def test_a_sink_that_does_not_fit_the_rig_is_refused_before_anything_changes(tmp_path):
    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build(rig_id="a-rig-id-too-long-for-the-hello-message")  # kept sinks name their own
    first = "memory://?rig_id=short"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [first], configs, rig)
    kept, cfg = daemon.sinks[first], daemon.config
    try:
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[first, "memory://?status_s=0.06"])
        daemon.request_reload()
        assert daemon._maybe_reload(None) == []
        assert daemon.health.reload_failures == 1 and "sinks[1]" in daemon.health.reload_error
        assert daemon.config is cfg and daemon.sinks == {first: kept}  # nothing swapped, nothing closed
        assert not kept._closed
    finally:
        daemon._close_sinks()


def test_a_reload_refused_at_its_second_added_sink_closes_the_first(tmp_path, monkeypatch, caplog):
    """Two sinks added, the second refused as it is built for the rig (its id too long for HELLO): the first, built
    already, was left behind open to a later start (its closed flag unset). It is closed now, never started (no
    worker, no socket), the running sinks and config untouched, and the journal's line names the refused URL."""
    import logging

    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build(rig_id="a-rig-id-too-long-for-the-hello-message")
    running, first, misfit = "memory://?rig_id=short", "udp://127.0.0.1:9?rig_id=short", "memory://?status_s=0.06"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [running], configs, rig)
    kept, cfg = daemon.sinks[running], daemon.config
    built = _sinks_built_by(daemon, monkeypatch)
    try:
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[running, first, misfit])
        daemon.request_reload()
        with caplog.at_level(logging.ERROR, logger="ghnerf.daemon"):
            assert daemon._maybe_reload(None) == []
        assert [s.url for s in built] == [first]  # the misfit raised in its build
        assert built[0]._closed and built[0]._thread is None and built[0]._link._sock is None
        assert daemon.config is cfg and daemon.sinks == {running: kept} and not kept._closed
        said = [r.getMessage() for r in caplog.records if "reload refused" in r.getMessage()]
        assert len(said) == 1 and f"sinks[2]: {misfit}: invalid rig_id=" in said[0], said
    finally:
        daemon._close_sinks()


def test_a_reload_whose_second_added_sink_cannot_start_closes_the_first_and_changes_nothing(tmp_path, monkeypatch,
                                                                                          caplog):
    """The second added sink's worker thread will not start (a task limit): the reload was refused with the swap
    half done, the config already the new one and the first added sink streaming. Now its sinks start (held, opening
    nothing) before the swap: the first is closed, its worker ended before it opened a thing, nothing changed."""
    import logging

    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build(rig_id="rig")
    running, first, second = "memory://", "udp://127.0.0.1:9", "memory://?status_s=0.06"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [running], configs, rig)
    kept, cfg = daemon.sinks[running], daemon.config
    built = _sinks_built_by(daemon, monkeypatch)
    _no_worker_thread_for(monkeypatch, second)
    try:
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[running, first, second])
        daemon.request_reload()
        with caplog.at_level(logging.ERROR, logger="ghnerf.daemon"):
            assert daemon._maybe_reload(None) == []
        assert daemon.config is cfg and daemon.sinks == {running: kept} and not kept._closed
        assert [s.url for s in built] == [first, second] and built[1]._closed
        started = built[0]
        started._thread.join(10)
        assert started._closed and not started._thread.is_alive() and started._link._sock is None
        assert started.stats().connects == started.stats().connect_failures == 0
        said = [r.getMessage() for r in caplog.records if "reload refused" in r.getMessage()]
        assert len(said) == 1 and f"sinks[2]: {second}: cannot start its worker: can't start new thread" in said[0]
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[running, first])  # accepted: released, it opens
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["sinks"]
        assert daemon.sinks[first].wait_connected(10)
    finally:
        daemon._close_sinks()


def test_a_reload_that_replaces_a_file_sink_by_one_on_the_same_file_opens_it_once_the_old_let_go(tmp_path, caplog):
    """The added sinks start before the swap, held: the new sink on the file the removed one holds (its options
    changed) opens only after that one closed, at its first try, with no "written by another sink" warning."""
    import logging

    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build(rig_id="rig")
    old, new = f"file://{tmp_path}/joints.jsonl", f"file://{tmp_path}/joints.jsonl?queue=8"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [old], configs, rig)
    held = daemon.sinks[old]
    try:
        assert held.wait_connected(10)
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[new])
        daemon.request_reload()
        with caplog.at_level(logging.WARNING):
            assert daemon._maybe_reload(None) == ["sinks"]
            assert daemon.sinks[new].wait_connected(10)
        assert held._closed and daemon.sinks[new].stats().connect_failures == 0
        assert [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING] == []
    finally:
        daemon._close_sinks()


def _sinks_built_by(daemon: Daemon, monkeypatch) -> list:
    """The sinks ``daemon`` builds from now on, in order, kept as they are built."""
    built: list = []
    build = daemon._build_sink
    monkeypatch.setattr(daemon, "_build_sink", lambda *a: built.append(build(*a)) or built[-1])
    return built


def _no_worker_thread_for(monkeypatch, url: str) -> None:
    """``Thread.start`` fails for the worker of the sink of ``url`` (by the thread's name), as at a task limit."""
    start_thread = threading.Thread.start

    def no_thread_for_that_sink(thread):
        if thread.name == f"sink {url}":
            raise RuntimeError("can't start new thread")
        start_thread(thread)

    monkeypatch.setattr(threading.Thread, "start", no_thread_for_that_sink)


def test_a_sink_whose_worker_cannot_start_as_the_rig_opens_stops_the_daemon_naming_it(sim_url, tmp_path,
                                                                                      monkeypatch):
    """The second sink's worker thread will not start as the rig opens (a task limit): the RuntimeError was not
    caught where the sinks' own errors are, and the daemon died of it (a traceback, exit 1: restarted by systemd
    into the same limit), its status file saying "stopped by RuntimeError: can't start new thread", no sink named.
    Now it stops as for a sink that does not fit the rig (exit 2), naming the sink, every sink closed first, the
    one started before it too."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    first, second = "memory://?status_s=0.05", "udp://127.0.0.1:9"
    built: list = []
    build = Daemon._build_sink
    monkeypatch.setattr(Daemon, "_build_sink", lambda self, *a: built.append(build(self, *a)) or built[-1])
    _no_worker_thread_for(monkeypatch, second)
    cfg = _config({"url": sim_url}, tmp_path, sinks=[first, second])
    with _Running(cfg, tmp_path) as run:
        run.thread.join(timeout=30)
        assert not run.thread.is_alive(), "the daemon did not stop"
    error = run.rc[0]
    assert isinstance(error, DaemonStartError), repr(error)
    assert str(error) == f"sinks[1]: {second}: cannot start its worker: can't start new thread"
    assert [s.url for s in built] == [first, second] and all(s._closed for s in built)
    started = built[0]
    started._thread.join(10)
    assert not started._thread.is_alive() and built[1]._thread is None
    assert run.daemon.sinks == {} and run.daemon._sinks_for is None
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["last_error"] == f"stopped by DaemonStartError: {error}"


class _PopRaises(dict):
    """The carried gaps of a daemon whose swap raises as it places the added sink of ``url``."""

    def __init__(self, url: str) -> None:
        super().__init__()
        self.url = url

    def pop(self, key, *default):
        if key == self.url:
            raise RuntimeError("a swap that raises")
        return super().pop(key, *default)


@pytest.mark.parametrize("raises_at", ["the removed sink", "the second added sink"])
def test_a_reload_whose_swap_raises_leaves_no_added_sink_held(tmp_path, monkeypatch, raises_at):
    """The added sinks start held before the swap, which releases them: a swap that raised (it should not) before
    it released them left their workers waiting for ever, frames queued in them never sent. Now each added sink the
    swap put in place is released (it streams), every other one is closed, having opened nothing."""
    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build(rig_id="rig")
    running, first, second = "memory://", "memory://?status_s=0.06", "udp://127.0.0.1:9"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [running], configs, rig)
    built = _sinks_built_by(daemon, monkeypatch)
    try:
        with monkeypatch.context() as patch:
            if raises_at == "the removed sink":  # before any added sink is placed
                patch.setattr(daemon, "_close_sink", lambda url: (_ for _ in ()).throw(RuntimeError("no close")))
                configs.next = _config({"url": "sim://"}, tmp_path, sinks=[first, second])
            else:  # the first added sink placed, not yet released; the second not placed
                patch.setattr(daemon, "_carried_gaps", _PopRaises(first))
                configs.next = _config({"url": "sim://"}, tmp_path, sinks=[running, first, second])
            daemon.request_reload()
            assert daemon._maybe_reload(None) == [] and daemon.health.reload_failures == 1
        assert [s.url for s in built] == [first, second]
        placed = [s for s in built if daemon.sinks.get(s.url) is s]
        for sink in built:
            if sink in placed:
                assert sink.wait_connected(10), f"{sink.url} held"
            else:
                sink._thread.join(10)
                assert not sink._thread.is_alive(), f"{sink.url} held"
                assert sink._closed and sink.stats().connects == sink.stats().connect_failures == 0
        assert [s.url for s in placed] == ([] if raises_at == "the removed sink" else [first])
        assert built[1]._link._sock is None
    finally:
        daemon._close_sinks()


def test_a_reload_adding_a_sink_that_cannot_connect_yet_is_accepted_and_retries_it(tmp_path, caplog):
    """Not a refusal, as at start: a serial port not plugged in (or a file:// sink whose folder is missing) is a
    sink down and retried, warned once naming it, while the sink added beside it streams."""
    import logging

    from drivers.sim.placement import RigPlacement
    from tests.firmware_host.joint_stream_helpers import make_frame

    rig = RigPlacement().build(rig_id="rig")
    running, added, absent = "memory://", "memory://?status_s=0.06", f"serial://{tmp_path}/ttyACM-unplugged"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [running], configs, rig)
    try:
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[running, added, absent])
        daemon.request_reload()
        with caplog.at_level(logging.WARNING):
            assert daemon._maybe_reload(None) == ["sinks"]
            wait_until(lambda: daemon.sinks[absent].stats().connect_failures >= 1, timeout=30,
                       what="the unplugged port's first try")
        assert list(daemon.sinks) == [running, added, absent] and daemon.health.reload_failures == 0
        daemon.sinks[added].send(make_frame(0))
        assert daemon.sinks[added].wait_drained(10)
        assert daemon.sinks[added].stats().sent == 1
        assert daemon.sink_stats()[absent]["last_error"].startswith(f"{absent}: unavailable: cannot open")
        said = [r.getMessage() for r in caplog.records if "ttyACM-unplugged" in r.getMessage()]
        assert len(said) == 1 and said[0].startswith(f"{absent}: unavailable"), said
    finally:
        daemon._close_sinks()


def test_a_reload_onto_a_status_file_that_is_a_folder_is_refused_and_removes_nothing(tmp_path):
    """Until session 75 the reload was accepted: the old status file was removed (a monitor must not read it frozen),
    then every write to the folder failed, leaving no report at all. Refused with the file read, nothing changes."""
    status, folder = tmp_path / "status.json", tmp_path / "run"
    folder.mkdir()
    data = {"rig": {"url": "sim://"}, "sinks": ["memory://?status_s=0.05"], "health": {"status_file": str(status)}}
    daemon = Daemon(daemon_config_from_dict(data), notifier=SystemdNotifier({}),
                    reload_config=lambda: daemon_config_from_dict(data))  # read at the reload, as the CLI's
    daemon._tick(force=True, tell_systemd=False)
    written, cfg = status.read_text(), daemon.config
    data["health"]["status_file"] = str(folder)
    daemon.request_reload()
    assert daemon._maybe_reload(None) == []
    assert daemon.health.reload_failures == 1 and "health.status_file: is a folder" in daemon.health.reload_error
    assert daemon.config is cfg and status.read_text() == written and list(folder.iterdir()) == []


def test_a_status_file_behind_a_link_or_on_a_fifo_is_written_there_and_stays_what_it_was(tmp_path):
    """Until session 75 the status file was renamed over its path whatever that was: a symbolic link became a plain
    file (its target never written again), a FIFO a monitor read was replaced (and /dev/null would have been, for a
    daemon run as root outside the unit)."""
    from firmware_host.daemon.health import write_status_file

    real, link = tmp_path / "real.json", tmp_path / "status.json"
    link.symlink_to(real)
    write_status_file(link, {"state": "running"})
    assert link.is_symlink() and json.loads(real.read_text()) == {"state": "running"}
    fifo = tmp_path / "status.fifo"
    os.mkfifo(fifo)
    with pytest.raises(OSError):  # no reader: said (the daemon warns once), not a daemon blocked in the open
        write_status_file(fifo, {"state": "running"})
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        write_status_file(fifo, {"state": "degraded"})
        assert json.loads(os.read(reader, 65536)) == {"state": "degraded"}
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(fifo.lstat().st_mode) and sorted(p.name for p in tmp_path.iterdir()) == [
        "real.json", "status.fifo", "status.json"]  # no temporary file left beside them


class _LoadedSession:
    """A stand-in for the model a reload loads (weakly referable, unlike ``object()``)."""


@pytest.mark.parametrize("refused_by", ["estimator", "sink"])
def test_a_refused_reload_that_loaded_a_model_hands_its_pages_back(tmp_path, monkeypatch, refused_by):
    """Until session 75 only an accepted reload trimmed the heap after a model load: a refused one (settings the new
    model cannot serve, a sink that does not fit the rig) left the new model's freed pages to the next accepted one,
    and the estimator built before a sink's refusal was never closed. Trimmed once the new session is garbage."""
    import firmware_host.daemon.service as service
    from drivers.sim.placement import RigPlacement

    loaded: list[weakref.ref] = []
    built: list[_StubEstimator] = []
    freed_at_trim = []

    def load(config) -> _LoadedSession:
        session = _LoadedSession()
        loaded.append(weakref.ref(session))
        return session

    def estimator(session, rig, config) -> _StubEstimator:
        if refused_by == "estimator":
            raise ValueError("settings this model cannot serve")
        built.append(_StubEstimator(rig))
        return built[-1]

    def trim() -> bool:
        gc.collect()  # as return_freed_memory does first
        freed_at_trim.append([ref() is None for ref in loaded])
        return True

    monkeypatch.setattr(service, "load_session", load)
    monkeypatch.setattr(service, "Estimator", estimator)
    monkeypatch.setattr(service, "return_freed_memory", trim)
    first = "memory://?rig_id=short"
    configs = _Configs()
    rig = RigPlacement().build(rig_id="a-rig-id-too-long-for-the-hello-message")  # the added sink does not fit it
    daemon = _idle_daemon(tmp_path, [first], configs, rig)
    session, cfg = daemon._session, daemon.config
    try:
        data = _config({"url": "sim://"}, tmp_path, sinks=[first, "memory://?status_s=0.06"])
        configs.next = dataclasses.replace(data, estimator=dataclasses.replace(
            data.estimator, session=dataclasses.replace(data.estimator.session, threads=1)))  # the model loaded again
        daemon.request_reload()
        assert daemon._maybe_reload(None) == []
        assert daemon.health.reload_failures == 1
        assert ("estimator" if refused_by == "estimator" else "sinks[1]") in daemon.health.reload_error
        assert daemon.config is cfg and daemon._session is session
        assert len(loaded) == 1 and freed_at_trim == [[True]]
        assert all(each.closed for each in built) and len(built) == (refused_by == "sink")
    finally:
        daemon._close_sinks()


def test_a_sink_removed_while_the_rig_is_away_is_closed_at_once(tmp_path):
    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build()
    first, second = "memory://?status_s=0.05", "memory://?status_s=0.06"
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, [first, second], configs, rig)
    removed = daemon.sinks[second]
    try:
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[first])
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["sinks"]  # no rig open: the serial port it held is freed now
        assert list(daemon.sinks) == [first] and removed._closed
    finally:
        daemon._close_sinks()


def test_one_usb_board_plugged_in_after_the_load_is_refused_to_its_second_name_in_the_status_file(
        tmp_path, monkeypatch):
    """One board named by one sink's ``serial=`` and another's ``port=``, plugged in after the config check: the
    second sink waited at connect for ever, its error the kernel's ``Resource busy`` (session 65 refused the pair
    only when the board was there at load). Now its status names the other sink, both names and the board, and it
    takes the board once a reload removes the other sink."""
    import libusb_package
    from drivers.sim.placement import RigPlacement
    from tests.firmware_host.fake_usb_backend import FakeBackend, two_boards

    board = two_boards()[0]
    board.present = False  # unplugged at load: the config check cannot tell the two names apart
    monkeypatch.setattr(libusb_package, "get_libusb1_backend", lambda: FakeBackend(board))
    by_serial, by_port = "usb://1209:0001?ep=0x01&serial=ABC123", "usb://1209:0001?ep=0x01&port=1-1.4"
    configs = _Configs()
    daemon = Daemon(_config({"url": "sim://"}, tmp_path, sinks=[by_serial, by_port]), notifier=SystemdNotifier({}),
                    sink_kwargs={"backoff": FAST_BACKOFF}, reload_config=configs)
    rig = RigPlacement().build()
    daemon._session, daemon._estimator = object(), _StubEstimator(rig)
    try:
        daemon._open_sinks(rig)
        board.plug()
        sinks = daemon.sinks
        wait_until(lambda: any(s.stats().state == "up" for s in sinks.values()), what="one sink up")
        holder, waiter = sorted(sinks, key=lambda url: sinks[url].stats().state != "up")
        # refused for the holder, not for the board's absence before the plug (connect failures counted those too)
        wait_until(lambda: "held by another sink" in (sinks[waiter].stats().last_error or ""),
                   what="a connect refused for the holder")
        daemon._tick(force=True, tell_systemd=False)
        shown = json.loads((tmp_path / "status.json").read_text())["sinks"][waiter]
        names = {by_serial: "serial='ABC123'", by_port: "port=1-1.4"}
        assert shown["state"] == "down" and shown["last_error"] == (
            f"{waiter}: unavailable: interface 0 of the 1209:0001 board at port 1-1.4 is held by another sink of "
            f"this daemon, {holder}, which names it {names[holder]}; this sink names it {names[waiter]}: two names "
            "of one board; remove one of the two sinks or name another board (this one takes the board once the "
            "other lets it go: a reload that removes it, the board moved)")
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[waiter])  # the holder removed
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["sinks"]
        assert sinks[waiter].wait_connected(5)
    finally:
        daemon._close_sinks()
    assert not board.claimed and board.open_handles == 0


def test_an_estimator_reload_while_the_rig_is_away_is_built_for_the_last_rig(tmp_path, monkeypatch):
    import firmware_host.daemon.service as service
    from drivers.sim.placement import RigPlacement

    rig = RigPlacement().build()
    configs = _Configs()
    daemon = _idle_daemon(tmp_path, ["memory://"], configs, rig)
    old, session = daemon._estimator, daemon._session
    built_for = []

    def misfit(session_, rig_, config_):
        built_for.append(rig_)
        raise ValueError("this rig cannot be used with these settings")

    monkeypatch.setattr(service, "Estimator", misfit)
    data = _config_dict("sim://", tmp_path)
    data["sinks"] = ["memory://"]
    data["estimator"]["smoothing"] = {"beta": 3.0}  # the same graphs and session settings: no model load
    configs.next = daemon_config_from_dict(data)
    try:
        daemon.request_reload()
        assert daemon._maybe_reload(None) == []
        assert built_for == [rig]  # the rig it ran on last, not deferred to the next open
        assert "estimator: does not load: this rig cannot be used" in daemon.health.reload_error
        assert daemon._estimator is old and not old.closed and daemon._session is session
        monkeypatch.setattr(service, "Estimator", lambda s, r, c: _StubEstimator(r))
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["estimator"]
        assert old.closed and daemon._estimator.rig is rig and daemon._session is session  # the model not reloaded
        assert daemon.health.status_line() == "starting"  # an accepted reload clears the refusal from STATUS
    finally:
        daemon._close_sinks()


def test_an_estimator_reload_before_any_rig_is_checked_on_a_stand_in(tmp_path, monkeypatch):
    import firmware_host.daemon.service as service
    from ghnerf_runtime.errors import ModelError

    configs = _Configs()
    daemon = Daemon(_config({"url": "sim://"}, tmp_path), notifier=SystemdNotifier({}), reload_config=configs)
    daemon._session = session = object()  # loaded; no rig opened yet (the OAK not plugged in)
    built_for = []

    def lacks_the_prior(session_, rig_, config_):
        built_for.append(rig_.rig_id)
        raise ModelError("joints3d.skeleton_prior = 'on' but the session has no skeleton prior")

    monkeypatch.setattr(service, "Estimator", lacks_the_prior)
    data = _config_dict("sim://", tmp_path)
    data["estimator"]["smoothing"] = {"beta": 3.0}
    configs.next = daemon_config_from_dict(data)
    daemon.request_reload()
    assert daemon._maybe_reload(None) == []  # refused now, not an exit 2 once the camera is plugged in
    assert built_for == ["stand-in"] and "no skeleton prior" in daemon.health.reload_error
    probes = []
    monkeypatch.setattr(service, "Estimator", lambda s, r, c: probes.append(_StubEstimator(r)) or probes[-1])
    daemon.request_reload()
    assert daemon._maybe_reload(None) == ["estimator"]
    assert probes[0].closed and daemon._estimator is None and daemon._session is session  # built at the open


def test_a_refused_reload_keeps_the_backoff_and_a_new_rig_is_tried_at_once(tmp_path):
    configs = _Configs()
    cfg = _config({"url": f"replay://{tmp_path / 'never'}", "reopen_min_s": 0.3, "reopen_max_s": 30}, tmp_path)
    daemon = Daemon(cfg, notifier=SystemdNotifier({}), reload_config=configs)
    stop = threading.Event()
    configs.next = DaemonConfigError("not valid JSON", key="daemon.json")
    daemon.request_reload()
    t0 = time.monotonic()
    assert daemon._wait(stop, 0.6) is True  # waited it out: the refusal changed nothing
    assert time.monotonic() - t0 >= 0.6 and daemon.health.reload_failures == 1
    daemon._backoff_s = 8.0  # after a few failed opens
    configs.next = _config({"url": "sim://?fps=15", "reopen_min_s": 0.05, "reopen_max_s": 2}, tmp_path)
    daemon.request_reload()
    assert daemon._wait(stop, 30.0) is False  # ended at once: the next attempt opens the new rig
    assert daemon._backoff_s == 0.05  # and backs off from the new rig's start, not the old rig's 8 s


def test_the_status_line_keeps_a_refusal_whatever_the_rig_error(tmp_path):
    from firmware_host.daemon.health import Health

    health = Health(rig_url="depthai://")
    health.enter(State.WAITING)
    health.last_error = "cannot open depthai://: " + "X_LINK_DEVICE_NOT_FOUND " * 20
    health.reload_error = "reload refused: /etc/ghnerf/daemon.json: rig.ulr: unknown key"
    line = health.status_line()
    assert len(line) <= 200 and line.startswith("waiting for the rig: cannot open depthai://")
    assert line.endswith("; reload refused: /etc/ghnerf/daemon.json: rig.ulr: unknown key")


def test_the_status_file_counts_rejected_frames_per_camera_and_reason():
    """"Why no joints?": the frame check's reason for each camera's rejected frame, counted (every reason of
    every rig camera listed, 0 included, so the section's shape never changes)."""
    from firmware_host.daemon.health import Health
    from ghnerf_runtime.frame_reasons import FLAT, NOISE, NON_FINITE

    health = Health(cameras=("left", "right"))
    zero = {NON_FINITE: 0, FLAT: 0, NOISE: 0}
    assert health.report()["rig"]["frames_rejected"] == {"left": zero, "right": zero}
    for reasons in ({"left": None, "right": FLAT}, {"left": None, "right": FLAT}, {"left": NOISE, "right": FLAT},
                    {"left": None, "right": None}):
        health.frames_checked(reasons)
    report = json.loads(json.dumps(health.report(), allow_nan=False))
    assert report["rig"]["frames_rejected"] == {"left": {**zero, NOISE: 1}, "right": {**zero, FLAT: 3}}


class _RejectingEstimator(_CountingEstimator):
    """Every pair's second camera rejected by the frame check as flat (a covered lens); no FrameError."""

    def estimate(self, images, *, sequence: int, timestamp_s: float):
        from dataclasses import replace

        self.calls = 0  # (the parent's third call is a FrameError: never reached)
        result = super().estimate(images, sequence=sequence, timestamp_s=timestamp_s)
        first, second = (c.name for c in self.rig.pair)
        return replace(result, frame_ok={first: True, second: False}, frame_reason={first: None, second: "flat"})


def test_the_daemon_writes_the_frame_checks_reasons_to_the_status_file(sim_url, tmp_path, monkeypatch):
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _RejectingEstimator)
    with _Running(_config({"url": sim_url}, tmp_path), tmp_path) as run:
        wait_until(lambda: run.daemon.health.pairs_estimated >= 5, timeout=60, what="5 estimated pairs")
        assert run.finish() == 0
    health = run.daemon.health
    first, second = health.cameras
    rejected = json.loads((tmp_path / "status.json").read_text())["rig"]["frames_rejected"]
    assert rejected[first] == {"non-finite": 0, "flat": 0, "noise": 0}
    assert rejected[second] == {"non-finite": 0, "flat": health.pairs_estimated, "noise": 0}


def test_the_rate_and_status_line_do_not_stay_healthy_when_no_pair_is_estimated():
    """Every pair rejected (or none coming): the rate of the last window stayed on, and STATUS read
    "running: 30.0 pairs/s" for as long as nothing was estimated."""
    from firmware_host.daemon.health import STALE_S, Health

    now = [100.0]
    health = Health(clock=lambda: now[0])
    health.enter(State.RUNNING)
    for _ in range(30):
        now[0] += 1 / 30
        health.estimated(20.0, 1.0)
    assert health.status_line().startswith("running: 30.0 pairs/s, 20 ms, 30 estimated")
    health.last_error = "pair 40 rejected: camera 'left': image is 320x240x1, expected 320x240x3"
    now[0] += STALE_S + 3
    assert health.report()["estimator"]["pairs_per_s"] == 0.0
    assert health.status_line() == ("running: no pair estimated for 5 s; last error: pair 40 rejected: camera "
                                    "'left': image is 320x240x1, expected 320x240x3")
    now[0] += 10
    health.enter(State.WAITING)
    health.enter(State.RUNNING)  # a rig opened again after 10 s away: counted from the open
    now[0] += 1
    assert health.status_line().startswith("running: 0.0 pairs/s")


def test_the_status_file_counts_the_window_s_pairs_that_said_someone_else_is_near():
    """``estimator.someone_else`` (``presence.scan_every_s``, docs/two-people.md, "Anyone else near?"): of the last
    WINDOW estimates, those whose scan said someone besides the subject is there; null where none had an answer."""
    from firmware_host.daemon.health import WINDOW, Health

    health = Health()
    assert health.report()["estimator"]["someone_else"] is None
    for answer in (None, False, True, True):
        health.estimated(20.0, 1.0, frozenset(), answer)
    assert health.report()["estimator"]["someone_else"] == 2
    for _ in range(WINDOW):  # the scan off since (a reload): the window holds no answer
        health.estimated(20.0, 1.0)
    assert health.report()["estimator"]["someone_else"] is None


def test_the_status_file_counts_the_window_s_pairs_of_each_scene_flag():
    """``estimator.flagged``: of the last WINDOW estimates, those with two people in view, a prior fallback or one
    camera alone (a ``PairResult``'s ``single_view`` is the camera's name); older ones leave the count."""
    from types import SimpleNamespace

    from firmware_host.daemon.health import WINDOW, Health, scene_flags_of

    def result(several=False, fallback=False, camera=None):
        return SimpleNamespace(several_people=several, prior_fallback=fallback, single_view=camera)

    health = Health()
    assert health.report()["estimator"]["flagged"] == {"several_people": 0, "prior_fallback": 0, "single_view": 0}
    assert scene_flags_of(result(camera="left")) == {"single_view"}
    for flags in (result(several=True), result(several=True, fallback=True), result(camera="right"), result()):
        health.estimated(20.0, 1.0, scene_flags_of(flags))
    assert health.report()["estimator"]["flagged"] == {"several_people": 2, "prior_fallback": 1, "single_view": 1}
    for _ in range(WINDOW - 1):  # the first three fall out of the window
        health.estimated(20.0, 1.0, scene_flags_of(result()))
    assert health.report()["estimator"]["flagged"] == {"several_people": 0, "prior_fallback": 0, "single_view": 0}


def test_on_two_videos_through_opencv(sim_url, tmp_path):
    """The daemon on ``opencv://``: two videos of a simulated take (what two webcams would give, OpenCV
    decoding them at their pace) with the take's rig file; the shipped model finds the person in them."""
    import cv2

    from ghnerf_runtime.rig_file import save_rig

    with drivers.open_rig(sim_url.replace("fps=30", "fps=30&policy=all"), clock=drivers.ManualClock()) as source:
        pairs = [source.read(timeout_s=5) for _ in range(30)]
        save_rig(source.rig, tmp_path / "rig.json")
        names = [c.name for c in source.rig.pair]
    for k, name in enumerate(names):
        writer = cv2.VideoWriter(str(tmp_path / f"{name}.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (320, 240))
        for pair in pairs:
            writer.write(pair.images[k])
        writer.release()
    # policy=all: every pair of the take reaches the estimator however busy the machine (under latest, a
    # loaded 2-core box estimated 12 of the 30 pairs, the rest replaced by newer ones as designed)
    url = (f"opencv://?first={tmp_path / 'left.avi'}&second={tmp_path / 'right.avi'}&rig={tmp_path / 'rig.json'}"
           f"&policy=all")
    with _Running(_config({"url": url}, tmp_path), tmp_path) as run:
        run.thread.join(timeout=60)  # rig.exit_at_end: the videos' end stops it
        assert not run.thread.is_alive() and run.rc == [0]
    assert run.daemon.health.pairs_estimated >= 20 and run.daemon.health.rig_lost == 0
    assert "ended after 30 frames" in run.daemon.health.last_error
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["estimator"]["joints_found"] > 0.8  # the person, seen through two lossy videos


def test_frames_lost_when_a_new_rig_reopens_the_sinks_are_flagged_dropped(tmp_path):
    """Frames still queued when another rig closes a sink are a gap the sender made: the rebuilt sink's
    first frame says DROPPED (docs/protocol.md section 3), not a silent gap the receiver blames on the link."""
    import json

    from drivers.sim.placement import RigPlacement
    from tests.firmware_host.joint_stream_helpers import make_frame

    folder = tmp_path / "stick"
    url = f"file://{folder}/joints.jsonl"  # the folder is missing: the old sink never connects
    daemon = _idle_daemon(tmp_path, [url], _Configs(), RigPlacement().build(rig_id="first"))
    old = daemon.sinks[url]
    try:
        for seq in range(3):
            old.send(make_frame(seq))
        daemon._open_sinks(RigPlacement().build(rig_id="second"))  # another OAK: every sink is rebuilt
        assert old._closed and old.stats().dropped_close == 3
        new = daemon.sinks[url]
        assert new is not old
        folder.mkdir()
        assert new.wait_connected(10)
        new.send(make_frame(3))
        new.send(make_frame(4))
        assert new.wait_drained(5)
    finally:
        daemon._close_sinks()
    messages = [json.loads(line) for line in (folder / "joints.jsonl").read_text().splitlines()]
    joints = [m for m in messages if m["type"] == "JOINTS"]
    assert [m["seq"] for m in joints] == [3, 4]
    assert joints[0]["flags"] & Flags.DROPPED
    assert not joints[1]["flags"] & Flags.DROPPED
    # STATUS counts the sender's totals: the three the old link dropped stay counted on the new one
    assert [m["dropped"] for m in messages if m["type"] == "STATUS"][0] == 3


def test_a_gap_carried_to_a_readded_sink_survives_a_refused_reload(tmp_path):
    """A reload that builds the re-added sink and is then refused (another sink does not fit) must leave the
    gap its predecessor made for the build that is accepted: the receiver still learns of it."""
    import json

    from drivers.sim.placement import RigPlacement
    from tests.firmware_host.joint_stream_helpers import make_frame

    folder = tmp_path / "stick"
    url, other = f"file://{folder}/joints.jsonl?rig_id=short", "memory://?rig_id=short"
    misfit = "memory://"  # takes the rig's own id, too long for HELLO: refused only when built for the rig
    configs = _Configs()
    rig = RigPlacement().build(rig_id="a-rig-id-too-long-for-the-hello-message")
    daemon = _idle_daemon(tmp_path, [url, other], configs, rig)
    try:
        for seq in range(2):
            daemon.sinks[url].send(make_frame(seq))  # the folder is missing: both still queued at close
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[other])
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["sinks"] and list(daemon.sinks) == [other]
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[other, url, misfit])
        daemon.request_reload()
        assert daemon._maybe_reload(None) == [] and daemon.health.reload_failures == 1
        configs.next = _config({"url": "sim://"}, tmp_path, sinks=[other, url])
        daemon.request_reload()
        assert daemon._maybe_reload(None) == ["sinks"]
        folder.mkdir()
        sink = daemon.sinks[url]
        assert sink.wait_connected(10)
        sink.send(make_frame(2))
        assert sink.wait_drained(5)
    finally:
        daemon._close_sinks()
    messages = [json.loads(line) for line in (folder / "joints.jsonl").read_text().splitlines()]
    joints = [m for m in messages if m["type"] == "JOINTS"]
    assert [m["seq"] for m in joints] == [2] and joints[0]["flags"] & Flags.DROPPED
    assert [m["dropped"] for m in messages if m["type"] == "STATUS"][0] == 2


def _seqs_announced_before_each_frame(messages: list) -> list[tuple[set, int]]:
    """(the seqs of the HELLO and STATUS messages just before a JOINTS, that JOINTS's seq), for each JOINTS."""
    pairs, announced = [], set()
    for m in messages:
        if isinstance(m, (Hello, Status)):
            announced.add(m.header.seq)
        elif isinstance(m, Joints):
            pairs.append((announced, m.header.seq))
            announced = set()
    return pairs


def test_hello_and_status_carry_the_last_frames_seq_also_on_a_reopened_sink(tmp_path):
    """docs/protocol.md section 3: HELLO and STATUS carry the seq of the producer's last frame, so the next
    JOINTS carries theirs plus one; before the first frame, 2**32 - 1. A sink rebuilt for another rig (or
    added by a reload) announced 0, a producer gone back to its start, in the middle of the numbering."""
    from drivers.sim.placement import RigPlacement
    from firmware_host.protocol.constants import U32_MAX
    from tests.firmware_host.joint_stream_helpers import make_frame

    url = "memory://?status_s=0.01"
    daemon = Daemon(_config({"url": "sim://"}, tmp_path, sinks=[url]), notifier=SystemdNotifier({}))
    sinks = []
    try:
        for rig_id in ("first", "second"):  # another OAK: the sink is rebuilt, the numbering runs on
            daemon._open_sinks(RigPlacement().build(rig_id=rig_id))
            sink = daemon.sinks[url]
            sinks.append(sink)
            wait_until(lambda: any(isinstance(m, Hello) for m in messages_of(sink.read())), timeout=10,
                       what="the HELLO on connect")
            time.sleep(0.05)  # a few STATUS before any frame
            for _ in range(3):
                sink.send(make_frame(daemon._frame_numbers.take()))
            assert sink.wait_drained(5)
            time.sleep(0.05)
    finally:
        daemon._close_sinks()
    first, second = (_seqs_announced_before_each_frame(messages_of(s.read())) for s in sinks)
    assert [seq for _, seq in first] == [0, 1, 2] and [seq for _, seq in second] == [3, 4, 5]
    assert first[0][0] == {U32_MAX}  # no frame sent yet: the one before 0, not 0 itself
    assert second[0][0] == {2}  # the last frame the producer sent, on the sink it replaces
    for announced, seq in first + second:
        assert announced <= {(seq - 1) & U32_MAX}, (announced, seq)


class _StandInWebcam:
    """What every stand-in ``cv2.VideoCapture`` here shares: opened, properties kept as set, nothing to release."""

    def __init__(self, target, api) -> None:
        self.props: dict = {}

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return True

    def set(self, prop, value) -> bool:
        self.props[prop] = value
        return True

    def get(self, prop) -> float:
        return float(self.props.get(prop, 0.0))

    def release(self) -> None:
        pass


class _HungWebcam(_StandInWebcam):
    """A stand-in ``cv2.VideoCapture`` whose every grab hangs until ``release_all`` is set: a wedged UVC stream."""

    release_all = threading.Event()

    def grab(self) -> bool:
        self.release_all.wait()
        return False

    def retrieve(self):
        return False, None


def test_a_camera_stuck_past_its_rigs_close_stops_the_watchdog_pings(tmp_path, monkeypatch):
    """A grab that never returns holds the camera: the driver gives up on it (the open fails), the loop waits and
    reopens, beating all along, and every reopen fails. Only a new process frees the device: once the stuck
    call outlives the close by health.open_allowance_s, the pings stop and systemd restarts the service."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)  # the start's stand-in check: no model here
    _HungWebcam.release_all.clear()
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(tmp_path / "notify.sock"))
    sock.settimeout(0.1)
    notifier = SystemdNotifier({"NOTIFY_SOCKET": str(tmp_path / "notify.sock"), "WATCHDOG_USEC": "100000"})
    cfg = _config({"url": "opencv://?first=0&second=1&open_timeout_s=0.2", "reopen_min_s": 0.05,
                   "reopen_max_s": 0.1}, tmp_path, open_allowance_s=1.0)
    daemon = Daemon(cfg, notifier=notifier, rig_kwargs={"capture_factory": _HungWebcam})
    stop = threading.Event()
    thread = threading.Thread(target=daemon.run, args=(stop,), daemon=True)
    thread.start()
    pings: list[float] = []
    try:
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not (getattr(daemon.watchdog, "wedged", None) and pings
                                                   and time.monotonic() - pings[-1] > 1.0):
            try:
                if b"WATCHDOG=1" in sock.recv(4096):
                    pings.append(time.monotonic())
            except socket.timeout:
                pass
        assert daemon.health.rig_open_failures >= 1 and thread.is_alive()  # the loop went on, retrying
        assert pings, "no ping while the rig was first tried"
        assert time.monotonic() - pings[-1] > 1.0, "still pinging: systemd never restarts the wedged service"
        assert "camera 'left' (0)" in daemon.watchdog.wedged
        assert "still in a device call" in daemon.health.last_error
    finally:
        stop.set()
        thread.join(timeout=10)
        _HungWebcam.release_all.set()  # the stuck grabs return; their threads end
        sock.close()
    assert not thread.is_alive()  # a stop still works


def test_a_full_disk_leaves_the_last_status_file_whole_and_is_logged_once(tmp_path, monkeypatch, caplog):
    """Checked, not changed: a write that fails half way (ENOSPC) leaves the previous report in place (the
    rename never happens), no temporary file behind, one warning however many refreshes fail, and the
    next write that succeeds replaces it."""
    import errno
    import logging

    import firmware_host.daemon.health as health

    daemon = Daemon(_config({"url": "sim://"}, tmp_path), notifier=SystemdNotifier({}))
    daemon._tick(force=True)
    before = (tmp_path / "status.json").read_text()
    real_dump = health.json.dump

    def full_disk(obj, fh, **kw):
        fh.write("{\"state\": ")
        fh.flush()
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(health.json, "dump", full_disk)
    with caplog.at_level(logging.WARNING, logger="ghnerf.daemon"):
        for _ in range(5):
            daemon.health.pairs_read += 1
            daemon._tick(force=True)
    warnings = [r.getMessage() for r in caplog.records if "status file" in r.getMessage()]
    assert len(warnings) == 1 and "No space left on device" in warnings[0]
    assert (tmp_path / "status.json").read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["status.json"]
    monkeypatch.setattr(health.json, "dump", real_dump)
    daemon._tick(force=True)
    assert json.loads((tmp_path / "status.json").read_text())["pairs"]["read"] == 5


def test_a_status_file_that_becomes_a_folder_while_running_is_warned_of_once_per_outage(tmp_path, caplog):
    """Checked, not changed: a status file path made a folder while the daemon runs (by hand, a deploy script) is
    one warning naming the path, not one per refresh; nothing is written into the folder; the file is written
    again once the folder is gone, and a second such outage is warned of again, once."""
    import logging

    status = tmp_path / "status.json"
    daemon = Daemon(_config({"url": "sim://"}, tmp_path), notifier=SystemdNotifier({}))
    daemon._tick(force=True)
    assert status.is_file()
    with caplog.at_level(logging.WARNING, logger="ghnerf.daemon"):
        for outage in range(2):
            status.unlink()
            status.mkdir()
            for _ in range(5):
                daemon.health.pairs_read += 1
                daemon._tick(force=True)
            assert list(status.iterdir()) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["status.json"]
            status.rmdir()
            daemon._tick(force=True)
            assert json.loads(status.read_text())["pairs"]["read"] == 5 * (outage + 1)
    warnings = [r.getMessage() for r in caplog.records if "status file" in r.getMessage()]
    assert warnings == [f"cannot write the status file {status}: [Errno 21] Is a directory: '{status}'"] * 2


def test_a_rig_lost_right_after_each_open_is_backed_off_and_does_not_flood_the_log(sim_url, tmp_path, monkeypatch,
                                                                                    caplog):
    """A device up for a pair or two, then gone, again and again: one pair reset the backoff, so it was reopened
    at once for ever (ten opens a second and more on sim://, two log lines each). Lost before pairs flowed for
    rig.stall_s, it is backed off as a rig that did not open: doubling up to reopen_max_s."""
    import logging

    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    cfg = _config({"url": f"{sim_url}&unplug_after_s=0.05", "reopen_min_s": 0.1, "reopen_max_s": 0.4}, tmp_path)
    with caplog.at_level(logging.INFO, logger="ghnerf.daemon"):
        with _Running(cfg, tmp_path) as run:
            wait_until(lambda: run.daemon.health.rig_opens >= 1, timeout=60, what="the first open")
            caplog.clear()
            opens, t0 = run.daemon.health.rig_opens, time.monotonic()
            time.sleep(3.0)
            opens, seconds = run.daemon.health.rig_opens - opens, time.monotonic() - t0
            assert run.finish() == 0
    assert run.daemon.health.pairs_read > 0  # up for a pair or two each time
    # waits of 0.1, 0.2, 0.4, 0.4... s: at most about one open per 0.4 s once capped, not one per open's time
    assert opens <= seconds / 0.4 + 3, f"{opens} opens in {seconds:.1f} s"
    lines = [r for r in caplog.records if r.name == "ghnerf.daemon"]
    assert len(lines) <= 2 * (seconds / 0.4 + 3) + 2, f"{len(lines)} log lines in {seconds:.1f} s"


def test_a_rig_url_password_stays_out_of_the_status_file_and_the_log(tmp_path, caplog):
    """The daemon logged its rig URL and wrote it to the status file (and into last_error) as configured:
    a camera stream's password in plain text for anyone who reads either."""
    from drivers.sim.placement import RigPlacement
    from ghnerf_runtime.rig_file import save_rig

    rig_file = tmp_path / "rig.json"
    save_rig(RigPlacement().build(), rig_file)
    stream = "rtsp%3A%2F%2Fadmin%3Ahunter2%40cam1%2Fs"
    url = f"opencv://?first={stream}&second={stream.replace('cam1', 'cam2')}&rig={rig_file}"
    cfg = _config({"url": url, "reopen_min_s": 30, "reopen_max_s": 30}, tmp_path)

    class Refused:  # the camera is not there: the daemon waits for it, saying why
        def isOpened(self):
            return False

        def release(self):
            pass

    with caplog.at_level(logging.DEBUG):
        with _Running(cfg, tmp_path, rig_kwargs={"capture_factory": lambda target, api: Refused()}) as run:
            wait_until(lambda: run.daemon.health.rig_open_failures >= 1, timeout=30, what="a failed open")
            wait_until(lambda: "last_error" in (tmp_path / "status.json").read_text()
                       and json.loads((tmp_path / "status.json").read_text())["last_error"], timeout=10,
                       what="the status file")
            status = (tmp_path / "status.json").read_text()
            assert run.finish() == 0
    assert "hunter2" not in status and "hunter2" not in caplog.text
    assert "admin%3A***%40cam1" in json.loads(status)["rig"]["url"]
    assert "rtsp://admin:***@cam1/s" in json.loads(status)["last_error"]


def _take_on_video(sim_url: str, folder: Path, frames: int) -> tuple[Path, Path, object]:
    """Two MJPG videos of a simulated take and its rig: ``(left video, right video, rig)``."""
    import cv2

    with drivers.open_rig(sim_url.replace("fps=30", "fps=30&policy=all"), clock=drivers.ManualClock()) as source:
        pairs = [source.read(timeout_s=5) for _ in range(frames)]
        rig = source.rig
    paths = []
    for k, cam in enumerate(rig.pair):
        paths.append(folder / f"{cam.name}.avi")
        writer = cv2.VideoWriter(str(paths[-1]), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (cam.width, cam.height))
        for pair in pairs:
            writer.write(pair.images[k])
        writer.release()
    return paths[0], paths[1], rig


@pytest.mark.parametrize("axis, degrees", [("tilt", 0.0), ("tilt", 2.0), ("pan", 3.0)])
def test_a_rig_file_that_no_longer_fits_its_cameras_is_said(sim_url, tmp_path, caplog, axis, degrees):
    """The cameras film through the true rig; the rig file has the second camera tilted 2 degrees (or panned 3)
    (knocked on its mount after calibration). The joints still flow, but the status file's ``calibration`` turns
    suspect, systemd's STATUS says to recalibrate and the log warns once, naming the symptom: the views' peaks
    apart for the tilt, the feet off the floor for the pan (whose views still meet). With the true rig file none
    of it (docs/daemon.md). (Until session 56, on this take a 2 degree pan left the lowest foot joint 0.08 m below
    the floor and the true rig 0.06 m above it, under the 0.1 m limit then: one of the pans that check missed,
    docs/calibration.md.)"""
    from benchmarks.measure_calibration_drift import turned
    from ghnerf_runtime.rig_file import save_rig

    left, right, rig = _take_on_video(sim_url, tmp_path, 24)
    save_rig(turned(rig, 1, axis, degrees), tmp_path / "rig.json")
    url = f"opencv://?first={left}&second={right}&rig={tmp_path / 'rig.json'}&policy=all"
    cfg = daemon_config_from_dict({
        "rig": {"url": url}, "sinks": ["memory://"],
        "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
        "health": {"status_file": str(tmp_path / "status.json"), "status_every_s": 0.05, "calibration_window": 10},
    })
    with caplog.at_level(logging.INFO, logger="ghnerf.daemon"), _Running(cfg, tmp_path) as run:
        run.thread.join(timeout=60)  # rig.exit_at_end: the videos' end stops it
        assert not run.thread.is_alive() and run.rc == [0]
    assert run.daemon.health.pairs_estimated >= 20
    calibration = json.loads((tmp_path / "status.json").read_text())["calibration"]
    assert calibration["pairs"] == 10 and calibration["window"] == 10 and calibration["max_px"] == 0.8
    assert calibration["floor_pairs"] == 10 and calibration["max_floor_m"] == 0.05  # the feet are in view
    said = [n["STATUS"] for n in run.notes if "calibration suspect: recalibrate (ghcal)" in n.get("STATUS", "")]
    warned = [r.getMessage() for r in caplog.records if r.getMessage().startswith("calibration suspect")
              and r.levelno == logging.WARNING]
    if not degrees:
        assert not calibration["suspect"] and calibration["reprojection_px_median"] < 0.8 / 2
        assert abs(calibration["lowest_foot_m_median"]) < 0.05 and not calibration["floor_suspect"]
        assert not said and not warned
    elif axis == "tilt":
        assert calibration["suspect"] and calibration["px_suspect"] and calibration["reprojection_px_median"] > 0.8
        assert said and [m for m in warned if "px apart" in m] == warned[:1]  # the px symptom said first, once
        assert run.daemon.health.report()["estimator"]["joints_found"] > 0.6  # wrong joints, not missing ones
    else:  # the views still meet: only the feet tell
        assert calibration["reprojection_px_median"] < 0.8 and not calibration["px_suspect"]
        assert calibration["suspect"] and calibration["floor_suspect"] and calibration["lowest_foot_m_median"] < -0.1
        assert said and "the floor > 0.05 m" in said[-1] and " px > " not in said[-1]
        assert len(warned) == 1 and "m below the floor" in warned[0]


class _SizedWebcam(_StandInWebcam):
    """A stand-in ``cv2.VideoCapture`` of a live camera that delivers the size ``sizes`` gives for its open (the
    rig's opens number 0, 1, ...: two captures each), whatever size was asked of it, 30 frames a second."""

    sizes: Callable[[int], tuple[int, int]] = staticmethod(lambda k: (640, 480))
    made = 0

    def __init__(self, target, api) -> None:
        super().__init__(target, api)
        self.size = _SizedWebcam.sizes(_SizedWebcam.made // 2)
        _SizedWebcam.made += 1

    def grab(self) -> bool:
        time.sleep(1 / 30)
        return True

    def retrieve(self):
        return True, np.full((self.size[1], self.size[0], 3), 100, np.uint8)


def _webcam_rig(tmp_path: Path, monkeypatch, sizes) -> tuple[object, Path]:
    """A daemon config on two stand-in webcams (``_SizedWebcam`` delivering ``sizes(open)``) with a 640x480 rig file,
    the model stood in for; and the rig file."""
    import firmware_host.daemon.service as service
    from drivers.sim.placement import RigPlacement
    from ghnerf_runtime.rig_file import save_rig

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    monkeypatch.setattr(_SizedWebcam, "sizes", staticmethod(sizes))
    monkeypatch.setattr(_SizedWebcam, "made", 0)
    rig_file = tmp_path / "rig.json"
    save_rig(RigPlacement(width=640, height=480).build(rig_id="desk"), rig_file)
    cfg = _config({"url": f"opencv://?first=0&second=1&rig={rig_file}&open_timeout_s=2", "reopen_min_s": 0.01,
                   "reopen_max_s": 0.05}, tmp_path)
    return cfg, rig_file


def test_cameras_that_never_deliver_the_rig_files_size_stop_the_daemon_as_a_bad_config(tmp_path, monkeypatch):
    """A rig file calibrated at another resolution (640x480 here, the webcams stream 320x240) was retried for ever
    (state waiting) with a warning, where a bad config exits 2: no restart fixes it. The same size on three opens in
    a row, the cameras never having delivered the rig's, stops the daemon with one message naming the rig file, the
    camera, both sizes and the likely cause, kept in the status file."""
    cfg, rig_file = _webcam_rig(tmp_path, monkeypatch, lambda k: (320, 240))
    with _Running(cfg, tmp_path, rig_kwargs={"capture_factory": _SizedWebcam}) as run:
        run.thread.join(timeout=20)
        assert not run.thread.is_alive(), "still retrying a rig file that does not fit the cameras"
    error = run.rc[0]
    assert isinstance(error, DaemonStartError)
    message = str(error)
    assert message.startswith(f"rig.url 'opencv://?first=0&second=1&rig={rig_file}&open_timeout_s=2': camera ")
    assert f"delivered 320x240, but its rig camera in {rig_file} is 640x480: the same shape at 0.5 times the size, " \
           "so the rig file was most likely calibrated at another resolution of this camera" in message
    assert "have the camera deliver 640x480 (a webcam offers its larger sizes only compressed: add fourcc=MJPG to " \
           "the URL) or calibrate again at 320x240 (ghcal, docs/calibration.md)" in message
    assert message.endswith("(the same on 3 opens in a row, the cameras never having delivered the rig's size: a rig "
                            "file that does not fit them, which no restart fixes)"), message
    assert run.daemon.health.rig_open_failures == 3 and run.daemon.health.rig_opens == 0
    report = json.loads((tmp_path / "status.json").read_text())
    assert report["last_error"] == f"stopped by DaemonStartError: {message}"


def test_a_camera_that_changes_size_is_retried_once_it_delivered_the_rigs(tmp_path, monkeypatch):
    """What stays retried: a webcam that comes up once in another mode (open 0), and cameras that delivered the rig's
    size (open 1 streamed) and then another at every open (a webcam renegotiating, a camera swapped mid-run)."""
    cfg, _ = _webcam_rig(tmp_path, monkeypatch, lambda k: (640, 480) if k == 1 else (320, 240))
    with _Running(cfg, tmp_path, rig_kwargs={"capture_factory": _SizedWebcam}) as run:
        wait_until(lambda: run.daemon.health.pairs_read >= 3, timeout=20, what="pairs once the camera took the size")
        # the open cameras switch to 320x240 (the rig is lost), as every later open's do
        monkeypatch.setattr(_SizedWebcam, "retrieve", lambda self: (True, np.zeros((240, 320, 3), np.uint8)))
        wait_until(lambda: run.daemon.health.rig_open_failures >= 5, timeout=20, what="reopens of the resized camera")
        assert run.thread.is_alive() and run.daemon.health.state == State.WAITING
        assert run.finish() == 0
    assert run.daemon.health.rig_opens == 1 and "delivered 320x240" in run.daemon.health.last_error


def _depthai_rig(tmp_path: Path, monkeypatch, sizes: Callable[[int], Optional[tuple[int, int]]], **rig):
    """A daemon config on a ``depthai://`` stand-in (no device: tests/drivers/depthai_host.py) whose open number k
    (0, 1, ...) streams a few groups of ``sizes(k)`` (None: none, a silent device), whatever size it was asked for,
    then nothing; the model stood in for; ``rig``: more of the config's rig section. Returns the config and the
    link factory."""
    import firmware_host.daemon.service as service
    from tests.drivers.depthai_host import ScriptedLink, image_group

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    opens = []

    class Sized(ScriptedLink):
        def start(self, request) -> None:
            opens.append(sizes(len(opens)))
            self.groups = [] if opens[-1] is None else [image_group(ix, opens[-1]) for ix in self.indices]

    cfg = _config({"url": "depthai://?width=160&height=100&mount_height=1.2", "reopen_min_s": 0.01,
                   "reopen_max_s": 0.05, "read_timeout_s": 0.05, "stall_s": 0.3, **rig}, tmp_path)
    return cfg, lambda: Sized([(k, k) for k in range(6)])


def test_a_depthai_device_that_never_delivers_the_rigs_size_stops_the_daemon_too(tmp_path, monkeypatch):
    """depthai:// opens before its first frames and checks their size as they are read: its wrong size was a plain
    RigOperationError, and the daemon reopened the device for ever. Now the first read of three opens in a row
    failing on the same size stops it (exit 2) as opencv://'s opens do, with the driver's message."""
    cfg, link = _depthai_rig(tmp_path, monkeypatch, lambda k: (320, 200))
    with _Running(cfg, tmp_path, rig_kwargs={"link_factory": link}) as run:
        run.thread.join(timeout=20)
        assert not run.thread.is_alive(), "still reopening a device that never delivers the rig's size"
    error = run.rc[0]
    assert isinstance(error, DaemonStartError)
    assert str(error).startswith("rig.url 'depthai://?width=160&height=100&mount_height=1.2': depthai device ")
    assert "camera 'left' delivered 320x200, but its rig camera (the device's calibration, at the width=/height= " \
           "asked) is 160x100" in str(error) and "the same on 3 opens in a row" in str(error)
    # no rig= in the URL: the size asked is at fault, not a rig file (the stop blamed one the URL did not name)
    assert str(error).endswith("never having delivered the rig's size: a size asked that they do not deliver, which "
                               "no restart fixes)"), str(error)
    assert "rig file" not in str(error)
    assert run.daemon.health.rig_opens == 3 and run.daemon.health.pairs_read == 0
    # each of the three opens lost at its first read, the last too (it read 2: the stop came before it was counted)
    report = json.loads((tmp_path / "status.json").read_text())
    assert (report["rig"]["opens"], report["rig"]["lost"], report["rig"]["open_failures"]) == (3, 3, 0)
    assert report["last_error"] == f"stopped by DaemonStartError: {error}"


def test_a_depthai_device_that_delivered_the_rigs_size_is_reopened_when_it_changes(tmp_path, monkeypatch):
    """Once a pair of the rig's size was read (open 0), frames of another size at every later open are retried, as
    for opencv://: the daemon waits, it does not stop."""
    cfg, link = _depthai_rig(tmp_path, monkeypatch, lambda k: (160, 100) if k == 0 else (320, 200))
    with _Running(cfg, tmp_path, rig_kwargs={"link_factory": link}) as run:
        wait_until(lambda: run.daemon.health.rig_opens >= 6, timeout=20, what="reopens of the resized device")
        assert run.thread.is_alive()
        assert run.finish() == 0
    assert run.daemon.health.pairs_read >= 1 and "delivered 320x200" in run.daemon.health.last_error


def test_the_opens_in_a_row_start_again_after_a_rig_lost_otherwise_or_a_new_rig_url(tmp_path, monkeypatch):
    """SIZE_MISMATCH_OPENS counts opens in a row: a device lost for another reason between them (silent for
    rig.stall_s) starts the count again, and so does a reload that sets another rig.url (its cameras and rig file are
    judged afresh); a reload that leaves rig.url as it was keeps it. Sizes 320x200 where 160x100 is asked."""
    wrong = (320, 200)
    # opens 0, 1 of the wrong size, 2 silent, then the wrong size again: three more opens before the stop
    cfg, link = _depthai_rig(tmp_path, monkeypatch, lambda k: None if k == 2 else wrong)
    with _Running(cfg, tmp_path, rig_kwargs={"link_factory": link}) as run:
        run.thread.join(timeout=20)
        assert not run.thread.is_alive()
    assert isinstance(run.rc[0], DaemonStartError) and "the same on 3 opens in a row" in str(run.rc[0])
    assert run.daemon.health.rig_opens == 6 and run.daemon.health.rig_lost == 6

    for new_url, opens in ((False, 3), (True, 2 + 3)):
        # a second's backoff, for the reload to land between opens 1 and 2; the reloaded config's is short
        folder = tmp_path / f"reload_{new_url}"  # a notify socket and status file of its own
        folder.mkdir()
        cfg, link = _depthai_rig(folder, monkeypatch, lambda k: wrong, reopen_min_s=1.0, reopen_max_s=1.0)
        reloaded = dataclasses.replace(cfg, rig=dataclasses.replace(
            cfg.rig, reopen_min_s=0.01, reopen_max_s=0.05,
            url="depthai://?width=160&height=100&mount_height=1.3" if new_url else cfg.rig.url))
        with _Running(cfg, folder, rig_kwargs={"link_factory": link}, reload_config=lambda: reloaded) as run:
            wait_until(lambda: run.daemon.health.rig_lost >= 2, timeout=20, what="two opens of the wrong size")
            run.daemon.request_reload()
            run.thread.join(timeout=20)
            assert not run.thread.is_alive()
        assert isinstance(run.rc[0], DaemonStartError), run.rc
        assert run.daemon.health.reloads == 1 and run.daemon.health.rig_opens == opens, reloaded.rig.url


def test_frames_that_come_but_never_pair_are_said_so_not_a_silent_camera(sim_url, tmp_path, monkeypatch):
    """Cameras half a frame apart (or one whose frames arrive many frames behind the other's) deliver every frame,
    but none pairs within the tolerance: the daemon said only 'no pair for 0.3 s', as for a camera that fell
    silent, and the operator looked for a dead camera. It now says frames came from both and why none paired."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    cfg = _config({"url": f"{sim_url}&offset_ms=16.6", "reopen_min_s": 0.05, "read_timeout_s": 0.05,
                   "stall_s": 0.3}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_lost >= 1, timeout=60, what="the rig given up on")
        assert run.finish() == 0
    why = run.daemon.health.last_error
    assert why.startswith("no pair for ") and "frames came from both cameras" in why, why
    assert "none paired within the pairing tolerance of 11 ms" in why, why
    assert run.daemon.health.pairs_read == 0


def test_a_camera_whose_frames_arrive_ten_frames_late_is_said_to_need_max_pending(sim_url, tmp_path, monkeypatch):
    """A camera whose frames reach the host 10 frames after the other's (340 ms at 30 fps: a slower USB path)
    never pairs at the default max_pending (8): the warning says so and names the rig URL's option, not the
    cameras' sync. With max_pending above the lag the same rig streams."""
    import firmware_host.daemon.service as service

    monkeypatch.setattr(service, "load_session", lambda config: object())
    monkeypatch.setattr(service, "Estimator", _CountingEstimator)
    cfg = _config({"url": f"{sim_url}&latency_ms=340", "reopen_min_s": 0.05, "read_timeout_s": 0.05,
                   "stall_s": 1.0}, tmp_path)
    with _Running(cfg, tmp_path) as run:
        wait_until(lambda: run.daemon.health.rig_lost >= 1, timeout=60, what="the rig given up on")
        assert run.finish() == 0
    why = run.daemon.health.last_error
    assert "frames came from both cameras" in why and "raise the rig URL's max_pending" in why, why
    assert run.daemon.health.pairs_read == 0
    raised = tmp_path / "raised"
    raised.mkdir()
    cfg = _config({"url": f"{sim_url}&latency_ms=340&max_pending=12", "read_timeout_s": 0.5, "stall_s": 1.0}, raised)
    with _Running(cfg, raised) as run:
        wait_until(lambda: run.daemon.health.pairs_read >= 10, timeout=60, what="pairs with max_pending=12")
        assert run.finish() == 0
    assert run.daemon.health.rig_lost == 0


class _ExchangedEstimator(_ScriptedEstimator):
    """Views that meet (0.2 px) and feet on the floor throughout, no handedness for pairs 0-2, a person (+0.8) for 3-5
    and a mirror image (-0.7) from pair 6 on: the cameras' inputs exchanged on a symmetric rig (the median of the
    handedness check's window of 3 passes -0.2 at pair 7)."""

    def _figures(self, n: int) -> dict:
        return dict(reprojection_px_median=0.2, lowest_foot_m=0.01,
                    handedness=None if n < 3 else -0.7 if n >= 6 else 0.8)


def test_exchanged_cameras_flag_the_calibration_on_the_link(sim_url, tmp_path, monkeypatch):
    """The cameras' inputs exchanged on a symmetric rig: the views meet and the feet stand on the floor, but the
    triangulated person is a mirror image. Once the handedness check's window of 3 (health.calibration_window) has its
    median below -0.2 the JOINTS and every STATUS carry CALIBRATION_SUSPECT, the status file says which symptom and
    the STATUS line says the cameras look exchanged (docs/calibration.md, "Cameras exchanged"). Before session 65
    nothing did."""
    run, messages, flags = _flags_on_the_link(_ExchangedEstimator, sim_url, tmp_path, monkeypatch)
    assert {seq: bool(f & Flags.CALIBRATION_SUSPECT) for seq, f in flags.items()} == {seq: seq >= 7 for seq in flags}
    assert [m for m in messages if isinstance(m, Status)][-1].header.flags == Flags.CALIBRATION_SUSPECT
    calibration = run.daemon.health.report()["calibration"]
    assert calibration["suspect"] and calibration["exchanged_suspect"]
    assert not calibration["px_suspect"] and not calibration["floor_suspect"]
    assert calibration["handedness_median"] == -0.7 and calibration["handedness_pairs"] == 3
    assert "; calibration suspect: swap the cameras' plugs or names in rig.url, cameras look exchanged (mirror " \
           "image: handedness -0.70 < -0.2)" in run.daemon.health.status_line()
    assert calibration["fix"] == "swap the cameras' plugs or names in rig.url"


def test_health_calibration_max_mirror_sets_the_exchanged_cameras_check_and_null_turns_it_off(sim_url, tmp_path,
                                                                                              monkeypatch):
    """A rig built mirror-imaged reads as a mirror image (a subject with their back to the rig gives no figure since
    session 66's heel rule): the key turns the check off (since session 65's follow-up; the limit was a constant the
    daemon always used)."""
    run, messages, flags = _flags_on_the_link(_ExchangedEstimator, sim_url, tmp_path, monkeypatch,
                                              calibration_max_mirror=None)
    assert not any(f & Flags.CALIBRATION_SUSPECT for f in flags.values())
    calibration = run.daemon.health.report()["calibration"]
    assert calibration["max_mirror"] is None and not calibration["exchanged_suspect"]
    assert calibration["handedness_median"] == -0.7 and calibration["fix"] is None
    (tmp_path / "looser").mkdir()  # a second daemon: its own notify socket
    run, messages, flags = _flags_on_the_link(_ExchangedEstimator, sim_url, tmp_path / "looser", monkeypatch,
                                              calibration_max_mirror=0.75)  # -0.7 is not below -0.75
    assert run.daemon.health.report()["calibration"]["max_mirror"] == 0.75
    assert not any(f & Flags.CALIBRATION_SUSPECT for f in flags.values())
