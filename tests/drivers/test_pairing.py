"""FramePairer frame by frame: tolerance, offset cameras, drops, LATEST vs ALL, gaps and unpaired counts."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers import DropPolicy, PairingConfig, RigConfigError
from drivers.frames import Frame
from drivers.pairing import FramePairer

MS = 1_000_000
PERIOD = 33_333_333
IMG = np.zeros((2, 2, 3), np.uint8)


def frame(camera: str, index: int, t_ns: int) -> Frame:
    return Frame(camera=camera, image=IMG, timestamp_ns=int(t_ns), index=index)


def drain(pairer: FramePairer) -> list[tuple[int, Frame, Frame]]:
    out = []
    while (item := pairer.pop()) is not None:
        out.append(item)
    return out


def stream(offset_ns: int = 0, n: int = 10, drop_a=(), drop_b=()):
    """Frames of cameras a and b in time order; b captures ``offset_ns`` after a."""
    events = []
    for k in range(n):
        if k not in drop_a:
            events.append(frame("a", k, k * PERIOD))
        if k not in drop_b:
            events.append(frame("b", k, k * PERIOD + offset_ns))
    return sorted(events, key=lambda f: f.timestamp_ns)


def run(config: PairingConfig, events) -> tuple[FramePairer, list]:
    pairer = FramePairer(("a", "b"), config)
    pairs = []
    for f in events:
        pairer.push(f)
        pairs += drain(pairer)  # a reader that keeps up
    return pairer, pairs


def test_simultaneous_cameras_pair_every_frame_in_order():
    pairer, pairs = run(PairingConfig(), stream())
    assert [s for s, _, _ in pairs] == list(range(10))
    assert all(a.index == b.index and a.camera == "a" and b.camera == "b" for _, a, b in pairs)
    assert pairer.stats.pairs_out == 10 and pairer.stats.unpaired == {"a": 0, "b": 0}


@pytest.mark.parametrize("offset_ms", [-8.0, 3.0, 10.9])
def test_offset_within_tolerance_pairs(offset_ms):
    _, pairs = run(PairingConfig(tolerance_ms=11.0), stream(int(offset_ms * MS)))
    assert len(pairs) == 10
    assert all(abs(a.timestamp_ns - b.timestamp_ns) == abs(int(offset_ms * MS)) for _, a, b in pairs)


def test_offset_beyond_tolerance_never_pairs_and_counts_unpaired():
    pairer, pairs = run(PairingConfig(tolerance_ms=5.0), stream(int(12 * MS)))
    assert pairs == []
    stats = pairer.stats
    assert stats.frames_in == {"a": 10, "b": 10}
    # every frame but the last pending ones was given up on
    assert stats.unpaired["a"] + stats.unpaired["b"] >= 18


def test_half_period_offset_pairs_with_the_nearest_frame():
    _, pairs = run(PairingConfig(tolerance_ms=20.0), stream(int(15 * MS)))
    assert pairs and all(b.timestamp_ns - a.timestamp_ns == 15 * MS for _, a, b in pairs)


def test_drops_leave_the_partner_unpaired_and_are_counted_as_gaps():
    pairer, pairs = run(PairingConfig(), stream(drop_a={3}, drop_b={6, 7}))
    paired = [a.index for _, a, _ in pairs]
    assert paired == [0, 1, 2, 4, 5, 8, 9]
    stats = pairer.stats
    assert stats.camera_gaps == {"a": 1, "b": 2}
    assert stats.unpaired == {"a": 2, "b": 1}


def test_latest_keeps_only_the_newest_pair_for_a_slow_reader():
    pairer = FramePairer(("a", "b"), PairingConfig(policy=DropPolicy.LATEST))
    for f in stream(n=5):
        pairer.push(f)
    pairs = drain(pairer)
    assert len(pairs) == 1
    sequence, a, _ = pairs[0]
    assert sequence == 4 and a.index == 4  # sequence numbers show the dropped pairs as a gap
    assert pairer.stats.pairs_dropped == 4


def test_all_keeps_every_pair_up_to_max_ready():
    pairer = FramePairer(("a", "b"), PairingConfig(policy=DropPolicy.ALL, max_ready=3))
    for f in stream(n=5):
        pairer.push(f)
    assert [s for s, _, _ in drain(pairer)] == [2, 3, 4]
    assert pairer.stats.pairs_dropped == 2
    pairer = FramePairer(("a", "b"), PairingConfig(policy="all"))
    for f in stream(n=5):
        pairer.push(f)
    assert [s for s, _, _ in drain(pairer)] == [0, 1, 2, 3, 4]


def test_one_camera_stalling_is_bounded_by_max_pending():
    events = [frame("a", k, k * PERIOD) for k in range(20)]
    pairer, pairs = run(PairingConfig(max_pending=4), events)
    assert pairs == [] and pairer.stats.unpaired["a"] == 16


def test_reset_counts_pending_as_unpaired_and_forgets_indices():
    pairer = FramePairer(("a", "b"), PairingConfig())
    pairer.push(frame("a", 0, 0))
    pairer.reset()
    assert pairer.stats.unpaired["a"] == 1
    pairer.push(frame("a", 10, 10 * PERIOD))  # after a reconnect counters restart: no gap
    assert pairer.stats.camera_gaps["a"] == 0


def test_unknown_camera_and_bad_config_are_rejected():
    pairer = FramePairer(("a", "b"))
    with pytest.raises(RigConfigError, match="'c'"):
        pairer.push(frame("c", 0, 0))
    for tolerance in (0, float("inf"), float("nan")):
        with pytest.raises(RigConfigError, match="tolerance_ms"):
            PairingConfig(tolerance_ms=tolerance)
    with pytest.raises(RigConfigError, match="policy"):
        PairingConfig(policy="newest")


@settings(max_examples=60, deadline=None)
@given(
    offset_ms=st.floats(-16, 16),
    tolerance_ms=st.floats(0.5, 16),
    drops=st.lists(st.tuples(st.sampled_from("ab"), st.integers(0, 29)), max_size=10),
)
def test_pairs_respect_tolerance_and_order(offset_ms, tolerance_ms, drops):
    drop_a = {k for cam, k in drops if cam == "a"}
    drop_b = {k for cam, k in drops if cam == "b"}
    pairer, pairs = run(PairingConfig(tolerance_ms=tolerance_ms, policy="all"),
                        stream(int(offset_ms * MS), 30, drop_a, drop_b))
    seqs = [s for s, _, _ in pairs]
    assert seqs == sorted(set(seqs))
    for _, a, b in pairs:
        assert abs(a.timestamp_ns - b.timestamp_ns) <= tolerance_ms * MS
    for cam in (0, 1):
        idx = [p[1 + cam].index for p in pairs]
        assert idx == sorted(set(idx))  # no frame used twice, order kept
    stats = pairer.stats
    assert stats.pairs_out == len(pairs)
    # conservation: every frame is paired, given up, or still pending (at most max_pending)
    for cam, k in (("a", 1), ("b", 2)):
        used = len(pairs)
        assert stats.frames_in[cam] - used - stats.unpaired[cam] in range(0, PairingConfig().max_pending + 1)
