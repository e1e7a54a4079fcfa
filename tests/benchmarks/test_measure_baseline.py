"""``benchmarks/measure_baseline.py``: its rigs are what the table says (the baseline asked for, the frame lifted with
its geometry kept), and its command line runs (the tiny test export, random weights: the figures mean nothing)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.measure_baseline import lifted, rig_with_baseline
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


@pytest.mark.parametrize("baseline_m", [0.02, 0.6])
def test_the_rig_has_the_baseline_asked_for_below_the_simulator_s_own_floor(baseline_m):
    rig = rig_with_baseline(baseline_m, 3.0)
    assert rig.baseline == pytest.approx(baseline_m, abs=1e-12)
    assert [-c.center[1] for c in rig.pair] == pytest.approx([1.3, 1.3])


def test_a_lifted_rig_keeps_every_pixel_of_a_point_lifted_with_it():
    rig = rig_with_baseline(1.2, 3.0)
    up = lifted(rig, 50.0)
    point = np.array([[0.1, -1.0, 3.0]])
    for a, b in zip(rig.pair, up.pair):
        assert b.project(point - [0.0, 50.0, 0.0])[0] == pytest.approx(a.project(point)[0], abs=1e-6)
    assert up.volume.max_corner[1] == pytest.approx(rig.volume.max_corner[1] - 50.0)


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_baseline", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1",
                     "--baselines", "0.02,0.6", "--lifts", "0,50", capsys=capsys, monkeypatch=monkeypatch)
    assert "| 0.02 | 0.38 | 1.180 |" in out and "| 0.6 | 11.37 | 0.039 |" in out, out
    assert "| 50 | 51.30 |" in out, out
