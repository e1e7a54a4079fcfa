"""Estimator geometry, tracking and missing-joint behaviour against the *oracle* session.

The oracle (benchmarks/bench_runtime_common.py) answers each graph with what a perfectly
trained model is trained to produce, from the simulator's truth, so these tests check
everything around the model exactly -- crops, decoding, coordinate mapping, 3D methods,
tracking -- without torch or a trained model.
"""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from benchmarks.bench_runtime_common import OracleSession, edge128_contract
from benchmarks.empty_rooms import empty_room_pair
from ghnerf_runtime.config import ConfigError, EstimatorConfig, FrameCheckConfig, HeatmapsConfig, Joints3DConfig, \
    NovelViewConfig, PresenceConfig, TrackingConfig, config_from_dict
from ghnerf_runtime.errors import ModelRunError
from ghnerf_runtime.estimator import NOVEL_STAGES, Estimator, check_crop
from ghnerf_runtime import estimator as estimator_module
from ghnerf_runtime.novel_view import NovelViewRequest
from ghnerf_runtime.metrics import mpjpe, pck
from ghnerf_runtime.preprocess import preprocess_image
from tests.one_camera import seen_by

sim = pytest.importorskip("drivers.sim")


class RayCounter(OracleSession):
    """The oracle, also recording the ray count of every render_heat call."""

    def __init__(self):
        super().__init__(edge128_contract())
        self.rays: list[int] = []

    def run(self, graph, feeds):
        if graph == "render_heat":
            self.rays.append(int(np.shape(feeds["ray_uv"])[1]))
        return super().run(graph, feeds)


@pytest.fixture(scope="module")
def clip():
    """A short clip of a person in view, then the same room without anyone (the scene's room with its person left
    out: a textured room, which the frame check passes; moving the person away took the room along, black frames)."""
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    frames, truth, visible, twod = [], [], [], []
    for i in range(5):
        t = i / 30
        rendered = [scene.render(c, t) for c in rig.pair]
        frames.append(tuple(img for img, _ in rendered))
        truth.append(scene.joints_3d(t))
        visible.append(np.stack([tr.visible for _, tr in rendered]))
        twod.append(np.stack([tr.joints_2d for _, tr in rendered]))
    empty = empty_room_pair(rig, scene.config.seed, 0.2)
    return rig, frames, truth, visible, empty, twod


#: The tests that watch a cold pair itself (reported cold, then tracked) keep it unrefined: refined (the default
#: since session 48) the pair reports its second, tracked pass.
COLD = TrackingConfig(refine_cold_start=False)


def _run(est, oracle, frames, truth, visible):
    out = []
    for pair, j3, vis in zip(frames, truth, visible):
        oracle.set_truth(j3, vis)
        out.append(est.estimate(pair))
    return out


RENDERED = HeatmapsConfig(source="rendered")


@pytest.mark.parametrize("source, flip", [("encoder", False), ("encoder", True), ("rendered", False)])
def test_triangulation_is_exact_on_oracle_heatmaps_and_tracking_engages(clip, source, flip):
    """Also with the flip test: the oracle's view of the mirrored crops (mirrored cameras see the mirror
    person, left and right swapped) comes back exactly onto the joints."""
    rig, frames, truth, visible, *_ = clip
    oracle = RayCounter()
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(source=source, flip_test=flip),
                                                 joints3d=Joints3DConfig(method="triangulate"), tracking=COLD))
    results = _run(est, oracle, frames, truth, visible)
    assert [r.tracked for r in results] == [False, True, True, True, True]
    both = np.stack(visible).all(axis=1)  # joints the oracle shows in both views
    pred = np.stack([r.joints_3d for r in results])
    found = ~np.stack([r.missing for r in results])
    assert np.array_equal(found, both), "exactly the joints visible in both views are triangulated"
    err = mpjpe(pred, np.stack(truth), both, pred_valid=found)
    assert err.value < 1.0, err.value  # mm: decoding + mapping + DLT are exact for Gaussian heatmaps
    if source == "encoder":  # the encoder's heatmaps cover the crop: nothing is rendered
        assert oracle.rays == [] and oracle.run_counts["volume"] == 0
        assert oracle.run_counts["encoder"] == len(frames) * (2 if flip else 1)
        return
    # Tracked pairs render only the rays covering the subject, fewer than the whole grid.
    grid = (oracle.contract.height // oracle.contract.heatmap_stride) ** 2
    assert oracle.rays[0] == grid and max(oracle.rays[1:]) < grid


class FeedRecorder(OracleSession):
    """The oracle, also recording the names of the feeds each graph run was handed."""

    def __init__(self):
        super().__init__(edge128_contract())
        self.feeds: list[tuple[str, frozenset]] = []

    def run(self, graph, feeds):
        self.feeds.append((graph, frozenset(feeds)))
        return super().run(graph, feeds)


#: The feeds of the cost volume's and the rendering's graphs besides the images and ``src_P``.
VOLUME_FEEDS = {"src_centers", "tgt_K_inv", "tgt_c2w", "near_far"}


def test_a_keypoint_pass_builds_no_feeds_for_a_volume_it_does_not_build(clip):
    """The encoder heatmaps' path (the default) runs the keypoint graph alone, on the crops and their ``src_P``
    (the oracle reads the cameras), cold and tracked, mirrored or not: the volume's camera feeds (``src_centers``,
    the sources as targets, ``near_far``: about 0.2 ms a pass) are not built for it, as they were on every pass. A
    pass that builds a volume (rendered heatmaps) hands them to its graphs as before."""
    rig, frames, truth, visible, *_ = clip
    for source, flip in (("encoder", True), ("encoder", False), ("rendered", False)):
        oracle = FeedRecorder()
        est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(source=source, flip_test=flip),
                                                     joints3d=Joints3DConfig(method="triangulate")))
        results = _run(est, oracle, frames, truth, visible)
        assert results[-1].tracked and not results[-1].missing.all()
        keypoint_feeds = {names for graph, names in oracle.feeds if graph == "encoder"}
        if source == "encoder":
            assert keypoint_feeds == {frozenset({"images", "src_P"})}, (source, flip, keypoint_feeds)
            assert {graph for graph, _ in oracle.feeds} == {"encoder"}
        else:
            assert all(VOLUME_FEEDS <= names for graph, names in oracle.feeds if graph != "encoder")
            assert {graph for graph, _ in oracle.feeds} >= {"volume", "render_heat"}


def test_2d_joints_land_on_the_truth_in_the_original_images(clip):
    rig, frames, truth, visible, *_, twod = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig)
    oracle.set_truth(truth[0], visible[0])
    r = est.estimate(frames[0])
    pred = np.stack([r.joints_2d[n] for n in rig.names[:2]])
    res = pck(pred, twod[0], visible[0], pred_valid=~np.stack([r.missing_2d[n] for n in rig.names[:2]]))
    assert res.value == 1.0 and res.num_pred_missing == 0
    d = np.linalg.norm(pred - twod[0], axis=-1)[visible[0]]
    assert d.max() < 0.5, d.max()  # pixels of the 640x480 image


