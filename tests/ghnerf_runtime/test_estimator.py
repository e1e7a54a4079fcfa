"""Estimator with the real (tiny, random-weight) model on simulator frames: outputs, bad frames,
novel views on/off (colour graph instrumented), errors.

Random weights make the joints meaningless here; accuracy and tracking are tested against the
oracle session (test_estimator_oracle.py) and the shipped model (test_estimator_accuracy.py).
"""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig, HeatmapsConfig, Joints3DConfig, NovelViewConfig, \
    PresenceConfig, RoiConfig, SessionConfig, TrackingConfig
from ghnerf_runtime.errors import ConfigError, FrameError, ModelError
from ghnerf_runtime.flip_test import flip_averaged, mirror_images
from ghnerf_runtime.estimator import KEYPOINT_STAGES, NOVEL_STAGES, Estimator
from ghnerf_runtime.novel_view import NovelViewRequest
from ghnerf_runtime.session import ModelSession
from tests.ghnerf_runtime.test_session import tiny_model_dir, tiny_session  # noqa: F401  (fixtures)

sim = pytest.importorskip("drivers.sim")


class Recorder:
    """Wraps a session and records every graph run (the instrument of the colour-graph tests)."""

    def __init__(self, session):
        self.session = session
        self.contract = session.contract
        self.graphs = session.graphs
        self.calls: list[tuple[str, dict]] = []

    def has(self, graph):
        return self.session.has(graph)

    def run(self, graph, feeds):
        self.calls.append((graph, {k: np.shape(v) for k, v in feeds.items()}))
        return self.session.run(graph, feeds)

    def run_both(self, graph, first, second):  # the flip test's two runs (side by side in the real session)
        return self.run(graph, first), self.run(graph, second)

    def ran(self, graph) -> int:
        return sum(1 for g, _ in self.calls if g == graph)


@pytest.fixture(scope="module")
def scene_rig():
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = [tuple(scene.render(c, t, with_truth=False)[0] for c in rig.pair) for t in (0.0, 0.05, 0.1)]
    return rig, frames


#: Random weights find nobody, or someone weakly, and such a pass tries the crop turns (roi.turn_search, on by
#: default since session 57: three encoder runs more); the tests that count one pass's graph runs set it off.
NO_TURN_SEARCH = RoiConfig(turn_search=False)


def _all_finite(result) -> bool:
    arrays = [result.joints_3d, result.confidence, *result.joints_2d.values(), *result.confidence_2d.values()]
    return all(np.all(np.isfinite(a)) for a in arrays) and all(np.isfinite(v) for v in result.timing_ms.values())


def _assert_all_missing(result):
    assert result.missing.all() and not result.joints_3d.any() and not result.confidence.any()
    for name in result.joints_2d:
        assert result.missing_2d[name].all() and not result.joints_2d[name].any()
        assert not result.confidence_2d[name].any()
    assert _all_finite(result)


def test_output_schema_and_finite(tiny_session, scene_rig):
    rig, frames = scene_rig
    est = Estimator(tiny_session, rig)
    r = est.estimate(frames[0], sequence=7)
    assert r.sequence == 7 and r.joint_names == JOINT_NAMES
    assert r.joints_3d.shape == (25, 3) and r.confidence.shape == (25,) and r.missing.shape == (25,)
    assert set(r.joints_2d) == set(rig.names[:2])
    for name in rig.names[:2]:
        assert r.joints_2d[name].shape == (25, 2) and r.confidence_2d[name].shape == (25,)
    assert _all_finite(r)
    # default: encoder heatmaps + triangulation, so neither the volume nor the heatmap rendering runs
    ran = {"preprocess", "encoder", "decode_2d", "joints_3d", "total"}
    assert ran <= set(r.timing_ms) <= set(KEYPOINT_STAGES) | {"total"}
    assert r.frame_ok == {n: True for n in rig.names[:2]} and r.tracked is False
    obj = json.loads(json.dumps(r.to_json(), allow_nan=False))
    assert obj["joint_names"] == list(JOINT_NAMES) and len(obj["joints_3d"]) == 25
    assert all(len(row) == 4 for row in obj["joints_3d"])
    assert {k: len(v) for k, v in obj["joints_2d"].items()} == {n: 25 for n in rig.names[:2]}
    assert all(len(row) == 3 for rows in obj["joints_2d"].values() for row in rows)


