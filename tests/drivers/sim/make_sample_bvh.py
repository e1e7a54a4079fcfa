"""Regenerate drivers/sim/data/jumping_jacks.bvh (the shipped sample clip).

The clip is the procedural ``jumping_jacks`` motion on the default body, exported the way
common BVH files look: CMU joint names plus toe joints, a T-pose rest, Z-X-Y Euler channels,
centimetres, 30 fps, one loop without a repeated first frame. Run from the repository root:

    .venv/bin/python -m tests.drivers.sim.make_sample_bvh
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from drivers.sim.body import BodyModel
from drivers.sim.bvh import BvhClip, BvhJoint, save_bvh
from drivers.sim.motions import make_motion
from drivers.sim.retarget import clip_from_poses
from drivers.sim.skeleton import BodyParams, Skeleton

OUT = Path(__file__).resolve().parents[3] / "drivers" / "sim" / "data" / "jumping_jacks.bvh"
FPS = 30


def sample_clip() -> BvhClip:
    skeleton = Skeleton.from_params(BodyParams())
    body = BodyModel(skeleton)
    motion = make_motion("jumping_jacks", skeleton)
    frames = int(round(motion.period_s * FPS))
    rotations, roots = [], []
    for f in range(frames):
        pose = motion.pose(f / FPS)
        G, P = skeleton.forward(pose.rotations, pose.root)
        P = body.settle(G, P, ground=motion.grounded, plant=motion.planted)
        rotations.append(pose.rotations)
        roots.append(P[0])
    clip = clip_from_poses(skeleton, np.array(rotations), np.array(roots), 1.0 / FPS, order="zxy", t_pose=True, units=100.0)
    # Add CMU-style toe joints under the feet (zero rotation), replacing the feet's end sites.
    joints, columns = [], []
    slices = clip.channel_slices()
    for k, joint in enumerate(clip.joints):
        parent = joint.parent
        if parent >= 0:  # indices shift as toes are inserted
            parent = next(i for i, j in enumerate(joints) if j.name == clip.joints[parent].name)
        foot = joint.name.endswith("Foot")
        joints.append(BvhJoint(joint.name, parent, joint.offset, joint.channels, None if foot else joint.end_site))
        columns.append(clip.frames[:, slices[k]])
        if foot:
            joints.append(BvhJoint(joint.name.replace("Foot", "ToeBase"), len(joints) - 1, joint.end_site, ("Zrotation", "Xrotation", "Yrotation"), np.array([0.0, 0.0, 4.0])))
            columns.append(np.zeros((clip.num_frames, 3)))
    return BvhClip(tuple(joints), clip.frame_time, np.concatenate(columns, axis=1), str(OUT))


if __name__ == "__main__":
    save_bvh(sample_clip(), OUT, precision=4)
    print(f"wrote {OUT}")