# The oracle's depth is a heatmap-weighted mix of nearby joints' depths, not a body surface: the
# depth centroid's tolerance reflects the oracle, not the method.
@pytest.mark.parametrize("method, tol_mm", [("volumetric", 5.0), ("depth_centroid", 150.0)])
def test_other_3d_methods_on_the_oracle(clip, method, tol_mm):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(joints3d=Joints3DConfig(method=method)))
    results = _run(est, oracle, frames, truth, visible)
    pred = np.stack([r.joints_3d for r in results])
    found = ~np.stack([r.missing for r in results])
    err = mpjpe(pred, np.stack(truth), np.ones_like(found), pred_valid=found)
    assert err.num_evaluated > 50 and err.value < tol_mm, (err.value, err.num_evaluated)


@pytest.mark.parametrize("left_behind", ["textured room", "black frames"])
def test_person_leaving_the_view_gives_missing_joints_and_drops_the_track(clip, left_behind):
    """The person leaves: the room they leave (the model finds nobody in it), or black frames (a covered rig: the
    frame check rejects them before the model runs)."""
    rig, frames, truth, visible, empty, _ = clip
    if left_behind == "black frames":
        empty = tuple(np.zeros_like(image) for image in empty)
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=COLD))
    first = _run(est, oracle, frames[:2], truth[:2], visible[:2])
    assert first[-1].num_found > 6 and est.tracker.track is not None
    oracle.set_truth(None)  # nobody in view
    gone = est.estimate(empty)
    assert gone.missing.all() and not gone.joints_3d.any() and not gone.confidence.any()
    assert all(m.all() for m in gone.missing_2d.values())
    # the tracked crops found nobody (or were rejected): the working volume was looked at in the same pair
    # (tracking.retry_cold), nobody there either, and the track is dropped
    assert gone.tracked is False and est.tracker.track is None
    assert all(gone.frame_ok.values()) == (left_behind == "textured room"), gone.frame_reason
    assert any(gone.frame_ok.values()) == (left_behind == "textured room"), gone.frame_reason
    cold = est.estimate(empty)
    assert cold.tracked is False and cold.missing.all()  # fell back to the working volume
    back = _run(est, oracle, frames[2:4], truth[2:4], visible[2:4])
    assert back[0].tracked is False and back[1].tracked is True and back[1].num_found > 6


def test_no_stale_joints_after_a_good_pair(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig)
    good = _run(est, oracle, frames[:1], truth[:1], visible[:1])[0]
    assert good.num_found > 6
    black = np.zeros_like(frames[0][0])
    r = est.estimate((black, black))  # oracle still "sees" the truth: the frame check must stop it
    assert r.missing.all() and not r.joints_3d.any() and est.tracker.track is None
    oracle.set_truth(None)  # nobody: the model renders nothing
    r2 = est.estimate(frames[1])
    assert r2.missing.all() and not np.isin(r2.joints_3d, good.joints_3d[~good.missing]).any()
    assert r2.tracked is False


def test_too_few_confident_joints_drop_the_track(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(min_joints=6, refine_cold_start=False),
                                                 presence=PresenceConfig(enabled=False),
                                                 joints3d=Joints3DConfig(method="triangulate")))
    _run(est, oracle, frames[:1], truth[:1], visible[:1])
    assert est.tracker.track is not None
    few = np.zeros_like(visible[1])
    few[:, :4] = True  # only 4 joints shown in both views
    oracle.set_truth(truth[1], few)
    r = est.estimate(frames[1])
    assert r.num_found == 4 and r.tracked is True and est.tracker.track is None
    oracle.set_truth(truth[2], visible[2])
    assert est.estimate(frames[2]).tracked is False


def test_presence_gate_reports_nobody_for_too_few_strong_joints(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(presence=PresenceConfig(min_joints=6)))
    _run(est, oracle, frames[:1], truth[:1], visible[:1])
    assert est.tracker.track is not None
    few = np.zeros_like(visible[1])
    few[:, :4] = True  # 4 strong joints: below min_joints, so nobody (2D joints too)
    oracle.set_truth(truth[1], few)
    r = est.estimate(frames[1])
    assert r.num_found == 0 and est.tracker.track is None
    assert all(r.missing_2d[n].all() and not r.joints_2d[n].any() for n in rig.names[:2])
    # every joint shown, but a threshold above the oracle's peaks: nobody either
    strict = Estimator(oracle, rig, EstimatorConfig(presence=PresenceConfig(min_confidence=1.0)))
    oracle.set_truth(truth[2], visible[2])
    assert strict.estimate(frames[2]).num_found == 0
    with pytest.raises(ConfigError, match="presence.min_joints"):
        config_from_dict({"presence": {"min_joints": 0}})


def test_tracking_disabled_always_uses_the_working_volume(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = RayCounter()
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(enabled=False)))
    results = _run(est, oracle, frames[:3], truth[:3], visible[:3])
    assert not any(r.tracked for r in results)
    assert len({r.rois[rig.names[0]] for r in results}) == 1


def test_refined_cold_start_reruns_the_first_pair_on_the_subject(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = RayCounter()
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(refine_cold_start=True), heatmaps=RENDERED,
                                                 joints3d=Joints3DConfig(method="triangulate")))
    results = _run(est, oracle, frames[:2], truth[:2], visible[:2])
    assert [r.tracked for r in results] == [True, True]  # the first pair is reported from its second pass
    assert oracle.run_counts["render_heat"] == 3 and oracle.run_counts["encoder"] == 3
    grid = (oracle.contract.height // oracle.contract.heatmap_stride) ** 2
    assert oracle.rays[0] == grid and oracle.rays[1] < grid
    err = mpjpe(results[0].joints_3d, truth[0], visible[0].all(axis=0), pred_valid=~results[0].missing)
    assert err.value < 1.0


class ThreadRecorder(OracleSession):
    """The oracle, recording which thread ran each graph; optionally failing one graph."""

    def __init__(self, fail: str | None = None):
        super().__init__(edge128_contract())
        self.threads: list[tuple[str, str]] = []
        self.fail = fail

    def run(self, graph, feeds):
        self.threads.append((graph, threading.current_thread().name))
        if graph == self.fail:
            raise ModelRunError(f"graph {graph!r} failed: injected")
        return super().run(graph, feeds)


def _novel_run(clip, overlap: bool, session=None):
    rig, frames, truth, visible, *_ = clip
    oracle = session or ThreadRecorder()
    cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, overlap=overlap), tracking=COLD)
    with Estimator(oracle, rig, cfg) as est:
        out = []
        for pair, j3, vis in zip(frames, truth, visible):
            oracle.set_truth(j3, vis)
            out.append(est.estimate(pair, novel_view=NovelViewRequest(alpha=0.5, overlay="skeleton")))
    return out, oracle.threads


def _novel_workers() -> set[threading.Thread]:
    return {t for t in threading.enumerate() if t.name.startswith("ghnerf-novel-view")}


