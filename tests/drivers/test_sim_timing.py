"""``sim://`` timing on a ManualClock: fps, offset, jitter statistics, drops, unplug, backlog, timeouts."""
import numpy as np
import pytest

from drivers import ManualClock, RigConfigError, RigDisconnectedError, RigTimeoutError, open_rig, why_no_pair
from drivers.backends.sim_timing import CaptureSchedule, TimingModel

START = 5_000_000_000
PERIOD = 1e9 / 30


def sim(cache, options: str = "", start_ns: int = START):
    clock = ManualClock(start_ns)
    url = f"sim://?width=32&height=24&cache={cache}&policy=all&tolerance_ms=16&{options}"
    return open_rig(url, clock=clock), clock


def read_pairs(source, n):
    return [source.read(timeout_s=1.0) for _ in range(n)]


# ----------------------------------------------------------------- the schedule itself
def captures(model: TimingModel, n: int):
    schedule = CaptureSchedule(model, START)
    return [schedule.pop() for _ in range(n)]


def test_schedule_without_jitter_is_exact_and_in_time_order():
    caps = captures(TimingModel(fps=30, offset_ms=4.0), 200)
    times = [c.time_ns for c in caps]
    assert times == sorted(times)
    for c in caps:
        expected = START + round(c.index * PERIOD) + (4_000_000 if c.camera == 1 else 0)
        assert c.time_ns == c.nominal_ns == expected
    assert [c.camera for c in caps[:4]] == [0, 1, 0, 1]


def test_schedule_jitter_is_gaussian_with_the_requested_spread_and_keeps_order():
    caps = captures(TimingModel(fps=30, jitter_ms=2.0, seed=7), 8000)
    residual_ms = np.array([(c.time_ns - c.nominal_ns) / 1e6 for c in caps])
    assert abs(residual_ms.mean()) < 0.1
    assert residual_ms.std() == pytest.approx(2.0, rel=0.05)
    # roughly normal: ~68 % within one sigma
    assert np.mean(np.abs(residual_ms) < 2.0) == pytest.approx(0.683, abs=0.03)
    for cam in (0, 1):
        times = [c.time_ns for c in caps if c.camera == cam]
        assert all(b > a for a, b in zip(times, times[1:]))


def test_schedule_large_jitter_is_clipped_so_captures_stay_in_order():
    caps = captures(TimingModel(fps=30, jitter_ms=100.0), 2000)
    assert max(abs(c.time_ns - c.nominal_ns) for c in caps) <= 0.45 * PERIOD + 1
    for cam in (0, 1):
        times = [c.time_ns for c in caps if c.camera == cam]
        assert all(b > a for a, b in zip(times, times[1:]))


def test_schedule_drop_rate_matches_per_camera_and_is_seeded():
    model = TimingModel(fps=30, drop=0.1, seed=3)
    caps = captures(model, 20000)
    for cam in (0, 1):
        dropped = [c.dropped for c in caps if c.camera == cam]
        assert np.mean(dropped) == pytest.approx(0.1, abs=0.01)
    # drops of the two cameras are independent
    both = {c.index for c in caps if c.camera == 0 and c.dropped} & {c.index for c in caps if c.camera == 1 and c.dropped}
    assert len(both) / 10000 == pytest.approx(0.01, abs=0.004)
    assert [c.time_ns for c in captures(model, 500)] == [c.time_ns for c in caps[:500]]
    assert [c.dropped for c in captures(model, 500)] == [c.dropped for c in caps[:500]]


# ----------------------------------------------------------------- through the backend
def test_delivered_timestamps_follow_fps_and_offset_exactly(sim_cache):
    source, _ = sim(sim_cache, "offset_ms=3.5")
    with source:
        pairs = read_pairs(source, 90)
    for k, pair in enumerate(pairs):
        left, right = pair.frames
        assert left.index == right.index == k
        assert left.timestamp_ns == START + round(k * PERIOD)
        assert right.timestamp_ns - left.timestamp_ns == 3_500_000
    assert pairs[-1].sequence == 89