@pytest.mark.parametrize("family", ["black", "saturated", "uniform_noise", "gaussian_noise", "nan_free_dark"])
def test_bad_frames_give_finite_missing_joints_without_running_the_model(tiny_session, scene_rig, family):
    rig, frames = scene_rig
    rec = Recorder(tiny_session)
    est = Estimator(rec, rig)
    h, w = frames[0][0].shape[:2]
    rng = np.random.default_rng(1)
    bad = {
        "black": np.zeros((h, w, 3), np.uint8),
        "saturated": np.full((h, w, 3), 255, np.uint8),
        "uniform_noise": rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
        "gaussian_noise": np.clip(rng.normal(128, 40, (h, w, 3)), 0, 255).astype(np.uint8),
        "nan_free_dark": np.full((h, w, 3), 3, np.uint8),
    }[family]
    r = est.estimate((bad, bad))
    _assert_all_missing(r)
    assert not any(r.frame_ok.values())
    # one bad camera, single_view_2d off: nothing either
    one_off = Estimator(rec, rig, EstimatorConfig(frame_check=FrameCheckConfig(single_view_2d=False)))
    for pair in ((frames[0][0], bad), (bad, frames[0][1])):
        r = one_off.estimate(pair)
        _assert_all_missing(r)
        assert sum(r.frame_ok.values()) == 1
    assert rec.calls == [], "the model must not run on frames that cannot show anyone"


@pytest.mark.parametrize("family", ["black", "saturated", "uniform_noise"])
def test_one_bad_camera_gives_the_other_cameras_2d_joints_only(tiny_session, scene_rig, family):
    """single_view_2d (the default): the good camera's encoder heatmaps are decoded; no 3D, no novel view,
    nothing in the bad camera; the human graph alone runs (random weights: which 2D joints survive the
    presence gate is the shipped model's test, test_estimator_accuracy.py)."""
    rig, frames = scene_rig
    h, w = frames[0][0].shape[:2]
    bad = {"black": np.zeros((h, w, 3), np.uint8), "saturated": np.full((h, w, 3), 255, np.uint8),
           "uniform_noise": np.random.default_rng(1).integers(0, 256, (h, w, 3), dtype=np.uint8)}[family]
    rec = Recorder(tiny_session)
    cfg = EstimatorConfig(novel_view=NovelViewConfig(enabled=True), presence=PresenceConfig(enabled=False))
    est = Estimator(rec, rig, cfg)
    names = est.camera_names
    both = Estimator(tiny_session, rig, cfg).estimate(frames[0])  # cold: the crops the single views get
    for good in (0, 1):
        pair = [frames[0][0], frames[0][1]]
        pair[1 - good] = bad
        est.reset()
        r = est.estimate(pair, novel_view=NovelViewRequest(alpha=0.5))
        assert r.frame_ok == {names[good]: True, names[1 - good]: False}
        # the good camera's, where it decoded any joint (random weights; the shipped model's test checks a person)
        assert r.single_view == (names[good] if (~r.missing_2d[names[good]]).any() else None)
        assert r.missing.all() and not r.joints_3d.any() and r.novel_view is None
        assert r.missing_2d[names[1 - good]].all() and not r.joints_2d[names[1 - good]].any()
        # each view's encoder heatmaps are its own: the good view decodes what it decodes in a full pair
        np.testing.assert_array_equal(r.missing_2d[names[good]], both.missing_2d[names[good]])
        np.testing.assert_allclose(r.joints_2d[names[good]], both.joints_2d[names[good]], atol=1e-9)
        assert _all_finite(r) and {"encoder", "decode_2d"} <= set(r.timing_ms)
    assert {g for g, _ in rec.calls} == {"human"}