def test_novel_view_overlap_renders_in_the_worker_and_changes_no_joint(clip):
    # An earlier test's estimator left for the garbage collector may still hold its worker: only this test's count
    earlier = _novel_workers()
    on, on_threads = _novel_run(clip, overlap=True)
    off, off_threads = _novel_run(clip, overlap=False)
    for a, b in zip(on, off):
        np.testing.assert_array_equal(a.joints_3d, b.joints_3d)
        np.testing.assert_array_equal(a.confidence, b.confidence)
        np.testing.assert_array_equal(a.missing, b.missing)
    main = threading.main_thread().name
    worker = {g for g, t in on_threads if t != main}
    assert worker == {"volume", "render_rgb"}  # the novel camera's volume and the colour passes
    assert all(t.startswith("ghnerf-novel-view") for g, t in on_threads if t != main)
    assert all(t == main for _, t in off_threads)
    # The cold first pair renders after its keypoints (on the main thread), every tracked pair in the worker.
    assert [r.tracked for r in on] == [False] + [True] * (len(on) - 1)
    worker_volumes = sum(1 for g, t in on_threads if g == "volume" and t != main)
    assert worker_volumes == len(on) - 1
    for r in on + off:  # the subject is in every view (the oracle paints it around the joints)
        nv = r.novel_view
        assert nv is not None and nv.rays > 0 and (nv.image > 0).any()
        assert set(NOVEL_STAGES) <= set(r.timing_ms)
    assert not _novel_workers() - earlier  # closed


def test_close_stops_the_novel_view_worker_before_it_returns(clip, monkeypatch):
    """``close()`` shuts the worker down and joins its thread. The test keeps the estimator and its executor
    referenced, so the garbage collector cannot end the thread in ``close()``'s place: the overlap test above
    passed with the shutdown taken out of ``close()``, the executor it dropped ending its thread soon after."""
    import ghnerf_runtime.estimator as estimator_module

    made: list[ThreadPoolExecutor] = []

    class KeptExecutor(ThreadPoolExecutor):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(estimator_module, "ThreadPoolExecutor", KeptExecutor)
    rig, frames, truth, visible, *_ = clip
    oracle = ThreadRecorder()
    est = Estimator(oracle, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True, overlap=True),
                                                 tracking=COLD))
    earlier = _novel_workers()
    try:
        for pair, j3, vis in zip(frames[:2], truth[:2], visible[:2]):  # the tracked second pair uses the worker
            oracle.set_truth(j3, vis)
            est.estimate(pair, novel_view=NovelViewRequest())
        started = _novel_workers() - earlier
        assert len(made) == 1 and len(started) == 1
        est.close()
        assert not [t.name for t in started if t.is_alive()]  # joined, not left to end later
        with pytest.raises(RuntimeError, match="after shutdown"):
            made[0].submit(int)
    finally:
        for executor in made:  # a failed check leaves no thread behind for later tests
            executor.shutdown(wait=True)


def test_a_failing_novel_view_in_the_worker_is_raised_and_the_estimator_goes_on(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = ThreadRecorder(fail="render_rgb")
    est = Estimator(oracle, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True)))
    oracle.set_truth(truth[0], visible[0])
    est.estimate(frames[0])  # tracks the subject: the next novel view goes to the worker
    oracle.set_truth(truth[1], visible[1])
    with pytest.raises(ModelRunError, match="injected"):
        est.estimate(frames[1], novel_view=NovelViewRequest())
    assert any(t.startswith("ghnerf-novel-view") for g, t in oracle.threads if g == "render_rgb")
    oracle.set_truth(truth[2], visible[2])
    r = est.estimate(frames[2])
    assert r.num_found > 20 and r.novel_view is None
    est.close()
    est.close()  # idempotent


def test_a_pair_that_finds_nobody_renders_no_novel_view(clip):
    """An empty room (one the frame check passes: a textured wall) with a novel view requested on every pair:
    there is no subject to view, so no novel-view graph runs and the pair has none. Before, each such pair
    built the novel camera's volume and rendered the working volume's box for nothing, the dearest thing an
    empty room cost."""
    rig, frames, truth, visible, *_ = clip
    oracle = ThreadRecorder()
    cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True), tracking=TrackingConfig(retry_cold=False))
    request = NovelViewRequest(alpha=0.5, overlay="skeleton")
    with Estimator(oracle, rig, cfg) as est:
        oracle.set_truth(None)  # the model sees nobody in the (textured) frames
        for k in range(3):
            r = est.estimate(frames[k], novel_view=request)
            assert all(r.frame_ok.values()) and r.missing.all() and r.novel_view is None
        assert not {g for g, _ in oracle.threads} & {"volume", "render", "render_rgb"}
        for k in (3, 4):  # someone comes in: viewed from the first pair on
            oracle.set_truth(truth[k], visible[k])
            r = est.estimate(frames[k], novel_view=request)
            assert r.num_found > 6 and r.novel_view is not None and (r.novel_view.image > 0).any()
        oracle.set_truth(None)  # and leaves: the tracked pass (its view started in the worker) finds nobody
        r = est.estimate(frames[0], novel_view=request)
        assert r.tracked and r.missing.all() and r.novel_view is None
        assert not set(NOVEL_STAGES) & set(r.timing_ms)


def test_an_empty_room_takes_the_heatmap_maxima_once_for_the_flip_test_and_once_for_the_turn_search(clip,
                                                                                                    monkeypatch):
    """A pair that shows nobody asks its heatmaps' per-joint maxima whether to run the flip test's mirrored crops (of
    both views, and of each alone: one camera's 2D joints are answered) and whether to search the crop turns (of each
    view): one taking of the maxima for each of the two, the same answers. Before, each view asked took them again:
    five times a pair, about 0.3 ms of an empty room's 5."""
    import ghnerf_runtime.estimator as estimator_module
    from ghnerf_runtime import flip_test

    taken = []

    def counted(name):
        def wrapper(*args, **kwargs):
            taken.append(name)
            return getattr(flip_test, name)(*args, **kwargs)
        return wrapper

    for name in ("joint_peaks", "presence_peak"):  # (the code before this change had presence_peak alone)
        monkeypatch.setattr(estimator_module, name, counted(name), raising=False)
    rig, frames, *_ = clip
    oracle = FeedRecorder()
    est = Estimator(oracle, rig, EstimatorConfig())
    oracle.set_truth(None)  # the model sees nobody in the (textured) frames
    for pair in frames[:3]:
        taken.clear()
        r = est.estimate(pair)
        assert all(r.frame_ok.values()) and r.missing.all() and "turn_search" not in r.timing_ms
        assert taken == ["joint_peaks", "joint_peaks"], taken
    assert oracle.run_counts["encoder"] == 3  # nobody: no mirrored run, no turn searched