def test_a_negative_offset_starts_the_late_camera_at_open_without_phantom_overruns(sim_cache):
    source, _ = sim(sim_cache, "offset_ms=-300")
    with source:
        pairs = read_pairs(source, 20)
        stats = source.stats
    assert stats.overruns == {"left": 0, "right": 0}  # nothing the reader missed
    first = pairs[0].frames[1]
    assert first.timestamp_ns >= START and first.index == 9  # captures due before open never happened
    assert all(b.frames[1].index - a.frames[1].index == 1 for a, b in zip(pairs, pairs[1:]))


def test_delivered_jitter_statistics(sim_cache):
    source, _ = sim(sim_cache, "jitter_ms=1.5&seed=11")
    with source:
        pairs = read_pairs(source, 600)
    residual_ms = np.array(
        [(f.timestamp_ns - (START + round(f.index * PERIOD))) / 1e6 for p in pairs for f in p.frames]
    )
    assert abs(residual_ms.mean()) < 0.15
    assert residual_ms.std() == pytest.approx(1.5, rel=0.08)
    intervals = np.diff([p.frames[0].timestamp_ns for p in pairs]) / 1e6
    assert np.median(intervals) == pytest.approx(1000 / 30, abs=0.3)


def test_drop_rate_is_what_was_asked_and_counted(sim_cache):
    source, _ = sim(sim_cache, "drop=0.2&seed=5")
    with source:
        pairs = read_pairs(source, 400)
        stats = source.stats
    captured = pairs[-1].frames[0].index + 1  # captures per camera so far (about)
    for cam in ("left", "right"):
        assert stats.simulated_drops[cam] / captured == pytest.approx(0.2, abs=0.04)
        # every drop shows as an index gap except possibly the trailing ones
        assert stats.camera_gaps[cam] <= stats.simulated_drops[cam] <= stats.camera_gaps[cam] + 3
    # a pair needs both frames: about (1 - 0.2)^2 of the captures pair
    assert len(pairs) / captured == pytest.approx(0.64, abs=0.06)


def test_unplug_raises_at_the_right_time_and_keeps_raising(sim_cache):
    source, clock = sim(sim_cache, "unplug_after_s=1.0")
    with source:
        pairs = []
        with pytest.raises(RigDisconnectedError, match="unplug"):
            while True:
                pairs.append(source.read(timeout_s=5.0))
        assert clock.now_ns() == START + 1_000_000_000
        assert len(pairs) == 30  # captures at 0 .. 29/30 s
        assert all(f.timestamp_ns < START + 1_000_000_000 for p in pairs for f in p.frames)
        with pytest.raises(RigDisconnectedError):
            source.read(timeout_s=5.0)
        assert clock.now_ns() == START + 1_000_000_000  # raised at once, no waiting


def test_unplug_beyond_the_timeout_is_a_timeout_first(sim_cache):
    source, clock = sim(sim_cache, "unplug_after_s=0.5&fps=1")
    with source:
        source.read(timeout_s=0.1)  # the t=0 pair
        with pytest.raises(RigTimeoutError):
            source.read(timeout_s=0.2)
        with pytest.raises(RigDisconnectedError):
            source.read(timeout_s=1.0)
        assert clock.now_ns() == START + 500_000_000


def test_timeout_advances_the_manual_clock_by_exactly_the_timeout(sim_cache):
    source, clock = sim(sim_cache, "fps=2")
    with source:
        source.read(timeout_s=0.1)
        t0 = clock.now_ns()
        with pytest.raises(RigTimeoutError):
            source.read(timeout_s=0.3)
        assert clock.now_ns() - t0 == 300_000_000
        pair = source.read(timeout_s=1.0)  # the next capture, at 0.5 s
        assert pair.frames[0].timestamp_ns == START + 500_000_000 == clock.now_ns()


def test_a_slow_reader_loses_old_captures_beyond_the_backlog(sim_cache):
    source, clock = sim(sim_cache)
    with source:
        source.read(timeout_s=1.0)
        clock.advance(1_000_000_000)  # the reader was busy for a second: captures 1..30 happened
        pair = source.read(timeout_s=1.0)
        stats = source.stats
    # the camera held the newest 8 (23..30); 1..22 were lost
    assert stats.overruns["left"] == stats.overruns["right"] == 22
    assert pair.frames[0].index == 23
    assert stats.camera_gaps["left"] == 22


