"""Empty simulated rooms for the benchmarks: the room a scene's person stands in, seen by the rig with nobody in it.

A scene's room is centred on its person's standing point, so moving the person out of view moves the room too:
at (40, 3) m, as the benchmarks placed them until session 65, the rig's cameras stand outside the room looking away
from it and see black frames (mean 0.6 of 255), which the frame check rejects before the model runs; behind the rig,
at (0, -3) m, they face the room's near wall, a plain wall in front of the lens for the smaller rooms. Here the
person stays where every scene with someone in it puts them (``SceneConfig`` defaults, 3 m in front of the rig) and
is left out of the picture: the room's own render, through the scene's sensor (its noise).
"""
from __future__ import annotations

import zlib

import cv2
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


#: where :func:`with_screen` puts the screen in each camera's picture: (top, left, bottom, right), fractions of the
#: frame (a television on the far wall, about a fifth of the frame each way: some 20 of the wake-up's 18 x 24 cells)
SCREEN_BOX = (0.10, 0.60, 0.30, 0.85)
#: the screen's picture, blocks (rows, columns): a coarse moving image, each block a fresh colour every pair
SCREEN_BLOCKS = (3, 4)


def with_screen(picture: np.ndarray, camera_name: str, t: float, box: tuple = SCREEN_BOX) -> np.ndarray:
    """``picture`` (display-space ``(H, W, 3)`` float32, as the renderer gives it; not modified) with a screen in
    ``box`` showing a picture that changes every instant: :data:`SCREEN_BLOCKS` blocks of colours drawn from
    ``camera_name`` and ``t`` (the same pair, the same picture). A scene that keeps moving with nobody in it."""
    h, w = picture.shape[:2]
    top, left, bottom, right = (int(round(f * n)) for f, n in zip(box, (h, w, h, w)))
    rng = np.random.default_rng([zlib.crc32(camera_name.encode()), int(round(float(t) * 1e6))])
    blocks = rng.uniform(0.05, 0.95, (*SCREEN_BLOCKS, 3)).astype(np.float32)
    out = np.array(picture, dtype=np.float32, copy=True)
    out[top:bottom, left:right] = cv2.resize(blocks, (right - left, bottom - top), interpolation=cv2.INTER_NEAREST)
    return out


def scene_with_screen(scene, cameras, t: float) -> tuple[np.ndarray, ...]:
    """:func:`scene_without_person` with a screen (:func:`with_screen`) in each camera's view: the room, nobody in
    it, a television playing."""
    return tuple(scene.capture(with_screen(scene.renderer.background(camera), camera.name, t), camera, t)
                 for camera in cameras)
