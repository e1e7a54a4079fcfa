"""The One Euro smoothing of the reported 3D joints: still joints steadied, fast ones barely delayed,
restarts on gaps, missing joints and time running backwards; its config validated; in the estimator it
smooths what is reported and leaves the tracker on the raw joints."""
from __future__ import annotations

import math
import re
import warnings

import numpy as np
import pytest

from ghnerf_runtime.config import MIN_CUTOFF_HZ, ConfigError, EstimatorConfig, Joints3DConfig, SmoothingConfig, \
    TrackingConfig, config_from_dict
from ghnerf_runtime.errors import FrameError, ShapeError
from ghnerf_runtime.smoothing import OneEuroJoints, smoothing_alpha

FPS = 30.0


def _run(filt, points, valid=None, fps=FPS):
    valid = np.ones(points.shape[:2], bool) if valid is None else valid
    return np.stack([filt(i / fps, p, v) for i, (p, v) in enumerate(zip(points, valid))])


def test_alpha_is_the_first_order_low_pass_factor():
    # tau = 1 / (2 pi fc); alpha = dt / (dt + tau): at fc = 1 / (2 pi dt), tau = dt, so a half
    dt = 1 / 30
    assert smoothing_alpha(1 / (2 * math.pi * dt), dt) == pytest.approx(0.5)
    assert smoothing_alpha(1e9, dt) == pytest.approx(1.0) and smoothing_alpha(1e-9, dt) < 1e-8


def test_a_still_joint_passes_exactly_and_noise_on_it_is_cut():
    still = np.tile(np.array([[0.1, -0.2, 3.0]]), (60, 25, 1))
    out = _run(OneEuroJoints(SmoothingConfig(enabled=True)), still)
    assert np.array_equal(out, still)
    noisy = still + np.random.default_rng(0).normal(0, 0.005, still.shape)  # 5 mm of noise per pair
    out = _run(OneEuroJoints(SmoothingConfig(enabled=True)), noisy)
    raw_err = np.linalg.norm(noisy[10:] - still[10:], axis=-1).mean()
    smooth_err = np.linalg.norm(out[10:] - still[10:], axis=-1).mean()
    assert smooth_err < 0.5 * raw_err, (smooth_err, raw_err)


def test_a_fast_joint_lags_little_with_beta_and_much_without():
    """A ramp at 2 m/s: the cutoff rises with the speed (beta), so the steady lag shrinks."""
    t = np.arange(60) / FPS
    ramp = np.zeros((60, 1, 3))
    ramp[:, 0, 0] = 2.0 * t
    lag = {}
    for beta in (0.0, 10.0):
        out = _run(OneEuroJoints(SmoothingConfig(enabled=True, beta=beta)), ramp)
        lag[beta] = float(np.abs(out[-1, 0, 0] - ramp[-1, 0, 0]))
    # beta 0: a 1 Hz low-pass, tau 0.16 s, so about 0.3 m behind; beta 10: about 21 Hz, a few centimetres
    assert lag[0.0] > 0.2 and lag[10.0] < 0.05 and lag[10.0] < 0.2 * lag[0.0], lag


def test_restarts_on_a_missing_joint_a_gap_and_time_going_back():
    cfg = SmoothingConfig(enabled=True, max_gap_s=0.25)
    f = OneEuroJoints(cfg)
    a, b = np.zeros((2, 3)), np.ones((2, 3))
    assert np.array_equal(f(0.0, a, np.ones(2, bool)), a)  # the first pair is reported as it is
    moved = f(1 / FPS, b, np.array([True, False]))
    assert 0 < moved[0, 0] < 1 and np.array_equal(moved[1], b[1])  # filtered / not reported: as given
    back = f(2 / FPS, b, np.ones(2, bool))
    assert back[0, 0] < 1 and np.array_equal(back[1], b[1])  # joint 1 returns: it restarts where it is
    assert np.array_equal(f(2 / FPS + 0.3, a, np.ones(2, bool)), a)  # a gap longer than max_gap_s
    assert np.array_equal(f(0.1, b, np.ones(2, bool)), b)  # time ran backwards (a restarted source)
    f.reset()
    assert np.array_equal(f(5.0, a, np.ones(2, bool)), a)
    # a broken timestamp (a driver's NaN) is no time to filter on: reported as given, never a NaN joint
    for t in (float("nan"), 5.0 + 1 / FPS, float("inf")):
        out = f(t, b, np.ones(2, bool))
        assert np.isfinite(out).all()
    assert np.array_equal(f(float("nan"), a, np.ones(2, bool)), a)
    assert np.array_equal(f(float("nan"), b, np.ones(2, bool)), b)


