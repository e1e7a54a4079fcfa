"""A static room around the person: tiled floor, painted walls, ceiling; rendered once per camera.

The room is an axis-aligned box in the rig frame centred (in x and z) on the
person's standing position. A camera anywhere sees its inside; a camera
outside the box sees through the near walls (back-face culling) so random
training views still get a background.

Not modelled: shadows (the person casts none), reflections, furniture,
windows, light falloff, other people.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.sim.appearance import srgb_to_linear
from drivers.sim.errors import SimConfigError
from drivers.sim.raycast import RayGrid


@dataclass(frozen=True)
class RoomStyle:
    """Colours (sRGB 0..1) and sizes of the room.

    Attributes:
        floor, floor2: the two tile colours; tile_m: tile size in metres.
        wall, ceiling: wall and ceiling colours.
        half_size_m: room half-extent in x and z around the person.
        height_m: floor-to-ceiling height.
    """

    floor: tuple[float, float, float] = (0.55, 0.47, 0.38)
    floor2: tuple[float, float, float] = (0.47, 0.40, 0.32)
    tile_m: float = 0.5
    wall: tuple[float, float, float] = (0.72, 0.74, 0.70)
    ceiling: tuple[float, float, float] = (0.85, 0.85, 0.85)
    half_size_m: float = 4.5
    height_m: float = 3.0

    def __post_init__(self) -> None:
        for name in ("floor", "floor2", "wall", "ceiling"):
            v = np.asarray(getattr(self, name), dtype=np.float64)
            if v.shape != (3,) or not np.all((v >= 0) & (v <= 1)):
                raise SimConfigError(f"RoomStyle.{name}", f"must be an (r, g, b) triple in [0, 1], got {getattr(self, name)!r}")
        for name, lo, hi in (("tile_m", 0.05, 3.0), ("half_size_m", 1.5, 50.0), ("height_m", 2.2, 20.0)):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise SimConfigError(f"RoomStyle.{name}", f"must be in [{lo}, {hi}], got {v!r}")

    @classmethod
    def random(cls, rng: np.random.Generator) -> "RoomStyle":
        base = rng.uniform(0.15, 0.75, 3)
        tone = rng.uniform(0.6, 0.95)
        return cls(
            floor=tuple(float(c) for c in base),
            floor2=tuple(float(c) for c in np.clip(base * tone, 0, 1)),
            tile_m=float(rng.uniform(0.2, 1.0)),
            wall=tuple(float(c) for c in rng.uniform(0.35, 0.9, 3)),
            ceiling=tuple(float(c) for c in rng.uniform(0.7, 0.95, 3)),
            half_size_m=float(rng.uniform(3.0, 6.0)),
            height_m=float(rng.uniform(2.5, 3.5)),
        )


def render_room(grid: RayGrid, style: RoomStyle, center_xz: tuple[float, float], light_dir: np.ndarray, ambient: float) -> np.ndarray:
    """Linear BGR radiance ``(H, W, 3)`` float32 of the room seen by ``grid.camera``.

    Args:
        center_xz: rig-frame (x, z) the room is centred on.
        light_dir: unit rig-frame direction towards the light.
        ambient: ambient share of the lighting (0..1).
    """
    cam = grid.camera
    H, W = cam.height, cam.width
    if grid.separable:
        X, Y = grid.xs[None, :], grid.ys[:, None]
    else:
        X, Y = grid.gx, grid.gy
    R, o = cam.R, cam.center
    # Rig-frame ray directions, one flat array per axis: d = R^T (x, y, 1).
    d = [np.broadcast_to(X * R[0, i] + Y * R[1, i] + R[2, i], (H, W)).ravel() for i in range(3)]
    lo = (center_xz[0] - style.half_size_m, -style.height_m, center_xz[1] - style.half_size_m)
    hi = (center_xz[0] + style.half_size_m, 0.0, center_xz[1] + style.half_size_m)
    # Slab method: where each axis' slab is left; the nearest exit is the surface seen.
    # (From outside the box this is the far wall: the near walls are culled.)
    exits, enters = [], []
    with np.errstate(divide="ignore", invalid="ignore"):
        for i in range(3):
            inv = 1.0 / d[i]
            t_hi, t_lo = (hi[i] - o[i]) * inv, (lo[i] - o[i]) * inv
            exits.append(np.where(d[i] > 0, t_hi, np.where(d[i] < 0, t_lo, np.inf)))
            outside = np.inf if not lo[i] <= o[i] <= hi[i] else -np.inf
            enters.append(np.where(d[i] > 0, t_lo, np.where(d[i] < 0, t_hi, outside)))
    t = np.minimum(np.minimum(exits[0], exits[1]), exits[2])
    seen = np.isfinite(t) & (t > 0) & (np.maximum(np.maximum(enters[0], enters[1]), enters[2]) <= t)
    on_y = seen & (exits[1] == t)
    on_x = seen & ~on_y & (exits[0] == t)
    on_z = seen & ~on_y & ~on_x
    lin = lambda rgb: srgb_to_linear(rgb)[::-1]  # noqa: E731 - BGR linear
    lit = lambda axis, sign: ambient + (1.0 - ambient) * max(0.0, sign * float(light_dir[axis]))  # noqa: E731 - inward normal
    out = np.zeros((H * W, 3), dtype=np.float32)
    # Floor: two-tone tiles, dark grout, mottling.
    k = np.flatnonzero(on_y & (d[1] > 0))
    px, pz = o[0] + t[k] * d[0][k], o[2] + t[k] * d[2][k]
    u, v = px / style.tile_m, pz / style.tile_m
    iu, iv = np.floor(u), np.floor(v)
    tiles = ((iu.astype(np.int64) + iv.astype(np.int64)) & 1).astype(np.float64)
    grout = np.minimum(np.minimum(u - iu, 1 - (u - iu)), np.minimum(v - iv, 1 - (v - iv))) < 0.015
    f1, f2 = lin(style.floor), lin(style.floor2)
    gain = (0.9 + 0.2 * lattice_noise(px / 0.05, pz / 0.05, 21)) * np.where(grout, 0.6, 1.0) * lit(1, -1.0)
    out[k] = (f1 + tiles[:, None] * (f2 - f1)) * gain[:, None]
    # Walls: painted and mottled, dark skirting board, each wall lit by its own normal.
    for mask, axis in ((on_x, 0), (on_z, 2)):
        k = np.flatnonzero(mask)
        py = o[1] + t[k] * d[1][k]
        along = o[2 - axis] + t[k] * d[2 - axis][k]  # the horizontal coordinate on this wall
        grain = 0.95 + 0.1 * lattice_noise(along / 0.08, py / 0.08, 23 + axis)
        grain = np.where(py > -0.1, 0.45, grain)
        shade = np.where(d[axis][k] > 0, lit(axis, -1.0), lit(axis, 1.0))
        out[k] = lin(style.wall) * (grain * shade)[:, None]
    out[np.flatnonzero(on_y & (d[1] < 0))] = lin(style.ceiling) * lit(1, 1.0)
    return out.reshape(H, W, 3)


# A fixed table of uniform values for background mottling (a constant, not state: never written).
_TABLE = np.random.default_rng(20240607).random((256, 256)).astype(np.float64)
_TABLE.setflags(write=False)


def lattice_noise(u: np.ndarray, v: np.ndarray, salt: int) -> np.ndarray:
    """Blocky value noise in [0, 1): one table value per integer cell of ``(u, v)``."""
    return _TABLE[(np.floor(u).astype(np.int64) + 97 * salt) & 255, np.floor(v).astype(np.int64) & 255]