@pytest.mark.parametrize("source, flip", [("encoder", True), ("encoder", False), ("rendered", False)])
def test_a_person_seen_by_one_camera_only_gets_that_cameras_2d_joints(clip, source, flip):
    """Someone entering at the edge of one camera's view, outside the other's: both frames pass the check and
    the model runs; one view has no depth, so no 3D joint, but the camera that sees them reports its 2D joints
    (its own encoder heatmaps pass the per-view presence rule, as a rejected frame's other view does), and
    ``single_view`` names it. The other camera's 2D joints are zeros with ``missing_2d`` set; no novel view;
    that camera's next crop follows its joints (the view track). Before session 53 every joint was missing.
    The view gets the flip test's mirrored run (with the encoder source) as a two-view pair with someone does;
    the pair's geometric mean alone (one view empty) skipped it."""
    rig, frames, truth, visible, _, twod = clip
    oracle = OracleSession(edge128_contract())
    cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True), heatmaps=HeatmapsConfig(source, flip_test=flip),
                          joints3d=Joints3DConfig(method="triangulate"))
    est = Estimator(oracle, rig, cfg)
    names = est.camera_names
    for k in (0, 1):
        oracle.set_truth(truth[0], seen_by(visible[0], k))
        runs = oracle.run_counts["encoder"]
        est.reset()
        r = est.estimate(frames[0], novel_view=NovelViewRequest(alpha=0.5))
        assert oracle.run_counts["encoder"] > runs and r.frame_ok == {n: True for n in names}
        assert r.frame_reason == {n: None for n in names}  # both frames were fine: not a rejected frame
        assert r.single_view == names[k] and r.novel_view is None
        assert r.missing.all() and not r.joints_3d.any() and not r.confidence.any()
        # one view's peaks meet nothing in the other: no agreement to measure, nothing for the calibration check
        assert r.reprojection_px_median is None
        other = names[1 - k]
        assert r.missing_2d[other].all() and not r.joints_2d[other].any() and not r.confidence_2d[other].any()
        found = ~r.missing_2d[names[k]]
        assert found.sum() >= 0.9 * visible[0][k].sum() and not (found & ~visible[0][k]).any()
        err = np.linalg.norm(r.joints_2d[names[k]][found] - twod[0][k][found], axis=-1)
        assert err.max() < 1.5, err  # the oracle's heatmaps: exact up to the grid's decoding
        assert ("encoder_flip" in r.timing_ms) == (source == "encoder" and flip), r.timing_ms
        assert est.tracker.track is None and est.tracker.view_track is not None and est.tracker.view_track[0] == k
        # both frames passed: the other camera's next crop looks along the seen joints' rays (session 69), not at
        # the whole volume, and holds the joints seen
        crop = est.tracker.regions().rois[1 - k]
        assert crop.size < est.tracker.volume_regions.rois[1 - k].size, crop
        uv = rig.pair[1 - k].project(truth[0][found], distort=False)[0]
        corner = np.array([crop.x0, crop.y0])
        assert (uv.min(0) >= corner).all() and (uv.max(0) <= corner + crop.size).all(), (uv, crop)
        obj = r.to_json()
        assert obj["single_view"] == names[k] and obj["frame_ok"] == {n: True for n in names}
        assert all(row == [0.0, 0.0, 0.0, 0.0] for row in obj["joints_3d"]) and all(obj["missing"])
        assert all(obj["missing_2d"][other]) and all(row == [0.0, 0.0, 0.0] for row in obj["joints_2d"][other])
    # they walk in: both cameras see them, and the 3D joints take over (single_view null again)
    oracle.set_truth(truth[1], visible[1])
    r = est.estimate(frames[1])
    assert r.num_found > 10 and r.single_view is None and r.to_json()["single_view"] is None
    assert est.tracker.track is not None and est.tracker.view_track is None


@pytest.mark.parametrize("flip", [True, False])
def test_a_covered_cameras_other_view_gets_its_2d_joints_from_the_oracle(clip, flip):
    """One camera covered (a black frame the frame check rejects): the other view's 2D joints through the oracle,
    whose keypoint graph reads the crops' cameras. The single-view pass fed it the images alone (KeyError: 'src_P'),
    so no oracle test reached that pass before session 70."""
    rig, frames, truth, visible, _, twod = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=flip)))
    names = est.camera_names
    oracle.set_truth(truth[0], visible[0])
    r = est.estimate((frames[0][0], np.zeros_like(frames[0][1])))
    assert r.frame_reason == {names[0]: None, names[1]: "flat"} and r.single_view == names[0]
    assert ("encoder_flip" in r.timing_ms) == flip, r.timing_ms
    found = ~r.missing_2d[names[0]]
    assert found.sum() >= 0.9 * visible[0][0].sum()
    err = np.linalg.norm(r.joints_2d[names[0]][found] - twod[0][0][found], axis=-1)
    assert err.max() < 1.5, err  # exact up to the grid's decoding: the mirrored run's cameras are mirrored too


def _with_panel(image: np.ndarray, roi, margin: int, grey: int = 128) -> np.ndarray:
    """``image`` with a plain ``grey`` panel over ``roi`` grown by ``margin`` pixels each side (clipped to the
    frame)."""
    out = image.copy()
    x0, y0 = max(0, int(roi.x0) - margin), max(0, int(roi.y0) - margin)
    out[y0:max(0, int(roi.y0 + roi.size) + margin), x0:max(0, int(roi.x0 + roi.size) + margin)] = grey
    return out


def test_a_plain_crop_on_the_rays_of_a_working_camera_is_kept_pair_after_pair(clip):
    """A person seen by camera 0 only, a plain panel hiding them from camera 1 (the rest of its frame the room):
    camera 1's crop on the seen joints' rays shows the panel alone, which the frame check rejects as flat. Until
    session 70 that sent camera 1 back to the whole volume on the next pair and to the rays on the one after,
    pair after pair, and reported camera 1 rejected every other pair (the same 2D joints of camera 0 and two
    keypoint runs a pair either way); now camera 1's whole-volume crop of the same frame, which passes, says the
    camera works: the rays crop is run and kept. A camera covered meanwhile is still rejected, back on the volume."""
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig())
    names = est.camera_names
    oracle.set_truth(truth[0], seen_by(visible[0], 0))
    first = est.estimate(frames[0])
    panel = est.tracker.view_other  # where camera 1 looks next: the panel covers it, and the person, from now on
    assert first.single_view == names[0] and first.rois[names[1]] == est.tracker.volume_regions.rois[1]
    assert panel is not None
    for k in range(1, len(frames)):
        oracle.set_truth(truth[k], seen_by(visible[k], 0))
        on_rays, runs = est.tracker.view_other, oracle.run_counts["encoder"]
        hidden = _with_panel(frames[k][1], panel, 16)
        maps, _ = est._crop(est._cams[1], on_rays)
        plane = preprocess_image(hidden, maps, est.contract.normalisation)[1]
        assert check_crop(plane, est._levels, est.config.frame_check, maps.inside) == (False, "flat"), k
        r = est.estimate((frames[k][0], hidden))
        assert r.rois[names[1]] == on_rays and on_rays.size < est.tracker.volume_regions.rois[1].size, k
        assert r.frame_reason == {n: None for n in names}, (k, r.frame_reason)
        assert r.single_view == names[0] and (~r.missing_2d[names[0]]).sum() >= 0.9 * visible[k][0].sum()
        assert oracle.run_counts["encoder"] - runs == 2  # the crops and the flip test's mirrored run
    covered = est.estimate((frames[-1][0], np.zeros_like(frames[-1][1])))
    assert covered.frame_reason == {names[0]: None, names[1]: "flat"} and covered.single_view == names[0]
    assert est.tracker.view_other is None  # camera 1's next crop: the whole volume


