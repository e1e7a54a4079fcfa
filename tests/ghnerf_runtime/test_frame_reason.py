"""``PairResult.frame_reason``: why the frame check rejected a camera's crop, in the result and its JSON."""
from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks.bench_runtime_common import OracleSession, edge128_contract
from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.config import EstimatorConfig
from ghnerf_runtime.estimator import Estimator, PairResult
from ghnerf_runtime.frame_reasons import FLAT, NOISE, NON_FINITE, REASONS

sim = pytest.importorskip("drivers.sim")

#: The per-pair JSON keys before session 51 (docs/runtime.md), which stay as they were.
KEYS_BEFORE = {"sequence", "joint_names", "joints_3d", "joints_2d", "missing", "missing_2d", "tracked", "frame_ok",
               "method", "timing_ms"}


@pytest.fixture(scope="module")
def shot():
    """The rig and one pair of a person in view."""
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    rendered = [scene.render(c, 0.0) for c in rig.pair]
    visible = np.stack([tr.visible for _, tr in rendered])
    return rig, tuple(img for img, _ in rendered), scene.joints_3d(0.0), visible


def _estimate(shot, images, truth: bool = True) -> PairResult:
    """The pair through the estimator on oracle heatmaps (``truth`` False: all-zero heatmaps, which the
    single-view pass needs, since the oracle draws its truth from both views' projections)."""
    rig, _, j3, visible = shot
    oracle = OracleSession(edge128_contract())
    if truth:
        oracle.set_truth(j3, visible)
    return Estimator(oracle, rig, EstimatorConfig()).estimate(images)


def _noise(image: np.ndarray) -> np.ndarray:
    return np.random.default_rng(3).integers(0, 256, image.shape, dtype=np.uint8)


def test_a_good_pair_has_no_reason(shot):
    rig, pair, *_ = shot
    r = _estimate(shot, pair)
    names = [c.name for c in rig.pair]
    assert r.frame_reason == {n: None for n in names} and all(r.frame_ok.values())
    assert r.num_found > 6  # the model ran


def test_a_black_pair_is_flat_in_both_cameras(shot):
    rig, pair, *_ = shot
    r = _estimate(shot, tuple(np.zeros_like(f) for f in pair))
    assert r.frame_reason == {c.name: FLAT for c in rig.pair}
    assert not any(r.frame_ok.values()) and r.missing.all()


def test_a_noise_frame_is_named_in_its_camera_and_the_good_one_has_none(shot):
    """One camera sending garbage: the single-view pass keeps the other camera's reason None."""
    rig, pair, *_ = shot
    left, right = (c.name for c in rig.pair)
    r = _estimate(shot, (pair[0], _noise(pair[1])), truth=False)
    assert r.frame_reason == {left: None, right: NOISE}
    assert r.frame_ok == {left: True, right: False}
    r = _estimate(shot, (np.full_like(pair[0], 255), _noise(pair[1])), truth=False)  # saturated: no contrast, so "flat"
    assert r.frame_reason == {left: FLAT, right: NOISE}


def test_the_json_carries_the_reason_and_keeps_the_old_keys(shot):
    rig, pair, *_ = shot
    left, right = (c.name for c in rig.pair)
    r = _estimate(shot, (np.zeros_like(pair[0]), pair[1]), truth=False)
    obj = json.loads(json.dumps(r.to_json(), allow_nan=False))
    # additive: every earlier key is still there (the skeleton prior's check came in session 52, the two-people
    # flag, single_view and the views' agreement in 53, the lowest foot in 54, someone_else in 64)
    assert set(obj) == KEYS_BEFORE | {"frame_reason", "prior_disagreement_m", "prior_fallback", "several_people",
                                      "single_view", "reprojection_px_median", "lowest_foot_m", "someone_else"}
    assert obj["someone_else"] is None  # presence.scan_every_s off (the default): never scanned
    assert obj["reprojection_px_median"] is None and obj["lowest_foot_m"] is None  # a frame rejected: nothing measured
    assert obj["single_view"] is None  # (the oracle's heatmaps are zeros here: nobody in the good camera either)
    assert obj["frame_reason"] == {left: FLAT, right: None}  # null: the frame passed
    assert list(obj["frame_reason"]) == list(obj["frame_ok"]) == [left, right]  # rig order
    assert obj["frame_ok"] == {left: False, right: True}


