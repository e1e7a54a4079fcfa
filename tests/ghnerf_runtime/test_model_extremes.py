"""The *shipped* model (models/) at extreme but legal inputs, fp32 and int8 as shipped.

Two layers (docs/model.md, "Numerics"):

* the graphs through :class:`~ghnerf_runtime.session.ModelSession`: every output finite, heatmaps, colour and
  opacity in [0, 1], densities and depths >= 0, at the inputs that reach the graphs' hazards (the ``Div``,
  ``Reciprocal``, ``Log``, ``Sqrt`` and ``Softmax`` nodes: the scene normalisation of a flat image, the
  plane sweep's ``1 / near``, the depth softmax and its ``sqrt(var)``, compositing's ``log`` and the
  division by the accumulated opacity, the projection's division by the camera depth, ``unit()`` of a zero
  vector);
* the :class:`~ghnerf_runtime.estimator.Estimator` around them: every joint finite or marked missing (then
  0), confidences in [0, 1], the JSON free of NaN, the novel view's depth finite and heat in [0, 1], and no
  exception but a typed, documented one.

Each case takes well under a second (the graphs load in ~0.3 s); the whole file ~30 s on two cores. Skips
until the trained model lands (models/model_card.json), as test_estimator_accuracy.py does.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import (EstimatorConfig, FrameCheckConfig, NovelViewConfig, PresenceConfig, RoiConfig,
                                   SessionConfig)
from ghnerf_runtime.errors import GeometryError

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"

pytestmark = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                reason="no trained model yet: models/model_card.json does not exist")

PRECISIONS = ("fp32", "int8")
#: Outputs that are sigmoid responses, colours or opacities: in [0, 1].
UNIT_RANGE = {"encoder_heatmaps", "heatmaps", "joint_heat", "rgb", "acc"}
#: Outputs that are densities or depths: >= 0.
NON_NEGATIVE = {"density", "depth"}
#: Frames of nobody: what a covered lens, a blinded sensor, a broken stream or a dark room gives.
FRAME_KINDS = ("black", "white", "grey", "noise", "one_pixel", "dark")


# ------------------------------------------------------------------ graph level
_SESSIONS: dict = {}


def _session(variant: str, precision: str):
    """All of a variant's graphs in one precision (loaded once per test session)."""
    from ghnerf_runtime.contract import GRAPH_NAMES
    from ghnerf_runtime.session import ModelSession, resolve_model_dir

    key = (variant, precision)
    if key not in _SESSIONS:
        folder = resolve_model_dir(MODELS / variant)
        graphs = [g for g in GRAPH_NAMES if ModelSession.has_graph_file(str(folder), g)]
        _SESSIONS[key] = ModelSession.load(SessionConfig(model_dir=str(folder), precision=precision, warmup=False,
                                                         threads=1), graphs)
    return _SESSIONS[key]