def _behind_a_panel(est, oracle, clip, pairs, covered_from=None):
    """Run ``pairs`` pairs of ``clip`` (in turn, from its second) seen by camera 0 only, camera 1 hidden by a plain
    panel over its first crop on the rays (as in the test above); from pair ``covered_from`` on camera 1's frame is
    the panel's grey all over (a lens covered by something of the panel's brightness). Returns the results and the
    preprocess_image calls of each pair."""
    rig, frames, truth, visible, *_ = clip
    oracle.set_truth(truth[0], seen_by(visible[0], 0))
    est.estimate(frames[0])
    panel = est.tracker.view_other
    assert panel is not None
    out, calls = [], []
    counted = [0]
    real = estimator_module.preprocess_image

    def counting(*args, **kwargs):
        counted[0] += 1
        return real(*args, **kwargs)

    estimator_module.preprocess_image = counting
    try:
        for n in range(pairs):
            k = 1 + n % (len(frames) - 1)
            oracle.set_truth(truth[k], seen_by(visible[k], 0))
            hidden = _with_panel(frames[k][1], panel, 16)
            if covered_from is not None and n >= covered_from:
                hidden = np.full_like(hidden, 128)
            before = counted[0]
            out.append(est.estimate((frames[k][0], hidden)))
            calls.append(counted[0] - before)
    finally:
        estimator_module.preprocess_image = real
    return out, calls


@pytest.mark.parametrize("every", [1, 8])
def test_a_plain_crop_on_the_rays_pays_the_whole_volume_recheck_once_in_so_many_pairs(clip, every):
    """Session 71: the whole-volume verdict that keeps a plain rays crop is reused for the next pairs, so such a pair
    preprocesses its two crops alone; the camera is checked again every ``frame_check.volume_recheck_every`` pairs
    (1: every pair, session 70's three preprocesses a pair). Answers as before: camera 1 passes, camera 0's joints."""
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, clip[0], EstimatorConfig(frame_check=FrameCheckConfig(volume_recheck_every=every)))
    results, calls = _behind_a_panel(est, oracle, clip, 10)
    assert all(r.frame_reason == {n: None for n in est.camera_names} for r in results), [r.frame_reason for r in
                                                                                        results]
    assert all(r.single_view == est.camera_names[0] for r in results)
    assert calls == [2 + (n % every == 0) for n in range(10)], calls
    assert est.volume_rechecks == sum(c - 2 for c in calls)


@pytest.mark.parametrize("every, covered_from", [(3, 1), (3, 3), (8, 2)])
def test_a_lens_covered_behind_a_cached_whole_volume_verdict_is_reported_within_the_bound(clip, every, covered_from):
    """Camera 1 covered by something of the panel's brightness after its whole-volume verdict was cached (the rays
    crop flat at the same level: nothing says the camera changed): reported rejected no later than the
    ``volume_recheck_every``-th covered pair, and from then on."""
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, clip[0], EstimatorConfig(frame_check=FrameCheckConfig(volume_recheck_every=every)))
    results, _ = _behind_a_panel(est, oracle, clip, covered_from + every + 2, covered_from)
    names = est.camera_names
    rejected = [r.frame_reason[names[1]] == "flat" for r in results]
    assert not any(rejected[:covered_from]), rejected
    first = rejected.index(True)
    assert first - covered_from < every and all(rejected[first:]), (rejected, every)
    assert all(r.frame_reason[names[0]] is None and r.single_view == names[0] for r in results)


@pytest.mark.parametrize("levels, rechecks", [(16.0, [1, 0, 0, 0]), (4.0, [1, 1, 0, 1])])
def test_a_panel_brightening_past_volume_recheck_levels_checks_the_camera_again_at_once(clip, levels, rechecks):
    """``frame_check.volume_recheck_levels`` (session 72; 16 levels, a module constant before): the panel over camera
    1's rays crop brightened by 8 levels on the second pair and back on the fourth is the same plain wall at the
    default bound (the verdict answers), a change at 4 (the camera is checked again at once, each time)."""
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(frame_check=FrameCheckConfig(volume_recheck_levels=levels)))
    oracle.set_truth(truth[0], seen_by(visible[0], 0))
    est.estimate(frames[0])
    panel = est.tracker.view_other
    assert panel is not None
    counted = []
    for k, grey in zip(range(1, 5), (128, 136, 136, 128)):
        oracle.set_truth(truth[k], seen_by(visible[k], 0))
        before = est.volume_rechecks
        r = est.estimate((frames[k][0], _with_panel(frames[k][1], panel, 16, grey)))
        assert r.frame_reason == {n: None for n in est.camera_names}, r.frame_reason
        counted.append(est.volume_rechecks - before)
    assert counted == rechecks


def test_a_tracker_reset_voids_the_cached_whole_volume_verdict(clip):
    """Whatever resets the tracker (a gap in the timestamps, ``Estimator.reset``) voids the cached verdict: the next
    rejected rays crop is checked again on the whole volume."""
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, clip[0], EstimatorConfig())
    _, calls = _behind_a_panel(est, oracle, clip, 2)
    assert calls == [3, 2] and est._volume_verdict is not None
    est.tracker.reset()
    assert est._volume_verdict is not None and not est._volume_verdict.holds(
        est._cams[1], est.tracker, est._volume_verdict.reason, est._volume_verdict.level)
    est.reset()
    assert est._volume_verdict is None


def test_a_turn_search_on_a_pair_on_the_rays_keeps_the_cached_whole_volume_verdict(clip):
    """Session 72: a pair on the rays whose person camera 0 reads weakly beside camera 1's faint view searches the crop
    turns, its turned passes cropping the working volume (off the rays); none is kept and the next pair is on the
    rays again. The verdict cached on that pair still answers it: the camera is checked on the whole volume once in
    ``frame_check.volume_recheck_every`` pairs, as without the search. Before, the turned passes voided it, and the
    pair after each search checked the camera again (3 rechecks in 10 pairs, not 2)."""
    rig, frames, truth, visible, *_ = clip
    oracle = ScaledViews((0.6, 0.25))  # the one-camera pair that searches (the test above)
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False)))
    # the oracle's heatmaps score every turn alike, so no turn would be tried: one is, and reads no better
    est._turn_candidates = lambda *args, **kwargs: [(90, 90)]
    oracle.set_truth(truth[0], seen_by(visible[0], 0))
    est.estimate(frames[0])
    panel = est.tracker.view_other
    assert panel is not None
    rechecks, searches, cached = [], [], []
    for n in range(10):
        k = 1 + n % (len(frames) - 1)
        oracle.set_truth(truth[k], visible[k])  # camera 1's faint view: the search's case
        before = est.volume_rechecks, est.turn_searches
        r = est.estimate((frames[k][0], _with_panel(frames[k][1], panel, 16)))
        assert r.single_view == est.camera_names[0] and r.frame_reason[est.camera_names[1]] is None
        assert est.tracker.view_other == panel and est.turns_kept == 0
        rechecks.append(est.volume_rechecks - before[0])
        searches.append(est.turn_searches - before[1])
        cached.append(est._volume_verdict is not None)
    assert sum(searches) >= 2 and searches[0] == 1, searches  # a search on the pair that took the verdict, and later
    assert rechecks == [int(n % 8 == 0) for n in range(10)], (rechecks, searches)
    assert all(cached), cached


