"""vmc:// facing= and mirror=: the solved avatar is the person's pose turned round or mirrored, and still
made of proper rotations (known poses and random ones)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_host.sinks.vmc_pose import BONE_PARENTS, VmcPose, quat_mul, solve_pose
from firmware_host.sinks.vmc_view import FACINGS, AvatarView
from ghnerf_runtime.body25 import JOINT_INDEX as J
from tests.firmware_host.joint_stream_helpers import t_pose_rig

ALL_VIEWS = [AvatarView(facing=f, mirror=m) for f in FACINGS for m in (False, True)]


def _swap(name: str) -> str:
    return name.replace("Left", "@").replace("Right", "Left").replace("@", "Right")


def _same_rotation(q: np.ndarray, expected: np.ndarray, atol: float = 1e-9) -> bool:
    return bool(min(np.abs(q - expected).max(), np.abs(q + expected).max()) < atol)


def _random_pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    j = t_pose_rig(facing_camera=bool(seed % 2))
    j[:, :3] += rng.normal(scale=0.08, size=(25, 3))
    return j


def _solve(view: AvatarView, j: np.ndarray) -> VmcPose:
    pose = solve_pose(view.apply(j))
    assert pose is not None
    return pose


def test_the_default_view_is_the_old_output() -> None:
    j = t_pose_rig()
    assert AvatarView().apply(j) is j  # not even a copy: the default sends what it always sent
    assert AvatarView() == AvatarView(facing="away", mirror=False) and AvatarView().is_identity


def test_a_view_leaves_its_input_alone() -> None:
    j = t_pose_rig()
    before = j.copy()
    for view in ALL_VIEWS:
        view.apply(j)
    np.testing.assert_array_equal(j, before)


def test_facing_the_cameras_with_facing_camera_is_the_rest_pose() -> None:
    # A person in a T-pose facing the cameras: by default the Hips turn half round (seen from behind);
    # facing=camera gives the avatar's own rest pose, facing the receiver's camera.
    for mirror in (False, True):
        pose = _solve(AvatarView(facing="camera", mirror=mirror), t_pose_rig(facing_camera=True))
        assert set(pose.bones) == set(BONE_PARENTS)
        for bone in pose.bones.values():
            assert _same_rotation(bone.local_rotation, np.array([0, 0, 0, 1.0]), atol=1e-9), bone


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31))
def test_mirror_is_the_mirror_image_made_of_proper_rotations(seed: int) -> None:
    """mirror=1 is the reflection x -> -x of the skeleton: each bone takes its other side's rotation conjugated
    by the reflection, a rotation about (x, -y, -z) by the same angle, i.e. quaternion (x, -y, -z, w); a
    reflected matrix (det -1) has no quaternion, so a slip would show here as a wrong bone, not a bad number."""
    j = _random_pose(seed)
    for facing in FACINGS:
        plain = _solve(AvatarView(facing=facing), j)
        mirrored = _solve(AvatarView(facing=facing, mirror=True), j)
        assert set(mirrored.bones) == set(BONE_PARENTS)
        np.testing.assert_allclose(mirrored.root_position, plain.root_position * [-1, 1, 1], atol=1e-12)
        for name, bone in plain.bones.items():
            other = mirrored.bones[_swap(name)]
            assert abs(np.linalg.norm(other.local_rotation) - 1.0) < 1e-12
            assert _same_rotation(other.local_rotation, bone.local_rotation * [1, -1, -1, 1], atol=1e-7), name
            np.testing.assert_allclose(other.local_position, bone.local_position * [-1, 1, 1], atol=1e-9)
            np.testing.assert_allclose(other.anchor, bone.anchor * [-1, 1, 1], atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**31))
def test_facing_camera_turns_only_the_hips_and_the_root(seed: int) -> None:
    j = _random_pose(seed)
    for mirror in (False, True):
        away = _solve(AvatarView(facing="away", mirror=mirror), j)
        camera = _solve(AvatarView(facing="camera", mirror=mirror), j)
        np.testing.assert_allclose(camera.root_position, away.root_position * [-1, 1, -1], atol=1e-12)
        half_turn = np.array([0.0, 1.0, 0.0, 0.0])  # 180 degrees about Unity +y, after the person's own turn
        turned = quat_mul(half_turn, away.bones["Hips"].local_rotation)
        assert _same_rotation(camera.bones["Hips"].local_rotation, turned, atol=1e-7)
        for name, bone in away.bones.items():
            if name != "Hips":
                assert _same_rotation(camera.bones[name].local_rotation, bone.local_rotation, atol=1e-7), name
                np.testing.assert_allclose(camera.bones[name].local_position, bone.local_position, atol=1e-9)


def test_a_missing_joint_stays_missing_on_its_mirrored_side() -> None:
    j = t_pose_rig(facing_camera=True)
    j[J["LElbow"], 3] = 0.0  # the person's left elbow, unseen
    j[J["RKnee"], :3] = np.nan
    pose = _solve(AvatarView(facing="camera", mirror=True), j)
    assert not {"RightUpperArm", "RightLowerArm", "RightHand", "LeftUpperLeg"} & set(pose.bones)
    assert {"LeftUpperArm", "RightUpperLeg", "Head"} <= set(pose.bones)


def test_bad_views_are_refused() -> None:
    with pytest.raises(ValueError, match=r"facing must be one of \['away', 'camera'\], got 'front'"):
        AvatarView(facing="front")
    with pytest.raises(ValueError, match=r"\(25, 4\)"):
        AvatarView(mirror=True).apply(np.zeros((18, 4)))
