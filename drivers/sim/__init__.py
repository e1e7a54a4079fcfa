"""Synthetic human scene for the ``sim://`` rig and for training data.

One procedurally built person (BODY_25 skeleton, ellipsoid/rounded-cone body,
randomised proportions, skin, hair and clothes) performs a periodic motion
(procedural, or any BVH clip) in a simple textured room. Any calibrated
:class:`~ghnerf_runtime.geometry.Camera` can render it by exact analytic ray
casting, with ground truth: 3D joints in the rig frame, and per camera 2D
joints with visibility, foreground mask, depth and body-part labels.

Quick start::

    from drivers.sim import RigPlacement, SceneConfig, SimScene
    rig = RigPlacement().build()
    scene = SimScene(SceneConfig(seed=3, motion="walk"))
    image, truth = scene.render(rig.cameras[0], t=0.5)

Several people: :func:`render_people` puts scenes' people into the first's room, the nearer person's pixel
where two overlap (no ground truth of the whole: each scene's joints are its person's; since session 55);
:func:`render_people_and_truth` adds the first person's maps, as ``sim://?second=X,Z`` films two people
(since session 64). What it
does NOT model: people casting light or shadow on each other, props or occluders other than the
body, cloth/hair/soft-tissue dynamics, shadows and inter-reflections,
specular materials, motion blur, rolling shutter, lens vignetting or flare,
anti-aliasing, and camera timing (jitter, drops, inter-camera skew: the
``sim://`` backend adds those).
"""
from __future__ import annotations

from drivers.sim.appearance import Appearance, Fabric
from drivers.sim.background import RoomStyle
from drivers.sim.body import PART_ID, PART_NAMES, BodyModel
from drivers.sim.bvh import BvhClip, dumps_bvh, load_bvh, parse_bvh, save_bvh
from drivers.sim.data import SAMPLE_BVH
from drivers.sim.errors import BvhError, SimConfigError
from drivers.sim.motions import MOTION_NAMES, MotionParams, Pose, make_motion
from drivers.sim.placement import RigPlacement
from drivers.sim.render import Lighting
from drivers.sim.retarget import BvhMotion
from drivers.sim.scene import SceneConfig, SimScene, random_scene, render_people, render_people_and_truth
from drivers.sim.sensor import SensorModel
from drivers.sim.skeleton import BodyParams, Skeleton

__all__ = [
    "MOTION_NAMES", "PART_ID", "PART_NAMES", "SAMPLE_BVH",
    "Appearance", "BodyModel", "BodyParams", "BvhClip", "BvhError", "BvhMotion", "Fabric", "Lighting",
    "MotionParams", "Pose", "RigPlacement", "RoomStyle", "SceneConfig", "SensorModel", "SimConfigError",
    "SimScene", "Skeleton", "dumps_bvh", "load_bvh", "make_motion", "parse_bvh", "random_scene", "render_people",
    "render_people_and_truth",
    "save_bvh",
]
