"""Cameras mounted on their side, upside down or crooked: the crops are rotated upright (``roi.upright``).

The model was trained on upright views only. Before the crops were rotated, the shipped model found no
joint through a camera on its side and placed half of them about a metre off through one upside down.
Runs the shipped model on a simulated sequence seen by the same rig rolled about each optical axis.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ghnerf_runtime.config import EstimatorConfig, RoiConfig, SessionConfig
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.rig_file import dumps_rig, loads_rig

MODELS = Path(__file__).resolve().parents[2] / "models"
pytestmark = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model in models/")

def rolled(rig: Rig, degrees: float) -> Rig:
    """The rig with every camera rolled (the benchmark's), through a rig file as a user would load it."""
    from benchmarks.measure_mounting import rolled as roll_cameras

    return rig if degrees == 0 else loads_rig(dumps_rig(roll_cameras(rig, degrees)))


@pytest.fixture(scope="module")
def run():
    import drivers.sim as sim
    from ghnerf_runtime.estimator import Estimator, load_session

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS / "ghnerf"), warmup=False))
    session = load_session(cfg)
    scene = sim.SimScene(sim.SceneConfig(seed=7, motion="wave"))
    base = sim.RigPlacement().build()

    def estimate(degrees: int, upright: bool = True) -> dict:
        rig = rolled(base, degrees)
        est = Estimator(session, rig, EstimatorConfig(session=cfg.session, roi=RoiConfig(upright=upright)))
        found, errors_3d, errors_2d = [], [], []
        for t in np.arange(0.0, 0.4, 1 / 15):
            shots = [scene.render(c, t) for c in rig.pair]
            r = est.estimate([image for image, _ in shots], timestamp_s=t)
            ok = ~r.missing
            found.append(int(ok.sum()))
            errors_3d += list(1000 * np.linalg.norm(r.joints_3d[ok] - scene.joints_3d(t)[ok], axis=1))
            for cam, (_, truth) in zip(rig.pair, shots):
                seen = ~r.missing_2d[cam.name] & truth.visible
                errors_2d += list(np.linalg.norm(r.joints_2d[cam.name][seen] - truth.joints_2d[seen], axis=1))
        return {"roll": [round(st.roll_deg, 6) for st in est._cams], "found": float(np.mean(found)),
                "mpjpe_mm": float(np.mean(errors_3d)) if errors_3d else np.inf,
                "median_2d_px": float(np.median(errors_2d)) if errors_2d else np.inf}

    return estimate


@pytest.mark.parametrize("degrees", [90, 180, 30])
def test_a_rolled_rig_sees_what_the_upright_one_does(run, degrees):
    upright, mounted = run(0), run(degrees)
    assert upright["roll"] == [0.0, 0.0]
    np.testing.assert_allclose((np.array(mounted["roll"]) + degrees + 180) % 360 - 180, 0.0, atol=1e-6)
    assert mounted["found"] >= upright["found"] - 1.0, (mounted, upright)
    assert mounted["mpjpe_mm"] <= upright["mpjpe_mm"] + 10.0, (mounted, upright)
    # 2D joints come back in the sensor's own pixels, as mounted
    assert mounted["median_2d_px"] <= upright["median_2d_px"] + 1.5, (mounted, upright)


def test_without_upright_crops_an_upside_down_rig_is_wrong(run):
    """What ``roi.upright`` is for: the same sequence, crops left in the sensor's orientation."""
    upright, as_mounted = run(0), run(180, upright=False)
    assert as_mounted["roll"] == [0.0, 0.0]
    assert as_mounted["mpjpe_mm"] > 3 * upright["mpjpe_mm"] or as_mounted["found"] < upright["found"] / 2