def _model_images(kind: str, size: int) -> np.ndarray:
    """``(2, 3, size, size)`` model inputs as the runtime makes them (uint8 / 255)."""
    rng = np.random.default_rng(7)
    shape = (2, 3, size, size)
    if kind == "black":
        u8 = np.zeros(shape, np.uint8)
    elif kind == "white":
        u8 = np.full(shape, 255, np.uint8)
    elif kind == "grey":
        u8 = np.full(shape, 128, np.uint8)
    elif kind == "noise":
        u8 = rng.integers(0, 256, shape).astype(np.uint8)
    elif kind == "one_pixel":
        u8 = np.zeros(shape, np.uint8)
        u8[:, :, size // 2, size // 2] = 255
    elif kind == "dark":
        u8 = rng.integers(0, 4, shape).astype(np.uint8)
    elif kind == "identical":
        u8 = np.repeat(rng.integers(0, 256, (1,) + shape[1:]).astype(np.uint8), 2, axis=0)
    else:
        raise ValueError(kind)
    return u8.astype(np.float32) / 255.0


def _check_graph_outputs(name: str, out: dict) -> None:
    for key, value in out.items():
        assert np.isfinite(value).all(), f"{name}: {key} has {np.count_nonzero(~np.isfinite(value))} non-finite values"
        if key in UNIT_RANGE:
            assert value.min() >= 0.0 and value.max() <= 1.0 + 1e-6, f"{name}: {key} in [{value.min()}, {value.max()}]"
        if key in NON_NEGATIVE:
            assert value.min() >= 0.0, f"{name}: {key} down to {value.min()}"
        if key == "depth_stats":  # mean, std, lo, hi of each volume pixel
            assert value[:, 1].min() > 0.0 and np.all(value[:, 2] < value[:, 3]), f"{name}: {key}"


def _run_graphs(session, feeds: dict, name: str, graphs=("render_heat", "render_rgb", "render", "query")) -> dict:
    """encoder (and human) -> volume -> the render and query graphs, each output checked."""
    feeds = dict(feeds)
    for graph in ("human", "encoder"):
        if session.has(graph):
            out = session.run(graph, feeds)
            _check_graph_outputs(f"{name} {graph}", out)
            if graph == "encoder":
                feeds.update(out)
    out = session.run("volume", feeds)
    _check_graph_outputs(f"{name} volume", out)
    feeds.update(out)
    for graph in graphs:
        if session.has(graph):
            _check_graph_outputs(f"{name} {graph}", session.run(graph, feeds))
    return feeds


def _feeds(session, targets: int) -> dict:
    from ghnerf_runtime.session import warmup_feeds

    return warmup_feeds(session.contract, targets=targets)


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("variant", ["ghnerf", "baseline"])
@pytest.mark.parametrize("kind", FRAME_KINDS + ("identical",))
def test_every_graph_is_finite_and_in_range_on_extreme_images(variant, precision, kind):
    """A flat image is the scene normalisation's ``x / sqrt(var + eps)`` with var 0, and the depth softmax over
    a featureless cost volume; identical images give a zero two-view variance everywhere."""
    s = _session(variant, precision)
    for targets in (2, 1):  # the sources as targets (keypoints), one novel camera
        feeds = _feeds(s, targets)
        feeds["images"] = _model_images(kind, s.contract.height)
        _run_graphs(s, feeds, f"{variant} {precision} {kind} B={targets}")


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("near_far", [
    (0.05, 0.051),  # near_far_from_box's floors: min_near, and far at least 1 mm beyond it
    (2.0, 2.001), (4.0, 4.001),  # a thin box at the simulated rig's working volume's near and far ends
    (3.0, 3.0),  # near == far: beyond the helper's floor (float32 loses its 1 mm past ~16 km), still finite
    (0.05, 1000.0),  # one plane sweep over everything
    (100.0, 100.001), (2e4, 2e4),  # far outside any working volume
], ids=str)
def test_every_graph_is_finite_at_depth_range_extremes(precision, near_far):
    """``1 / near`` and ``1 / far`` of the inverse-depth planes, the interval refined to ``min_depth_range`` when
    near and far (almost) meet, the linear plane index ``(z - lo) / (hi - lo)`` of ``query``."""
    s = _session("ghnerf", precision)
    for targets in (2, 1):
        feeds = _feeds(s, targets)
        feeds["near_far"] = np.tile(np.array(near_far, np.float32), (targets, 1))
        out = _run_graphs(s, feeds, f"{precision} near_far={near_far} B={targets}")
        lo, hi = out["depth_stats"][:, 2], out["depth_stats"][:, 3]
        assert lo.min() > 0.0  # the sweep never reaches behind the camera


@pytest.mark.parametrize("precision", PRECISIONS)
def test_every_graph_is_finite_for_rays_off_the_image_and_points_at_the_cameras(precision):
    """A ray's direction ``K^-1 (u, v, 1)`` has unit camera depth, so it tends to the image plane only as
    ``|uv|`` grows: rays at 1e6 px are as near parallel as float32 feeds get. Query points at a camera's
    centre (camera depth exactly 0), on its principal plane, behind it and far off hit the projection's
    division by depth and ``unit()`` of a zero vector (colour's view directions)."""
    s = _session("ghnerf", precision)
    base = _feeds(s, 2)
    for uv in ([-0.5, -0.5], [127.5, 127.5], [-1e3, 64.0], [64.0, -1e5], [1e6, 1e6]):
        feeds = dict(base)
        feeds["ray_uv"] = np.tile(np.array(uv, np.float32), (2, 16, 1))
        _run_graphs(s, feeds, f"{precision} ray_uv={uv}", graphs=("render_heat", "render_rgb", "render"))
    centres = base["src_centers"]
    points = [centres[0], centres[1], centres[0] + [0.5, 0.0, 0.0], centres[0] - [0.0, 0.0, 1.0],
              [0.0, -1.0, 1e3], [0.0, -1.0, -1e3], [1e6, 1e6, 1e6]]
    for p in points:
        feeds = dict(base)
        feeds["points"] = np.tile(np.asarray(p, np.float32), (2, 8, 1))
        _run_graphs(s, feeds, f"{precision} point={np.round(p, 2).tolist()}", graphs=("query",))
    # the novel camera standing at a source camera: its rays start at that camera's centre
    feeds = _feeds(s, 1)
    feeds["tgt_c2w"] = feeds["tgt_c2w"].copy()
    feeds["tgt_c2w"][0, :, 3] = centres[0]
    _run_graphs(s, feeds, f"{precision} target at a source centre")


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("case", ["swapped images", "identical cameras", "swapped cameras"])
def test_every_graph_is_finite_with_identical_or_swapped_sources(precision, case):
    s = _session("ghnerf", precision)
    feeds = _feeds(s, 2)
    if case == "swapped images":
        feeds["images"] = feeds["images"][::-1].copy()
    elif case == "identical cameras":  # no baseline: zero parallax, identical view directions
        feeds["src_P"] = np.repeat(feeds["src_P"][:1], 2, axis=0)
        feeds["src_centers"] = np.repeat(feeds["src_centers"][:1], 2, axis=0)
    else:
        feeds["src_P"] = feeds["src_P"][::-1].copy()
        feeds["src_centers"] = feeds["src_centers"][::-1].copy()
    _run_graphs(s, feeds, f"{precision} {case}")


# ------------------------------------------------------------------ estimator level
_ESTIMATORS: dict = {}


@pytest.fixture(scope="module", autouse=True)
def _close_the_estimators():
    """Close this module's estimators after its tests: their novel-view worker threads outlived the module, and a
    test run after it that asserts no such thread is left (test_estimator_oracle's overlap test, run in another
    order than the files' names) failed on them."""
    yield
    for est in _ESTIMATORS.values():
        est.close()
    _ESTIMATORS.clear()


def _rig(**placement):
    sim = pytest.importorskip("drivers.sim")
    return sim.RigPlacement(**placement).build()


def _estimator(precision: str, frame_check: bool = True, roi: RoiConfig | None = None, presence: bool = True):
    """An estimator over the default simulated rig with the novel view (and its heatmaps) on; reset."""
    from ghnerf_runtime.estimator import Estimator

    key = (precision, frame_check, roi, presence)
    if key not in _ESTIMATORS:
        cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), precision=precision, threads=2),
                              frame_check=FrameCheckConfig(enabled=frame_check), roi=roi or RoiConfig(),
                              novel_view=NovelViewConfig(enabled=True, heatmaps=True),
                              presence=PresenceConfig(enabled=presence))
        _ESTIMATORS[key] = Estimator.from_config(_rig(), cfg)
    est = _ESTIMATORS[key]
    est.reset()
    return est


