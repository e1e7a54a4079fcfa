"""``DropPolicy.LATEST``: a reader slower than the cameras gets the newest pair, older ones dropped and counted."""
import time

import numpy as np
import pytest

from drivers import (
    DropPolicy,
    EndOfStream,
    Frame,
    ManualClock,
    PairingConfig,
    RigDisconnectedError,
    RigSource,
    RigTimeoutError,
    create_rig_source,
    open_rig,
)
from drivers.sim import RigPlacement
from tests.drivers.test_depthai_pipeline import URL as DEPTHAI_URL
from tests.drivers.depthai_host import HostPipelineLink, ScriptedLink

START = 5_000_000_000
PERIOD_NS = 1e9 / 30
WORK_NS = 100_000_000  # the reader's time per pair: three 30 fps periods
SMALL = "width=32&height=24"


def sim(cache, options: str = ""):
    clock = ManualClock(START)
    return open_rig(f"sim://?{SMALL}&fps=30&cache={cache}&{options}", clock=clock), clock


def slow_reads(source, clock, n):
    """``n`` reads with ``WORK_NS`` of work after each; returns (pair, clock at read) pairs."""
    out = []
    for _ in range(n):
        out.append((source.read(timeout_s=1.0), clock.now_ns()))
        clock.advance(WORK_NS)
    return out


# ----------------------------------------------------------------- sim://
@pytest.mark.parametrize("options", ["", "offset_ms=2"])
def test_a_slow_reader_gets_the_newest_pair_and_the_skipped_ones_are_counted(sim_cache, options):
    source, clock = sim(sim_cache, options)  # policy: latest, the default of a live source
    with source:
        reads = slow_reads(source, clock, 15)
        stats = source.stats
    for pair, now in reads:
        assert 0 <= now - max(pair.timestamps_ns) < PERIOD_NS  # newest: within one frame period of now
    seqs = [p.sequence for p, _ in reads]
    assert all(b - a >= 2 for a, b in zip(seqs[1:], seqs[2:])), seqs  # ~3 pairs captured per read: gaps
    assert stats.pairs_dropped >= 2 * (len(reads) - 2)
    assert stats.pairs_out + stats.pairs_dropped == seqs[-1] + 1
    # nothing lost silently inside the simulated camera: every capture reached the pairer
    assert stats.overruns == {"left": 0, "right": 0}
    assert stats.camera_gaps == {"left": 0, "right": 0}


def test_policy_all_gives_the_same_reader_every_pair_in_order(sim_cache):
    source, clock = sim(sim_cache, "policy=all")
    with source:
        reads = slow_reads(source, clock, 4)  # the lag stays within the camera's 8-frame backlog
        stats = source.stats
    pairs = [p for p, _ in reads]
    assert [p.sequence for p in pairs] == list(range(4))
    assert [p.frames[0].index for p in pairs] == list(range(4))  # the oldest waiting, as before
    assert stats.pairs_dropped == 0 and stats.overruns == {"left": 0, "right": 0}


def test_a_reader_that_keeps_up_loses_nothing_under_latest(sim_cache):
    source, clock = sim(sim_cache)
    with source:
        pairs = [source.read(timeout_s=1.0) for _ in range(20)]  # the clock moves only by waiting for captures
        assert source.stats.pairs_dropped == 0
    assert [p.sequence for p in pairs] == list(range(20))


def test_a_slow_reader_gets_the_pairs_before_an_unplug_then_the_error(sim_cache):
    source, clock = sim(sim_cache, "unplug_after_s=0.5")
    with source:
        source.read(timeout_s=1.0)
        clock.advance(600_000_000)  # past the unplug at 0.5 s
        pair = source.read(timeout_s=1.0)
        assert pair.frames[0].index == 14  # the last capture before 0.5 s (15/30 s is the unplug instant)
        with pytest.raises(RigDisconnectedError, match="unplug"):
            source.read(timeout_s=1.0)


def test_drained_frames_are_recorded(tmp_path, sim_cache):
    out = tmp_path / "take"
    clock = ManualClock(START)
    with open_rig(f"record+sim://?{SMALL}&cache={sim_cache}&out={out}&lossless=1", clock=clock) as source:
        reads = slow_reads(source, clock, 6)
    stats = source.stats
    assert stats.pairs_dropped > 0
    assert stats.frames_written == sum(stats.frames_in.values())  # the skipped pairs' frames too
    with open_rig(f"replay://{out}?speed=free&policy=all") as replay:
        replayed = list(replay)
    assert len(replayed) == reads[-1][0].sequence + 1


# ----------------------------------------------------------------- replay://
def _record_take(tmp_path_factory, sim_cache, folder: str, pairs: int):
    """``pairs`` pairs of the small sim rig, no jitter or drops: pair k at START + k/30 s."""
    out = tmp_path_factory.mktemp(folder) / "take"
    with open_rig(f"record+sim://?{SMALL}&cache={sim_cache}&out={out}&policy=all&lossless=1",
                  clock=ManualClock(START)) as source:
        for _ in range(pairs):
            source.read(timeout_s=1.0)
    return out


