"""How much of a rig's working volume both cameras of its stereo pair see.

A foreign calibration's translations carry no unit. OpenCV's ``stereo_calib`` measures in board squares unless
given ``-s``, so a 0.6 m pair calibrated on 80 mm squares and imported with ``--units-to-metres 1`` comes out
7.5 m apart: under the rig's 10 m bound, and nothing else in the file shows it. Such a pair sees next to nothing
of the working volume in common (its views meet only beyond it), which is what :func:`common_view_warning`
measures. It warns rather than refuses: a real rig given a volume its lenses do not cover shows the same figure,
and the user may mean it.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume

__all__ = ["MIN_COMMON_SHARE", "common_view_share", "common_view_warning", "farthest_depth"]

#: Below this share of the working volume in both views of the pair, ``ghcal import`` warns. The real rigs
#: measured see 0.55 or more (``benchmarks/measure_import_common_view.py``; docs/rig-file.md); the 0.6 m pair read
#: in 80 mm squares as metres 0.003 (the tool's own volume) or 0.10 (levelled).
MIN_COMMON_SHARE = 0.25
#: Points per axis of the grid that samples the volume (11^3: a millisecond's projection).
GRID_POINTS = 11


def volume_grid(volume: WorkingVolume, per_axis: int = GRID_POINTS) -> np.ndarray:
    """``(per_axis**3, 3)`` points evenly over ``volume``, its faces included."""
    axes = [np.linspace(lo, hi, per_axis) for lo, hi in zip(volume.min_corner, volume.max_corner)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def in_image(cam: Camera, points: np.ndarray) -> np.ndarray:
    """Which ``points`` (rig frame) land inside ``cam``'s image, in front of it and within its lens model."""
    uv, _ = cam.project(points)  # NaN where no pixel shows the point
    with np.errstate(invalid="ignore"):
        return (np.isfinite(uv).all(axis=-1) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width)
                & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height))


def common_view_share(rig: Rig) -> float:
    """The share (0-1) of ``rig``'s working volume that both cameras of its pair see."""
    points = volume_grid(rig.volume)
    a, b = rig.pair
    return float(np.mean(in_image(a, points) & in_image(b, points)))


def farthest_depth(rig: Rig) -> float:
    """How far the working volume reaches in front of the pair: the largest depth of a corner from either camera."""
    corners = rig.volume.corners()
    return max(float(np.max(cam.to_camera(corners)[:, 2])) for cam in rig.pair)


def _likely_cause(rig: Rig) -> str:
    """Why the pair shares so little of the volume: a baseline beyond the volume's depth is read as a unit error."""
    baseline, reach = rig.baseline, farthest_depth(rig)
    if baseline >= reach:
        return (f"they are {baseline:.2f} m apart, farther than the volume reaches in front of them ({reach:.2f} m), "
                "so their views meet beyond it. Translations in another unit than --units-to-metres says? OpenCV's "
                "stereo_calib writes T in board squares unless given -s: import again with --units-to-metres the "
                "square's side in metres (0.08 for 80 mm squares), and check the baseline against a tape measure")
    return (f"they are {baseline:.2f} m apart and the volume reaches {reach:.2f} m in front of them: it is not where "
            "the pair looks, or wider than its fields of view. Give the volume the cameras face (--volume, metres, "
            "in the written rig's frame)")


def common_view_warning(rig: Rig) -> str | None:
    """What ``ghcal import`` says of a rig whose pair sees less than :data:`MIN_COMMON_SHARE` of its working
    volume in common (naming the baseline, the volume and the likely cause), or None."""
    share = common_view_share(rig)
    if share >= MIN_COMMON_SHARE:
        return None
    a, b = rig.pair
    lo, hi = (np.round(c, 2).tolist() for c in (rig.volume.min_corner, rig.volume.max_corner))
    return (f"cameras {a.name!r} and {b.name!r} both see {100 * share:.1f} % of the working volume {lo} to {hi} m "
            f"(under {100 * MIN_COMMON_SHARE:.0f} %: the rest is in one view or none): {_likely_cause(rig)}")
