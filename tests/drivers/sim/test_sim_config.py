"""Bad configuration values raise ValueError naming the field; valid random ones always build."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.errors import DriverError
from drivers.sim import (
    Appearance, BodyParams, BvhError, Fabric, Lighting, MotionParams, RigPlacement, RoomStyle, SceneConfig,
    SensorModel, SimConfigError, SimScene, random_scene,
)
from drivers.sim.body import BodyModel
from drivers.sim.skeleton import Skeleton


@pytest.mark.parametrize(
    "make,field",
    [
        (lambda: SceneConfig(seed=-1), "SceneConfig.seed"),
        (lambda: SceneConfig(seed=1.5), "SceneConfig.seed"),
        (lambda: SceneConfig(speed=0.0), "SceneConfig.speed"),
        (lambda: SceneConfig(speed=float("nan")), "SceneConfig.speed"),
        (lambda: SceneConfig(motion="moonwalk"), "SceneConfig.motion"),
        (lambda: SceneConfig(position_xz=(0.0, float("inf"))), "SceneConfig.position_xz"),
        (lambda: SceneConfig(position_xz=(1.0, 2.0, 3.0)), "SceneConfig.position_xz"),
        (lambda: SceneConfig(heading_deg=float("nan")), "SceneConfig.heading_deg"),
        (lambda: SceneConfig(background="yes"), "SceneConfig.background"),
        (lambda: SceneConfig(plain_background=(2.0, 0.0, 0.0)), "SceneConfig.plain_background"),
        (lambda: SceneConfig(body={"height_m": 1.8}), "SceneConfig.body"),
        (lambda: SceneConfig(sensor=None), "SceneConfig.sensor"),
        (lambda: BodyParams(height_m=2.3), "BodyParams.height_m"),
        (lambda: BodyParams(girth=0.1), "BodyParams.girth"),
        (lambda: BodyParams(leg_length=float("nan")), "BodyParams.leg_length"),
        (lambda: Appearance(hair_style="mohawk"), "Appearance.hair_style"),
        (lambda: Appearance(skin=(1.2, 0.5, 0.5)), "Appearance.skin"),
        (lambda: Appearance(shirt=Fabric(pattern="paisley")), "Appearance.shirt.pattern"),
        (lambda: Appearance(pants=Fabric(scale_m=2.0)), "Appearance.pants.scale_m"),
        (lambda: Appearance(sleeves="three-quarter"), "Appearance.sleeves"),
        (lambda: MotionParams(amplitude=3.0), "MotionParams.amplitude"),
        (lambda: MotionParams(period_s=0.01), "MotionParams.period_s"),
        (lambda: SceneConfig(motion_params=MotionParams(strides_per_lap=-1)), "MotionParams.strides_per_lap"),
        (lambda: RigPlacement(width=0), "RigPlacement.width"),
        (lambda: RigPlacement(width=640.0), "RigPlacement.width"),
        (lambda: RigPlacement(hfov_deg=179.0), "RigPlacement.hfov_deg"),
        (lambda: RigPlacement(baseline_m=-1.0), "RigPlacement.baseline_m"),
        (lambda: RigPlacement(distortion=(0.1, 0.2, 0.3)), "RigPlacement.distortion"),
        (lambda: RigPlacement(names=("cam", "cam")), "RigPlacement.names"),
        (lambda: RigPlacement(distance_m=2.0, volume_depth_m=4.0), "RigPlacement.volume_depth_m"),
        (lambda: SensorModel(exposure=0.0), "SensorModel.exposure"),
        (lambda: SensorModel(read_noise=-1.0), "SensorModel.read_noise"),
        (lambda: Lighting(direction=(0.0, 0.0, 0.0)), "Lighting.direction"),
        (lambda: Lighting(ambient=1.5), "Lighting.ambient"),
        (lambda: RoomStyle(tile_m=0.0), "RoomStyle.tile_m"),
        (lambda: SimScene(SceneConfig()).bounding_box(0.0, margin=-1.0), "margin"),
        (lambda: SimScene(SceneConfig()).joints_3d(float("nan")), "t"),
        (lambda: random_scene(-3), "seed"),
        (lambda: random_scene(0, motions=("walk", "fly")), "motions"),
    ],
)
def test_bad_values_name_the_field(make, field):
    with pytest.raises(SimConfigError) as info:
        make()
    assert isinstance(info.value, ValueError) and isinstance(info.value, DriverError)
    assert info.value.field == field and str(info.value).startswith(field + ":")


def test_missing_bvh_motion_names_the_file(tmp_path):
    path = tmp_path / "gone.bvh"
    with pytest.raises(BvhError, match="gone.bvh: cannot read"):
        SimScene(SceneConfig(motion=str(path)))


@settings(max_examples=25, deadline=None)
@given(
    height=st.floats(1.5, 2.0), girth=st.floats(0.75, 1.4), shoulders=st.floats(0.85, 1.2), hips=st.floats(0.85, 1.2),
    legs=st.floats(0.92, 1.08), arms=st.floats(0.92, 1.08), head=st.floats(0.9, 1.1), long_hair=st.booleans(),
)
def test_any_valid_body_builds_finite_and_to_height(height, girth, shoulders, hips, legs, arms, head, long_hair):
    params = BodyParams(height, girth, shoulders, hips, legs, arms, head)
    skeleton = Skeleton.from_params(params)
    body = BodyModel(skeleton, long_hair=long_hair)
    G = np.broadcast_to(np.eye(3), (17, 3, 3))
    posed = body.pose(G, skeleton.rest_positions())
    lo, hi = posed.bounding_box()
    assert abs(hi[1] - height) < 1e-9 and abs(lo[1]) < 1e-9  # crown at the stature, soles on the floor
    for value in (posed.ell_center, posed.ell_radii, posed.cone_a, posed.cone_b, posed.joints):
        assert np.all(np.isfinite(value))
    assert np.all(posed.cone_ra > 0) and np.all(posed.ell_radii > 0)


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**63 - 1))
def test_random_scenes_are_valid(seed):
    scene = random_scene(seed)
    joints = scene.joints_3d(0.5)
    assert np.all(np.isfinite(joints)) and scene.period_s > 0
    assert scene.config.position_xz == pytest.approx(scene.config.position_xz)
