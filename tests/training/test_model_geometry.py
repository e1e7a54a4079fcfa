"""Torch camera geometry against the numpy Camera (pixel-centre convention, planar layout)."""
from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from training.model.camera_inputs import box_corners, scene_inputs, synthetic_rig, to_torch  # noqa: E402
from training.model.cost_volume import build_cost_volume  # noqa: E402
from training.model.projection import (  # noqa: E402
    block_centres, grid_sample, planar_to_grid, project_planar, ray_directions, to_grid,
)
from training.model.sampling import (  # noqa: E402
    interpolate_planes, inverse_depth_planes, plane_index, refine_interval,
)

H = W = 64


@pytest.fixture(scope="module")
def rig():
    src = synthetic_rig(H, W)
    return src, to_torch(scene_inputs(src, src, box_corners(), H, W))


def test_project_planar_matches_camera_project(rig):
    src, cam = rig
    X = np.array([[0.1, -1.0, 3.1], [-0.3, -0.2, 2.8], [0.2, -1.7, 3.3]])
    grid, visible = project_planar(cam["src_P"], torch.tensor(X.T, dtype=torch.float32), H, W)
    for s, c in enumerate(src):
        uv, _ = c.project(X)
        expected = (2 * uv + 1) / W - 1
        np.testing.assert_allclose(grid[s].T.numpy(), expected, atol=1e-4)
    assert torch.all(visible == 1)
    behind = torch.tensor([[0.0], [-1.0], [-2.0]])  # behind both cameras
    g, v = project_planar(cam["src_P"], behind, H, W)
    assert torch.all(v == 0) and torch.all(g.abs() == 2.0)


def test_rays_hit_their_pixels(rig):
    src, cam = rig
    uv = block_centres(H, W, 4)  # (2, 256)
    origin, direction = ray_directions(cam["tgt_K_inv"], cam["tgt_c2w"], uv)
    X = origin[0] + 3.0 * direction[0]  # depth 3 m in target 0 (= source 0)
    np.testing.assert_allclose(src[0].to_camera(X.T.numpy())[:, 2], 3.0, atol=1e-4)
    back, _ = src[0].project(X.T.numpy())
    np.testing.assert_allclose(back, uv.T.numpy(), atol=1e-3)


def test_grid_sample_convention_reads_pixel_centres():
    f = torch.arange(16 * 16, dtype=torch.float32).reshape(1, 1, 16, 16)
    # pixel (u=5, v=7) at stride 4 of a 64-pixel image is the block centre (5*4+1.5, 7*4+1.5)
    uv = torch.tensor([[5 * 4 + 1.5], [7 * 4 + 1.5]])
    g = to_grid(uv, 64, 64, axis=0).T.reshape(1, 1, 1, 2)
    assert grid_sample(f, g).item() == pytest.approx(7 * 16 + 5)