def test_novel_view_off_never_runs_or_loads_a_colour_graph(tiny_model_dir, scene_rig):  # noqa: F811
    rig, frames = scene_rig
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(tiny_model_dir)), heatmaps=HeatmapsConfig("rendered"),
                          joints3d=Joints3DConfig(method="depth_centroid"), roi=NO_TURN_SEARCH)
    est = Estimator.from_config(rig, cfg)
    assert est.session.graphs == ("encoder", "volume", "render_heat")  # colour graphs not even loaded
    rec = Recorder(est.session)
    est.session = rec
    for pair in frames:
        est.estimate(pair)
    assert rec.ran("render_rgb") == 0 and rec.ran("render") == 0
    assert rec.ran("render_heat") == len(frames) and rec.ran("encoder") == len(frames)
    with pytest.raises(ModelError, match="novel_view.enabled is false"):
        est.estimate(frames[0], novel_view=NovelViewRequest())


def test_novel_view_off_with_colour_graph_loaded_still_never_runs_it(tiny_session, scene_rig):
    rig, frames = scene_rig
    rec = Recorder(tiny_session)
    est = Estimator(rec, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True)))
    for pair in frames:
        est.estimate(pair)  # no request: no novel view
    assert rec.ran("render_rgb") == 0 and rec.ran("render") == 0
    assert rec.ran("volume") == 0  # encoder heatmaps + triangulation: no volume for keypoints either


#: Random weights: the presence gate says nobody is there, and such a pair has no novel view; the novel-view
#: tests run with the gate off (nothing then decides that nobody is there: every pair is viewed).
NOBODY_UNDECIDED = PresenceConfig(enabled=False)


@pytest.mark.parametrize("stride, overlay", [(1, "skeleton"), (2, "none")])
def test_novel_view_on_request(tiny_session, scene_rig, stride, overlay):
    rig, frames = scene_rig
    rec = Recorder(tiny_session)
    cfg = NovelViewConfig(enabled=True, stride=stride, silhouette_stride=0)  # every ray of the box
    # random weights: the presence gate would say nobody, and a pair with nobody has no novel view
    est = Estimator(rec, rig, EstimatorConfig(novel_view=cfg, presence=NOBODY_UNDECIDED))
    r = est.estimate(frames[0], novel_view=NovelViewRequest(alpha=0.3, overlay=overlay))
    S = tiny_session.contract.height
    assert r.novel_view is not None and r.novel_view.image.shape == (S, S, 3) and r.novel_view.image.dtype == np.uint8
    assert rec.ran("render_rgb") == 1 and rec.ran("render") == 0 and rec.ran("volume") == 1  # the novel camera's
    rays = [shapes["ray_uv"] for g, shapes in rec.calls if g == "render_rgb"][0]
    assert rays[0] == 1 and rays[1] <= (S // stride) ** 2
    # With the coarse silhouette pass (the default): a coarse run, then a fine one over at most the box.
    rec.calls.clear()
    est = Estimator(rec, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True, stride=stride),
                                              presence=NOBODY_UNDECIDED))
    coarse = est.estimate(frames[0], novel_view=NovelViewRequest(alpha=0.3, overlay=overlay))
    calls = [shapes["ray_uv"][1] for g, shapes in rec.calls if g == "render_rgb"]
    assert len(calls) in (1, 2) and calls[0] <= (S // 4) ** 2
    assert coarse.novel_view.rays == sum(calls) and coarse.novel_view.image.shape == (S, S, 3)
    assert set(NOVEL_STAGES) <= set(r.timing_ms)


@pytest.mark.parametrize("height", [-1.3, -0.95])  # tilted down (axes 167 degrees apart), level (collinear)
def test_a_view_between_facing_cameras_takes_the_configured_path(tiny_session, height):
    """``novel_view.path``: the line puts the halfway camera in the subject; the orbit (and auto, the axes 167-180
    degrees apart) keeps it 3 m out, round the axes' pivot or, collinear, the subject box's centre."""
    from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, intrinsics_from_fov, look_at

    subject = np.array([0.0, -0.95, 3.0])
    K = intrinsics_from_fov(160, 120, 80.0)
    cams = tuple(Camera(n, 160, 120, K, [], *look_at((x, height, 3.0), subject)) for n, x in (("l", -3.0), ("r", 3.0)))
    rig = Rig(cams, WorkingVolume(subject - [0.8, 1.15, 0.8], subject + [0.8, 1.0, 0.8]))
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    centre = {}
    for path in ("line", "orbit", "auto"):
        # (the random weights find nobody, and a pair with nobody gets no view: the presence gate is off here)
        est = Estimator(tiny_session, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True, path=path),
                                                           presence=NOBODY_UNDECIDED))
        r = est.estimate(frames, novel_view=NovelViewRequest(alpha=0.5))
        centre[path] = r.novel_view.camera.center
    line_xz = np.hypot(centre["line"][0], centre["line"][2] - 3.0)
    assert line_xz < 1e-9  # above or at the subject's feet-to-head axis: inside the body
    for path in ("orbit", "auto"):
        assert np.hypot(centre[path][0], centre[path][2] - 3.0) > 1.5, path
    np.testing.assert_allclose(centre["auto"], centre["orbit"])