def test_the_config_is_validated_by_its_dotted_path():
    assert EstimatorConfig().smoothing.enabled  # on by default (it needs the pairs' capture times)
    assert config_from_dict({"smoothing": {"enabled": True, "beta": 3}}).smoothing.beta == 3
    for bad, key in (({"min_cutoff_hz": 0}, "smoothing.min_cutoff_hz"), ({"beta": -1}, "smoothing.beta"),
                     ({"max_gap_s": float("nan")}, "smoothing.max_gap_s"), ({"enabled": "yes"}, "smoothing.enabled"),
                     ({"bta": 3}, "smoothing.bta")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            config_from_dict({"smoothing": bad})


@pytest.mark.parametrize("key", ["min_cutoff_hz", "d_cutoff_hz"])
def test_a_cutoff_below_the_lowest_is_refused_and_the_lowest_filters_quietly(key):
    """A cutoff of 1e-310 Hz was taken: its time constant overflowed (numpy warned on every pair) and the filter
    held its first pair for the whole stream."""
    for tiny in (1e-310, 5e-324, MIN_CUTOFF_HZ / 2):
        with pytest.raises(ConfigError, match=rf"smoothing\.{key}.*got {tiny!r}"):
            config_from_dict({"smoothing": {key: tiny}})
    f = OneEuroJoints(SmoothingConfig(min_cutoff_hz=MIN_CUTOFF_HZ, d_cutoff_hz=MIN_CUTOFF_HZ, beta=1e4))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow on the device's log
        outs = [f(i / FPS, np.full((2, 3), 0.1 * i), np.ones(2, bool)) for i in range(5)]
    assert np.isfinite(outs).all() and 0 < outs[-1][0, 0] <= 0.4


def test_the_estimator_smooths_the_reported_joints_and_tracks_the_raw_ones():
    sim = pytest.importorskip("drivers.sim")
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    frames = []
    for i in range(4):
        rendered = [scene.render(c, i / FPS) for c in rig.pair]
        frames.append((tuple(img for img, _ in rendered), scene.joints_3d(i / FPS),
                       np.stack([tr.visible for _, tr in rendered])))
    runs = {}
    for enabled in (False, True):
        oracle = OracleSession(edge128_contract())
        cfg = EstimatorConfig(joints3d=Joints3DConfig(method="triangulate"),
                              smoothing=SmoothingConfig(enabled=enabled, beta=0.0),
                              tracking=TrackingConfig(refine_cold_start=False))  # the first pair reported cold
        est = Estimator(oracle, rig, cfg)
        out = []
        for i, (pair, truth, vis) in enumerate(frames):
            oracle.set_truth(truth, vis)
            r = est.estimate(pair, timestamp_s=i / FPS)
            out.append((r, est.tracker.track))
        runs[enabled] = out
    raw, smooth = runs[False], runs[True]
    assert np.array_equal(raw[0][0].joints_3d, smooth[0][0].joints_3d)  # nothing to smooth against yet
    # The cold pair 0 (cropped from the whole volume) is crude: the filter starts again at the tracked pair 1.
    assert not raw[0][0].tracked and raw[1][0].tracked
    assert np.array_equal(raw[1][0].joints_3d, smooth[1][0].joints_3d)
    for (r0, t0), (r1, t1) in zip(raw[2:], smooth[2:]):
        assert np.array_equal(r0.missing, r1.missing)
        found = ~r0.missing
        assert not np.allclose(r0.joints_3d[found], r1.joints_3d[found])  # smoothed (beta 0: a 1 Hz low-pass)
        assert not r1.joints_3d[~found].any()  # missing joints stay 0
        assert np.array_equal(t0.box, t1.box)  # the crop follows the raw joints either way
    # a pair without a capture time is reported raw and restarts the filter (no time to filter on)
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(joints3d=Joints3DConfig(method="triangulate"),
                                                 smoothing=SmoothingConfig(beta=0.0),
                                                 tracking=TrackingConfig(refine_cold_start=False)))
    for i, (pair, truth, vis) in enumerate(frames):
        oracle.set_truth(truth, vis)
        r = est.estimate(pair, timestamp_s=i / FPS if i != 1 else None)
        if i in (1, 2):  # the timeless pair, and the first after it (a fresh start)
            assert np.array_equal(r.joints_3d, raw[i][0].joints_3d)
        else:
            assert np.array_equal(r.joints_3d, smooth[i][0].joints_3d) == (i == 0)
    # without tracking every pair is cold: smoothing still runs (it restarts only on the step to a tracked pair)

    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(joints3d=Joints3DConfig(method="triangulate"),
                                                 smoothing=SmoothingConfig(beta=0.0),
                                                 tracking=TrackingConfig(enabled=False)))
    untracked = []
    for i, (pair, truth, vis) in enumerate(frames):
        oracle.set_truth(truth, vis)
        untracked.append(est.estimate(pair, timestamp_s=i / FPS))
    assert not any(r.tracked for r in untracked)
    raw_cold = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(
        joints3d=Joints3DConfig(method="triangulate"), smoothing=SmoothingConfig(enabled=False),
        tracking=TrackingConfig(enabled=False)))
    for i, (pair, truth, vis) in enumerate(frames):
        raw_cold.session.set_truth(truth, vis)
        r = raw_cold.estimate(pair, timestamp_s=i / FPS)
        assert np.array_equal(r.joints_3d, untracked[i].joints_3d) == (i == 0)