def test_plane_sweep_is_zero_cost_for_a_fronto_parallel_textured_plane(rig):
    """Features that are a function of the 3D point make the variance vanish on the right plane."""
    src, cam = rig
    depth = 3.0
    # Source feature maps: render the rig-frame x, y of the plane z_cam0 = depth through each source.
    feats = []
    for c in src:
        uv = np.stack(np.meshgrid(np.arange(W // 4) * 4 + 1.5, np.arange(H // 4) * 4 + 1.5), -1).reshape(-1, 2)
        # intersect the rays of source s's stride-4 pixels with the plane z_cam0 = depth
        R0, t0 = src[0].R, src[0].t
        oc = torch.tensor(c.center, dtype=torch.float32)
        dirs_world = torch.tensor(c.R.T @ np.linalg.inv(c.K) @ np.c_[uv, np.ones(len(uv))].T, dtype=torch.float32)
        n = torch.tensor(R0[2], dtype=torch.float32)
        lam = (depth - float(t0[2]) - n @ oc) / (n @ dirs_world)
        P = oc[:, None] + lam * dirs_world
        feats.append(torch.stack([P[0], P[1], P[0] * P[1], P[1] ** 2]).reshape(4, H // 4, W // 4))
    features = torch.stack(feats)  # (2, 4, 16, 16) at stride 4
    depths = torch.tensor([2.6, 2.8, 3.0, 3.2, 3.4]).view(1, 5, 1, 1).expand(1, 5, H // 8, W // 8)
    cost = build_cost_volume(features, cam["src_P"], cam["tgt_K_inv"][0:1], cam["tgt_c2w"][0:1], depths, 8, H, W,
                             groups=1)
    per_plane = cost[0, 0, :, 1:-1, 1:-1].mean(dim=(1, 2))  # inner pixels
    assert int(per_plane.argmin()) == 2
    assert per_plane[2] < 0.05 * per_plane[0]


def test_inverse_planes_and_indices():
    nf = torch.tensor([[2.0, 4.0]])
    d = inverse_depth_planes(nf, 5, 2, 2)
    assert d[0, 0, 0, 0] == pytest.approx(2.0) and d[0, -1, 0, 0] == pytest.approx(4.0)
    idx = plane_index(d[:, :, 0, 0].unsqueeze(-1), nf[:, :1, None], nf[:, 1:, None], 5, "inverse")
    np.testing.assert_allclose(idx.flatten().numpy(), np.arange(5), atol=1e-4)


def test_interpolate_planes_is_trilinear_with_zero_padding():
    col = torch.randn(1, 3, 4, 5)  # (B, C, D, M)
    idx = torch.tensor([[0.0, 1.5, 3.0, -0.5, 3.75]]).reshape(1, 1, 5)
    out = interpolate_planes(col, idx)[0, :, 0]  # (C, M)
    torch.testing.assert_close(out[:, 0], col[0, :, 0, 0])
    torch.testing.assert_close(out[:, 1], 0.5 * (col[0, :, 1, 1] + col[0, :, 2, 1]))
    torch.testing.assert_close(out[:, 3], 0.5 * col[0, :, 0, 3])
    torch.testing.assert_close(out[:, 4], 0.25 * col[0, :, 3, 4])


def test_interpolate_planes_fades_to_zero_at_minus_one_and_d_as_grid_sample_does():
    """Past the end planes the value fades linearly to zero at -1 and D (half the end plane's at -0.5 and
    D - 0.5), as ``grid_sample`` with zero padding: the docstring said zero outside [-0.5, D - 0.5]."""
    import torch.nn.functional as F

    D = 5
    plane = torch.randn(1, 3, D, 1)  # (B, C, D, 1): one column
    idx = torch.tensor([-1.5, -1.0, -0.75, -0.5, 0.0, 2.3, D - 1.0, D - 0.5, D - 0.25, float(D), D + 0.5])
    out = interpolate_planes(plane.expand(1, 3, D, len(idx)), idx.reshape(1, 1, -1))[0, :, 0]  # (C, K)
    col = plane[0, :, :, 0]
    for k, want in ((1, 0.0 * col[:, 0]), (2, 0.25 * col[:, 0]), (3, 0.5 * col[:, 0]), (4, col[:, 0]),
                    (6, col[:, D - 1]), (7, 0.5 * col[:, D - 1]), (8, 0.25 * col[:, D - 1]), (9, 0.0 * col[:, 0])):
        torch.testing.assert_close(out[:, k], want)
    assert (out[:, 0] == 0).all() and (out[:, -1] == 0).all()
    # grid_sample over the planes as an image of height D and width 1 (pixel centres: index i at (2i + 1) / D - 1)
    grid = torch.stack([torch.zeros_like(idx), (2 * idx + 1) / D - 1], -1).reshape(1, -1, 1, 2)
    ref = F.grid_sample(plane, grid, mode="bilinear", padding_mode="zeros", align_corners=False)[0, :, :, 0]
    torch.testing.assert_close(out, ref)


def test_refine_interval_respects_bounds_and_floor():
    mean = torch.tensor([2.0, 3.0, 3.99])
    std = torch.tensor([0.0, 0.2, 0.5])
    lo, hi = refine_interval(mean, std, torch.tensor(2.0), torch.tensor(4.0), 1.0, 0.05)
    assert torch.all(lo >= 2.0) and torch.all(hi <= 4.0) and torch.all(hi - lo >= 0.05 - 1e-6)


def test_planar_to_grid_layout():
    g = torch.arange(2 * 2 * 6, dtype=torch.float32).reshape(2, 2, 6)
    out = planar_to_grid(g, 2)
    assert out.shape == (2, 2, 3, 2)
    assert out[1, 1, 2, 0] == g[1, 0, 5] and out[1, 1, 2, 1] == g[1, 1, 5]