def test_novel_view_with_heatmaps_uses_the_render_graph(tiny_session, scene_rig):
    rig, frames = scene_rig
    rec = Recorder(tiny_session)
    est = Estimator(rec, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True, heatmaps=True),
                                              presence=NOBODY_UNDECIDED))
    from ghnerf_runtime.geometry import look_at
    cam = rig.pair[0]
    R, t = look_at((0.0, -1.5, 0.5), (0.0, -1.0, 3.0))
    given = cam.with_pose(R, t)
    r = est.estimate(frames[0], novel_view=NovelViewRequest(camera=given, overlay="heatmap"))
    assert rec.ran("render") in (1, 2) and rec.ran("render_rgb") == 0  # (coarse pass +) fine pass
    assert r.novel_view.heat is not None and np.all(np.isfinite(r.novel_view.heat))


#: the graphs each 3D method runs beyond the encoder's heatmaps, once a pair (triangulation: none)
METHOD_GRAPHS = {"triangulate": (), "volumetric": ("volume", "query"), "depth_centroid": ("volume", "render_heat")}


@pytest.mark.parametrize("method", ["triangulate", "volumetric", "depth_centroid"])
def test_every_3d_method_runs_and_is_finite(tiny_session, scene_rig, method, monkeypatch):
    # The random weights give flat heatmaps and query responses (peaks ~0.6 over most of the map): the
    # default decoder and the volumetric flood check call every joint missing, and all-zero outputs are
    # finite trivially. Here the flood checks are off, and the presence gate too, so each method's own
    # estimate is what comes out. The two-people check is off as well: those flat maps' peaks pass the presence
    # threshold anywhere, so their torso is no one body's (two_people.mixed_torso) and a tracked pass was read as
    # two people's, whose subject split left no joint.
    import ghnerf_runtime.joints3d as joints3d
    from ghnerf_runtime.keypoints import KeypointDecoderConfig

    monkeypatch.setattr(joints3d, "VOLUMETRIC_MAX_REGION_FRAC", 1.0)
    rig, frames = scene_rig

    def estimator(m):
        cfg = EstimatorConfig(joints3d=Joints3DConfig(method=m, second_person_min_joints=0),
                                  presence=PresenceConfig(enabled=False),
                              decoder=KeypointDecoderConfig(max_region_frac=1.0),
                              tracking=TrackingConfig(refine_cold_start=False))  # graph runs counted per pair
        est = Estimator(tiny_session, rig, cfg)
        est.session = Recorder(est.session)
        return est

    est, tri = estimator(method), estimator("triangulate")
    for i, pair in enumerate(frames):
        r = est.estimate(pair)
        assert _all_finite(r) and r.method == method
        assert np.all(r.confidence[r.missing] == 0) and not r.joints_3d[r.missing].any()
        found = ~r.missing
        assert found.sum() >= 10, (method, i, int(found.sum()))
        assert np.all(r.confidence[found] > 0) and np.all(np.abs(r.joints_3d[found]).sum(-1) > 0)
        for name in rig.names:
            assert not r.missing_2d[name].all()
        if method != "triangulate":  # the method's own estimate, not triangulation's under its name
            t = tri.estimate(pair)
            both = found & ~t.missing
            assert both.any() and not np.allclose(r.joints_3d[both], t.joints_3d[both], atol=1e-3)
    for graph in {g for gs in METHOD_GRAPHS.values() for g in gs}:
        expected = len(frames) if graph in METHOD_GRAPHS[method] else 0
        assert est.session.ran(graph) == expected, (method, graph, [g for g, _ in est.session.calls])