@pytest.fixture(scope="module")
def take(tmp_path_factory, sim_cache):
    """10 pairs: 20 frames."""
    return _record_take(tmp_path_factory, sim_cache, "latest", 10)


def test_unpaced_replay_under_latest_never_reads_ahead(take):
    with open_rig(f"replay://{take}?speed=free&policy=latest") as source:
        first = source.read(timeout_s=1.0)
        assert sum(source.stats.frames_in.values()) == 2  # just the first pair's frames
        pairs = [first, *source]
        stats = source.stats
    assert [p.sequence for p in pairs] == list(range(10))
    assert stats.pairs_dropped == 0


def test_paced_replay_under_latest_skips_to_the_newest_pair_due(take):
    clock = ManualClock(123_000_000_000)
    with open_rig(f"replay://{take}?speed=recorded&policy=latest", clock=clock) as source:
        assert source.read(timeout_s=1.0).sequence == 0
        clock.advance(WORK_NS)
        pair = source.read(timeout_s=1.0)
        assert (pair.sequence, pair.frames[0].index) == (3, 3)  # recorded 100 ms after the first
        assert source.stats.pairs_dropped == 2
        clock.advance(10_000_000_000)  # far past the end: the last pair first, then the end
        assert source.read(timeout_s=1.0).frames[0].index == 9
        with pytest.raises(EndOfStream):
            source.read(timeout_s=1.0)


@pytest.fixture(scope="module")
def long_take(tmp_path_factory, sim_cache):
    """40 pairs (80 frames, more than the old drain bound of 32)."""
    return _record_take(tmp_path_factory, sim_cache, "latest-long", 40)


def test_paced_replay_under_latest_keeps_a_slow_readers_lag_bounded(long_take, monkeypatch):
    from drivers.backends import replay as replay_module

    decoded = []
    real_load = replay_module.load_image
    monkeypatch.setattr(replay_module, "load_image", lambda path: decoded.append(path) or real_load(path))
    clock = ManualClock(123_000_000_000)
    with open_rig(f"replay://{long_take}?speed=recorded&policy=latest&loop=1", clock=clock) as source:
        first = source.read(timeout_s=1.0)
        anchor = clock.now_ns()
        lags, per_read = [], []
        for _ in range(5):  # one pair a second: 30 pairs (60 frames) due at each read
            clock.advance(1_000_000_000)
            decoded.clear()
            pair = source.read(timeout_s=1.0)
            per_read.append(len(decoded))
            lags.append((clock.now_ns() - anchor) - (pair.frames[0].timestamp_ns - first.frames[0].timestamp_ns))
        stats = source.stats
    assert all(0 <= lag < PERIOD_NS for lag in lags), lags  # the newest pair due, every time: no growing lag
    assert max(per_read) <= 4, per_read  # the pair handed out (and a partner awaited), not the 60 skipped
    assert stats.pairs_out + stats.pairs_dropped == pair.sequence + 1
    assert stats.pairs_dropped >= 5 * 28


# ----------------------------------------------------------------- the drain bound
class FloodSource(RigSource):
    """Both cameras always have a frame ready: a source faster than any reader."""

    scheme = "flood"

    def __init__(self, policy: DropPolicy) -> None:
        super().__init__(RigPlacement(width=16, height=16).build("flood"), pairing=PairingConfig(policy=policy),
                         clock=ManualClock())
        self.frames_read = 0

    @classmethod
    def from_url(cls, url, **kwargs):  # pragma: no cover - built directly
        raise NotImplementedError

    def _open(self) -> None:
        pass

    def _frame_available(self) -> bool:
        return True

    def _read_frame(self, timeout_s: float) -> Frame:
        k, camera = divmod(self.frames_read, 2)
        self.frames_read += 1
        return Frame(camera=self.rig.pair[camera].name, image=np.zeros((16, 16, 3), np.uint8),
                     timestamp_ns=int(k * PERIOD_NS), index=k)

    def _close(self) -> None:
        pass


def test_the_drain_is_bounded_so_a_flood_cannot_trap_read():
    with FloodSource(DropPolicy.LATEST) as source:
        pair = source.read(timeout_s=1.0)
        assert source.frames_read == source.drain_limit
        assert pair.sequence == source.drain_limit // 2 - 1  # the newest pair of the drained frames
        source.read(timeout_s=1.0)
        assert source.frames_read == 2 * source.drain_limit  # the bound holds per read
    with FloodSource(DropPolicy.ALL) as source:
        assert source.read(timeout_s=1.0).sequence == 0
        assert source.frames_read == 2  # no draining under ALL


