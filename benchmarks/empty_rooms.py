"""Empty simulated rooms for the benchmarks: the room a scene's person stands in, seen by the rig with nobody in it.

A scene's room is centred on its person's standing point, so moving the person out of view moves the room too:
at (40, 3) m, as the benchmarks placed them until session 65, the rig's cameras stand outside the room looking away
from it and see black frames (mean 0.6 of 255), which the frame check rejects before the model runs; behind the rig,
at (0, -3) m, they face the room's near wall, a plain wall in front of the lens for the smaller rooms. Here the
person stays where every scene with someone in it puts them (``SceneConfig`` defaults, 3 m in front of the rig) and
is left out of the picture: the room's own render, through the scene's sensor (its noise).
"""
from __future__ import annotations

import numpy as np

import drivers.sim as sim


def empty_room_pair(rig, seed: int, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The images ``rig.pair`` takes at scene time ``t`` of simulated scene ``seed``'s room with nobody in it:
    uint8 BGR, as ``SimScene.render`` gives them with the person taken out."""
    return scene_without_person(sim.SimScene(sim.SceneConfig(seed=seed)), rig.pair, t)


def scene_without_person(scene, cameras, t: float) -> tuple[np.ndarray, ...]:
    """What each of ``cameras`` sees of ``scene`` (a ``SimScene``) at scene time ``t`` with its person left out:
    the scene's own room (or plain background) where it stands, through its sensor, uint8 BGR. The room the scene's
    frames with the person show, at the same instant (``measure_one_camera.py``'s other camera)."""
    return tuple(scene.capture(scene.renderer.background(camera), camera, t) for camera in cameras)