def _assert_sane(r, name: str) -> None:
    """What every PairResult promises (docs/runtime.md, the per-frame JSON): finite, or missing and then 0."""
    assert np.isfinite(r.joints_3d).all() and np.isfinite(r.confidence).all(), name
    assert r.confidence.min() >= 0.0 and r.confidence.max() <= 1.0, (name, r.confidence)
    assert not r.joints_3d[r.missing].any() and not r.confidence[r.missing].any(), name
    for cam in r.joints_2d:
        uv, conf, missing = r.joints_2d[cam], r.confidence_2d[cam], r.missing_2d[cam]
        assert np.isfinite(uv).all() and np.isfinite(conf).all(), (name, cam)
        assert conf.min() >= 0.0 and conf.max() <= 1.0, (name, cam, conf)
        assert not uv[missing].any() and not conf[missing].any(), (name, cam)
    json.dumps(r.to_json(), allow_nan=False)
    nv = r.novel_view
    if nv is not None:
        assert nv.image.dtype == np.uint8 and nv.image.ndim == 3, name
        assert np.isfinite(nv.depth).all() and nv.depth.min() >= 0.0, name
        assert np.isfinite(nv.heat).all() and nv.heat.min() >= 0.0 and nv.heat.max() <= 1.0, name


def _frames(kind: str, size=(480, 640)) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    h, w = size
    if kind == "black":
        return [np.zeros((h, w, 3), np.uint8)] * 2
    if kind == "white":
        return [np.full((h, w, 3), 255, np.uint8)] * 2
    if kind == "grey":
        return [np.full((h, w, 3), 128, np.uint8)] * 2
    if kind == "noise":
        return [rng.integers(0, 256, (h, w, 3)).astype(np.uint8) for _ in range(2)]
    if kind == "one_pixel":
        one = np.zeros((h, w, 3), np.uint8)
        one[h // 2, w // 2] = 255
        return [one, one.copy()]
    if kind == "dark":
        return [rng.integers(0, 4, (h, w, 3)).astype(np.uint8) for _ in range(2)]
    raise ValueError(kind)


#: The novel view's alphas: the cameras themselves, between, and slightly outside [0, 1] (legal to [-1, 2]).
ALPHAS = (0.0, 0.5, 1.0, -0.1, 1.1)


def _estimate_with_views(est, frames, name: str, alphas=ALPHAS, subject=None):
    """One pair per alpha (cold, then tracked where someone is found), every result checked; the last one."""
    from ghnerf_runtime.novel_view import NovelViewRequest

    r = None
    for i, alpha in enumerate(alphas):
        pair = frames if subject is None else subject(0.2 + i / 30)
        r = est.estimate(pair, novel_view=NovelViewRequest(alpha=alpha, overlay="heatmap"), timestamp_s=i / 30)
        _assert_sane(r, f"{name} alpha={alpha}")
    return r


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("frame_check", [True, False], ids=["checked", "unchecked"])
@pytest.mark.parametrize("kind", FRAME_KINDS)
def test_estimator_on_frames_of_nobody(precision, frame_check, kind):
    """With the frame check (the default) these crops never reach the model; without it the model runs on them
    and must say "nobody" in finite numbers. Neither pair gets a novel view (a rejected pair, and one with nobody
    in it: documented); with the presence gate off as well, the view is rendered at every alpha, finite."""
    est = _estimator(precision, frame_check)
    r = _estimate_with_views(est, _frames(kind), f"{precision} {kind}")
    assert r.num_found == 0 and not r.confidence.any()
    assert (not any(r.frame_ok.values())) if frame_check else all(r.frame_ok.values()), r.frame_ok
    assert r.novel_view is None
    if not frame_check:
        r = _estimate_with_views(_estimator(precision, frame_check, presence=False), _frames(kind),
                                 f"{precision} {kind} (presence gate off)")
        assert r.novel_view is not None and all(r.frame_ok.values())


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("position_xz, inside", [
    ((0.0, 2.0), True), ((0.0, 4.0), True),  # the working volume's near and far ends (z 2..4 m)
    ((0.8, 2.0), True), ((-0.8, 4.0), True),  # its corners at those ends (x +-0.8 m)
    ((0.0, 1.8), False), ((0.0, 4.3), False),  # just outside it
], ids=str)
def test_estimator_with_the_subject_at_the_ends_of_the_working_volume(precision, position_xz, inside):
    """The plane sweep's near/far come from the subject box: at the volume's ends it is clamped by the volume
    box, just outside it the cold crop and sweep show part of the subject. Measured (this test's pairs, the
    shipped tenth model): 22-25 joints, MPJPE 12-23 mm inside, 14-28 mm just outside, in both precisions."""
    sim = pytest.importorskip("drivers.sim")
    est = _estimator(precision)
    rig = est.rig
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave", position_xz=position_xz))

    def pair(t):
        return [scene.render(c, t, with_truth=False)[0] for c in rig.pair]

    r = _estimate_with_views(est, None, f"{precision} at {position_xz}", subject=pair)
    t_last = 0.2 + (len(ALPHAS) - 1) / 30
    found = ~r.missing
    assert found.sum() >= 15, r.num_found
    err_mm = 1e3 * np.linalg.norm(r.joints_3d[found] - scene.joints_3d(t_last)[found], axis=1)
    assert err_mm.mean() <= (60.0 if inside else 100.0), err_mm


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("roi", ["min_size", "min_size off the frame", "max_size", "max_size config"])
def test_estimator_with_crop_boxes_of_the_extreme_sizes(precision, roi):
    """``roi.min_size_px`` allows 8..4096 px: an 8 px crop (a 16x upsampling to the model's 128) on the subject
    and wholly off the frame (all padding), and a 4096 px one (the 640x480 frame a small patch in it), given as
    the tracked regions; and the same maximum through the configuration's own tracking path."""
    from ghnerf_runtime.preprocess import Roi
    from ghnerf_runtime.tracking import Regions

    sim = pytest.importorskip("drivers.sim")
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave"))
    if roi == "max_size config":
        est = _estimator(precision, roi=RoiConfig(min_size_px=4096))
    else:
        est = _estimator(precision)
        box = np.stack([est.rig.volume.min_corner, est.rig.volume.max_corner])
        window = {"min_size": Roi(316, 236, 8), "min_size off the frame": Roi(-4000, -4000, 8),
                  "max_size": Roi(-1728, -1808, 4096)}[roi]
        regions = Regions((window, window), box, True)
        est.tracker.regions = lambda: regions  # shadows the method on this instance only
    try:
        _estimate_with_views(est, None, f"{precision} {roi}",
                             subject=lambda t: [scene.render(c, t, with_truth=False)[0] for c in est.rig.pair])
    finally:
        est.tracker.__dict__.pop("regions", None)  # the method again, for the next test


@pytest.mark.parametrize("precision", PRECISIONS)
@pytest.mark.parametrize("case", ["identical", "swapped"])
def test_estimator_with_identical_or_swapped_images(precision, case):
    """Both cameras given the left image, or the two images swapped: a wrong pair, which the runtime cannot
    tell from a right one, but its numbers stay finite and its joints inside the working volume's gate."""
    sim = pytest.importorskip("drivers.sim")
    est = _estimator(precision)
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave"))

    def pair(t):
        left, right = (scene.render(c, t, with_truth=False)[0] for c in est.rig.pair)
        return [left, left.copy()] if case == "identical" else [right, left]

    r = _estimate_with_views(est, None, f"{precision} {case}", subject=pair)
    margin = est.config.joints3d.max_outside_box_m
    pts = r.joints_3d[~r.missing]
    assert np.all(pts >= est.rig.volume.min_corner - margin - 1e-9)
    assert np.all(pts <= est.rig.volume.max_corner + margin + 1e-9)


def _moved_rig(rig, offset):
    """``rig`` with its frame's origin moved by ``-offset``: every camera and the working volume at ``offset``."""
    from ghnerf_runtime.geometry.rig import Rig, WorkingVolume

    offset = np.asarray(offset, np.float64)
    cameras = tuple(c.with_pose(c.R, c.t - c.R @ offset) for c in rig.cameras)
    return Rig(cameras, WorkingVolume(rig.volume.min_corner + offset, rig.volume.max_corner + offset), rig.rig_id,
               rig.metadata)


@pytest.mark.parametrize("offset", [(1000.0, 0.0, 1000.0), (7000.0, 0.0, 7000.0)], ids=["1.4 km", "9.9 km"])
def test_a_rig_far_from_its_origin_gives_the_joints_of_the_rig_at_it_moved(offset):
    """The graphs take the cameras' matrices and centres in float32 (``contract.source_projections``), whose
    spacing is 0.06 mm at 1 km and 1 mm at 10 km: a rig file whose origin lies that far from the cameras (the
    convention puts it under them, nothing enforces it) gives the joints of the same rig at its origin, moved,
    within 5 mm (the floor, y = 0, stays where it is: the frame's height is no free choice)."""
    from ghnerf_runtime.estimator import Estimator

    sim = pytest.importorskip("drivers.sim")
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave"))
    near = _rig()
    pairs = [(t, [scene.render(c, t, with_truth=False)[0] for c in near.pair]) for t in np.arange(6) / 30]
    answers = []
    for rig in (near, _moved_rig(near, offset)):
        cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), precision="int8", threads=2))
        with Estimator.from_config(rig, cfg) as est:
            for t, pair in pairs:
                r = est.estimate(pair, timestamp_s=t)
            _assert_sane(r, f"rig at {offset}" if rig is not near else "rig at 0")
            answers.append(r)
    at_origin, moved = answers
    assert moved.num_found >= 20 and np.array_equal(moved.missing, at_origin.missing)
    found = ~moved.missing
    gap = np.abs(moved.joints_3d[found] - offset - at_origin.joints_3d[found]).max()
    assert gap < 5e-3, gap


