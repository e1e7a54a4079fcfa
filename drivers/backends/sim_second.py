"""``sim://?second=X,Z``: a second person in front of the simulated rig (since session 64).

The options (``second``, ``second_motion``, ``second_after_s``) are read here, the second person's
:class:`~drivers.sim.SceneConfig` built, and a place the rig cannot film is refused. Places are rig-frame
``(x, z)`` metres, as ``benchmarks/measure_two_people.py --places`` gives them (x to the right as the cameras
look, z ahead of the rig); the subject stands at ``(0, distance)``. The second person's body, clothes and
motion come from the URL's ``seed`` plus :data:`SECOND_SEED_OFFSET`, as the benchmark draws its second person.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.errors import RigConfigError
from drivers.sim import MOTION_NAMES, MotionParams, SceneConfig, SimScene
from drivers.url import RigUrl, decimal_number
from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.geometry import Rig

#: The second person's seed is the subject's plus this (``measure_two_people.py``'s ``seed + 1000``).
SECOND_SEED_OFFSET = 1000
#: Hips closer than this (horizontal metres, at any instant of the loop) put two torsos through each other.
MIN_HIPS_APART_M = 0.4
#: Instants of the loop at which the two people's hips are compared.
_APART_SAMPLES = 16
_MID_HIP = JOINT_INDEX["MidHip"]


@dataclass(frozen=True)
class SecondPerson:
    """The second person of a ``sim://`` URL: who (``scene``) and when, from open, they join (``after_s``;
    ``None``: in every frame)."""

    scene: SceneConfig
    after_s: float | None = None


def take_second_person(url: RigUrl, seed: int, subject_motion: str | None) -> SecondPerson | None:
    """Reads ``second``, ``second_motion`` and ``second_after_s`` from ``url``; ``None`` without ``second``
    (the two others are then refused, naming ``second``). ``subject_motion``: the subject's procedural motion,
    the second person's default (``wave`` for a ``bvh=`` subject)."""
    place = _take_place(url, "second")
    motion = url.take_str("second_motion", None, choices=MOTION_NAMES)
    after_s = url.take_float("second_after_s", -1.0, lo=0.0, hi=1e6) if "second_after_s" in url.options else None
    if place is None:
        given = [name for name, value in (("second_motion", motion), ("second_after_s", after_s)) if value is not None]
        if given:
            raise RigConfigError(f"rig URL {url.url!r}: option {given[0]}= needs second=X,Z (where the second person "
                                 "stands, rig-frame metres)")
        return None
    motion = motion or subject_motion or "wave"
    second_seed = seed + SECOND_SEED_OFFSET
    params = MotionParams(seed=second_seed) if motion == "freestyle" else MotionParams()
    return SecondPerson(SceneConfig(seed=second_seed, motion=motion, motion_params=params, position_xz=place), after_s)


def _take_place(url: RigUrl, name: str) -> tuple[float, float] | None:
    """The option ``name`` as ``X,Z`` (two numbers, metres), ``None`` when absent."""
    raw = url.take_str(name)
    if raw is None:
        return None
    parts = raw.split(",")
    try:
        if len(parts) != 2:
            raise ValueError(f"has {len(parts)} part(s)")
        x, z = (decimal_number(part) for part in parts)
    except ValueError as e:
        raise RigConfigError(f"rig URL {url.url!r}: option {name}={raw!r} must be two numbers X,Z (rig-frame "
                             f"metres: x to the right, z ahead of the rig), e.g. {name}=1.0,3.4 ({e})") from None
    if not (-10.0 <= x <= 10.0 and 0.0 < z <= 20.0):
        raise RigConfigError(f"rig URL {url.url!r}: option {name}={raw!r}: x must be in [-10, 10] and z in "
                             "(0, 20] (metres, z ahead of the rig)")
    return x, z


def check_second_person(subject: SimScene, second: SimScene, rig: Rig) -> None:
    """Refuses a second person that both cameras do not see (their hips outside an image: they would never reach
    the runtime, and the rehearsal would show one person without a word) or whose torso passes through the
    subject's (hips closer than :data:`MIN_HIPS_APART_M` at some instant of the loop: the renderer draws the nearer
    surface per pixel, so the picture would be one body of two people's parts, which no rig films)."""
    where = "second={:g},{:g}".format(*second.config.position_xz)
    hips = second.joints_3d(0.0)[_MID_HIP]
    for cam in rig.pair:
        uv, depth = cam.project(hips)
        if depth > 0 and np.all(np.isfinite(uv)) and 0 <= uv[0] < cam.width and 0 <= uv[1] < cam.height:
            continue
        raise RigConfigError(f"sim: camera {cam.name!r} does not see the second person at {where}: "
                             "their hips are outside its image (give a place both cameras film, nearer the subject)")
    closest = _closest_hips_m(subject, second)
    if closest < MIN_HIPS_APART_M:
        raise RigConfigError(f"sim: the second person at {where} comes within {closest:.2f} m of "
                             f"the subject (hips, over the loop): under {MIN_HIPS_APART_M:g} m their bodies pass "
                             "through each other; stand them further apart")


def _closest_hips_m(subject: SimScene, second: SimScene) -> float:
    """The least horizontal distance between the two people's mid-hips over the subject's motion period."""
    times = np.linspace(0.0, subject.period_s, _APART_SAMPLES, endpoint=False)
    gaps = [np.linalg.norm(subject.joints_3d(t)[_MID_HIP, [0, 2]] - second.joints_3d(t)[_MID_HIP, [0, 2]])
            for t in times]
    return float(min(gaps))