# ----------------------------------------------------------------- depthai://
def _read_after_a_stall(policy: str):
    """One pair read 12 groups (0.4 s at 30 fps) after the previous one; the newest index sent before it."""
    link = HostPipelineLink()
    with open_rig(f"{DEPTHAI_URL}&queue=4&policy={policy}", link_factory=lambda: link) as source:
        read = source.read(timeout_s=3.0).frames[0].index
        # waited for, not slept: a loaded host's camera threads had sent fewer groups than 0.4 s holds
        deadline = time.monotonic() + 60.0
        while not (_sent_since(link, read) >= 12 and link.queue.isFull()) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert _sent_since(link, read) >= 12 and link.queue.isFull()  # the host queue holds its 4 newest groups
        newest_sent = max(k for k, _ in list(link.cameras[0].sent))
        pair = source.read(timeout_s=3.0)
        return pair, newest_sent, source.stats


def _sent_since(link: HostPipelineLink, index: int) -> int:
    """Frames both host cameras have sent after frame ``index``."""
    return min(sum(k > index for k, _ in list(camera.sent)) for camera in link.cameras)


def test_depthai_slow_reader_gets_the_newest_group_not_the_oldest_queued():
    pair, newest_sent, stats = _read_after_a_stall("latest")
    assert pair.frames[0].index >= newest_sent - 1  # the host queue was drained (one may be in Sync)
    assert stats.pairs_dropped >= 2  # the older queued groups: counted as dropped, not as camera gaps


def test_depthai_policy_all_reads_the_queued_groups_in_order():
    pair, newest_sent, stats = _read_after_a_stall("all")
    assert pair.frames[0].index <= newest_sent - 2  # the oldest of the queued groups comes first
    # the groups the full queue (4) dropped during the 12-group stall: whole pairs lost, not camera gaps
    assert stats.pairs_dropped >= 4
    assert stats.pairs_out + stats.pairs_dropped == pair.sequence + 1
    assert stats.camera_gaps == {"left": 0, "right": 0}


def test_depthai_latest_drains_a_deep_queue_whole():
    # queue=64 holds up to 129 frames for the reader: a bound of 32 returned a pair 24 groups old
    link = ScriptedLink([(k, k) for k in range(40)])
    with open_rig(f"{DEPTHAI_URL}&queue=64&policy=latest", link_factory=lambda: link) as source:
        pair = source.read(timeout_s=0.1)
        stats = source.stats
    assert (pair.sequence, pair.frames[0].index) == (39, 39)
    assert stats.pairs_dropped == 39 and stats.camera_gaps == {"left": 0, "right": 0}


def test_depthai_serves_its_pending_frame_before_the_link():
    source = create_rig_source(DEPTHAI_URL, link_factory=HostPipelineLink)  # not opened: no link at all
    try:
        assert not source._frame_available()
        frame = Frame(camera="right", image=np.zeros((100, 160, 3), np.uint8), timestamp_ns=0, index=0)
        source._pending.append(frame)
        assert source._frame_available()
        assert source._read_frame(0.0) is frame  # served from the deque; the (absent) link untouched
        assert not source._frame_available()
    finally:
        source.close()


@pytest.mark.parametrize("policy", ["latest", "all"])
def test_a_poll_takes_the_pair_already_there_and_only_then_times_out(sim_cache, policy):
    # read(timeout_s=0) once timed out before asking the backend for a frame under policy=all
    source, clock = sim(sim_cache, f"policy={policy}")
    with source:
        clock.advance(WORK_NS)  # three periods: pairs are waiting
        polled = []
        while True:
            try:
                polled.append(source.read(timeout_s=0))
            except RigTimeoutError:
                break
            assert len(polled) <= 8, "a poll kept finding pairs that had not been captured"
        assert clock.now_ns() == START + WORK_NS  # a poll never waits
    assert polled, "a poll found no pair with three captured"
    if policy == "all":
        assert [p.sequence for p in polled] == list(range(len(polled))) and len(polled) >= 3
    else:
        assert len(polled) == 1 and 0 <= clock.now_ns() - max(polled[0].timestamps_ns) < PERIOD_NS


def test_paced_replay_under_latest_raises_a_corrupt_row_once_then_goes_on(take, tmp_path):
    """A row that cannot be loaded while catching up is raised once, not by every read until it ages out."""
    import json
    import shutil

    from drivers import RigOperationError

    copy = tmp_path / "take"
    shutil.copytree(take, copy)
    rows = [json.loads(line) for line in (copy / "frames.jsonl").read_text().splitlines()]
    bad = next(r for r in rows if r["camera"] == "left" and r["index"] == 3)
    (copy / bad["image"]).write_bytes(b"\x89PNG garbage")
    clock = ManualClock(123_000_000_000)
    with open_rig(f"replay://{copy}?speed=recorded&policy=latest", clock=clock) as source:
        assert source.read(timeout_s=1.0).sequence == 0
        clock.advance(WORK_NS)  # pair 3 is the newest due
        with pytest.raises(RigOperationError, match="corrupt") as info:
            source.read(timeout_s=1.0)
        assert bad["image"] in str(info.value)
        pair = source.read(timeout_s=1.0)  # the bad row is behind us
        assert pair.frames[0].index == 4 and all(f.image.size for f in pair.frames)
        assert source.stats.pairs_dropped == 3  # pairs 1 and 2 skipped, pair 3 lost to the corrupt image