def test_wrong_frames_and_missing_graphs_are_errors(tiny_session, tiny_model_dir, scene_rig):  # noqa: F811
    rig, frames = scene_rig
    est = Estimator(tiny_session, rig)
    with pytest.raises(FrameError, match=rig.names[1]):
        est.estimate((frames[0][0], frames[0][1][:100]))
    with pytest.raises(FrameError, match="uint8"):
        est.estimate((frames[0][0].astype(np.float32), frames[0][1]))
    with pytest.raises(FrameError, match="expected 2 images"):
        est.estimate((frames[0][0],))
    # a frame missing, empty, or of a camera reconfigured to another size: named, never projected as it comes
    h, w = frames[0][0].shape[:2]
    for bad, got in ((None, r"got None \(no frame\)"), (np.zeros((0, 0, 3), np.uint8), r"got uint8 \(0, 0, 3\)"),
                     (np.zeros((2 * h, 2 * w, 3), np.uint8), rf"file's {w}x{h}\), got uint8 \({2 * h}, {2 * w}, 3\)")):
        with pytest.raises(FrameError, match=rf"camera {rig.names[1]!r}: expected a \({h}, {w}, 3\).*{got}"):
            est.estimate((frames[0][0], bad))
    small = ModelSession.load(SessionConfig(model_dir=str(tiny_model_dir), warmup=False),
                              ("encoder", "volume", "render_heat"))
    with pytest.raises(ModelError, match="query"):
        Estimator(small, rig, EstimatorConfig(joints3d=Joints3DConfig(method="volumetric")))


def test_a_pair_that_is_no_list_or_a_ragged_image_is_a_frame_error_naming_what_came(tiny_session, scene_rig):
    """A dict of the cameras' images was read by its keys ("got <U4 ()"), None or a generator of images raised
    len()'s TypeError, and an image of ragged nested lists numpy's ValueError naming no camera."""
    rig, frames = scene_rig
    est = Estimator(tiny_session, rig)
    left, right = frames[0]
    not_lists = ((dict(zip(rig.names, frames[0])), "dict"), (None, "NoneType"),
                 (iter(list(frames[0])), "list_iterator"), ("ab", "str"))
    for pair, got in not_lists:
        with pytest.raises(FrameError, match=rf"expected 2 images in the rig's camera order.*got {got}$"):
            est.estimate(pair)
    with pytest.raises(FrameError, match=rf"camera {rig.names[1]!r}: .*got a list that is no array \(ragged\)"):
        est.estimate((left, [[1, 2], [3]]))
    assert est.estimate(np.stack([left, right])).sequence == 0  # an array of the two images is still a pair


def test_a_0d_array_is_no_pair_and_a_deque_or_object_array_of_two_images_is_one(tiny_session, scene_rig):
    """A 0-d array passed the sequence check and then len() raised a bare TypeError; a deque and a NumPy object
    array of the two images are pairs in the rig's camera order."""
    import collections
    rig, frames = scene_rig
    est = Estimator(tiny_session, rig)
    with pytest.raises(FrameError, match=r"expected 2 images in the rig's camera order.*got ndarray$"):
        est.estimate(np.array(None, dtype=object))
    as_objects = np.empty(2, dtype=object)
    as_objects[:] = list(frames[0])
    assert est.estimate(collections.deque(frames[0])).sequence == 0
    assert est.estimate(as_objects).sequence == 1


def test_a_refused_call_leaves_the_running_count_as_it_was(tiny_session, scene_rig):
    """A bad image, time or novel-view request is refused before the pair is read: the next pair keeps the number
    it would have had (the count was advanced before the checks, so a refused call left a gap in the sequence)."""
    rig, frames = scene_rig
    est = Estimator(tiny_session, rig)
    assert est.estimate(frames[0]).sequence == 0
    with pytest.raises(FrameError, match="expected 2 images"):
        est.estimate((frames[1][0],))
    with pytest.raises(FrameError, match=rig.names[1]):
        est.estimate((frames[1][0], None), sequence=40)
    with pytest.raises(FrameError, match="timestamp_s"):
        est.estimate(frames[1], timestamp_s=float("nan"))
    with pytest.raises(ModelError, match="novel view was requested"):
        est.estimate_then_view(frames[1], novel_view=NovelViewRequest())
    assert est.estimate(frames[1]).sequence == 1


