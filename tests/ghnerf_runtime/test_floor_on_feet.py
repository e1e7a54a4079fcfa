"""The floor check's figure (``PairResult.lowest_foot_m``) comes from a person standing on their feet only: one
upside down (a handstand: feet 1.6 m up) or lying (feet a little above the floor, the neck beside them) says
nothing of where the floor is, and a window of them would read to the daemon's ``FloorWatch`` as a camera
turned since calibration. The oracle session (``benchmarks.bench_runtime_common``) answers the true joints'
heatmaps, so the estimator triangulates the poses as they are, whatever the trained model makes of them."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_runtime_common import OracleSession, edge128_contract
from benchmarks.measure_lying_rendered import posed_as, render_pair
from ghnerf_runtime.config import EstimatorConfig
from ghnerf_runtime.estimator import Estimator


def _feet(pose: str) -> list[float | None]:
    """``lowest_foot_m`` of three pairs of a waving person in ``pose`` (the oracle's heatmaps, the defaults)."""
    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=2, motion="wave"))
    oracle = OracleSession(edge128_contract())
    out = []
    with Estimator(oracle, rig, EstimatorConfig()) as est:
        for k in range(3):
            t = 0.1 * k
            body = posed_as(scene.posed(t), pose, rig.volume)
            oracle.set_truth(body.joints)
            images, _, _ = render_pair(scene, rig, body, t)
            r = est.estimate(images, timestamp_s=t)
            assert r.num_found > 15, (pose, r.num_found)  # someone is reported: only the floor figure is withheld
            out.append(r.lowest_foot_m)
    return out


def test_a_standing_person_s_feet_are_on_the_floor():
    feet = _feet("upright")
    assert all(f is not None and abs(f) < 0.08 for f in feet), feet


@pytest.mark.parametrize("pose", ["upside_down", "lying_z"])
def test_a_person_not_on_their_feet_gives_no_floor_figure(pose):
    assert _feet(pose) == [None, None, None]


def test_the_figure_takes_the_standing_foot_from_the_config():
    """Soles or a mat raise every foot joint: the person rendered 3 cm above the floor reads 3 cm higher, and with
    ``joints3d.foot_standing_m`` raised by those 3 cm (what ``ghnerf-daemon --measure-floor`` has a user set) reads
    as the person on the floor at the default; the figure of the same pairs moves by exactly the setting's change."""
    from dataclasses import replace

    sim = pytest.importorskip("drivers.sim")
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=2, motion="wave"))
    oracle = OracleSession(edge128_contract())
    default = EstimatorConfig()
    raised_by = default.joints3d.foot_standing_m + 0.03
    soles = replace(default, joints3d=replace(default.joints3d, foot_standing_m=raised_by))

    def feet(lift_m: float, config: EstimatorConfig) -> np.ndarray:
        out = []
        with Estimator(oracle, rig, config) as est:
            for k in range(3):
                t = 0.1 * k
                body = scene.posed(t).transformed(np.eye(3), np.array([0.0, -lift_m, 0.0]))  # y down: raised
                oracle.set_truth(body.joints)
                images, _, _ = render_pair(scene, rig, body, t)
                out.append(est.estimate(images, timestamp_s=t).lowest_foot_m)
        assert all(f is not None for f in out), out
        return np.array(out, float)

    on_floor, raised, raised_soles = feet(0.0, default), feet(0.03, default), feet(0.03, soles)
    assert np.allclose(raised - raised_soles, 0.03, atol=1e-9)  # the setting alone: the same pairs, 3 cm less
    assert np.allclose(raised - on_floor, 0.03, atol=0.01), (raised, on_floor)  # the oracle sees the lift
    assert np.allclose(raised_soles, on_floor, atol=0.01), (raised_soles, on_floor)
