"""Render one frame pair of the default simulated rig with its 2D ground truth drawn on top.

Usage: ``python -m drivers.sim.demo [--out sim_pair.png] [--seed 0] [--motion wave] [--t 0.3]``
(also installed as ``ghnerf-sim-demo``). Writes a side-by-side PNG of both
cameras with BODY_25 joints (filled: visible, hollow: hidden) and limbs, and
prints the ground-truth 3D joints in the rig frame.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from drivers.errors import RigConfigError
from drivers.frames import CameraTruth
from drivers.sim.motions import MOTION_NAMES
from drivers.sim.placement import RigPlacement
from drivers.sim.scene import SceneConfig, SimScene
from ghnerf_runtime.body25 import JOINT_NAMES, LIMBS
from ghnerf_runtime.path_check import user_path


def draw_truth(image: np.ndarray, truth: CameraTruth) -> np.ndarray:
    """A copy of ``image`` with limbs between visible joints and every in-image joint marked."""
    out = image.copy()
    h, w = out.shape[:2]
    pts = np.rint(truth.joints_2d).astype(int)
    for a, b in LIMBS:
        if truth.visible[a] and truth.visible[b]:
            cv2.line(out, tuple(pts[a]), tuple(pts[b]), (0, 255, 255), 1, cv2.LINE_AA)
    for k, (u, v) in enumerate(pts):
        if not (0 <= u < w and 0 <= v < h):
            continue
        # Person's right in red, left in blue (BGR), centre line in green.
        name = JOINT_NAMES[k]
        colour = (0, 0, 255) if name.startswith("R") else (255, 80, 0) if name.startswith("L") else (0, 200, 0)
        cv2.circle(out, (int(u), int(v)), 3, colour, -1 if truth.visible[k] else 1, cv2.LINE_AA)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="ghnerf-sim-demo", description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=user_path, default="sim_pair.png", help="image file to write (.png or .jpg)")
    parser.add_argument("--seed", type=int, default=0, help="scene seed (body, clothes, room)")
    parser.add_argument("--motion", type=user_path, default="wave", help=f"one of {', '.join(MOTION_NAMES)}, or a .bvh path")
    parser.add_argument("--t", type=float, default=0.3, help="scene time in seconds")
    args = parser.parse_args(argv)
    # said before the render, as a usage error: cv2.imwrite raised a cv2.error traceback for these
    if Path(args.out).is_dir():
        parser.error(f"--out {args.out}: is a folder; give the PNG file's path")
    if not cv2.haveImageWriter(args.out):
        parser.error(f"--out {args.out}: cannot write an image of this kind; give .png or .jpg")
    rig = RigPlacement().build()
    try:  # an unknown --motion, an unreadable .bvh, a --t of nan: one line naming it, not a traceback
        scene = SimScene(SceneConfig(seed=args.seed, motion=args.motion))
        rendered = scene.render_batch(rig.pair, args.t)
    except RigConfigError as e:
        parser.error(str(e))
    views = []
    for cam, (image, truth) in zip(rig.pair, rendered):
        panel = draw_truth(image, truth)
        cv2.putText(panel, f"{cam.name}  t={args.t:.2f}s", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
        views.append(panel)
    if not cv2.imwrite(args.out, np.hstack(views)):
        parser.error(f"could not write {args.out}")
    joints = scene.joints_3d(args.t)
    print(f"ground-truth BODY_25 joints at t={args.t:.3f}s, rig frame (m; x right, y down, z forward):")
    for name, (x, y, z) in zip(JOINT_NAMES, joints):
        print(f"  {name:10s} {x:+.3f} {y:+.3f} {z:+.3f}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
