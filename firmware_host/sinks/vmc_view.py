"""Which way the VMC avatar faces, and whether it mirrors the person: the vmc:// ``facing`` and ``mirror`` options.

Both act on the BODY_25 joints (rig frame) before ``vmc_pose`` solves the bones, never on the solved
quaternions: the solver builds every rotation from right-handed frames and shortest arcs, so what it
sends stays a proper rotation (determinant +1) whatever is done to the joints. Mirroring the
quaternions themselves would need the reflection conjugated in, and a sign slip there sends an avatar
turned inside out.

- ``facing=camera`` turns the whole capture half round about the rig's vertical axis (x and z negated,
  the origin fixed): a person facing the cameras drives an avatar that faces the receiver's camera
  (a VRM avatar's front is Unity +z, where receivers put their camera), and Root/Pos turns with it,
  so walking towards the cameras walks the avatar towards the viewer. ``facing=away`` (the default)
  keeps the rig's physical directions (docs/protocol.md, "VMC output"): a person facing the cameras
  is seen from behind.
- ``mirror=1`` reflects x and swaps every left joint with its right one (``FLIP_INDEX``): the avatar
  is the person's mirror image, so their left hand moves the avatar's right hand. The reflection
  alone leaves left-labelled joints on the right: the solver then turns the hips half round and the
  head upside down (ears say one way, nose the other); with the swap too, the skeleton is a body again.

The two commute; ``facing=camera&mirror=1`` is what webcam VTuber trackers show: the avatar faces the
viewer and moves on screen like a mirror.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ghnerf_runtime.body25 import FLIP_INDEX, NUM_JOINTS

#: Values of the vmc:// ``facing`` option; the first is the default.
FACINGS = ("away", "camera")
_FLIP = np.array(FLIP_INDEX)


@dataclass(frozen=True)
class AvatarView:
    facing: str = FACINGS[0]
    mirror: bool = False

    def __post_init__(self) -> None:
        if self.facing not in FACINGS:
            raise ValueError(f"facing must be one of {list(FACINGS)}, got {self.facing!r}")

    @property
    def is_identity(self) -> bool:
        return self.facing == "away" and not self.mirror

    def apply(self, joints_3d: np.ndarray) -> np.ndarray:
        """(25, 4) rig-frame joints (x, y, z, confidence) as this view shows them; the input is not changed.
        The default view returns ``joints_3d`` itself, so the default output is what it always was."""
        if self.is_identity:
            return joints_3d
        j = np.array(joints_3d, dtype=np.float64)  # a copy
        if j.ndim != 2 or j.shape[1] != 4 or j.shape[0] < NUM_JOINTS:
            raise ValueError(f"joints_3d must have shape (25, 4) for BODY_25, got {j.shape}")
        if self.mirror:
            j[:NUM_JOINTS] = j[_FLIP]  # the person's left joints drive the avatar's right bones
            j[:, 0] *= -1.0
        if self.facing == "camera":
            j[:, 0] *= -1.0  # half a turn about the vertical (rig y): x and z change sign
            j[:, 2] *= -1.0
        return j
