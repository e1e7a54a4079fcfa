"""Levelling an imported rig: the project's frame (gravity down, floor at 0) back from a tool's own frame."""
from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.level import LEVEL_VOLUME, down_in_camera, level_rig
from ghnerf_runtime.errors import GeometryError
from ghnerf_runtime.geometry import Camera, Rig


def as_stereo_calib(rig: Rig) -> Rig:
    """The rig as stereo_calib hands it over: the first camera's frame is the world."""
    R0, t0 = rig.cameras[0].R, rig.cameras[0].t
    cams = [Camera(c.name, c.width, c.height, c.K, c.dist, c.R @ R0.T, c.t - c.R @ R0.T @ t0) for c in rig.cameras]
    return Rig(tuple(cams), rig.volume, rig_id=rig.rig_id)


@pytest.mark.parametrize("height, roll", [(1.2, 0.0), (2.4, 180.0), (1.6, 12.0)])
def test_levelling_a_tools_frame_gives_the_rig_back(height, roll):
    sim = pytest.importorskip("drivers.sim")
    true = sim.RigPlacement(camera_height_m=height).build()
    if roll:  # both cameras turned about their optical axes, as a rig hung upside down or crooked
        a = math.radians(roll)
        Rz = np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])
        true = Rig(tuple(Camera(c.name, c.width, c.height, c.K, c.dist, Rz @ c.R, Rz @ c.t) for c in true.cameras),
                   true.volume, rig_id=true.rig_id)
    d = true.cameras[0].R @ np.array([0.0, 1.0, 0.0])  # gravity in camera 0, as an inclinometer would say
    pitch, roll_measured = math.degrees(math.asin(d[2])), math.degrees(math.atan2(-d[0], d[1]))
    assert np.allclose(down_in_camera(pitch, roll_measured), d)
    back = level_rig(as_stereo_calib(true), camera_height_m=-true.cameras[0].center[1], pitch_deg=pitch,
                     roll_deg=roll_measured)
    for a, b in zip(true.cameras, back.cameras):
        np.testing.assert_allclose(b.R, a.R, atol=1e-9)
        np.testing.assert_allclose(b.t, a.t, atol=1e-9)
    assert back.metadata["levelled"]["reference"] == true.cameras[0].name and back.volume is LEVEL_VOLUME


def test_level_rig_refuses_what_it_cannot_do():
    K = [[50.0, 0, 32], [0, 50.0, 32], [0, 0, 1]]
    rig = Rig((Camera("a", 64, 64, K), Camera("b", 64, 64, K, t=np.array([-0.1, 0.0, 0.0]))), LEVEL_VOLUME)
    with pytest.raises(GeometryError, match="camera_height_m"):
        level_rig(rig, camera_height_m=0.0)
    with pytest.raises(GeometryError, match="along gravity"):
        level_rig(rig, camera_height_m=3.0, pitch_deg=90.0)  # a pair looking straight down: no forward
    with pytest.raises(GeometryError, match="along gravity"):
        level_rig(rig, camera_height_m=3.0, pitch_deg=-90.0)  # or straight up
    assert level_rig(rig, camera_height_m=3.0, pitch_deg=89.0).metadata["levelled"]["pitch_deg"] == 89.0  # nearly: fine
    # a NaN or infinite angle (an inclinometer that read nothing) raised a bare ValueError or blamed R;
    # a reference past the cameras an IndexError
    for bad in (math.nan, math.inf, -math.inf, "10", None):
        for key in ("pitch_deg", "roll_deg"):
            with pytest.raises(GeometryError, match=key):
                level_rig(rig, camera_height_m=1.5, **{key: bad})
        with pytest.raises(GeometryError, match="camera_height_m"):
            level_rig(rig, camera_height_m=bad)
    for reference in (2, -1, True, 0.0):
        with pytest.raises(GeometryError, match="reference"):
            level_rig(rig, camera_height_m=1.5, reference=reference)
    assert level_rig(rig, camera_height_m=1.5, reference=1).metadata["levelled"]["reference"] == "b"


def test_the_estimator_warns_about_a_tool_frame_until_the_rig_is_levelled(caplog):
    sim = pytest.importorskip("drivers.sim")
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime.estimator import Estimator

    true = sim.RigPlacement().build()
    imported = Rig(as_stereo_calib(true).cameras, true.volume, rig_id="calib",
                   metadata={"source": {"format": "opencv-stereo-calib", "path": "intrinsics.yml"}})
    with caplog.at_level("WARNING"):
        Estimator(OracleSession(edge128_contract()), imported)
    assert "level it first" in caplog.text
    caplog.clear()
    d = true.cameras[0].R @ np.array([0.0, 1.0, 0.0])
    levelled = level_rig(imported, camera_height_m=-true.cameras[0].center[1],
                         pitch_deg=math.degrees(math.asin(d[2])))
    with caplog.at_level("WARNING"):
        Estimator(OracleSession(edge128_contract()), levelled)
    assert "level it first" not in caplog.text


@pytest.mark.parametrize("bad", [math.nan, math.inf, "10", None, True])
def test_gravity_from_angles_that_are_not_numbers_is_refused(bad):
    # a NaN pitch gave a NaN direction, silently: every caller had to check the angles itself
    for key in ("pitch_deg", "roll_deg"):
        with pytest.raises(GeometryError, match=key):
            down_in_camera(**{key: bad})
    np.testing.assert_allclose(down_in_camera(90.0), [0.0, 0.0, 1.0], atol=1e-15)  # straight down: along the axis
    np.testing.assert_allclose(down_in_camera(-90.0), [0.0, 0.0, -1.0], atol=1e-15)  # straight up
