"""BODY_25 -> Unity humanoid rotations (pure maths, known poses)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_host.sinks.vmc_pose import (
    BONE_PARENTS,
    DOWN,
    FORWARD,
    LEFT,
    RIGHT,
    UP,
    quat_between,
    quat_from_matrix,
    quat_mul,
    quat_rotate,
    rig_to_unity,
    solve_pose,
)
from ghnerf_runtime.body25 import JOINT_INDEX as J
from tests.firmware_host.joint_stream_helpers import t_pose_rig

ALL_BONES = set(BONE_PARENTS)
S45 = np.sqrt(0.5)


def assert_quat(q: np.ndarray, expected: np.ndarray, atol: float = 1e-6) -> None:
    # q and -q are the same rotation.
    assert min(np.abs(q - expected).max(), np.abs(q + expected).max()) < atol, (q, expected)


def test_rig_to_unity_flips_only_y() -> None:
    assert rig_to_unity(np.array([1.0, 2.0, 3.0])).tolist() == [1.0, -2.0, 3.0]  # down becomes -up


def test_t_pose_gives_identity_everywhere() -> None:
    pose = solve_pose(t_pose_rig())
    assert pose is not None and set(pose.bones) == ALL_BONES
    for bone in pose.bones.values():
        assert_quat(bone.local_rotation, np.array([0, 0, 0, 1.0]))
    np.testing.assert_allclose(pose.root_position, [0.0, 0.0, 3.0])


def test_facing_the_cameras_is_a_half_turn_of_the_hips_only() -> None:
    pose = solve_pose(t_pose_rig(facing_camera=True))
    assert pose is not None
    assert_quat(pose.bones["Hips"].local_rotation, np.array([0, 1.0, 0, 0]))  # 180 deg about +y
    for name, bone in pose.bones.items():
        if name != "Hips":
            assert_quat(bone.local_rotation, np.array([0, 0, 0, 1.0]))


def test_raised_left_arm() -> None:
    j = t_pose_rig()
    shoulder = j[J["LShoulder"], :3]
    j[J["LElbow"], :3] = shoulder + [0, -0.27, 0]  # straight up (rig y is down)
    j[J["LWrist"], :3] = shoulder + [0, -0.52, 0]
    pose = solve_pose(j)
    assert pose is not None
    # Rest direction -x turned onto +y: 90 degrees about -z.
    assert_quat(pose.bones["LeftUpperArm"].local_rotation, np.array([0, 0, -S45, S45]))
    np.testing.assert_allclose(quat_rotate(pose.bones["LeftUpperArm"].global_rotation, LEFT), UP, atol=1e-9)
    assert_quat(pose.bones["LeftLowerArm"].local_rotation, np.array([0, 0, 0, 1.0]))  # straight elbow
    assert_quat(pose.bones["RightUpperArm"].local_rotation, np.array([0, 0, 0, 1.0]))


def test_bent_right_elbow_is_local_to_the_upper_arm() -> None:
    j = t_pose_rig()
    elbow = j[J["RElbow"], :3]
    j[J["RWrist"], :3] = elbow + [0, 0, 0.25]  # forearm points forward
    pose = solve_pose(j)
    assert pose is not None
    # Rest +x turned onto +z: 90 degrees about -y.
    assert_quat(pose.bones["RightLowerArm"].local_rotation, np.array([0, -S45, 0, S45]))


def test_missing_joints_leave_bones_out() -> None:
    j = t_pose_rig()
    j[J["LElbow"], 3] = 0.0  # confidence 0: missing
    j[J["RKnee"], :3] = np.nan
    pose = solve_pose(j)
    assert pose is not None
    assert not {"LeftUpperArm", "LeftLowerArm", "LeftHand", "RightUpperLeg", "RightLowerLeg",
                "RightFoot"} & set(pose.bones)
    assert {"Hips", "RightUpperArm", "LeftFoot", "Head"} <= set(pose.bones)
    j[J["MidHip"], 3] = 0.0
    assert solve_pose(j) is None


@pytest.mark.parametrize("value", [32.8, -40.0, 1e20, 1e39, np.inf, -np.inf])
def test_a_coordinate_beyond_the_wire_s_reach_is_missing(value: float) -> None:
    j = t_pose_rig()
    j[J["RKnee"], 2] = value
    pose = solve_pose(j)
    assert pose is not None
    assert not {"RightUpperLeg", "RightLowerLeg", "RightFoot"} & set(pose.bones)
    assert "LeftFoot" in pose.bones
    for bone in pose.bones.values():
        assert np.abs(bone.local_position).max() < 33 and np.isfinite(bone.local_rotation).all()
    j[J["RKnee"], 2] = 32.0  # inside the reach: still a joint
    assert "RightLowerLeg" in solve_pose(j).bones


@pytest.mark.skipif(np.finfo(np.longdouble).max <= np.finfo(np.float64).max, reason="long double is float64 here")
def test_a_long_double_beyond_float64_is_missing_without_a_warning() -> None:
    """JointFrame takes any real dtype, as the same float64 array would go out (docs/protocol.md, "NumPy values"):
    the binary wire's quantiser made such a joint missing in silence, the VMC solver's cast warned "overflow
    encountered in cast" (and raised under -W error) before making it missing."""
    j = t_pose_rig().astype(np.longdouble)
    j[J["RKnee"], 2] = np.longdouble(np.finfo(np.float64).max) * 16
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        pose = solve_pose(j)
    assert pose is not None and "RightLowerLeg" not in pose.bones and "LeftFoot" in pose.bones