def test_a_tracked_person_leaving_one_cameras_view_is_looked_for_again_and_kept_in_the_other(clip):
    """A 3D track, then the person seen by camera 0 only: the tracked pass finds nobody in 3D, the pair is run
    again (``tracking.retry_cold``) from camera 0's view track and, since session 69, camera 1's crop on the seen
    joints' rays (the working volume's before), and answers camera 0's 2D joints; the next such pair starts from
    there, one pass."""
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    # roi.turn_search at its default, on: the view reads them well, so no pair searches the crop turns (counted
    # below; test_a_person_seen_well_by_one_camera_only_does_not_search_the_turns)
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False)))
    oracle.set_truth(truth[0], visible[0])
    assert est.estimate(frames[0]).num_found > 10 and est.tracker.track is not None
    for k in (1, 2):
        oracle.set_truth(truth[k], seen_by(visible[k], 0))
        runs = oracle.run_counts["encoder"]
        r = est.estimate(frames[k])
        assert r.single_view == est.camera_names[0] and r.missing.all() and not r.tracked
        assert oracle.run_counts["encoder"] - runs == (2 if k == 1 else 1)  # the tracked pass, then the retry
        assert est.tracker.track is None and est.tracker.view_track[0] == 0
        volume = est.tracker.volume_regions.rois[1]
        assert r.rois[est.camera_names[1]].size < volume.size  # the retry's camera 1 crop: on the rays, not the volume


@pytest.mark.parametrize("k", [0, 1])
def test_a_person_seen_well_by_one_camera_only_does_not_search_the_turns(clip, k):
    """``roi.turn_search`` at its default (on for this model): a person seen by one camera only finds nobody in
    3D, but the view that sees them reads them well, so no crop turn could be kept (a kept turn must find them in
    3D, in the other view too): no pair searches, tracked before or cold, over more pairs than
    ``roi.turn_search_every``. Each pair runs the encoder as with the search off (the tracked pass and the retry,
    then one); before, the first such pair ran it 5 times (three turns), and every fifth after it again."""
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False)))
    assert est.config.roi.turn_search and est.config.roi.turn_search_every == 5
    oracle.set_truth(truth[0], visible[0])
    assert est.estimate(frames[0]).num_found > 10 and est.tracker.track is not None
    for cold in (False, True):
        if cold:
            est.reset()
        for i in range(7):
            f = 1 + i % 4
            oracle.set_truth(truth[f], seen_by(visible[f], k))
            runs = oracle.run_counts["encoder"]
            r = est.estimate(frames[f])
            assert r.single_view == est.camera_names[k] and r.missing.all()
            assert oracle.run_counts["encoder"] - runs == (2 if i == 0 and not cold else 1), (cold, i)
            assert "turn_search" not in r.timing_ms
    assert est.turn_searches == 0


class ScaledViews(OracleSession):
    """The oracle, each view's encoder heatmaps scaled by its factor in ``scale``: a view that reads the person
    weakly (as upright crops read someone lying across them), or not at all (0)."""

    def __init__(self, scale: tuple[float, float]):
        super().__init__(edge128_contract())
        self.scale = scale

    def _source_heatmaps(self, src_P):
        maps = super()._source_heatmaps(src_P)
        return maps * np.asarray(self.scale, maps.dtype)[:, None, None, None]


@pytest.mark.parametrize("scale, searches", [
    ((1.0, 0.0), 0),  # seen well, the other view empty
    ((1.0, 0.25), 0),  # seen well, the other view faint
    ((0.6, 0.0), 0),  # read weakly, the other view empty: nobody there for a turn to find in 3D
    ((0.6, 0.25), 1),  # read weakly beside a view that may show them: the misread the search exists for
])
def test_a_one_camera_pair_searches_the_turns_only_where_a_turn_could_find_the_person(clip, scale, searches):
    """Camera 0's view passes the per-view presence rule, camera 1's does not (nobody in 3D: a one-camera pair).
    It searches the crop turns only when camera 0 reads the person under ``roi.turn_search_below`` (0.5) median
    and camera 1's 6th-strongest peak reaches the search's floor (0.1): someone lying across both views, misread
    upright. Before, all four searched."""
    rig, frames, truth, visible, *_ = clip
    oracle = ScaledViews(scale)
    est = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(flip_test=False)))
    oracle.set_truth(truth[0], visible[0])
    r = est.estimate(frames[0])
    names = est.camera_names
    assert r.single_view == names[0] and r.missing.all()
    found = ~r.missing_2d[names[0]]
    seen = float(np.median(r.confidence_2d[names[0]][found]))
    assert (seen >= 0.5) == (scale[0] == 1.0) and seen >= 0.35, seen
    assert est.turn_searches == searches
    assert ("turn_search" in r.timing_ms) == bool(searches)


def test_a_person_seen_by_one_camera_only_is_nobody_with_single_view_2d_off(clip):
    """``frame_check.single_view_2d: false`` keeps the earlier answer: every joint missing, the frames said to
    have been looked at (``frame_ok`` true), no track of any kind."""
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(frame_check=FrameCheckConfig(single_view_2d=False)))
    for k in (0, 1):
        oracle.set_truth(truth[0], seen_by(visible[0], k))
        r = est.estimate(frames[0])
        assert all(r.frame_ok.values()) and r.single_view is None
        assert r.missing.all() and all(r.missing_2d[n].all() and not r.joints_2d[n].any() for n in rig.names[:2])
        assert est.tracker.track is None and est.tracker.view_track is None


class ApartViews(OracleSession):
    """The oracle, but camera 1's encoder heatmaps show the person ``drop`` metres lower than camera 0's: both
    views show someone, and their peaks meet nowhere in 3D."""

    def __init__(self, drop: float):
        super().__init__(edge128_contract())
        self.drop = drop

    def _source_heatmaps(self, src_P):
        maps = super()._source_heatmaps(src_P)
        truth = self.truth
        self.truth = truth + [0.0, self.drop, 0.0]
        try:
            maps[1] = super()._source_heatmaps(src_P)[1]
        finally:
            self.truth = truth
        return maps


def test_an_empty_room_and_two_views_that_do_not_meet_stay_nobody(clip):
    """The one-camera answer needs exactly one view that shows someone: an empty room (neither) reports
    nobody, and so does a pair whose views both show someone who does not triangulate (the views' peaks are
    0.4 m apart across the epipolar lines: whose joints would be the answer?)."""
    rig, frames, truth, visible, *_ = clip
    oracle = ApartViews(0.4)
    est = Estimator(oracle, rig)
    oracle.set_truth(None)
    r = est.estimate(frames[0])
    assert all(r.frame_ok.values()) and r.single_view is None and r.missing.all()
    assert all(r.missing_2d[n].all() for n in rig.names[:2]) and est.tracker.view_track is None
    assert r.reprojection_px_median is None  # an empty room: nothing strong in both views to measure
    oracle.set_truth(truth[0], visible[0])
    r = est.estimate(frames[0])
    assert r.single_view is None and r.missing.all()
    assert all(r.missing_2d[n].all() for n in rig.names[:2]) and est.tracker.view_track is None
    # nobody reported, but the views' disagreement is measured before the gate: what the daemon's calibration
    # check reads for a camera knocked far off (docs/daemon.md, "The status file": its `calibration` row)
    assert r.reprojection_px_median is not None and r.reprojection_px_median > 6.0
    oracle.drop = 0.0  # the same pair with views that agree: the person, in 3D
    est.reset()
    assert est.estimate(frames[0]).num_found > 10


