"""``benchmarks/time_scenes.py``'s ``empty`` scene: the room of its scene seed (``EMPTY_ROOM_SEED``) with its person
left out, as the benchmarks' other empty rooms (``benchmarks/empty_rooms.py``); until session 65 the person stood 3 m
behind the rig, which moved the room back so that the cameras faced its near wall."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("drivers.sim")

from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from benchmarks.time_scenes import EMPTY_ROOM_SEED, scene_pairs  # noqa: E402


def test_the_empty_scene_is_the_room_of_its_seed_without_its_person():
    rig, pairs = scene_pairs("empty", 2)
    expected = empty_room_pair(rig, EMPTY_ROOM_SEED)
    for images, _ in pairs:
        for image, room in zip(images, expected):
            np.testing.assert_array_equal(image, room)