@pytest.mark.parametrize("precision", PRECISIONS)
def test_novel_views_at_the_alpha_bounds_and_at_odd_cameras(precision):
    """alpha -1 and 2 (the bounds ``NovelViewRequest`` allows), and requested cameras standing at a source
    camera, inside the subject box, facing away from it, far off and looking straight down on it."""
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
    from ghnerf_runtime.novel_view import NovelViewRequest

    sim = pytest.importorskip("drivers.sim")
    est = _estimator(precision)
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave"))
    pair = [scene.render(c, 0.2, with_truth=False)[0] for c in est.rig.pair]
    _estimate_with_views(est, pair, f"{precision} alpha bounds", alphas=(-1.0, 2.0))
    K = intrinsics_from_fov(640, 480, 60.0)

    def camera(eye, target):
        return Camera("novel", 640, 480, K, np.zeros(5), *look_at(eye, target))

    cameras = {"at a source": camera(est.rig.pair[0].center, (0.0, -1.0, 3.0)),
               "inside the box": camera((0.0, -1.0, 3.0), (0.0, -1.0, 5.0)),
               "facing away": camera((0.0, -1.0, 0.0), (0.0, -1.0, -3.0)),
               "far off": camera((0.0, -1.0, -200.0), (0.0, -1.0, 3.0)),
               "overhead": camera((0.0, -10.0, 3.0), (0.0, -1.0, 3.0001))}
    for name, cam in cameras.items():
        r = est.estimate(pair, novel_view=NovelViewRequest(camera=cam, overlay="heatmap"))
        _assert_sane(r, f"{precision} {name}")
        assert r.novel_view is not None and r.num_found > 0, name


