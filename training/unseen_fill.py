"""Colouring the surfaces neither source camera sees, from what they do see and the skeleton.

A two-camera blend (``training.blend_ceiling``) has no colour for a surface point no source sees:
on the novel views ``ghnerf-eval`` scores, about half of the subject. This module measures two
ways a human-aware renderer could paint those points, given the geometry (depth maps) and the 3D
joints, without reading the view's own image:

* :func:`part_fill`: each point takes the mean colour the sources see on the same bone, in the same
  bin along it (a shirt's back is the shirt).
* :func:`relit_fill`: the same per-bin colours taken as albedos under a fitted light (a distant key
  light plus a hemispherical ambient term, Lambertian: the simulator's model), so a point facing
  away from the light is painted darker than the lit side it borrows its albedo from.

Pure numpy and OpenCV on one ``MultiViewDataset`` item (numpy arrays); the sources' rows come first
among its ``tgt_*`` rows. ``benchmarks/measure_novel_ceiling.py --oracles`` runs both over a split.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np

from drivers.sim.sensor import GAMMA  # display values are gamma-encoded; shading multiplies linear radiance
from ghnerf_runtime.body25 import FLIP_INDEX, LIMBS
from ghnerf_runtime.geometry.surface import surface_normals as surface_from_points
from training.blend_ceiling import unproject

#: Bins along each bone: clothing changes along a limb (a short sleeve, shorts).
PART_BINS = 4
#: The world's up direction (the rig frame's y points down).
UP = np.array([0.0, -1.0, 0.0])
#: Each bone's mirror bone (the left forearm's is the right forearm), for a bone no source sees.
FLIP_LIMB = tuple(LIMBS.index((FLIP_INDEX[i], FLIP_INDEX[j])) for i, j in LIMBS)


def bone_coordinates(points: np.ndarray, joints: np.ndarray, valid: np.ndarray,
                     bins: int = PART_BINS) -> tuple[np.ndarray, np.ndarray]:
    """Each point's nearest BODY_25 bone (index into ``LIMBS``) and its bin along that bone.

    ``points`` ``(N, 3)``, ``joints`` ``(25, 3)`` with ``valid`` ``(25,)``; a bone with an invalid end
    is never chosen. Returns ``bone`` ``(N,)`` (-1 where no bone is valid, or the point has no finite
    position: a NaN or infinite depth's) and ``bin`` ``(N,)`` in ``[0, bins)``: the point's position along
    the bone from parent to child, clamped to its ends (0 without a bone).
    """
    a = np.array([joints[i] for i, _ in LIMBS], np.float64)
    b = np.array([joints[j] for _, j in LIMBS], np.float64)
    ok = np.array([bool(valid[i]) and bool(valid[j]) for i, j in LIMBS])
    p = np.asarray(points, np.float64).reshape(-1, 1, 3)
    placed = np.isfinite(p).all(axis=-1)[:, 0]
    p = np.where(placed[:, None, None], p, 0.0)  # a NaN bin cast to int is garbage: an IndexError downstream
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)  # (N, L)
    dist = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)
    dist[:, ~ok] = np.inf
    bone = np.argmin(dist, axis=1)
    along = t[np.arange(len(p)), bone]
    bone = np.where(ok.any() & placed, bone, -1)
    return bone, np.where(placed, np.minimum((along * bins).astype(int), bins - 1), 0)


def surface_normals(depth: np.ndarray, mask: np.ndarray, K_inv: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World-frame unit normals ``(H, W, 3)`` of a depth map's surface inside ``mask``, facing the camera
    (``ghnerf_runtime.geometry.surface.surface_normals`` on the unprojected pixels)."""
    points = unproject(np.where(np.asarray(mask, bool), depth, 0.0), K_inv, c2w)
    return surface_from_points(points, mask, np.asarray(c2w, np.float64)[:, 3])


def _hemisphere(normals: np.ndarray) -> np.ndarray:
    """The ambient term's share at unit normals: a little brighter from above."""
    return 0.85 + 0.15 * (normals @ UP)


def shading(normals: np.ndarray, light: np.ndarray, ambient: float) -> np.ndarray:
    """Lambertian key light plus hemispherical ambient at unit normals."""
    return ambient * _hemisphere(normals) + (1.0 - ambient) * np.clip(normals @ light, 0.0, None)


@dataclass(frozen=True)
class SeenSurface:
    """The subject's surface the sources see: one row per source pixel inside its (eroded) mask."""

    normals: np.ndarray  # (N, 3) world frame
    linear: np.ndarray  # (N, 3) linear radiance (display ** GAMMA)
    cell: np.ndarray  # (N,) bone * bins + bin; -1 where no bone is valid
    bins: int


def seen_surface(scene: Mapping[str, np.ndarray], bins: int = PART_BINS) -> SeenSurface:
    """What the sources see of the subject, from their images, masks and depth maps and the 3D joints.

    Silhouette pixels (their normals straddle the edge) and clipped ones (no radiance to read) are left
    out."""
    normals, linear, cells = [], [], []
    for s in range(len(scene["images"])):
        if not scene["tgt_has_depth"][s]:
            continue
        depth = np.asarray(scene["tgt_depth"][s])
        mask = np.asarray(scene["tgt_masks"][s], bool) & (depth > 0) & np.isfinite(depth)  # no position, no sample
        inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        colours = scene["images"][s].transpose(1, 2, 0)
        inner &= colours.max(-1) < 0.98
        if not inner.any():
            continue
        K_inv, c2w = scene["tgt_K_inv"][s], scene["tgt_c2w"][s]
        points = unproject(scene["tgt_depth"][s], K_inv, c2w)[inner]
        bone, k = bone_coordinates(points, scene["joints_3d"], scene["joints_3d_valid"], bins)
        normals.append(surface_normals(scene["tgt_depth"][s], mask, K_inv, c2w)[inner])
        linear.append(np.asarray(colours[inner], np.float64) ** GAMMA)
        cells.append(np.where(bone >= 0, bone * bins + k, -1))
    if not normals:
        return SeenSurface(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int), bins)
    return SeenSurface(np.concatenate(normals), np.concatenate(linear), np.concatenate(cells), bins)


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


