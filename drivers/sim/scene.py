"""The synthetic scene: one procedurally built person, moving, in a room, seen by any camera.

``SimScene`` is a pure function of its config and time: ``render(camera, t)``
gives the same bytes every call (noise is seeded by scene seed, camera name
and ``t``), and all randomness (body, clothes, room) derives from
``SceneConfig.seed`` through independent streams, so fixing one part (say
``body``) does not change the others.

Not modelled here: multiple people (:func:`render_people` puts several scenes' people in one
picture), props, cloth or hair dynamics, motion blur, rolling shutter, shadows, camera timing
(jitter, drops, skew: the ``sim://`` backend adds those on top of this scene).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from drivers.frames import CameraTruth
from drivers.sim.appearance import Appearance, Look, srgb_to_linear
from drivers.sim.background import RoomStyle
from drivers.sim.body import BodyModel, PosedBody
from drivers.sim.errors import SimConfigError
from drivers.sim.motions import MOTION_NAMES, Motion, MotionParams, make_motion
from drivers.sim.render import BodyRenderer, Lighting, composite_nearest
from drivers.sim.retarget import BvhMotion
from drivers.sim.rotations import rot_y
from drivers.sim.sensor import SensorModel
from drivers.sim.skeleton import BodyParams, Skeleton
from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.geometry import Camera, WorkingVolume

# Independent random streams derived from the seed, one per purpose.
_BODY, _LOOK, _ROOM, _RANDOM_SCENE = 1, 2, 3, 4
# Body frame (x left, y up, z forward) -> rig frame for a person facing the rig (heading 0).
_FACING_RIG = np.diag([1.0, -1.0, -1.0])
_MID_HIP = JOINT_INDEX["MidHip"]


@dataclass(frozen=True)
class SceneConfig:
    """Everything that defines a simulated scene.

    Attributes:
        seed: root of all randomness (non-negative int).
        body: proportions; ``None`` draws them from ``seed``.
        appearance: skin/hair/clothes; ``None`` draws it from ``seed``.
        motion: a procedural motion name (see ``MOTION_NAMES``) or a path to a ``.bvh`` file.
        motion_params: amplitude/period of a procedural motion.
        speed: playback rate (scene time x speed = motion time), in (0, 10].
        position_xz: rig-frame (x, z) of the person's standing point (metres).
        heading_deg: rotation about the vertical; 0 faces the rig, 90 faces the rig's +x.
        background: render the room; ``False`` gives a plain ``plain_background`` colour.
        room: room style; ``None`` draws it from ``seed``.
        plain_background: sRGB colour (0..1) used when ``background`` is off.
        lighting: the light.
        sensor: exposure and noise.
        bvh_in_place: BVH motions only: remove the clip's net horizontal travel.
    """

    seed: int = 0
    body: BodyParams | None = None
    appearance: Appearance | None = None
    motion: str = "wave"
    motion_params: MotionParams = field(default_factory=MotionParams)
    speed: float = 1.0
    position_xz: tuple[float, float] = (0.0, 3.0)
    heading_deg: float = 0.0
    background: bool = True
    room: RoomStyle | None = None
    plain_background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lighting: Lighting = field(default_factory=Lighting)
    sensor: SensorModel = field(default_factory=SensorModel)
    bvh_in_place: bool = True

    def __post_init__(self) -> None:
        def fail(name: str, message: str) -> None:
            raise SimConfigError(f"SceneConfig.{name}", message)

        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            fail("seed", f"must be a non-negative int, got {self.seed!r}")
        for name, kind in (("body", BodyParams), ("appearance", Appearance), ("room", RoomStyle)):
            value = getattr(self, name)
            if value is not None and not isinstance(value, kind):
                fail(name, f"must be a {kind.__name__} or None, got {type(value).__name__}")
        for name, kind in (("motion_params", MotionParams), ("lighting", Lighting), ("sensor", SensorModel)):
            if not isinstance(getattr(self, name), kind):
                fail(name, f"must be a {kind.__name__}, got {type(getattr(self, name)).__name__}")
        self.motion_params.validate()
        if not isinstance(self.motion, (str, Path)) or not str(self.motion):
            fail("motion", f"must be a motion name or a .bvh path, got {self.motion!r}")
        if not str(self.motion).lower().endswith(".bvh") and str(self.motion) not in MOTION_NAMES:
            fail("motion", f"unknown motion {self.motion!r}; choose one of {MOTION_NAMES} or a .bvh path")
        if isinstance(self.speed, bool) or not isinstance(self.speed, (int, float)) or not (0 < self.speed <= 10) or not np.isfinite(self.speed):
            fail("speed", f"must be in (0, 10], got {self.speed!r}")
        pos = np.asarray(self.position_xz, dtype=np.float64) if _is_numeric(self.position_xz) else None
        if pos is None or pos.shape != (2,) or not np.all(np.isfinite(pos)) or np.any(np.abs(pos) > 100):
            fail("position_xz", f"must be a finite (x, z) pair within 100 m, got {self.position_xz!r}")
        if isinstance(self.heading_deg, bool) or not isinstance(self.heading_deg, (int, float)) or not np.isfinite(self.heading_deg):
            fail("heading_deg", f"must be a finite number, got {self.heading_deg!r}")
        if not isinstance(self.background, bool):
            fail("background", f"must be True or False, got {self.background!r}")
        if not isinstance(self.bvh_in_place, bool):
            fail("bvh_in_place", f"must be True or False, got {self.bvh_in_place!r}")
        bg = np.asarray(self.plain_background, dtype=np.float64) if _is_numeric(self.plain_background) else None
        if bg is None or bg.shape != (3,) or not np.all((bg >= 0) & (bg <= 1)):
            fail("plain_background", f"must be an (r, g, b) triple in [0, 1], got {self.plain_background!r}")


def _is_numeric(value) -> bool:
    try:
        np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


class SimScene:
    """A simulated person in a room, renderable from any calibrated camera at any time.

    Holds small caches (the last pose, per-camera rays and backgrounds), so one instance must not
    be shared between threads; build one per thread (same config, same output).

    Args:
        config: the scene; ``None`` uses ``SceneConfig()`` (seed 0, waving).

    Raises:
        SimConfigError: bad config values (the message names the field).
        BvhError: the motion's BVH file is malformed (the message names file and line).
    """

    def __init__(self, config: SceneConfig | None = None) -> None:
        config = SceneConfig() if config is None else config
        if not isinstance(config, SceneConfig):
            raise SimConfigError("config", f"must be a SceneConfig, got {type(config).__name__}")
        self.config = config
        seed = int(config.seed)
        params = config.body or BodyParams.random(np.random.default_rng([seed, _BODY]))
        self.appearance = config.appearance or Appearance.random(np.random.default_rng([seed, _LOOK]))
        self.skeleton = Skeleton.from_params(params)
        self.body = BodyModel(self.skeleton, long_hair=self.appearance.hair_style == "long")
        self.look = Look(self.appearance, self.body)
        motion_name = str(config.motion)
        self.motion: Motion
        if motion_name.lower().endswith(".bvh"):
            self.motion = BvhMotion(motion_name, self.skeleton, in_place=config.bvh_in_place)
        else:
            self.motion = make_motion(motion_name, self.skeleton, config.motion_params)
        room = None
        if config.background:
            room = config.room or RoomStyle.random(np.random.default_rng([seed, _ROOM]))
        self.room = room
        plain = tuple(float(c) for c in srgb_to_linear(config.plain_background)[::-1])
        self.renderer = BodyRenderer(self.body, self.look, config.lighting, room, tuple(config.position_xz), plain)
        heading = np.radians(config.heading_deg)
        self._to_rig_R = _FACING_RIG @ rot_y(heading)
        self._to_rig_t = np.array([config.position_xz[0], 0.0, config.position_xz[1]], dtype=np.float64)
        self._last: tuple[float, PosedBody] | None = None

    # ----------------------------------------------------------------- motion
    @property
    def period_s(self) -> float:
        """Scene time after which the motion repeats exactly."""
        return self.motion.period_s / self.config.speed

    def posed(self, t: float) -> PosedBody:
        """The body's primitives and joints at scene time ``t``, in the rig frame."""
        t = float(t)
        if not np.isfinite(t):
            raise SimConfigError("t", f"scene time must be finite, got {t!r}")
        if self._last is not None and self._last[0] == t:
            return self._last[1]
        pose = self.motion.pose(t * self.config.speed)
        G, P = self.skeleton.forward(pose.rotations, pose.root)
        P = self.body.settle(G, P, ground=self.motion.grounded, plant=self.motion.planted)
        posed = self.body.pose(G, P).transformed(self._to_rig_R, self._to_rig_t)
        self._last = (t, posed)
        return posed

    def joints_3d(self, t: float) -> np.ndarray:
        """``(25, 3)`` BODY_25 joints at scene time ``t`` in the rig frame (metres)."""
        return self.posed(t).joints.copy()

    def bounding_box(self, t: float, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The person's exact axis-aligned box ``(min (3,), max (3,))`` in the rig frame, grown by ``margin``."""
        if not np.isfinite(margin) or margin < 0:
            raise SimConfigError("margin", f"must be a finite non-negative number, got {margin!r}")
        lo, hi = self.posed(t).bounding_box()
        return lo - margin, hi + margin

    # ----------------------------------------------------------------- render
    def render(self, camera: Camera, t: float, *, with_truth: bool = True) -> tuple[np.ndarray, CameraTruth | None]:
        """Render what ``camera`` sees at scene time ``t``.

        Returns:
            ``image`` ``(H, W, 3)`` uint8 BGR and, when ``with_truth``, the :class:`CameraTruth`
            (background depth is ``inf``; everything else is finite).
        """
        radiance, truth = self.renderer.render(self.posed(t), camera, with_truth=with_truth)
        return self.capture(radiance, camera, t), truth

    def capture(self, radiance: np.ndarray, camera: Camera, t: float) -> np.ndarray:
        """``radiance`` (a renderer's picture for ``camera`` at scene time ``t``) through this scene's sensor, its
        noise seeded by the scene's seed, the camera's name and ``t``: what :meth:`render` returns for it, also for
        pictures composed or posed otherwise (:func:`render_people`, ``benchmarks/measure_lying_rendered.py``)."""
        sensor = self.config.sensor
        return sensor.capture(radiance, sensor.rng(int(self.config.seed), camera.name, float(t)))

    def render_batch(self, cameras: Sequence[Camera], t: float, *, with_truth: bool = True) -> list[tuple[np.ndarray, CameraTruth | None]]:
        """Render several cameras at one time; the pose is computed once."""
        self.posed(t)
        return [self.render(cam, t, with_truth=with_truth) for cam in cameras]


def render_people(scenes: Sequence[SimScene], camera: Camera, t: float) -> np.ndarray:
    """Several people in one room: each scene's person rendered by its own renderer (its own body and look), put
    together per pixel by depth (the nearer person's pixel where two overlap, :func:`composite_nearest`) over the
    first scene's room, and captured by the first scene's sensor (its noise seed). ``(H, W, 3)`` uint8 BGR, as
    :meth:`SimScene.render`. The other scenes' rooms and sensors are not used; no ground truth (each scene's
    :meth:`SimScene.joints_3d` is its person's; :func:`render_people_and_truth` gives the first's maps too)."""
    return render_people_and_truth(scenes, camera, t)[0]


def render_people_and_truth(scenes: Sequence[SimScene], camera: Camera, t: float) -> tuple[np.ndarray, CameraTruth]:
    """:func:`render_people`'s image and the first scene's person's :class:`CameraTruth` as that person alone gives
    it (``sim://?second=``: the frames carry the subject's truth). Its mask, depth and part labels are the first
    person's whole silhouette, also where another person stands in front of it, and ``visible`` says only whether
    the first person's own body hides a joint (the other people are not asked)."""
    if not scenes:
        raise SimConfigError("render_people", "needs at least one scene")
    layers = [scene.renderer.render(scene.posed(t), camera) for scene in scenes]
    radiance = composite_nearest([image for image, _ in layers], [truth.depth for _, truth in layers])
    return scenes[0].capture(radiance, camera, t), layers[0][1]


def random_scene(seed: int, *, volume: WorkingVolume | None = None, motions: Sequence[str] = MOTION_NAMES,
                 motion_weights: Sequence[float] | None = None) -> SimScene:
    """A scene with everything drawn from ``seed``: body, clothes, room, motion, speed, place,
    heading, light, exposure and noise.

    Args:
        volume: where the person may be: the pelvis stays 0.3 m inside it in x and z over the
            whole motion loop (when the volume is large enough); default: the working volume of
            the default :class:`RigPlacement`.
        motions: procedural motion names to choose from.
        motion_weights: relative probability of each of ``motions``; default: uniform (the draw
            then consumes the stream exactly as it did before weights existed, so seeds keep
            their scenes).
    """
    from drivers.sim.placement import RigPlacement  # local: placement is only needed for the default volume

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SimConfigError("seed", f"must be a non-negative int, got {seed!r}")
    bad = [m for m in motions if m not in MOTION_NAMES]
    if not motions or bad:
        raise SimConfigError("motions", f"must be a non-empty subset of {MOTION_NAMES}, got {list(motions)}")
    if motion_weights is not None:
        w = np.asarray(motion_weights, dtype=float)
        if w.shape != (len(motions),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise SimConfigError("motion_weights", f"must be {len(motions)} non-negative weights with a positive sum, "
                                                   f"got {list(motion_weights)}")
    volume = volume or RigPlacement().build().volume
    rng = np.random.default_rng([int(seed), _RANDOM_SCENE])
    lo, hi = volume.min_corner, volume.max_corner
    inset = np.minimum(0.3, 0.45 * (hi - lo))
    x = float(rng.uniform(lo[0] + inset[0], hi[0] - inset[0]))
    z = float(rng.uniform(lo[2] + inset[2], hi[2] - inset[2]))
    if motion_weights is None:
        motion = str(motions[int(rng.integers(len(motions)))])
    else:
        motion = str(motions[int(rng.choice(len(motions), p=w / w.sum()))])
    light = (float(rng.uniform(-1, 1)), float(rng.uniform(-1.0, -0.3)), float(rng.uniform(-1, 0.5)))
    config = SceneConfig(
        seed=int(seed),
        motion=motion,
        motion_params=MotionParams(amplitude=float(rng.uniform(0.7, 1.15)),
                                   # own stream: the other motions' scenes stay what they were
                                   seed=int(np.random.default_rng([int(seed), _RANDOM_SCENE, 1]).integers(2**62))),
        speed=float(rng.uniform(0.7, 1.3)),
        position_xz=(x, z),
        heading_deg=float(rng.uniform(-180.0, 180.0)),
        background=bool(rng.uniform() < 0.9),
        lighting=Lighting(direction=light, ambient=float(rng.uniform(0.2, 0.5))),
        sensor=SensorModel(
            exposure=float(2.0 ** rng.uniform(-0.7, 0.7)),
            exposure_jitter=float(rng.uniform(0.0, 0.05)),
            read_noise=float(rng.uniform(0.5, 4.0)),
            shot_noise=float(rng.uniform(0.0, 0.5)),
        ),
    )
    scene = SimScene(config)
    # Motions that travel (walking a circle) must keep the whole loop inside the volume: shift
    # the standing point so the pelvis' path fits (centred when it cannot fit).
    path = np.array([scene.joints_3d(t)[_MID_HIP, [0, 2]] for t in np.linspace(0.0, scene.period_s, 16, endpoint=False)])
    lo_xz, hi_xz = lo[[0, 2]] + inset[[0, 2]], hi[[0, 2]] - inset[[0, 2]]
    span_lo, span_hi = path.min(axis=0), path.max(axis=0)
    shift = np.where(span_hi - span_lo > hi_xz - lo_xz, 0.5 * (lo_xz + hi_xz) - 0.5 * (span_lo + span_hi),
                     np.maximum(lo_xz - span_lo, 0.0) + np.minimum(hi_xz - span_hi, 0.0))
    if np.any(np.abs(shift) > 1e-9):
        scene = SimScene(replace(config, position_xz=(x + float(shift[0]), z + float(shift[1]))))
    return scene