def test_a_pair_at_the_same_instant_again_keeps_the_state():
    """The estimator keeps its track for a pair of the last pair's time (the same frames estimated again); the
    filter restarted there, reporting the raw joint and forgetting the smoothing for the pairs after."""
    f, g = OneEuroJoints(SmoothingConfig(beta=0.0)), OneEuroJoints(SmoothingConfig(beta=0.0))
    ok = np.ones(2, bool)
    a, b = np.zeros((2, 3)), np.full((2, 3), 0.1)
    for filt in (f, g):
        filt(0.0, a, ok)
    first = f(1 / FPS, b, ok)
    assert 0 < first[0, 0] < 0.1
    g(1 / FPS, b, ok)
    again = f(1 / FPS, b, np.array([True, False]))  # joint 1 not reported this time: as given, no state kept
    assert np.array_equal(again[0], first[0]) and np.array_equal(again[1], b[1])
    after_f, after_g = f(2 / FPS, b, ok), g(2 / FPS, b, ok)
    assert np.array_equal(after_f[0], after_g[0])  # as if the repeat had not been
    assert np.array_equal(after_f[1], b[1])  # joint 1 restarts where it comes back


def test_a_joint_that_moved_at_the_same_instant_restarts_there_and_never_freezes():
    """A clock that does not tick between captures (a coarse clock, a caller's constant stamp): answered from the
    state, every joint stayed where the first pair of that instant put it, however far the subject went."""
    f = OneEuroJoints(SmoothingConfig())
    ok = np.ones(2, bool)
    f(0.0, np.zeros((2, 3)), ok)
    for i in range(1, 6):
        walked = np.zeros((2, 3))
        walked[0, 0] = 0.1 * i  # joint 0 walks 0.1 m a pair, joint 1 stands still
        out = f(0.0, walked, ok)
        assert np.array_equal(out, walked), (i, out)  # the moved joint as given; the still one is its state (0)
    # the clock ticks again: filtered from where the joint was last given, not from the first pair
    on = f(1 / FPS, np.array([[0.52, 0.0, 0.0], [0.0, 0.0, 0.0]]), ok)
    assert 0.5 < on[0, 0] < 0.52 and np.array_equal(on[1], np.zeros(3))


def test_the_estimator_follows_a_walking_subject_whose_pairs_share_one_stamp():
    sim = pytest.importorskip("drivers.sim")
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator

    rig = sim.RigPlacement().build()
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig())
    for i in range(4):
        scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.15 * i, 3.0)))
        rendered = [scene.render(c, i / FPS) for c in rig.pair]
        truth = scene.joints_3d(i / FPS)
        oracle.set_truth(truth, np.stack([tr.visible for _, tr in rendered]))
        r = est.estimate(tuple(img for img, _ in rendered), timestamp_s=0.0)
        found = ~r.missing
        err = np.linalg.norm(r.joints_3d[found] - truth[found], axis=-1)
        assert r.num_found > 6 and err.max() < 0.01, (i, err.max())  # the oracle's joints are exact; frozen: 0.45 m