def test_a_requested_camera_beyond_float32_depths_is_a_typed_error_naming_the_box():
    """A camera 20 km off (past ``MAX_DEPTH_M``): its near/far were handed to the graphs as float32 that had lost
    the millimetre between them (at 1e200 m, inf). The view cannot be served: a DepthRangeError says why."""
    from ghnerf_runtime.errors import DepthRangeError
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov, look_at
    from ghnerf_runtime.novel_view import NovelViewRequest

    sim = pytest.importorskip("drivers.sim")
    est = _estimator("fp32")
    scene = sim.SimScene(sim.SceneConfig(seed=1, motion="wave"))
    pair = [scene.render(c, 0.2, with_truth=False)[0] for c in est.rig.pair]
    far = Camera("far", 640, 480, intrinsics_from_fov(640, 480, 2.0), np.zeros(5),
                 *look_at((0.0, -1.0, -2e4), (0.0, -1.0, 3.0)))
    said = r"\(rig frame, grown by 0\.1 m\) reaches 2000\d\.\d+ m from camera 'far'"
    with pytest.raises(DepthRangeError, match=said):
        est.estimate(pair, novel_view=NovelViewRequest(camera=far))
    assert est.estimate(pair).num_found > 0  # the estimator goes on


@pytest.mark.parametrize("alpha", [-1.0001, 2.0001, float("nan"), float("inf")])
def test_a_novel_view_alpha_past_its_bounds_is_a_typed_error(alpha):
    """Past [-1, 2] the request is refused with the documented GeometryError, before any graph runs."""
    from ghnerf_runtime.novel_view import NovelViewRequest

    with pytest.raises(GeometryError, match="alpha must be in"):
        NovelViewRequest(alpha=alpha)
