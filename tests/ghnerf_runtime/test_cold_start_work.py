"""The cold first pair's overhead done before it: the working volume's crop tables built with the estimator (and kept
outside the map cache's LRU), the skeleton prior's onnxruntime session run once at load (docs/runtime.md, "The cold
first pair")."""
from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from ghnerf_runtime import estimator as estimator_module
from ghnerf_runtime.config import EstimatorConfig, RoiConfig
from ghnerf_runtime.estimator import Estimator
from ghnerf_runtime.preprocess import Roi, build_undistort_crop_maps
from ghnerf_runtime.skeleton_prior import CONTEXT_FEATURES, INPUTS, JOINT_FEATURES, SkeletonPrior
from tests.ghnerf_runtime.test_session import tiny_model_dir, tiny_session  # noqa: F401  (fixtures)

sim = pytest.importorskip("drivers.sim")

#: the tiny model's random weights find nobody weakly: no turn search, whose turned crops would build tables too
NO_TURN_SEARCH = RoiConfig(turn_search=False)


@pytest.fixture(scope="module")
def rig_and_frames():
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    return rig, tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)


@pytest.fixture
def built_rois(monkeypatch):
    """The windows (camera name, roi) whose remap tables the estimator builds, in order."""
    built: list[tuple[str, Roi]] = []
    real = estimator_module.build_undistort_crop_maps

    def counting(camera, roi, *args, **kwargs):
        built.append((camera.name, roi))
        return real(camera, roi, *args, **kwargs)

    monkeypatch.setattr(estimator_module, "build_undistort_crop_maps", counting)
    return built


def _volume_windows(est: Estimator) -> list[tuple[str, Roi]]:
    return [(st.camera.name, roi) for st, roi in zip(est._cams, est.tracker.volume_regions.rois)]


def test_the_volume_window_is_built_with_the_estimator_not_by_the_first_pair(tiny_session, rig_and_frames,
                                                                              built_rois):
    rig, frames = rig_and_frames
    with Estimator(tiny_session, rig, EstimatorConfig(roi=NO_TURN_SEARCH)) as est:
        at_start = list(built_rois)
        result = est.estimate(frames, sequence=0)
        by_first_pair = built_rois[len(at_start):]
        assert not result.tracked  # the first pair is cold: it crops the working volume
        assert result.rois == dict(_volume_windows(est))
    assert at_start == _volume_windows(est)
    assert not set(by_first_pair) & set(at_start), by_first_pair


def test_the_volume_crops_terms_are_built_with_the_estimator_not_by_the_first_pair(tiny_session, rig_and_frames,
                                                                                        monkeypatch):
    """The two-view solver's (and the prior's) terms of the volume's crop cameras: every cold pass solves in them."""
    rig, frames = rig_and_frames
    built = []
    real = estimator_module._CropTerms.of
    monkeypatch.setattr(estimator_module._CropTerms, "of", lambda P, prior: built.append(P) or real(P, prior))
    asked = []
    real_for = Estimator._crop_terms_for
    monkeypatch.setattr(Estimator, "_crop_terms_for", lambda self, crops: asked.append(crops) or real_for(self, crops))
    with Estimator(tiny_session, rig, EstimatorConfig(roi=NO_TURN_SEARCH)) as est:
        (volume_P,) = built
        est.estimate(frames, sequence=0)
        est.reset()
        est.estimate(frames, sequence=1)  # cold again: after a track, its crops' terms the last ones
    assert asked, "the passes solved in no crop terms: the test shows nothing"
    assert all(not np.array_equal(P, volume_P) for P in built[1:]), len(built)


def test_a_cold_pair_after_a_long_track_finds_the_volume_window_built(tiny_session, rig_and_frames, built_rois):
    """Kept outside the LRU: the tracked windows that fill the map cache do not push it out."""
    rig, frames = rig_and_frames
    with Estimator(tiny_session, rig, EstimatorConfig(roi=replace(NO_TURN_SEARCH, map_cache_size=1))) as est:
        for k in range(3):  # tracked windows, each pushing the last out of a one-window cache
            for st in est._cams:
                est._crop(st, Roi(40 + 8 * k, 30, 160))
        del built_rois[:]
        est.estimate(frames, sequence=0)
        assert not set(built_rois) & set(_volume_windows(est)), built_rois


