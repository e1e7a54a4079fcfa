"""Image formation: background on/off, exposure, lighting, caches and the demo."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from drivers.sim import Lighting, RigPlacement, RoomStyle, SceneConfig, SensorModel, SimConfigError, SimScene
from drivers.sim.demo import main
from ghnerf_runtime.geometry import Camera, intrinsics_from_fov, look_at


@pytest.fixture(scope="module")
def cam():
    return RigPlacement(width=256, height=192).build().cameras[0]


def _config(**kw) -> SceneConfig:
    return SceneConfig(seed=8, motion="stand", **{"sensor": SensorModel(read_noise=0.0), **kw})


def test_plain_background_is_exactly_the_colour(cam):
    scene = SimScene(_config(background=False, plain_background=(0.2, 0.4, 0.6)))
    image, truth = scene.render(cam, 0.0)
    bg = image[~truth.mask]
    expected = np.rint(255 * np.array([0.6, 0.4, 0.2]))  # BGR; display values are sRGB-like (gamma 2.2)
    assert np.all(np.abs(bg.astype(int) - expected) <= 1)
    assert np.any(image[truth.mask] != image[~truth.mask][0])


def test_room_background_is_textured_and_static(cam):
    scene = SimScene(_config(room=RoomStyle()))
    a, ta = scene.render(cam, 0.0)
    b, tb = scene.render(cam, 1.3)
    both = ~ta.mask & ~tb.mask
    np.testing.assert_array_equal(a[both], b[both])  # no noise: the empty room does not change
    assert a[~ta.mask].std() > 5  # tiles, walls, ceiling


def test_exposure_and_light(cam):
    dark = SimScene(_config(sensor=SensorModel(read_noise=0.0, exposure=0.5)))
    bright = SimScene(_config(sensor=SensorModel(read_noise=0.0, exposure=2.0)))
    img_d, truth = dark.render(cam, 0.0)
    img_b, _ = bright.render(cam, 0.0)
    assert img_b[truth.mask].mean() > 1.3 * img_d[truth.mask].mean()
    jitter = SimScene(_config(sensor=SensorModel(read_noise=0.0, exposure_jitter=0.5)))
    means = [jitter.render(cam, t)[0].mean() for t in (0.0, 0.1, 0.2)]
    assert np.ptp(means) > 1.0
    # Lit from the person's front vs from behind: the front of the body is brighter.
    front = SimScene(_config(lighting=Lighting(direction=(0.0, -0.3, -1.0), ambient=0.2)))
    back = SimScene(_config(lighting=Lighting(direction=(0.0, -0.3, 1.0), ambient=0.2)))
    m = front.render(cam, 0.0)[1].mask
    assert front.render(cam, 0.0)[0][m].mean() > 1.5 * back.render(cam, 0.0)[0][m].mean()


def test_small_views_and_caches():
    scene = SimScene(_config())
    rng = np.random.default_rng(0)
    for i in range(12):
        a = rng.uniform(0, 2 * np.pi)
        eye = [2.5 * np.sin(a), -rng.uniform(0.5, 2.0), 3.0 - 2.5 * np.cos(a)]
        R, t = look_at(eye, [0.0, -0.9, 3.0])
        view = Camera(f"v{i}", 128, 128, intrinsics_from_fov(128, 128, 50), np.zeros(5), R, t)
        image, truth = scene.render(view, 0.1 * i)
        assert image.shape == (128, 128, 3) and 500 < truth.mask.sum() < 128 * 128
        uv, _ = view.project(scene.joints_3d(0.1 * i))
        np.testing.assert_allclose(truth.joints_2d, uv, atol=1e-9)
    assert len(scene.renderer._backgrounds) <= scene.renderer.cache_size


def test_demo_writes_a_pair(tmp_path, capsys):
    out = tmp_path / "pair.png"
    assert main(["--out", str(out), "--seed", "2", "--motion", "squat", "--t", "0.4"]) == 0
    image = cv2.imread(str(out))
    assert image.shape == (480, 1280, 3)
    printed = capsys.readouterr().out
    assert "RBigToe" in printed and "wrote" in printed


def test_composite_nearest_the_nearer_layer_wins_and_the_first_keeps_the_room():
    from drivers.sim.render import composite_nearest

    room, person_a, person_b = (np.full((2, 3, 3), v, np.float32) for v in (0.1, 0.5, 0.9))
    inf = np.inf
    depth_a = np.array([[2.0, 2.0, inf], [inf, 3.0, inf]], np.float32)
    depth_b = np.array([[3.0, inf, 2.5], [inf, 2.5, inf]], np.float32)
    image_a = np.where(np.isfinite(depth_a)[..., None], person_a, room)
    image_b = np.where(np.isfinite(depth_b)[..., None], person_b, room + 0.05)  # its own room, never shown
    out = composite_nearest([image_a, image_b], [depth_a, depth_b])
    expected = np.array([[0.5, 0.5, 0.9],    # both (A nearer), A only, B only
                         [0.1, 0.9, 0.1]])   # nobody (the first's room), both (B nearer), nobody
    np.testing.assert_array_equal(out[..., 0], expected.astype(np.float32))
    with pytest.raises(SimConfigError, match=r"composite_nearest\[1\]"):
        composite_nearest([image_a, image_b[:, :2]], [depth_a, depth_b[:, :2]])


def test_render_people_shows_each_person_where_only_they_are_and_the_nearer_where_both(cam):
    from drivers.sim import render_people

    near = SimScene(_config(position_xz=(-0.2, 2.8)))
    far = SimScene(SceneConfig(seed=9, motion="stand", position_xz=(0.2, 3.6), sensor=SensorModel(read_noise=0.0)))
    both = render_people([near, far], cam, 0.0)
    own_near, truth_near = near.render(cam, 0.0)
    own_far, truth_far = far.renderer.render(far.posed(0.0), cam)
    # the far person through the near scene's sensor (exposure and noise seed), as render_people captures them
    own_far = near.config.sensor.capture(own_far, near.config.sensor.rng(8, cam.name, 0.0))
    only_near, only_far = truth_near.mask & ~truth_far.mask, truth_far.mask & ~truth_near.mask
    overlap = truth_near.mask & truth_far.mask
    assert only_near.sum() > 100 and only_far.sum() > 100 and overlap.sum() > 100  # the places make all three
    np.testing.assert_array_equal(both[only_near], own_near[only_near])
    np.testing.assert_array_equal(both[only_far], own_far[only_far])
    np.testing.assert_array_equal(both[overlap], own_near[overlap])  # the nearer one hides the other
    nobody = ~truth_near.mask & ~truth_far.mask
    np.testing.assert_array_equal(both[nobody], own_near[nobody])  # the first scene's room