def _result(frame_ok: dict, **kw) -> PairResult:
    n = len(JOINT_NAMES)
    names = list(frame_ok)
    return PairResult(0, JOINT_NAMES, np.zeros((n, 3)), np.zeros(n, np.float32), np.ones(n, bool),
                      {c: np.zeros((n, 2)) for c in names}, {c: np.zeros(n) for c in names},
                      {c: np.ones(n, bool) for c in names}, {"total": 1.0}, False, frame_ok, {}, "stub", **kw)


def test_a_result_built_without_reasons_passes_only_when_every_frame_passed():
    assert _result({"a": True, "b": True}).frame_reason == {"a": None, "b": None}
    with pytest.raises(ValueError, match=r"frame_reason\['b'\] is None but frame_ok\['b'\] is False"):
        _result({"a": True, "b": False})
    with pytest.raises(ValueError, match="'dark' is not one of"):
        _result({"a": True, "b": False}, frame_reason={"a": None, "b": "dark"})
    with pytest.raises(ValueError, match="cameras"):
        _result({"a": True, "b": False}, frame_reason={"a": None})
    assert _result({"a": True, "b": False}, frame_reason={"a": None, "b": NON_FINITE}).to_json()["frame_reason"] \
        == {"a": None, "b": NON_FINITE}


def test_single_view_names_a_camera_whose_frame_passed():
    """``PairResult.single_view``: the camera whose 2D joints alone are the answer; the model ran on its frame."""
    assert _result({"a": True, "b": True}).single_view is None
    assert _result({"a": True, "b": True}, single_view="b").to_json()["single_view"] == "b"
    with pytest.raises(ValueError, match=r"single_view: 'b' is not a camera whose frame passed"):
        _result({"a": True, "b": False}, frame_reason={"a": None, "b": FLAT}, single_view="b")
    with pytest.raises(ValueError, match=r"single_view: 'c' is not a camera"):
        _result({"a": True, "b": True}, single_view="c")


def test_the_reasons_are_the_words_the_check_returns():
    from ghnerf_runtime.config import FrameCheckConfig
    from ghnerf_runtime.estimator import check_crop

    cfg = FrameCheckConfig()
    bad = np.random.default_rng(0).random((64, 64)).astype(np.float32)
    words = {check_crop(bad, 255.0, cfg)[1], check_crop(np.zeros((64, 64), np.float32), 255.0, cfg)[1]}
    bad[3, 3] = np.nan
    words.add(check_crop(bad, 255.0, cfg)[1])
    assert words == set(REASONS)


def test_the_docs_name_every_reason():
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    runtime, daemon = ((root / "docs" / f).read_text(encoding="utf-8") for f in ("runtime.md", "daemon.md"))
    for word in REASONS:
        assert f"| `{word}` |" in runtime, word  # the table of docs/runtime.md, "Frame check"
        assert f"`{word}`" in daemon.split("frames_rejected", 1)[1].split("\n", 1)[0], word  # rig.frames_rejected


def test_the_session_53_fields_hold_only_what_the_json_can_say():
    """``reprojection_px_median`` is a finite number >= 0 or None (``to_json`` promises no NaN: a NaN one was
    accepted and failed only at ``json.dumps(..., allow_nan=False)``, in whoever wrote the line); ``single_view``
    never goes with ``several_people`` (the estimator keeps no one view's joints of two people)."""
    ok = _result({"a": True, "b": True}, reprojection_px_median=np.float64(0.25))
    assert json.loads(json.dumps(ok.to_json(), allow_nan=False))["reprojection_px_median"] == 0.25
    for bad in (float("nan"), float("inf"), -0.5, "0.3"):
        with pytest.raises(ValueError, match=r"reprojection_px_median must be a finite number >= 0 or None"):
            _result({"a": True, "b": True}, reprojection_px_median=bad)
    with pytest.raises(ValueError, match=r"single_view 'a' with several_people"):
        _result({"a": True, "b": True}, single_view="a", several_people=True)


def test_the_lowest_foot_holds_only_what_the_json_can_say():
    """``lowest_foot_m`` is a finite number (below the floor is negative) or None, rounded to 0.1 mm in the JSON."""
    ok = _result({"a": True, "b": True}, lowest_foot_m=np.float64(-0.12345))
    assert json.loads(json.dumps(ok.to_json(), allow_nan=False))["lowest_foot_m"] == -0.1235
    assert _result({"a": True, "b": True}).to_json()["lowest_foot_m"] is None
    for bad in (float("nan"), float("inf"), "0.3", [0.1]):
        with pytest.raises(ValueError, match=r"lowest_foot_m must be a finite number or None"):
            _result({"a": True, "b": True}, lowest_foot_m=bad)