@pytest.mark.parametrize("roi_config", [NO_TURN_SEARCH, replace(NO_TURN_SEARCH, supersample=1),
                                        replace(NO_TURN_SEARCH, pad_fill="black"),
                                        replace(NO_TURN_SEARCH, volume_margin_m=0.4)])
@pytest.mark.parametrize("placement", [sim.RigPlacement(), sim.RigPlacement(distance_m=3.5)])
def test_the_built_volume_window_is_this_rig_s_and_this_config_s(tiny_session, roi_config, placement):
    """Each estimator builds its own rig's volume window with its own crop settings: the tables are the ones a
    first pair would have built (a rig, volume margin, supersampling or fill of another estimator's would differ)."""
    rig = placement.build()
    with Estimator(tiny_session, rig, EstimatorConfig(roi=roi_config)) as est:
        roi_cfg = est.config.roi  # (the pad fill resolved against the model)
        for st, roi in zip(est._cams, est.tracker.volume_regions.rois):
            assert list(st.cold) == [(roi, 0.0)]
            maps, crop = st.cold[roi, 0.0]
            fresh = build_undistort_crop_maps(st.camera, roi, est.size, roll_deg=st.crop_roll_deg,
                                              supersample=roi_cfg.supersample, pad_fill=roi_cfg.pad_fill,
                                              pad_fade=roi_cfg.pad_fade).compact()
            for field in fields(maps):
                assert _same(getattr(maps, field.name), getattr(fresh, field.name)), field.name
            assert est._crop(st, roi)[0] is maps
            np.testing.assert_array_equal(crop.P, est._build_crop(st, roi)[1].P)
        volume_P = np.stack([est._build_crop(st, roi)[1].P
                             for st, roi in zip(est._cams, est.tracker.volume_regions.rois)])
        assert est._volume_terms.two_view.is_for(volume_P)


def _same(a, b) -> bool:
    """Equal to the bit: arrays, tuples of them (OpenCV's fixed-point maps), None and plain values."""
    if isinstance(a, tuple):
        return isinstance(b, tuple) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.dtype == b.dtype and np.array_equal(a, b)
    return a == b


class _CountingRuns:
    """An onnxruntime session stand-in that records the batch of each run."""

    def __init__(self) -> None:
        self.batches: list[int] = []

    def run(self, names, feeds):
        features, context = (feeds[n] for n in INPUTS)
        assert features.shape[1:] == (25, JOINT_FEATURES) and context.shape[1:] == (CONTEXT_FEATURES,)
        self.batches.append(len(features))
        n = len(features)
        return np.zeros((n, 25, 3), np.float32), np.zeros((n, 25), np.float32)


def test_the_skeleton_prior_is_run_at_each_batch_the_estimator_runs_before_the_first_pair():
    """One pair with its mirror (joints3d.prior_flip_test) and without: onnxruntime's first run of a shape is the slow
    one (0.8-6 ms against 0.5 after in a one-off timing on session 68's host)."""
    runs = _CountingRuns()
    prior = SkeletonPrior(runs, None, {})
    assert prior.warm_up() >= 0.0
    assert sorted(runs.batches) == [1, 2]


def test_a_warmed_session_has_run_its_skeleton_prior(monkeypatch, tiny_session):
    warmed = []
    monkeypatch.setattr(SkeletonPrior, "warm_up", lambda self: warmed.append(self) or 1.0)
    monkeypatch.setattr(tiny_session, "skeleton_prior", SkeletonPrior(_CountingRuns(), None, {}))
    tiny_session.warm_up()
    assert warmed == [tiny_session.skeleton_prior] and tiny_session.warmup_ms["skeleton_prior"] == 1.0