@dataclass(frozen=True)
class Lighting:
    """A fitted light and the per-cell albedos it implies (linear radiance, exposure folded in)."""

    direction: np.ndarray  # (3,) towards the light, world frame
    ambient: float
    albedo: np.ndarray  # (cells, 3)
    weight: np.ndarray  # (cells,) sum of squared shading over the cell's samples (0: none)
    bins: int


def _best_light(surface: SeenSurface, directions: np.ndarray, ambients: np.ndarray) -> Lighting:
    """The candidate light (every direction with every ambient share) whose least-squares albedos
    explain the most of the seen radiance; the albedos solved in closed form per cell and light."""
    keep = surface.cell >= 0
    order = np.argsort(surface.cell[keep], kind="stable")
    n, lin, cell = surface.normals[keep][order], surface.linear[keep][order], surface.cell[keep][order]
    starts = np.flatnonzero(np.r_[True, cell[1:] != cell[:-1]])  # each cell's first row
    key = np.clip(directions @ n.T, 0.0, None)  # (D, N)
    hemi = _hemisphere(n)  # (N,)
    best_energy, best = -np.inf, None
    for a in ambients:
        s = a * hemi + (1.0 - a) * key  # (D, N)
        ss = np.add.reduceat(s * s, starts, axis=1)  # (D, cells)
        sy = np.stack([np.add.reduceat(s * lin[:, c], starts, axis=1) for c in range(3)], -1)  # (D, cells, 3)
        # least squares per cell: albedo = sy / ss; the energy it explains is sy^2 / ss
        energy = ((sy ** 2).sum(-1) / np.maximum(ss, 1e-12)).sum(-1)  # (D,)
        j = int(np.argmax(energy))
        if energy[j] > best_energy:
            best_energy, best = energy[j], (directions[j], float(a), sy[j] / np.maximum(ss[j], 1e-12)[:, None], ss[j])
    direction, ambient, albedo_cells, weight_cells = best
    n_cells = len(LIMBS) * surface.bins
    albedo, weight = np.zeros((n_cells, 3)), np.zeros(n_cells)
    albedo[cell[starts]], weight[cell[starts]] = albedo_cells, weight_cells
    return Lighting(direction, ambient, albedo, weight, surface.bins)


def fit_lighting(surface: SeenSurface, coarse_directions: int = 400, refine: int = 300) -> Lighting | None:
    """The light (direction, ambient share) and per-cell albedos that best explain the seen radiance.

    Least squares over the seen pixels, albedo solved in closed form per candidate light: a search
    over ``coarse_directions`` directions on the sphere and 11 ambient shares, then ``refine``
    directions within about 12 degrees of the best and finer shares. ``None`` when nothing is seen.
    """
    if not (surface.cell >= 0).any():
        return None
    coarse = _best_light(surface, _fibonacci_sphere(coarse_directions), np.linspace(0.0, 1.0, 11))
    rng = np.random.default_rng(0)  # a fixed jitter: the fit is a function of the scene alone
    near = coarse.direction + rng.normal(0.0, 0.12, (refine, 3))
    near = np.concatenate([coarse.direction[None], near / np.linalg.norm(near, axis=1, keepdims=True)])
    return _best_light(surface, near, np.clip(coarse.ambient + np.linspace(-0.1, 0.1, 9), 0.0, 1.0))