class RenderedOffset(OracleSession):
    """The oracle, but its rendered heatmaps show every joint ``offset`` metres away from the truth
    (a rendered path that errs), while the encoder's heatmaps stay exact."""

    def __init__(self, offset):
        super().__init__(edge128_contract())
        self.offset = np.asarray(offset, np.float64)

    def run(self, graph, feeds):
        if graph != "render_heat" or self.truth is None:
            return super().run(graph, feeds)
        truth = self.truth
        self.truth = truth + self.offset
        try:
            return super().run(graph, feeds)
        finally:
            self.truth = truth


@pytest.mark.parametrize("follow", [True, False])
def test_rendered_heatmaps_place_the_next_crop_from_the_encoder_joints_when_following_it(clip, follow):
    """``tracking.follow_encoder``: the reported joints are the rendered ones either way; only the track
    (where the next pair looks) comes from the encoder's heatmaps."""
    rig, frames, truth, *_ = clip
    offset = np.array([0.2, 0.0, 0.0])
    oracle = RenderedOffset(offset)
    cfg = EstimatorConfig(heatmaps=HeatmapsConfig(source="rendered"), joints3d=Joints3DConfig(method="triangulate"),
                          tracking=TrackingConfig(follow_encoder=follow))
    est = Estimator(oracle, rig, cfg)
    oracle.set_truth(truth[0])
    r = est.estimate(frames[0])
    assert r.num_found > 10
    reported = np.linalg.norm(r.joints_3d[~r.missing] - (truth[0] + offset)[~r.missing], axis=-1)
    assert reported.max() < 0.01  # the rendered (offset) joints are what the pair reports
    track = est.tracker.track
    assert track is not None and track.valid.sum() > 10
    followed = track.joints[track.valid]
    aim = truth[0] if follow else truth[0] + offset
    assert np.linalg.norm(followed - aim[track.valid], axis=-1).max() < 0.01
    # nobody reported (the presence gate): nothing to follow, whatever the encoder says
    oracle.set_truth(truth[1])
    quiet = Estimator(oracle, rig, EstimatorConfig(heatmaps=HeatmapsConfig(source="rendered"),
                                                   tracking=TrackingConfig(follow_encoder=follow),
                                                   presence=PresenceConfig(min_joints=25, min_confidence=1.0)))
    assert quiet.estimate(frames[1]).missing.all() and quiet.tracker.track is None


@pytest.mark.parametrize("overlap", [True, False])
def test_the_proxy_blend_recolours_the_novel_view_with_the_subjects_colours(clip, overlap):
    """``novel_view.proxy_blend``: with the oracle's exact joints, the view's subject gets the source crops'
    colours at the body proxy's depth, much nearer the simulator's picture than the oracle's flat paint;
    it runs on the main thread after the joints (``novel_proxy``), and changes no joint."""
    from benchmarks.bench_runtime_common import truth_view
    from ghnerf_runtime.metrics import masked_psnr

    rig, frames, truth, visible, *_ = clip
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    runs = {}
    for blend in (False, True):
        oracle = OracleSession(edge128_contract())
        cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, overlap=overlap, proxy_blend=blend))
        with Estimator(oracle, rig, cfg) as est:
            runs[blend] = []
            for pair, j3, vis in zip(frames, truth, visible):
                oracle.set_truth(j3, vis)
                runs[blend].append(est.estimate(pair, novel_view=NovelViewRequest(alpha=0.5)))
    gains = []
    for i, (off, on) in enumerate(zip(runs[False], runs[True])):
        np.testing.assert_array_equal(off.joints_3d, on.joints_3d)
        assert "novel_proxy" in on.timing_ms and "novel_proxy" not in off.timing_ms
        assert on.novel_view.camera is off.novel_view.camera or np.allclose(on.novel_view.camera.P,
                                                                            off.novel_view.camera.P)
        want, mask = truth_view(scene, on.novel_view.camera, i / 30, 0.0)
        psnr = [masked_psnr(r.novel_view.image[..., ::-1] / 255.0, want, mask).value for r in (off, on)]
        gains.append(psnr[1] - psnr[0])
        changed = np.any(on.novel_view.image != off.novel_view.image, axis=-1)
        assert changed.sum() > 0.5 * mask.sum()
    assert min(gains) > 3.0, gains


def test_the_matte_fades_the_view_away_from_the_proxy_and_only_when_asked(clip):
    """``novel_view.matte``: after the joints (``novel_matte``), the oracle's paint that lies far from the body
    proxy of this pair's joints goes to the background; the simulated person's own pixels stay; no joint
    changes."""
    from benchmarks.bench_runtime_common import truth_view

    rig, frames, truth, visible, *_ = clip
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    runs = {}
    for matte in (False, True):
        oracle = OracleSession(edge128_contract())
        cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, proxy_blend=False, matte=matte,
                                                         matte_feather_m=0.0))
        with Estimator(oracle, rig, cfg) as est:
            oracle.set_truth(truth[0], visible[0])
            runs[matte] = est.estimate(frames[0], novel_view=NovelViewRequest(alpha=0.5))
    off, on = runs[False], runs[True]
    np.testing.assert_array_equal(off.joints_3d, on.joints_3d)
    assert "novel_matte" in on.timing_ms and "novel_matte" not in off.timing_ms
    changed = np.any(on.novel_view.image != off.novel_view.image, axis=-1)
    assert changed.sum() > 50, changed.sum()
    assert not on.novel_view.image[changed].any()  # to the background (black), nothing else
    _, mask = truth_view(scene, on.novel_view.camera, 0.0, 0.0)
    assert (changed & mask).sum() <= 0.01 * mask.sum(), ((changed & mask).sum(), mask.sum())  # the person stays