def test_a_non_finite_joint_or_an_overflowing_jump_does_not_poison_the_state():
    from ghnerf_runtime.config import SmoothingConfig

    f = OneEuroJoints(SmoothingConfig())
    x = np.zeros((2, 3))
    ok = np.ones(2, bool)
    f(0.0, x, ok)
    bad = x.copy()
    bad[0] = np.nan
    f(0.033, bad, ok)  # reported as valid, but NaN: not taken into the state
    out = f(0.066, x + 0.01, ok)
    assert np.isfinite(out).all()
    jump = x.copy()
    jump[1] = 1e308
    f(0.1, jump, ok)
    out = f(0.133, x, ok)
    assert np.isfinite(out).all() and np.abs(out).max() < 1.0


@pytest.mark.parametrize("refine", [False, True])
def test_a_subject_found_again_from_the_working_volume_is_not_pulled_toward_the_lost_track(refine):
    """tracking.retry_cold: the tracked crop found nobody (the subject left it) and the working volume's crop
    found someone 1.3 m away, in the same pair (then, with refine_cold_start, cropped around them). That pair
    is reported as it is, as the first pair of any (re)acquisition is: smoothed from the lost track it lagged
    ~8 cm behind, toward where nobody is."""
    sim = pytest.importorskip("drivers.sim")
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.config import TrackingConfig
    from ghnerf_runtime.estimator import Estimator

    rig = sim.RigPlacement().build()
    here = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    there = sim.SimScene(sim.SceneConfig(seed=3, motion="wave", position_xz=(1.1, 2.4)))
    clip = []
    for i, scene in enumerate((here, here, here, there)):
        rendered = [scene.render(c, i / FPS) for c in rig.pair]
        clip.append((tuple(img for img, _ in rendered), scene.joints_3d(i / FPS),
                     np.stack([tr.visible for _, tr in rendered])))
    out = {}
    for enabled in (False, True):
        oracle = OracleSession(edge128_contract())
        est = Estimator(oracle, rig, EstimatorConfig(smoothing=SmoothingConfig(enabled=enabled),
                                                     tracking=TrackingConfig(refine_cold_start=refine)))
        out[enabled] = []
        for i, (pair, truth, vis) in enumerate(clip):
            oracle.set_truth(truth, vis)
            out[enabled].append(est.estimate(pair, timestamp_s=i / FPS))
    raw, smooth = out[False], out[True]
    assert raw[2].tracked and raw[3].tracked == refine and raw[3].num_found > 6  # found again, in the same pair
    assert not np.allclose(raw[2].joints_3d, smooth[2].joints_3d)  # the tracked pairs were smoothed
    assert np.array_equal(smooth[3].joints_3d, raw[3].joints_3d)


@pytest.mark.parametrize("points, valid", [(np.zeros(3), np.ones(3, bool)), (np.zeros((4, 3)), np.ones(2, bool)),
                                           (np.zeros((4, 2)), np.ones(4, bool))])
def test_points_and_valid_of_the_wrong_shape_are_refused(points, valid):
    """(3,) points were taken for three joints and came back (3, 3) from the second pair on."""
    f = OneEuroJoints(SmoothingConfig())
    with pytest.raises(ShapeError, match=r"points \(J, 3\)"):
        f(0.0, points, valid)
        f(1 / FPS, points, valid)


@pytest.mark.parametrize("dt", [5e-324, 1e-310, 1e-300])
def test_a_tiny_step_of_time_warns_of_nothing_and_is_the_filter_s_limit(dt):
    """A step of 5e-324 s overflowed the velocity (step / dt) and tau / dt: numpy warned on the device's log, the
    joint restarted at its raw place (5e-324 s) or lost its speed (1e-310 s), unlike any other small step. Now
    every tiny step answers the limit of the filter as dt goes to 0 (the state), and the next pair as after any."""
    import warnings

    ok = np.ones(2, bool)
    a, b, c = np.zeros((2, 3)), np.full((2, 3), 0.01), np.full((2, 3), 0.02)
    f, ref = OneEuroJoints(SmoothingConfig()), OneEuroJoints(SmoothingConfig())
    f(0.0, a, ok)
    ref(0.0, a, ok)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tiny = f(dt, b, ok)
        after = f(1 / FPS, c, ok)
    np.testing.assert_allclose(tiny, a, atol=1e-12)
    ref(1e-12, b, ok)  # a small step of time that never overflowed
    np.testing.assert_allclose(after, ref(1 / FPS, c, ok), rtol=1e-9)