def test_same_seed_same_timeline(sim_cache):
    options = "jitter_ms=2&drop=0.1&offset_ms=1&seed=9"
    runs = []
    for _ in range(2):
        source, _ = sim(sim_cache, options)
        with source:
            runs.append([(p.sequence, p.timestamps_ns) for p in read_pairs(source, 50)])
    assert runs[0] == runs[1]


def test_real_clock_delivers_at_the_nominal_rate(sim_cache):
    # policy=all: on a loaded machine a reader may fall a frame behind now and then; LATEST would then
    # (correctly) skip to the newest pair, which is not what this test is about
    with open_rig(f"sim://?width=32&height=24&fps=60&policy=all&cache={sim_cache}") as source:
        pairs = read_pairs(source, 40)
    stamps = np.array([p.frames[0].timestamp_ns for p in pairs])
    assert np.median(np.diff(stamps)) / 1e6 == pytest.approx(1000 / 60, abs=0.5)
    assert [p.sequence for p in pairs] == list(range(40))  # every pair delivered, in order


# ----------------------------------------------------------------- a camera whose frames arrive late
def test_schedule_latency_delays_the_second_cameras_arrival_not_its_stamps():
    caps = captures(TimingModel(fps=30, latency_ms=100.0), 40)
    assert [c.arrival_ns for c in caps] == sorted(c.arrival_ns for c in caps)  # in order of arrival
    for c in caps:
        assert c.time_ns == START + round(c.index * PERIOD)
        assert c.arrival_ns - c.time_ns == (100_000_000 if c.camera == 1 else 0)
    assert [(c.camera, c.index) for c in caps[:5]] == [(0, 0), (0, 1), (0, 2), (0, 3), (1, 0)]


#: Ten frames and a bit at 30 fps: each 'right' frame arrives after 'left' captured ten more.
LAG_10_FRAMES_MS = 340


def test_a_camera_lagging_ten_frames_pairs_with_max_pending_above_ten(sim_cache):
    # USB webcams' frames reach the host 100-300 ms apart; their stamps still pair, once the pairer holds enough
    source, _ = sim(sim_cache, f"latency_ms={LAG_10_FRAMES_MS}&max_pending=11")
    with source:
        pairs = read_pairs(source, 30)
        stats = source.stats
    assert [p.frames[0].index for p in pairs] == [p.frames[1].index for p in pairs] == list(range(30))
    assert all(p.frames[0].timestamp_ns == p.frames[1].timestamp_ns for p in pairs)
    assert stats.overruns == {"left": 0, "right": 0} and stats.overflowed == {"left": 0, "right": 0}


def test_a_camera_lagging_ten_frames_never_pairs_at_the_default_max_pending_and_is_said_to(sim_cache):
    source, _ = sim(sim_cache, f"latency_ms={LAG_10_FRAMES_MS}")
    with source:
        before = source.stats
        with pytest.raises(RigTimeoutError):
            source.read(timeout_s=2.0)
        why = why_no_pair(before, source.stats, source.pairing)
    assert why.startswith("frames came from both cameras (left 61, right 50) but none paired: camera 'left' held "
                          "max_pending=8 frames waiting for 'right''s")
    assert "raise the rig URL's max_pending" in why


def test_a_latency_no_max_pending_can_hold_is_refused_naming_latency_fps_and_the_largest_that_pairs(sim_cache):
    # 10 s at 30 fps is 300 frames of lag, past the 256 frames max_pending holds at most: it opened, then timed out
    with pytest.raises(RigConfigError, match=r"latency_ms=10000 at fps=30 .* 300 frames .*max_pending holding at "
                                             r"most 256 .*largest latency that pairs is under 8533 ms"):
        open_rig(f"sim://?width=32&height=24&cache={sim_cache}&latency_ms=10000")


def test_a_latency_just_under_what_max_pending_holds_still_opens_and_pairs(sim_cache):
    source, _ = sim(sim_cache, "latency_ms=8520&max_pending=256")  # 255.6 frames: the first camera holds 256
    with source:
        pair = source.read(timeout_s=12.0)
    assert pair.frames[0].index == pair.frames[1].index == 0
