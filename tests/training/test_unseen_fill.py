"""Painting the unseen surface (``training.unseen_fill``): bones, normals, the light fit, the fills."""
from __future__ import annotations

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_INDEX, LIMBS
from training.unseen_fill import (FLIP_LIMB, SeenSurface, bone_coordinates, fit_lighting, shading,
                                  surface_normals)


def _joints() -> tuple[np.ndarray, np.ndarray]:
    """A T-pose-ish skeleton, metres, y down: every joint distinct."""
    rng = np.random.default_rng(3)
    joints = rng.uniform(-1.0, 1.0, (25, 3))
    joints[JOINT_INDEX["RElbow"]] = [0.5, 0.0, 0.0]
    joints[JOINT_INDEX["RWrist"]] = [0.9, 0.0, 0.0]
    return joints, np.ones(25, bool)


def test_a_point_beside_a_bone_gets_that_bone_and_its_bin_along_it():
    joints, valid = _joints()
    forearm = LIMBS.index((JOINT_INDEX["RElbow"], JOINT_INDEX["RWrist"]))
    points = np.array([[0.51, 0.01, 0.0], [0.62, 0.01, 0.0], [0.89, -0.01, 0.0], [1.5, 0.0, 0.0]])
    bone, k = bone_coordinates(points, joints, valid, bins=4)
    assert list(bone) == [forearm] * 4
    assert list(k) == [0, 1, 3, 3]  # the last point lies past the wrist: clamped to the last bin


def test_a_bone_with_an_invalid_end_is_never_chosen_and_none_valid_gives_minus_one():
    joints, valid = _joints()
    forearm = LIMBS.index((JOINT_INDEX["RElbow"], JOINT_INDEX["RWrist"]))
    valid[JOINT_INDEX["RWrist"]] = False
    bone, _ = bone_coordinates(np.array([[0.7, 0.0, 0.0]]), joints, valid)
    assert bone[0] != forearm
    bone, k = bone_coordinates(np.array([[0.7, 0.0, 0.0]]), joints, np.zeros(25, bool))
    assert bone[0] == -1 and 0 <= k[0] < 4


def test_the_mirror_bone_map_swaps_left_and_right_and_is_its_own_inverse():
    assert all(FLIP_LIMB[FLIP_LIMB[i]] == i for i in range(len(LIMBS)))
    r_forearm = LIMBS.index((JOINT_INDEX["RElbow"], JOINT_INDEX["RWrist"]))
    l_forearm = LIMBS.index((JOINT_INDEX["LElbow"], JOINT_INDEX["LWrist"]))
    spine = LIMBS.index((JOINT_INDEX["Neck"], JOINT_INDEX["MidHip"]))
    assert FLIP_LIMB[r_forearm] == l_forearm and FLIP_LIMB[spine] == spine


def test_the_normals_of_a_tilted_plane_are_its_normal_facing_the_camera():
    H = W = 32
    K = np.array([[40.0, 0, 15.5], [0, 40.0, 15.5], [0, 0, 1]])
    K_inv = np.linalg.inv(K)
    c2w = np.hstack([np.eye(3), np.zeros((3, 1))])  # camera at the origin looking down +z
    normal = np.array([0.3, -0.2, -1.0])
    normal /= np.linalg.norm(normal)  # faces the camera (negative z)
    # the plane n . X = n . (0, 0, 2): depth z where the pixel's ray r (z = 1) meets it: z = d / (n . r)
    v, u = np.mgrid[0:H, 0:W].astype(float)
    rays = np.stack([u, v, np.ones_like(u)], -1) @ K_inv.T
    depth = (normal @ np.array([0, 0, 2.0])) / (rays @ normal)
    mask = np.zeros((H, W), bool)
    mask[4:28, 6:26] = True
    n = surface_normals(depth, mask, K_inv, c2w)
    assert np.allclose(n[mask], normal, atol=1e-3)  # edge pixels included: the inpainted depth continues the plane
    assert np.allclose(np.linalg.norm(n[mask], axis=-1), 1.0) and not n[~mask].any()  # zero outside


def test_the_light_fit_recovers_a_known_light_ambient_and_albedos():
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(3000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    light = np.array([0.4, -0.8, -0.45])
    light /= np.linalg.norm(light)
    cells = rng.integers(0, 6, 3000)
    albedo = rng.uniform(0.1, 0.9, (6, 3))
    linear = albedo[cells] * shading(normals, light, 0.3)[:, None]
    fit = fit_lighting(SeenSurface(normals, linear, cells, bins=4))
    assert fit is not None
    assert np.degrees(np.arccos(np.clip(fit.direction @ light, -1, 1))) < 4.0
    assert abs(fit.ambient - 0.3) < 0.05
    assert np.allclose(fit.albedo[:6], albedo, rtol=0.05)
    assert np.all(fit.weight[6:] == 0) and np.all(fit.weight[:6] > 0)  # cells without samples: no weight


def test_nothing_seen_fits_no_light():
    assert fit_lighting(SeenSurface(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int), 4)) is None
    assert fit_lighting(SeenSurface(np.ones((2, 3)), np.ones((2, 3)), -np.ones(2, int), 4)) is None


@pytest.fixture(scope="module")
def scene(data64):
    pytest.importorskip("torch")
    from training.data.torch_dataset import MultiViewDataset

    return {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[0].items()}


def test_the_fills_paint_the_region_only_with_finite_display_colours(scene):
    from ghnerf_runtime.metrics import masked_psnr
    from training.blend_ceiling import blend_sources
    from training.unseen_fill import part_fill, relit_fill, seen_surface

    lighting = fit_lighting(seen_surface(scene))
    assert lighting is not None and 0.0 <= lighting.ambient <= 1.0
    psnrs = []
    for view in range(len(scene["tgt_is_source"])):
        mask = np.asarray(scene["tgt_masks"][view], bool)
        rgb, seen = blend_sources(scene, view, scene["tgt_depth"][view])
        region = mask & ~seen if not scene["tgt_is_source"][view] else mask  # a source: repaint all of it
        for out in (part_fill(rgb, scene, view, scene["tgt_depth"][view], region),
                    relit_fill(rgb, scene, view, scene["tgt_depth"][view], region, mask=mask, lighting=lighting)):
            assert np.array_equal(out[~region], rgb[~region])
            assert np.all(np.isfinite(out)) and out.min() >= 0.0
        if scene["tgt_is_source"][view]:
            truth = scene["tgt_images"][view].transpose(1, 2, 0) * mask[..., None]
            relit = relit_fill(np.zeros_like(rgb), scene, view, scene["tgt_depth"][view], mask, lighting=lighting)
            psnrs.append(float(np.ravel(masked_psnr(np.clip(relit, 0, 1)[None], truth[None], mask[None]).per_image)[0]))
    # the albedo-and-light model explains the images it was fitted to (a flat mid-grey scores about 10 dB)
    assert min(psnrs) > 15.0