def test_encoder_heatmaps_skip_volume_and_rendering(tiny_model_dir, scene_rig):  # noqa: F811
    rig, frames = scene_rig
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(tiny_model_dir)), heatmaps=HeatmapsConfig("encoder", flip_test=False),
                          joints3d=Joints3DConfig(method="triangulate"), roi=NO_TURN_SEARCH)
    assert cfg.required_graphs() == ("encoder",)  # a model without the human graph
    assert cfg.required_graphs(human_graph=True) == ("human",)
    assert ModelSession.has_graph_file(tiny_model_dir, "human")
    est = Estimator.from_config(rig, cfg)
    assert est.session.graphs == ("human",)  # nothing else is even loaded: no feature network, no volume
    rec = Recorder(est.session)
    est.session = rec
    for pair in frames:
        r = est.estimate(pair)
        assert _all_finite(r)
        assert "volume" not in r.timing_ms and "render_heat" not in r.timing_ms
    assert [g for g, _ in rec.calls] == ["human"] * len(frames)
    # the flip test (heatmaps.flip_test, on by default) runs the human graph again, on the mirrored crops
    est = Estimator(rec, rig, replace(cfg, heatmaps=HeatmapsConfig("encoder", flip_test=True)))
    rec.calls.clear()
    assert "encoder_flip" in est.estimate(frames[0]).timing_ms
    assert [g for g, _ in rec.calls] == ["human", "human"]


class _FlipAveragingSession:
    """A session whose heatmaps are already the flip test's average (the reference for the wiring)."""

    def __init__(self, session):
        self.session, self.contract, self.graphs = session, session.contract, session.graphs
        self.images: list[np.ndarray] = []

    def has(self, graph):
        return self.session.has(graph)

    def run(self, graph, feeds):
        self.images.append(np.array(feeds["images"]))
        out = dict(self.session.run(graph, feeds))
        mirrored = self.session.run(graph, {"images": mirror_images(feeds["images"])})["encoder_heatmaps"]
        out["encoder_heatmaps"] = flip_averaged(out["encoder_heatmaps"], mirrored)
        return out


def test_the_flip_test_averages_a_second_pass_over_the_mirrored_crops(tiny_session, scene_rig):
    rig, frames = scene_rig
    flip = EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=True),
                           joints3d=Joints3DConfig(method="triangulate"), roi=NO_TURN_SEARCH)
    plain = EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=False), joints3d=Joints3DConfig(method="triangulate"),
                            roi=NO_TURN_SEARCH)
    assert flip.heatmaps.flip_test and flip.flips_encoder_heatmaps and not plain.flips_encoder_heatmaps
    assert not EstimatorConfig(heatmaps=HeatmapsConfig("rendered")).flips_encoder_heatmaps  # rendered: no effect
    seen = _FlipAveragingSession(tiny_session)
    rec = Recorder(tiny_session)
    with_flip, reference = Estimator(rec, rig, flip), Estimator(seen, rig, plain)
    for pair in frames:
        a, b = with_flip.estimate(pair), reference.estimate(pair)
        np.testing.assert_allclose(a.joints_3d, b.joints_3d, atol=1e-5)
        np.testing.assert_array_equal(a.missing, b.missing)
        np.testing.assert_allclose(a.confidence, b.confidence, atol=1e-6)
        assert "encoder_flip" in a.timing_ms and "encoder_flip" not in b.timing_ms
    assert [g for g, _ in rec.calls] == ["human", "human"] * len(frames)
    with pytest.raises(ConfigError, match="flip_test"):
        HeatmapsConfig(flip_test="yes")