def test_shape_is_checked() -> None:
    with pytest.raises(ValueError, match=r"\(25, 4\)"):
        solve_pose(np.zeros((18, 4)))


def test_quaternion_helpers() -> None:
    q = quat_between(LEFT, UP)
    np.testing.assert_allclose(quat_rotate(q, LEFT), UP, atol=1e-12)
    q = quat_between(DOWN, UP)  # opposite vectors
    np.testing.assert_allclose(quat_rotate(q, DOWN), UP, atol=1e-12)
    m = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # 90 degrees about +y
    assert_quat(quat_from_matrix(m), np.array([0, S45, 0, S45]))
    np.testing.assert_allclose(quat_rotate(quat_from_matrix(m), RIGHT), -FORWARD, atol=1e-12)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**31))
def test_whole_body_rotation_goes_to_the_hips(seed: int) -> None:
    rng = np.random.default_rng(seed)
    q = _random_rotation(rng)
    j = t_pose_rig()
    centre = j[J["MidHip"], :3].copy()
    # Rotate the T-pose about MidHip in Unity axes, then back to the rig frame.
    unity = rig_to_unity(j[:, :3] - centre)
    j[:, :3] = rig_to_unity(quat_rotate(q, unity)) + centre
    pose = solve_pose(j)
    assert pose is not None
    assert_quat(pose.bones["Hips"].local_rotation, q, atol=1e-6)
    for name, bone in pose.bones.items():
        if name != "Hips":
            assert_quat(bone.local_rotation, np.array([0, 0, 0, 1.0]), atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**31))
def test_forward_kinematics_rebuilds_the_skeleton(seed: int) -> None:
    """Local rotations and positions, chained from Root/Pos, land on the measured joints."""
    rng = np.random.default_rng(seed)
    j = t_pose_rig()
    j[:, :3] += rng.normal(scale=0.08, size=(25, 3))  # a random, plausible pose
    pose = solve_pose(j)
    assert pose is not None
    world_q: dict[str, np.ndarray] = {}
    world_p: dict[str, np.ndarray] = {}
    for name, bone in pose.bones.items():
        parent = BONE_PARENTS[name]
        if parent is None:
            world_q[name], world_p[name] = bone.local_rotation, pose.root_position + bone.local_position
        else:
            world_q[name] = quat_mul(world_q[parent], bone.local_rotation)
            world_p[name] = world_p[parent] + quat_rotate(world_q[parent], bone.local_position)
        np.testing.assert_allclose(world_p[name], bone.anchor, atol=1e-9)
        assert_quat(world_q[name], bone.global_rotation, atol=1e-9)
    unity = rig_to_unity(j[:, :3])
    for bone, (a, b), rest in [
        ("LeftUpperArm", ("LShoulder", "LElbow"), LEFT),
        ("LeftLowerArm", ("LElbow", "LWrist"), LEFT),
        ("RightLowerArm", ("RElbow", "RWrist"), RIGHT),
        ("LeftUpperLeg", ("LHip", "LKnee"), DOWN),
        ("RightLowerLeg", ("RKnee", "RAnkle"), DOWN),
    ]:
        seg = unity[J[b]] - unity[J[a]]
        np.testing.assert_allclose(quat_rotate(world_q[bone], rest), seg / np.linalg.norm(seg), atol=1e-9)
        np.testing.assert_allclose(world_p[bone], unity[J[a]], atol=1e-9)


@pytest.mark.parametrize("shape", ["one point", "denormal", "tiny", "coincident pairs", "one line", "one plane"])
def test_degenerate_skeletons_give_proper_rotations_or_leave_bones_out(shape: str) -> None:
    """Property sweep of the shapes with no direction to take: every joint at one point, joints 1e-300 m or
    denormals apart, some joints on others, the body on a line or in a plane. No exception and no warning; every
    bone sent has a finite unit quaternion, a finite offset and anchor, the root a finite position."""
    import warnings

    rng = np.random.default_rng(sum(map(ord, shape)))
    for _ in range(100):
        j = t_pose_rig()
        if shape == "one point":
            j[:, :3] = j[rng.integers(25), :3]
        elif shape == "denormal":
            j[:, :3] = rng.choice([0.0, 5e-324, 1e-310, 1e-300], (25, 3))
        elif shape == "tiny":
            j[:, :3] = rng.normal(size=(25, 3)) * rng.choice([1e-300, 1e-150, 1e-12])
        elif shape == "coincident pairs":
            j[rng.integers(0, 25, 6), :3] = j[rng.integers(25), :3]
        elif shape == "one line":
            j[:, :3] *= rng.permutation([1.0, 0.0, 0.0])
        else:
            j[:, :3] *= rng.permutation([1.0, 1.0, 0.0])
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            pose = solve_pose(j)
        if pose is None:
            continue
        assert np.isfinite(pose.root_position).all()
        for name, bone in pose.bones.items():
            q = bone.local_rotation
            assert np.isfinite(q).all() and abs(np.linalg.norm(q) - 1.0) < 1e-9, (shape, name, q)
            assert np.isfinite(bone.global_rotation).all() and np.isfinite(bone.local_position).all()
            assert np.isfinite(bone.anchor).all()
