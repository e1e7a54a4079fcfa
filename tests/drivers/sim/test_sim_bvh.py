"""BVH parsing, forward kinematics, writing, retargeting and error reporting."""
from __future__ import annotations

import numpy as np
import pytest

from drivers.sim import SAMPLE_BVH, BodyParams, BvhError, BvhMotion, dumps_bvh, load_bvh, make_motion, parse_bvh
from drivers.sim.body import BodyModel
from drivers.sim.bvh import BvhClip, BvhJoint
from drivers.sim.retarget import clip_from_poses, map_joints, normalize_name
from drivers.sim.rotations import euler_to_matrix, matrix_to_euler, rot_x
from drivers.sim.skeleton import JOINT_ID, Skeleton

TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 20 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Neck
    {
      OFFSET 0 30 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT Head
      {
        OFFSET 0 10 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
          OFFSET 0 20 0
        }
      }
    }
    JOINT LeftArm
    {
      OFFSET 20 28 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT LeftForeArm
      {
        OFFSET 30 0 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        JOINT LeftHand
        {
          OFFSET 25 0 0
          CHANNELS 3 Zrotation Xrotation Yrotation
          End Site
          {
            OFFSET 15 0 0
          }
        }
      }
    }
    JOINT RightArm
    {
      OFFSET -20 28 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT RightForeArm
      {
        OFFSET -30 0 0
        CHANNELS 3 Xrotation Yrotation Zrotation
        JOINT RightHand
        {
          OFFSET -25 0 0
          CHANNELS 3 Zrotation Xrotation Yrotation
          End Site
          {
            OFFSET -15 0 0
          }
        }
      }
    }
  }
  JOINT LeftUpLeg
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT LeftLeg
    {
      OFFSET 0 -45 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT LeftFoot
      {
        OFFSET 0 -45 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
          OFFSET 0 -8 15
        }
      }
    }
  }
  JOINT RightUpLeg
  {
    OFFSET -10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT RightLeg
    {
      OFFSET 0 -45 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      JOINT RightFoot
      {
        OFFSET 0 -45 0
        CHANNELS 3 Zrotation Xrotation Yrotation
        End Site
        {
          OFFSET 0 -8 15
        }
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
"""
# Channels: Hips 6, Spine, Neck, Head, LeftArm, LeftForeArm, LeftHand, RightArm, RightForeArm,
# RightHand, LeftUpLeg, LeftLeg, LeftFoot, RightUpLeg, RightLeg, RightFoot: 3 each -> 51.
_ORDER = ["Hips", "Spine", "Neck", "Head", "LeftArm", "LeftForeArm", "LeftHand", "RightArm", "RightForeArm",
          "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot"]


def _frame(root=(0.0, 98.0, 0.0), **angles) -> str:
    values = list(root) + [0.0, 0.0, 0.0]
    for name in _ORDER[1:]:
        values += list(angles.get(name, (0.0, 0.0, 0.0)))
    if "Hips" in angles:
        values[3:6] = angles["Hips"]
    return " ".join(f"{v:g}" for v in values)


# Frame 1: whole body turned 90 degrees about y, left forearm bent 90 about z,
# right forearm X=90, Y=90 in "Xrotation Yrotation Zrotation" order.
TINY_TEXT = TINY + _frame() + "\n" + _frame((1.0, 98.0, 2.0), Hips=(0.0, 0.0, 90.0), LeftForeArm=(90.0, 0.0, 0.0), RightForeArm=(90.0, 90.0, 0.0)) + "\n"


def test_tiny_bvh_forward_kinematics_matches_hand_computation():
    clip = parse_bvh(TINY_TEXT, "tiny.bvh")
    assert clip.num_frames == 2 and clip.frame_time == 0.5 and len(clip.joints) == 16
    G, P = clip.forward()
    pos = {name: P[:, clip.names.index(name)] for name in clip.names}
    np.testing.assert_allclose(pos["LeftHand"][0], [75, 146, 0])
    np.testing.assert_allclose(pos["LeftFoot"][0], [10, 8, 0])
    # Frame 1 by hand: Ry(90) maps (x, y, z) -> (z, y, -x).
    np.testing.assert_allclose(pos["LeftArm"][1], [1, 146, -18], atol=1e-9)
    np.testing.assert_allclose(pos["LeftForeArm"][1], [1, 146, -48], atol=1e-9)
    np.testing.assert_allclose(pos["LeftHand"][1], [1, 171, -48], atol=1e-9)  # bent straight up
    # X then Y in the file means R = Rx(90) @ Ry(90): (-25, 0, 0) -> (0, 0, 25) -> (0, -25, 0).
    np.testing.assert_allclose(pos["RightHand"][1] - pos["RightForeArm"][1], [0, -25, 0], atol=1e-9)
    np.testing.assert_allclose(pos["RightForeArm"][1], [1, 146, 2 + 50], atol=1e-9)


def test_euler_orders_round_trip():
    rng = np.random.default_rng(0)
    angles = rng.uniform(-170, 170, (50, 3))
    angles[:, 1] = rng.uniform(-85, 85, 50)
    for order in ("xyz", "zxy", "zyx", "yxz", "yzx", "xzy"):
        R = euler_to_matrix(angles, order)
        np.testing.assert_allclose(euler_to_matrix(matrix_to_euler(R, order), order), R, atol=1e-9)
    lock = euler_to_matrix(np.array([[30.0, 90.0, 20.0]]), "zxy")
    np.testing.assert_allclose(euler_to_matrix(matrix_to_euler(lock, "zxy"), "zxy"), lock, atol=1e-9)


def test_tiny_bvh_retargets_bone_directions():
    skeleton = Skeleton.from_params(BodyParams(height_m=1.8))
    motion = BvhMotion(parse_bvh(TINY_TEXT, "tiny.bvh"), skeleton, in_place=False)
    assert motion.period_s == 1.0 and motion.mapping["chest"] == "Spine" and "spine" not in motion.mapping
    clip_G, clip_P = parse_bvh(TINY_TEXT).forward()
    names = parse_bvh(TINY_TEXT).names
    pairs = [("l_shoulder", "l_elbow", "LeftArm", "LeftForeArm"), ("l_elbow", "l_wrist", "LeftForeArm", "LeftHand"),
             ("r_elbow", "r_wrist", "RightForeArm", "RightHand"), ("l_hip", "l_knee", "LeftUpLeg", "LeftLeg"),
             ("neck", "head", "Neck", "Head")]
    for frame in (0, 1):
        pose = motion.pose(frame * 0.5)
        _, P = skeleton.forward(pose.rotations, pose.root)
        for a, b, ca, cb in pairs:
            ours = P[JOINT_ID[b]] - P[JOINT_ID[a]]
            theirs = clip_P[frame, names.index(cb)] - clip_P[frame, names.index(ca)]
            np.testing.assert_allclose(ours / np.linalg.norm(ours), theirs / np.linalg.norm(theirs), atol=1e-9)
            assert np.isclose(np.linalg.norm(ours), np.linalg.norm(skeleton.offsets[JOINT_ID[b]]))
    # The clip's T-pose rest drives our arms sideways at frame 0; and its floor is ours.
    pose = motion.pose(0.0)
    _, P = skeleton.forward(pose.rotations, pose.root)
    arm = P[JOINT_ID["l_wrist"]] - P[JOINT_ID["l_shoulder"]]
    np.testing.assert_allclose(arm / np.linalg.norm(arm), [1, 0, 0], atol=1e-9)
    rest = skeleton.rest_positions()
    scale = (rest[JOINT_ID["pelvis"], 1] - rest[JOINT_ID["l_ankle"], 1]) / 90.0  # clip: hips 90 above ankles
    assert abs(P[JOINT_ID["l_ankle"], 1] - 8.0 * scale) < 1e-3  # clip ankles 8 above its floor (y = 0)


def test_shipped_sample_round_trips():
    clip = load_bvh(SAMPLE_BVH)
    assert clip.source == str(SAMPLE_BVH)
    again = parse_bvh(dumps_bvh(clip, precision=4))
    assert again.names == clip.names
    np.testing.assert_array_equal(again.frames, clip.frames)
    for a, b in zip(clip.joints, again.joints):
        assert a.channels == b.channels and a.parent == b.parent
        np.testing.assert_array_equal(a.offset, b.offset)
    # It was exported from the procedural jumping jacks on the default body (see
    # tests/drivers/sim/make_sample_bvh.py); played back it must reproduce them.
    skeleton = Skeleton.from_params(BodyParams())
    body = BodyModel(skeleton)
    motion = BvhMotion(clip, skeleton, in_place=False)
    assert motion.mapping["r_toe"] == "RightToeBase" and motion.mapping["chest"] == "Spine1"
    assert abs(motion.period_s - clip.num_frames * clip.frame_time) < 1e-12
    reference = make_motion("jumping_jacks", skeleton)
    for f in (0, 5, 21, 33):
        t = f * clip.frame_time
        pose = motion.pose(t)
        G, P = skeleton.forward(pose.rotations, pose.root)
        ref = reference.pose(f / 30.0)
        G2, P2 = skeleton.forward(ref.rotations, ref.root)
        P2 = body.settle(G2, P2, ground=True, plant=True)
        np.testing.assert_allclose(body.joints(G, P), body.joints(G2, P2), atol=1e-3)


@pytest.mark.parametrize("name", ["walk", "squat", "turn", "arm_circles"])
def test_export_import_round_trip(name):
    skeleton = Skeleton.from_params(BodyParams(height_m=1.66, girth=1.2))
    body = BodyModel(skeleton)
    motion = make_motion(name, skeleton)
    F = 24
    dt = motion.period_s / F
    rotations, roots, joints = [], [], []
    for f in range(F):
        pose = motion.pose(f * dt)
        G, P = skeleton.forward(pose.rotations, pose.root)
        P = body.settle(G, P, ground=True, plant=motion.planted)
        rotations.append(pose.rotations)
        roots.append(P[0])
        joints.append(body.joints(G, P))
    for prefix, up_z in (("", False), ("mixamorig:", True)):
        clip = clip_from_poses(skeleton, np.array(rotations), np.array(roots), dt, order="yxz", prefix=prefix)
        if up_z:
            clip = _to_z_up(clip)
        back = BvhMotion(parse_bvh(dumps_bvh(clip, precision=6)), skeleton, in_place=False)
        for f in range(0, F, 5):
            pose = back.pose(f * dt)
            G, P = skeleton.forward(pose.rotations, pose.root)
            np.testing.assert_allclose(body.joints(G, P), joints[f], atol=1e-3)


def _to_z_up(clip: BvhClip) -> BvhClip:
    """The same clip authored Z-up (y -> z)."""
    M = rot_x(np.pi / 2)
    R, T = clip.local_transforms()
    R = M @ R @ M.T
    cols = []
    for k, joint in enumerate(clip.joints):
        if any(c.endswith("position") for c in joint.channels):
            cols.append(T[:, k] @ M.T)
        cols.append(matrix_to_euler(R[:, k], "".join(c[0].lower() for c in joint.channels if c.endswith("rotation"))))
    joints = tuple(BvhJoint(j.name, j.parent, M @ j.offset, j.channels, None if j.end_site is None else M @ j.end_site) for j in clip.joints)
    return BvhClip(joints, clip.frame_time, np.concatenate(cols, axis=1), clip.source)


def test_name_normalisation_covers_common_conventions():
    assert normalize_name("mixamorig:LeftForeArm") == ("l", "forearm")
    assert normalize_name("mixamorig1:RightUpLeg") == ("r", "upleg")
    assert normalize_name("upperarm_r") == ("r", "upperarm")
    assert normalize_name("thigh_l") == ("l", "thigh")
    assert normalize_name("LHipJoint") == ("l", "hipjoint")
    assert normalize_name("RThigh") == ("r", "thigh")
    assert normalize_name("LowerBack") == ("", "lowerback")
    assert normalize_name("Left Knee") == ("l", "knee")
    assert normalize_name("Hand.R") == ("r", "hand")
    assert normalize_name("Hips") == ("", "hips")
    clip = parse_bvh(TINY_TEXT.replace("LeftArm", "LeftShoulder").replace("LeftForeArm", "LeftElbow").replace("LeftHand", "LeftWrist"))
    assert clip.names[map_joints(clip)["l_shoulder"]] == "LeftShoulder"


# ------------------------------------------------------------------------ errors
def _write(tmp_path, text: str, name: str = "bad.bvh"):
    path = tmp_path / name
    path.write_text(text)
    return path


def _line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


@pytest.mark.parametrize(
    "old,new,needle,message",
    [
        ("OFFSET 30 0 0", "OFFSET 30 zero 0", "OFFSET 30 zero 0", "expected a number"),
        ("CHANNELS 3 Xrotation Yrotation Zrotation", "CHANNELS 3 Xrotation Wrotation Zrotation", "Wrotation", "unknown channel"),
        ("JOINT RightUpLeg", "JIONT RightUpLeg", "JIONT", "unexpected 'JIONT'"),
        ("Frame Time: 0.5", "Frame Time: fast", "Frame Time", "Frame Time must be a number"),
        # frames x 1e308 was an infinite clip: an OverflowError where sim:// sized its loop
        ("Frame Time: 0.5", "Frame Time: 1e308", "Frame Time", "at most 60 s, got '1e308'"),
        ("Frames: 2", "Frames: -1", "Frames:", "at least 1"),
    ],
)
def test_bad_bvh_names_file_and_line(tmp_path, old, new, needle, message):
    text = TINY_TEXT.replace(old, new, 1)
    path = _write(tmp_path, text)
    with pytest.raises(BvhError) as info:
        load_bvh(path)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.path == str(path) and err.line == _line_of(text, needle)
    assert f"{path}:{err.line}" in str(err) and message in str(err)


def test_bad_frames_name_the_line(tmp_path):
    lines = TINY_TEXT.splitlines()
    short = "\n".join(lines[:-1] + [" ".join(lines[-1].split()[:-2])]) + "\n"
    path = _write(tmp_path, short)
    with pytest.raises(BvhError, match=rf"{path}:{len(lines)}: frame 1 has 49 values, the hierarchy has 51"):
        load_bvh(path)
    bad = TINY_TEXT.replace(lines[-1], lines[-1].replace("98", "9x8", 1))
    with pytest.raises(BvhError, match=rf"bad.bvh:{len(lines)}: frame 1: '9x8' is not a number"):
        load_bvh(_write(tmp_path, bad))
    with pytest.raises(BvhError, match=r"Frames: 2 but only 1 frame lines"):
        load_bvh(_write(tmp_path, "\n".join(lines[:-1]) + "\n"))
    with pytest.raises(BvhError, match=r"no MOTION section"):
        load_bvh(_write(tmp_path, TINY_TEXT.split("MOTION")[0]))
    with pytest.raises(BvhError, match=r"unexpected end of file"):
        load_bvh(_write(tmp_path, TINY_TEXT.replace("  }\n}\nMOTION", "  }\nMOTION")))


def test_unusable_bvh_is_reported(tmp_path):
    with pytest.raises(BvhError, match=r"nowhere\.bvh: cannot read"):
        load_bvh(tmp_path / "nowhere.bvh")
    legless = TINY_TEXT.replace("LeftUpLeg", "LeftTail").replace("RightUpLeg", "RightTail")
    with pytest.raises(BvhError, match=r"legless\.bvh: cannot map joints \['r_hip', 'l_hip'\]"):
        BvhMotion(load_bvh(_write(tmp_path, legless, "legless.bvh")), Skeleton.from_params(BodyParams()))


def test_a_huge_frame_count_and_a_byte_order_mark(tmp_path):
    lines = TINY_TEXT.splitlines()
    frames_line = next(k for k, line in enumerate(lines) if line.startswith("Frames:"))
    huge = "\n".join(lines[:frames_line] + ["Frames: 99999999999"] + lines[frames_line + 1:]) + "\n"
    with pytest.raises(BvhError, match=rf"bad.bvh:{frames_line + 1}: Frames: 99999999999 but only"):
        load_bvh(_write(tmp_path, huge))  # not a MemoryError for 44 TiB
    path = tmp_path / "bom.bvh"
    path.write_bytes(b"\xef\xbb\xbf" + TINY_TEXT.encode())  # saved by a Windows editor
    assert load_bvh(path).num_frames == load_bvh(_write(tmp_path, TINY_TEXT, "plain.bvh")).num_frames


def _t_pose_clip(children: str, channels: int) -> str:
    """A T-pose clip (every rotation zero) whose Hips have ``children``; ``channels`` below the root."""
    text = ("HIERARCHY\nROOT Hips {\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n" + children + "}\nMOTION\nFrames: 2\nFrame Time: 0.0333\n")
    row = " ".join(["0", "95", "0"] + ["0"] * (3 + channels))
    return text + row + "\n" + row + "\n"


def _limb(name: str, offsets, end, extra: str = "") -> str:
    out, close = "", ""
    for k, (n, off) in enumerate(zip(name.split(","), offsets)):
        out += f"JOINT {n} {{ OFFSET {off} CHANNELS 3 Zrotation Xrotation Yrotation\n"
        close += "}"
    return out + (extra or f"End Site {{ OFFSET {end} }}\n") + close + "\n"


def _legs() -> str:
    return "".join(_limb(f"{s}UpLeg,{s}Leg,{s}Foot", [f"{x} 0 0", "0 -42 0", "0 -40 0"], "0 -5 12")
                   for s, x in (("Left", 9), ("Right", -9)))


def _arms(fingers: bool = False) -> str:
    def hand(x):
        if not fingers:
            return ""
        side = "Left" if x > 0 else "Right"
        return "".join(f"JOINT {side}Hand{f}1 {{ OFFSET {x * a} 0 {z} CHANNELS 3 Zrotation Xrotation Yrotation "
                       f"End Site {{ OFFSET {x * 3} 0 0 }} }}\n" for f, a, z in (("Thumb", 2, 3), ("Index", 8, 1),
                                                                                   ("Middle", 8, 0)))
    return "".join(_limb(f"{s}Arm,{s}ForeArm,{s}Hand", [f"{x * 17} 10 0", f"{x * 28} 0 0", f"{x * 25} 0 0"],
                         f"{x * 10} 0 0", hand(x)) for s, x in (("Left", 1), ("Right", -1)))


@pytest.mark.parametrize("legs_first", [False, True])
@pytest.mark.parametrize("neck", [True, False])
def test_a_short_spine_listed_after_the_legs_keeps_the_torso_upright(legs_first, neck):
    """One spine joint between the hips and the arms (or no neck): the torso's bones point up the
    chain, not at the clip joint's first child (a thigh, a collarbone)."""
    head = "JOINT Head { OFFSET 0 10 0 CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 20 0 } }\n"
    top = ("JOINT Neck { OFFSET 0 12 0 CHANNELS 3 Zrotation Xrotation Yrotation\n" + head + "}\n") if neck else \
        head.replace("OFFSET 0 10 0", "OFFSET 0 22 0")
    spine = ("JOINT Spine { OFFSET 0 45 0 CHANNELS 3 Zrotation Xrotation Yrotation\n"
             + (_arms() + top if neck else top + _arms()) + "}\n")
    channels = 3 * (1 + (2 if neck else 1) + 6 + 6)
    clip = parse_bvh(_t_pose_clip(_legs() + spine if legs_first else spine + _legs(), channels), "t.bvh")
    sk = Skeleton.from_params(BodyParams())
    pose = BvhMotion(clip, sk).pose(0.0)
    P = sk.forward(pose.rotations[None], pose.root[None])[1][0]
    up = P[JOINT_ID["head"]] - P[JOINT_ID["pelvis"]]
    assert up[1] > 0.99 * np.linalg.norm(up)  # the head straight above the pelvis
    across = P[JOINT_ID["l_shoulder"]] - P[JOINT_ID["r_shoulder"]]
    assert abs(across[1]) < 0.02 * np.linalg.norm(across)  # the shoulders level


def test_a_hand_with_fingers_points_along_the_hand_not_at_the_thumb():
    sk = Skeleton.from_params(BodyParams())
    poses = []
    for fingers in (False, True):
        spine = ("JOINT Spine { OFFSET 0 45 0 CHANNELS 3 Zrotation Xrotation Yrotation\n" + _arms(fingers)
                 + "JOINT Neck { OFFSET 0 12 0 CHANNELS 3 Zrotation Xrotation Yrotation\nJOINT Head { OFFSET 0 10 0 "
                 "CHANNELS 3 Zrotation Xrotation Yrotation End Site { OFFSET 0 20 0 } }\n}\n}\n")
        channels = 3 * (1 + 2 + 6 + 6 + (6 if fingers else 0))
        clip = parse_bvh(_t_pose_clip(spine + _legs(), channels), "h.bvh")
        poses.append(BvhMotion(clip, sk).pose(0.0).rotations[JOINT_ID["l_wrist"]])
    assert np.allclose(poses[0], poses[1], atol=1e-6)