def _cell_values(values: np.ndarray, weight: np.ndarray, bins: int, bone: np.ndarray,
                 k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per query point, the value of its cell, else of its bone, else of the mirror bone; and whether any."""
    L = len(LIMBS)
    v, w = values.reshape(L, bins, -1), weight.reshape(L, bins)
    bone_w = w.sum(1)
    bone_v = (v * w[..., None]).sum(1) / np.maximum(bone_w, 1e-12)[:, None]
    b = np.maximum(bone, 0)
    mirror = np.asarray(FLIP_LIMB)[b]
    out, have = np.zeros((len(b), v.shape[-1])), np.zeros(len(b), bool)
    # coarsest first: each finer estimate overwrites where it has samples
    for value, has in ((bone_v[mirror], bone_w[mirror] > 0), (bone_v[b], bone_w[b] > 0), (v[b, k], w[b, k] > 0)):
        use = (bone >= 0) & has
        out[use], have = value[use], have | use
    return out, have


def part_fill(rgb: np.ndarray, scene: Mapping[str, np.ndarray], view: int, depth: np.ndarray,
              region: np.ndarray, surface: SeenSurface | None = None) -> np.ndarray:
    """``rgb`` ``(H, W, 3)`` with each ``region`` pixel's surface point (at ``depth``) painted the mean
    display colour the sources see on its bone's bin (else its bone, else the mirror bone; else left).

    ``surface``: a :func:`seen_surface` to reuse across a scene's views (default: gathered here)."""
    out = rgb.copy()
    if not region.any():
        return out
    surface = surface or seen_surface(scene)
    bins = surface.bins
    L = len(LIMBS) * bins
    keep = surface.cell >= 0
    count = np.bincount(surface.cell[keep], minlength=L).astype(np.float64)
    total = np.zeros((L, 3))
    np.add.at(total, surface.cell[keep], surface.linear[keep] ** (1.0 / GAMMA))
    points = unproject(depth, scene["tgt_K_inv"][view], scene["tgt_c2w"][view])[region]
    bone, k = bone_coordinates(points, scene["joints_3d"], scene["joints_3d_valid"], bins)
    colour, have = _cell_values(total / np.maximum(count, 1.0)[:, None], count, bins, bone, k)
    fill = out[region]
    fill[have] = colour[have]
    out[region] = fill
    return out


def relit_fill(rgb: np.ndarray, scene: Mapping[str, np.ndarray], view: int, depth: np.ndarray,
               region: np.ndarray, mask: np.ndarray | None = None,
               lighting: Lighting | None = None) -> np.ndarray:
    """``rgb`` ``(H, W, 3)`` with each ``region`` pixel re-rendered: its bin's fitted albedo (else its
    bone's, else the mirror bone's) shaded by the fitted light at the surface normal of ``depth``.

    ``mask``: the subject's pixels in the view (for the normals; default ``region``). ``lighting``:
    a :func:`fit_lighting` result to reuse across a scene's views (default: fitted here).
    """
    out = rgb.copy()
    if not region.any():
        return out
    lighting = lighting or fit_lighting(seen_surface(scene))
    if lighting is None:
        return out
    bins = lighting.bins
    K_inv, c2w = scene["tgt_K_inv"][view], scene["tgt_c2w"][view]
    normals = surface_normals(depth, region if mask is None else mask, K_inv, c2w)[region]
    points = unproject(depth, K_inv, c2w)[region]
    bone, k = bone_coordinates(points, scene["joints_3d"], scene["joints_3d_valid"], bins)
    albedo, have = _cell_values(lighting.albedo, lighting.weight, bins, bone, k)
    linear = albedo * shading(normals, lighting.direction, lighting.ambient)[:, None]
    fill = out[region]
    fill[have] = np.clip(linear[have], 0.0, None) ** (1.0 / GAMMA)
    out[region] = fill
    return out


__all__ = ["PART_BINS", "FLIP_LIMB", "bone_coordinates", "surface_normals", "shading", "SeenSurface",
           "seen_surface", "Lighting", "fit_lighting", "part_fill", "relit_fill"]