def test_the_painter_runs_over_the_proxy_before_the_blend_and_only_when_asked(clip, tmp_path):
    """``novel_view.painter``: a session's painter repaints the view after the joints (``novel_paint``), before
    the proxy blend, and changes no joint; ``off`` skips it, as does a view nearer a source camera than
    ``painter_min_angle_deg``; ``on`` without one is an error."""
    from ghnerf_runtime.errors import ModelError
    from ghnerf_runtime.novel_painter import NovelPainter
    from tests.ghnerf_runtime.test_novel_painter import blend_painter

    rig, frames, truth, visible, *_ = clip
    painter = NovelPainter.load(blend_painter(tmp_path / "novel_painter.onnx"))
    runs = {}
    for mode, min_angle in (("off", 0.0), ("auto", 0.0), ("near", 30.0)):
        oracle = OracleSession(edge128_contract())
        oracle.novel_painter = painter
        cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True, painter="off" if mode == "off" else "auto",
                                                         proxy_blend=False, painter_min_angle_deg=min_angle))
        with Estimator(oracle, rig, cfg) as est:
            assert (est.novel_painter is painter) == (mode != "off")
            oracle.set_truth(truth[0], visible[0])
            runs[mode] = est.estimate(frames[0], novel_view=NovelViewRequest(alpha=0.5))
    off, on, near = runs["off"], runs["auto"], runs["near"]
    # halfway between cameras about a metre apart, 3 m away: about 10 degrees from each
    assert "novel_paint" not in near.timing_ms and np.array_equal(near.novel_view.image, off.novel_view.image)
    np.testing.assert_array_equal(off.joints_3d, on.joints_3d)
    assert "novel_paint" in on.timing_ms and "novel_paint" not in off.timing_ms
    assert np.any(on.novel_view.image != off.novel_view.image, axis=-1).sum() > 500
    with pytest.raises(ModelError, match="novel_painter.onnx"):
        Estimator(OracleSession(edge128_contract()), rig,
                  EstimatorConfig(novel_view=NovelViewConfig(enabled=True, painter="on")))


def _jump(rig, position_xz):
    """One pair of the same person suddenly elsewhere in the room."""
    there = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=position_xz))
    rendered = [there.render(c, 0.2) for c in rig.pair]
    return tuple(img for img, _ in rendered), there.joints_3d(0.2), np.stack([tr.visible for _, tr in rendered])


@pytest.mark.parametrize("retry", [True, False])
def test_a_subject_who_left_the_tracked_crop_is_found_in_the_same_pair(clip, retry):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(retry_cold=retry, refine_cold_start=False)))
    assert _run(est, oracle, frames[:2], truth[:2], visible[:2])[-1].tracked
    pair, j3, vis = _jump(rig, (1.1, 2.4))
    oracle.set_truth(j3, vis)
    r = est.estimate(pair)
    if retry:  # the tracked crop saw nobody: looked again at the whole working volume
        assert r.tracked is False and r.num_found > 6
        err = np.linalg.norm(r.joints_3d[~r.missing] - j3[~r.missing], axis=-1)
        assert np.median(err) < 1e-3 and err.max() < 0.1  # (a cold crop's coarser heatmaps: a few cm at worst)
    else:  # a pair lost, found again on the next one
        assert r.tracked is True and r.num_found == 0


@pytest.mark.parametrize("retry", [True, False])
def test_a_tracked_crop_left_a_flat_wall_is_retried_from_the_working_volume(clip, retry):
    """The subject left; where the tracked crops look is now a plain wall, which the frame check rejects.
    That is finding nobody too: the pair looks at the whole working volume at once."""
    import copy

    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(retry_cold=retry, refine_cold_start=False)))
    assert _run(est, oracle, frames[:2], truth[:2], visible[:2])[-1].tracked
    tracked = copy.deepcopy(est.tracker).regions()  # where this pair's tracked crops will look
    assert tracked.tracked and not any(c.has_distortion for c in rig.pair)
    pair, j3, vis = _jump(rig, (1.1, 2.4))
    walled = []
    for img, roi in zip(pair, tracked.rois):
        img = img.copy()
        m = 4  # the window is in undistorted pixels: the sim's lenses have none (asserted below)
        img[max(roi.y0 - m, 0):max(roi.y0 + roi.size + m, 0), max(roi.x0 - m, 0):max(roi.x0 + roi.size + m, 0)] = 128
        walled.append(img)
    oracle.set_truth(j3, vis)
    r = est.estimate(tuple(walled))
    if retry:
        assert r.tracked is False and all(r.frame_ok.values()) and r.num_found > 6
    else:  # a pair lost: re-detection waits for the next one
        assert r.tracked is True and not any(r.frame_ok.values()) and r.num_found == 0


def test_a_track_older_than_max_gap_or_from_the_future_is_dropped(clip):
    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=TrackingConfig(max_gap_s=0.5, refine_cold_start=False)))
    tracked = []
    for t, k in ((0.0, 0), (1 / 30, 1), (2 / 30, 2), (10.0, 3), (10 + 1 / 30, 4), (10 + 1 / 30, 4), (5.0, 0)):
        oracle.set_truth(truth[k], visible[k])
        tracked.append(est.estimate(frames[k], timestamp_s=t).tracked)
    # 10 s later the subject may be anywhere; the same instant again keeps the track; a time before the last
    # (a looped recording) starts over
    assert tracked == [False, True, True, False, True, True, False]


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"),
                                 pytest.param(10 ** 400, id="10**400"), "0.1"])
def test_a_capture_time_that_is_not_finite_is_a_frame_error_that_keeps_the_track(clip, bad):
    """NaN is neither before nor after the last time: taken, it dropped the track on its pair and on the next. An
    integer past the float range, or no number, raised math.isfinite's OverflowError / TypeError instead, which the
    daemon (it skips a pair on a FrameError) did not catch."""
    from ghnerf_runtime.errors import FrameError

    rig, frames, truth, visible, *_ = clip
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(tracking=COLD))
    tracked = []
    for k, t in ((0, 0.0), (1, 1 / 30), (2, bad), (2, 2 / 30), (3, 3 / 30)):
        oracle.set_truth(truth[k], visible[k])
        if t is bad:
            with pytest.raises(FrameError, match="timestamp_s"):
                est.estimate(frames[k], timestamp_s=t)
            continue
        tracked.append(est.estimate(frames[k], timestamp_s=t).tracked)
    assert tracked == [False, True, True, True]


def test_a_flat_frame_with_min_std_zero_is_rejected_not_a_crash(clip):
    from ghnerf_runtime.config import FrameCheckConfig

    rig, frames, *_ = clip
    est = Estimator(OracleSession(edge128_contract()), rig, EstimatorConfig(frame_check=FrameCheckConfig(min_std=0.0)))
    black = tuple(np.zeros_like(f) for f in frames[0])
    r = est.estimate(black)
    assert r.missing.all() and not any(r.frame_ok.values())


def test_legs_hidden_for_a_few_pairs_are_found_again_when_they_come_back():
    """The tracked crop framed the joints found: legs hidden for three pairs (a table) shrank it to the upper
    body, and when they came back they lay outside it; 13 of 21 joints were found from then on, while the track
    held. Their last place, moved with the body, keeps them in the crop."""
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig())
    legs = [9, 10, 11, 12, 13, 14, 19, 20, 21, 22, 23, 24]
    found, shown = [], []
    for i in range(7):
        rendered = [scene.render(c, i / 30) for c in rig.pair]
        vis = np.stack([tr.visible for _, tr in rendered])
        if 2 <= i < 5:
            vis[:, legs] = False
        oracle.set_truth(scene.joints_3d(i / 30), vis)
        r = est.estimate(tuple(img for img, _ in rendered), timestamp_s=i / 30)
        assert r.tracked
        found.append(r.num_found)
        shown.append(int(vis.all(axis=0).sum()))
    assert shown[4] < 12 and found[2:5] == shown[2:5]
    assert found[5:] == shown[5:] and min(shown[5:]) > 18, (found, shown)
