"""``benchmarks/measure_floor_signals.py``: the pan's effect on the feet that it divides by is the effect a pan has
(docs/calibration.md, "Half-degree pans: other signals tried"), its window statistics, and its command line runs
(the tiny test export, random weights: the figures mean nothing)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.measure_calibration_drift import turned
from benchmarks.measure_floor_signals import caught, floor_height_per_pan_deg, trimmed_mean
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, look_at, triangulate_dlt
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


def _level_rig(baseline_m: float = 1.0, height_m: float = 1.6) -> Rig:
    K = [[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]]
    cams = tuple(Camera(n, 640, 480, K, [], *look_at((x, -height_m, 0), (0, -1.0, 3)))
                 for n, x in (("left", -baseline_m / 2), ("right", baseline_m / 2)))
    return Rig(cams, WorkingVolume((-0.5, -2, 2.5), (0.5, 0, 3.5)), "test")


def _height_after_pan(rig: Rig, point: np.ndarray, camera: int, deg: float) -> float:
    """The height ``point`` triangulates at once ``camera``'s rig entry is panned ``deg`` (what the runtime reads)."""
    uv = np.stack([c.project(point[None])[0] for c in rig.cameras])
    return float(-triangulate_dlt(uv, list(turned(rig, camera, "pan", deg).cameras)).points[0, 1])


@pytest.mark.parametrize("camera", [0, 1])
def test_the_pan_effect_predicts_a_half_degree_pan_of_either_camera(camera):
    rig, foot = _level_rig(), np.array([0.2, 0.0, 3.2])
    effect = floor_height_per_pan_deg(rig, foot, camera)
    for deg in (-0.5, 0.5):
        assert _height_after_pan(rig, foot, camera, deg) == pytest.approx(deg * effect, rel=0.05, abs=1e-4)
    assert abs(effect) > 0.02  # a pan does move a foot 3 m away by centimetres


def test_the_pan_effect_grows_with_the_distance_and_shrinks_with_the_baseline():
    rig = _level_rig()
    near, far = (abs(floor_height_per_pan_deg(rig, np.array([0.0, 0.0, z]), 1)) for z in (2.5, 4.0))
    assert far > 1.3 * near
    wide = abs(floor_height_per_pan_deg(_level_rig(baseline_m=2.0), np.array([0.0, 0.0, 3.0]), 1))
    assert wide < 0.7 * abs(floor_height_per_pan_deg(rig, np.array([0.0, 0.0, 3.0]), 1))


def test_window_statistics():
    assert trimmed_mean(np.array([0.0, 0.01, 0.02, 0.03, 0.5])) == pytest.approx(0.02)
    assert trimmed_mean(np.array([0.1, 0.3])) == pytest.approx(0.2)  # too few to drop any
    assert caught([0.06, -0.07, 0.01, 0.05], 0.05) == 2  # either way, strictly past the limit


def test_the_command_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_floor_signals", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "2",
                     "--window", "2", capsys=capsys, monkeypatch=monkeypatch)
    assert "1 sequences x 2 pairs, one 2-pair window each" in out, out
    assert "median (today)" in out, out