def test_human_graph_gives_the_encoder_graphs_keypoints(tiny_session, scene_rig):
    """The human graph is the encoder graph's heatmap branch: same joints either way."""
    rig, frames = scene_rig
    cfg = EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=False), joints3d=Joints3DConfig(method="triangulate"))
    calls = []
    results = {}
    for name, session in (("human", tiny_session), ("encoder", _Without(tiny_session, "human"))):
        rec = Recorder(session)
        est = Estimator(rec, rig, cfg)
        results[name] = [est.estimate(pair) for pair in frames]
        calls.append({g for g, _ in rec.calls})
    assert calls == [{"human"}, {"encoder"}]
    for a, b in zip(results["human"], results["encoder"]):
        np.testing.assert_allclose(a.joints_3d, b.joints_3d, atol=1e-4)
        np.testing.assert_array_equal(a.missing, b.missing)
        for cam in a.joints_2d:
            np.testing.assert_allclose(a.joints_2d[cam], b.joints_2d[cam], atol=1e-3)


def test_older_model_without_human_graph_runs_the_encoder(tiny_model_dir, scene_rig, tmp_path):  # noqa: F811
    import shutil

    rig, frames = scene_rig
    old = tmp_path / "old"
    shutil.copytree(tiny_model_dir, old)
    for f in old.glob("human*.onnx"):
        f.unlink()
    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(old), warmup=False), heatmaps=HeatmapsConfig("encoder", flip_test=False))
    est = Estimator.from_config(rig, cfg)
    assert est.session.graphs == ("encoder",)
    assert _all_finite(est.estimate(frames[0]))


def test_novel_view_pairs_run_the_encoder_other_pairs_the_human_graph(tiny_session, scene_rig):
    rig, frames = scene_rig
    # the cold start not refined: the pass itself reads the image features (the default: below)
    cfg = EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=False), joints3d=Joints3DConfig(method="triangulate"),
                          novel_view=NovelViewConfig(enabled=True), presence=NOBODY_UNDECIDED,
                          tracking=TrackingConfig(refine_cold_start=False), roi=NO_TURN_SEARCH)
    assert cfg.required_graphs(human_graph=True) == ("encoder", "human", "volume", "render_rgb")
    rec = Recorder(tiny_session)
    est = Estimator(rec, rig, cfg)
    est.estimate(frames[0])
    plain = [g for g, _ in rec.calls]
    rec.calls.clear()
    reference = est.estimate(frames[1], novel_view=NovelViewRequest(alpha=0.5))
    novel = [g for g, _ in rec.calls]
    assert "encoder" not in plain and "human" in plain
    assert "human" not in novel and novel.count("encoder") >= 1 and "render_rgb" in novel
    # with the flip test the mirrored pass needs the heatmaps alone: the human graph, beside the encoder
    est = Estimator(rec, rig, replace(cfg, heatmaps=HeatmapsConfig("encoder", flip_test=True)))
    rec.calls.clear()
    est.estimate(frames[1], novel_view=NovelViewRequest(alpha=0.5))
    assert [g for g, _ in rec.calls if g in ("encoder", "human")] == ["encoder", "human"]
    # Refined (the default), a cold pass runs the human graph: a subject found is run again on their crop, with
    # the features. A cold pass reported with a view (here: no joints, so no track to refine on) gets the
    # features for its view then, and the same view and joints.
    est = Estimator(rec, rig, replace(cfg, tracking=TrackingConfig()))
    rec.calls.clear()
    later = est.estimate(frames[1], novel_view=NovelViewRequest(alpha=0.5))
    assert [g for g, _ in rec.calls if g in ("encoder", "human")] == ["human", "encoder"]
    assert not later.tracked and "render_rgb" in [g for g, _ in rec.calls]
    np.testing.assert_array_equal(later.novel_view.image, reference.novel_view.image)
    np.testing.assert_array_equal(later.missing, reference.missing)
    for cam in later.joints_2d:
        np.testing.assert_allclose(later.joints_2d[cam], reference.joints_2d[cam], atol=1e-3)


