"""``benchmarks/measure_presence.py``'s empty rooms: textured rooms with nobody in them, which pass the frame check as
a real empty room does (until session 65 they were black frames, mean 0.6 of 255, which the frame check rejects before
the model runs, so the false-presence figures measured on them tested almost nothing)."""
from __future__ import annotations

import numpy as np
import pytest

import drivers.sim as sim
from benchmarks.empty_rooms import empty_room_pair
from benchmarks.measure_presence import empty_rooms
from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig, SessionConfig
from ghnerf_runtime.estimator import Estimator
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

#: A textured room's frame: far from black and far from flat (the old rooms: mean 0.59, std 0.91 of 255).
MIN_MEAN, MIN_STD = 40.0, 5.0


@pytest.fixture(scope="module")
def rig():
    return sim.RigPlacement().build()


def test_the_benchmark_s_empty_rooms_are_textured_not_black(rig):
    for seed, pair in enumerate(empty_rooms(rig, 4), start=1):
        for camera, image in zip(rig.pair, pair):
            assert image.dtype == np.uint8 and image.shape == (camera.height, camera.width, 3)
            # the frame check's flat-crop floor is 2 levels of standard deviation: a room is well above it
            assert image.std() > max(MIN_STD, FrameCheckConfig().min_std), (seed, camera.name, image.std())
            assert image.mean() > MIN_MEAN, (seed, camera.name, image.mean())


def test_an_empty_room_is_the_scene_s_own_room_with_its_person_left_out(rig):
    """The pixels around the person are the scene's render to the level (the same room, lighting and sensor noise),
    and where the person stands the room shows through."""
    seed, t = 3, 0.2
    scene = sim.SimScene(sim.SceneConfig(seed=seed))
    for camera, empty in zip(rig.pair, empty_room_pair(rig, seed, t)):
        image, truth = scene.render(camera, t)
        assert truth.mask.mean() > 0.01  # the person is in view in the scene's render
        np.testing.assert_array_equal(empty[~truth.mask], image[~truth.mask])
        person = np.abs(empty[truth.mask].astype(int) - image[truth.mask].astype(int)).mean()
        assert person > 10, person


def test_the_benchmark_s_empty_rooms_pass_the_frame_check(rig, tiny_model_dir):  # noqa: F811
    """The runtime's own frame check (its defaults) lets every view of them through to the model, as it lets a real
    empty room through; the black frames before were all rejected as flat. The tiny export's random weights do not
    matter: the check runs on the crops before the model."""
    config = EstimatorConfig(session=SessionConfig(model_dir=str(tiny_model_dir)))
    with Estimator.from_config(rig, config) as estimator:
        for seed, pair in enumerate(empty_rooms(rig, 4), start=1):
            estimator.reset()
            result = estimator.estimate(pair)
            assert result.frame_reason == {camera.name: None for camera in rig.pair}, (seed, result.frame_reason)