def test_a_jump_near_the_float_range_restarts_the_joint_without_a_warning():
    """The overflowing jump (test above) restarted the joint as meant, but numpy warned of the overflow first."""
    import warnings

    f = OneEuroJoints(SmoothingConfig())
    x, ok = np.zeros((2, 3)), np.ones(2, bool)
    f(0.0, x, ok)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        up = f(0.1, x + 1e308, ok)
        down = f(0.2, x - 1e308, ok)
        back = f(0.3, x, ok)
    assert np.array_equal(up, x + 1e308) and np.array_equal(down, x - 1e308) and np.array_equal(back, x)


@pytest.mark.parametrize("seed", range(4))
def test_a_hostile_stream_never_poisons_the_state_and_a_clean_one_recovers(seed):
    """Property sweep (clock skew, corrupt joints): stamps that repeat, step back, jump by hours or 1e300 s, are
    denormal apart, NaN or infinite, and joints that are NaN, infinite, 1e308 or denormal, each reported valid or
    not. The filter warns of nothing, answers every finite reported joint finitely, and a clean 30 Hz stream
    afterwards brings a still joint back to its place with a finite state."""
    rng = np.random.default_rng(seed)
    stamps = [np.nan, np.inf, -np.inf, -1.0, 1e300, -1e300, 5e-324, 3600.0]
    values = [np.nan, np.inf, -np.inf, 1e308, -1e308, 1e-300, 0.0]
    for beta, max_gap_s in ((0.0, 0.25), (10.0, 60.0), (1e4, 1e-6)):
        f = OneEuroJoints(SmoothingConfig(beta=beta, max_gap_s=max_gap_s))
        t = 0.0
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            for _ in range(60):
                draw = rng.uniform()
                if draw < 0.25:
                    stamp = float(rng.choice(stamps))
                elif draw < 0.35:
                    stamp = t  # the same instant again
                else:
                    stamp = t + float(rng.choice([1 / FPS, 1e-12, 0.3, -0.1]))
                t = stamp if math.isfinite(stamp) else t
                points = rng.normal(0.0, 1.0, (5, 3))
                hostile = rng.uniform(size=points.shape) < 0.15
                points[hostile] = rng.choice(values, int(hostile.sum()))
                valid = rng.uniform(size=5) < 0.8
                out = f(stamp, points, valid)
                reported = valid & np.isfinite(points).all(axis=-1)
                assert np.isfinite(out[reported]).all()
            still = np.ones((5, 3))
            for _ in range(90):
                t += 1 / FPS
                out = f(t, still, np.ones(5, bool))
        np.testing.assert_allclose(out, still, atol=1e-4)
        assert np.isfinite(f._x).all() and np.isfinite(f._dx).all() and math.isfinite(f._t)


def test_no_capture_time_reports_the_joints_raw_and_restarts_the_filter():
    """``t_s=None`` is the estimator's "no capture time" (a still image): raw joints, every joint restarted; it
    was a bare TypeError from ``float(None)``."""
    f = OneEuroJoints(SmoothingConfig())
    ok = np.ones(2, bool)
    f(0.0, np.zeros((2, 3)), ok)
    jumped = np.full((2, 3), 0.05)
    np.testing.assert_array_equal(f(None, jumped, ok), jumped)
    np.testing.assert_array_equal(f(1 / FPS, np.zeros((2, 3)), ok), np.zeros((2, 3)))  # restarted: raw again


@pytest.mark.parametrize("bad", ["0.5", True, b"1", [0.1], 10**400],  # 10**400: a bare OverflowError
                         ids=["text", "bool", "bytes", "list", "int-past-float64"])
def test_a_time_that_is_no_number_is_a_frame_error_naming_it(bad):
    with pytest.raises(FrameError, match=re.escape(repr(bad))):
        OneEuroJoints(SmoothingConfig())(bad, np.zeros((2, 3)), np.ones(2, bool))