def test_an_empty_room_with_a_novel_view_asked_runs_the_keypoint_graph_alone(tiny_session, scene_rig):
    """Random weights: the presence gate says nobody (frames the frame check passes, as a textured empty room).
    Such a pair has no novel view, and its cold pass runs the human graph, not the encoder's image features:
    before, every such pair ran the encoder, the novel camera's volume and the colour graph."""
    rig, frames = scene_rig
    rec = Recorder(tiny_session)
    est = Estimator(rec, rig, EstimatorConfig(novel_view=NovelViewConfig(enabled=True)))
    for pair in frames * 2:
        r = est.estimate(pair, novel_view=NovelViewRequest(alpha=0.5))
        assert all(r.frame_ok.values()) and r.missing.all() and r.novel_view is None and _all_finite(r)
        assert not r.tracked and not set(NOVEL_STAGES) & set(r.timing_ms)
    assert {g for g, _ in rec.calls} == {"human"}


class _Without:
    """A session that hides one graph (as a model exported before it existed)."""

    def __init__(self, session, graph):
        self._s, self._hidden = session, graph
        self.contract = session.contract
        self.graphs = tuple(g for g in session.graphs if g != graph)

    def has(self, graph):
        return graph != self._hidden and self._s.has(graph)

    def run(self, graph, feeds):
        assert graph != self._hidden
        return self._s.run(graph, feeds)


@pytest.mark.parametrize("method, graphs", [("depth_centroid", ("encoder", "volume", "render_heat")),
                                            ("volumetric", ("encoder", "volume", "query"))])
def test_encoder_heatmaps_run_what_the_3d_method_reads(tiny_session, scene_rig, method, graphs):
    rig, frames = scene_rig
    cfg = EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=False), joints3d=Joints3DConfig(method=method),
                          roi=NO_TURN_SEARCH)
    assert cfg.required_graphs() == cfg.required_graphs(human_graph=True) == graphs
    # the flip test's mirrored pass runs the human graph when the model has one
    flip = replace(cfg, heatmaps=HeatmapsConfig("encoder", flip_test=True))
    assert flip.required_graphs() == graphs
    assert flip.required_graphs(human_graph=True) == (graphs[0], "human", *graphs[1:])
    for c, ran in ((cfg, set(graphs)), (flip, {*graphs, "human"})):
        rec = Recorder(tiny_session)
        r = Estimator(rec, rig, c).estimate(frames[0])
        assert _all_finite(r)
        assert {g for g, _ in rec.calls} == ran


def test_encoder_heatmaps_need_a_model_that_has_them(tiny_session, scene_rig):
    from dataclasses import replace

    from ghnerf_runtime.config import ConfigError, config_from_dict

    rig, _ = scene_rig
    rec = Recorder(tiny_session)
    rec.contract = replace(tiny_session.contract, encoder_heatmaps=False)  # as a 1.0.0 export reads
    with pytest.raises(ModelError, match="encoder heatmaps"):
        Estimator(rec, rig, EstimatorConfig(heatmaps=HeatmapsConfig("encoder", flip_test=False)))
    with pytest.raises(ConfigError, match="heatmaps.source"):
        config_from_dict({"heatmaps": {"source": "volumetric"}})


def test_an_empty_room_with_rendered_heatmaps_renders_them_to_ask_whether_someone_is_there(tiny_session, scene_rig):
    """The rendered source cannot skip its render graphs where nobody is (the encoder source runs the human graph
    alone there): the presence gate reads the rendered heatmaps' own peaks against their own threshold
    (presence.min_confidence, 0.4 rendered), so nothing is known of presence before render_heat has run
    (docs/runtime.md, "Compute only what the scene requires", "Rendered heatmaps, nobody there")."""
    rig, frames = scene_rig
    ran = {}
    for source in ("rendered", "encoder"):
        rec = Recorder(tiny_session)
        est = Estimator(rec, rig, EstimatorConfig(heatmaps=HeatmapsConfig(source, flip_test=False), roi=NO_TURN_SEARCH))
        for pair in frames:
            r = est.estimate(pair)
            assert all(r.frame_ok.values()) and r.missing.all() and not r.tracked and _all_finite(r)
        ran[source] = {g for g, _ in rec.calls}
    assert ran == {"rendered": {"encoder", "volume", "render_heat"}, "encoder": {"human"}}
