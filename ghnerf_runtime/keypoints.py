"""Decode 2D keypoints from rendered joint heatmaps (OpenPose style), and map them to images.

Algorithm, per joint map (a single person is assumed):

1. Gaussian filter (``KeypointDecoderConfig.sigma``, heatmap pixels; zero border: the
   model renders 0 where a ray hits nothing, so 0 is the honest value outside the map).
2. Threshold (strictly greater than ``threshold``) and label connected regions
   (8-connectivity, ``cv2.connectedComponents``).
3. The best region is the one with the highest peak, i.e. the region holding the
   map's maximum. A region covering more than ``max_region_frac`` of the map is no
   peak (saturated, flat or noise-flooded map): the joint is missing.
4. Subpixel refinement of that peak (below), confidence = filtered peak value. With ``"quadratic"``, a
   saturated top (a plateau at the map's maximum: a sigmoid at 1.0 in float32) is placed by a paraboloid
   fitted to the log of its flank, the unclipped samples around it (:func:`_place_flat_tops`).
5. The runner-up: the highest filtered value outside the best region (so the peak of another
   region above the threshold), or, where higher, a second local maximum inside the best region
   with a valley between it and the peak (the map dipping to at most :data:`RUNNER_UP_DIP` of it
   on the line between them: two blobs a few cells apart join into one region above the
   threshold), and where it is, refined as the peak is (``runner_up``, ``runner_up_uv``): with
   two people in view, the other person's peak of that joint.

Threshold and confidence are both in *filtered* units (as in OpenPose). The filter
lowers peaks: a unit-height Gaussian blob of sigma ``s`` peaks at about
``s^2 / (s^2 + sigma^2)`` after filtering (0.69 for ``s = 1.5``, ``sigma = 1``).

Missing joints (peak not above threshold, non-finite values anywhere in the map,
or an oversized region) get ``valid = False``, ``confidence = 0`` and ``uv = 0``
(:data:`MISSING_FILL`). Outputs are always finite. Values outside [0, 1] are out of contract:
negative ones count as 0, and a map whose maximum exceeds 1 is divided by it (its shape, and
so its peak, kept), so every confidence lies in [0, 1].

Subpixel refinement: ``"quadratic"`` (default) fits a quadratic to the log of the
map over the 3x3 neighbourhood of the peak (one Newton step, full 2x2 Hessian,
falling back per axis when the Hessian is not negative definite). The log of a
Gaussian is exactly quadratic, and a Gaussian filtered by a Gaussian stays
Gaussian, so this is unbiased for Gaussian-shaped peaks. Near the map edge (within
the filter radius) the zero border biases the filtered map, so the fit uses the raw
map there, from the raw map's own maximum next to the filtered one (stopping a pixel
short of the edge, from where the fit still reaches it): with a decoder sigma of 2-3 the
filtered peak of a sigma-3 blob on the edge lies 2 px inside, and a fit from there was
a pixel off (now < 0.01 px: ``tests/ghnerf_runtime/test_keypoints.py -k wide_decoder_filter``).
Results stay in ``[0, W - 1] x [0, H - 1]``; a blob centred past the edge is placed on
the edge pixel. ``"centroid"`` is the value-weighted centroid over a ``(2r+1)^2`` window
restricted to the peak's region; the window truncates the Gaussian's tails, which
biases it towards the centre pixel. Measured on 200 random subpixel centres per
case (64x64 maps, decoder sigma 1; ``tests/ghnerf_runtime/test_keypoints.py``
keeps the comparison):

=============  ===================  =======================  =====================
peak sigma     quadratic, clean     centroid r=2, clean      + noise N(0, 0.02):
                                                             quadratic / centroid
=============  ===================  =======================  =====================
1.5 px         < 0.001 px (max)     0.20 mean, 0.34 max      0.02 / 0.20 mean
3.0 px         < 0.001 px (max)     0.31 mean, 0.55 max      0.05 / 0.33 mean
=============  ===================  =======================  =====================

so ``"quadratic"`` is the default; ``"centroid"`` is kept for comparison.

Coordinates: pixel centres at integers (OpenCV). Heatmaps are rendered on a grid
``heatmap_stride`` times coarser than the model input, whose pixel ``i`` covers model
pixels ``stride * i .. stride * i + stride - 1`` (``contract.ray_grid``):
:func:`heatmap_to_model_pixels` and :func:`model_to_heatmap_pixels` convert;
:func:`model_to_image_pixels` and :func:`heatmap_to_image_pixels` go back to the
(distorted) camera frame through :func:`~ghnerf_runtime.preprocess.crop_camera`.

Pure functions; numpy and OpenCV only.
"""
from __future__ import annotations

import numbers
from dataclasses import dataclass, fields, replace
from typing import Literal

import cv2
import numpy as np

from ghnerf_runtime.errors import RuntimeErrorBase, ShapeError
from ghnerf_runtime.geometry.camera import Camera, check_last_dim
from ghnerf_runtime.plain_values import is_finite_number, plain_scalar
from ghnerf_runtime.preprocess import Roi, camera_normalized, crop_camera

__all__ = [
    "MISSING_FILL", "KeypointConfigError", "KeypointDecoderConfig", "Keypoints2D", "decode_keypoints", "decode_blocks",
    "heatmap_to_model_pixels", "model_to_heatmap_pixels", "model_to_image_pixels", "heatmap_to_image_pixels",
]

#: Coordinate value of a missing joint (never NaN).
MISSING_FILL = 0.0

RefineMethod = Literal["quadratic", "centroid", "none"]


class KeypointConfigError(RuntimeErrorBase, ValueError):
    """A :class:`KeypointDecoderConfig` field is out of range; the message names it, ``field`` too."""

    def __init__(self, message: str, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


@dataclass(frozen=True)
class KeypointDecoderConfig:
    """Heatmap decoder settings, validated on construction.

    Attributes:
        sigma: Gaussian filter standard deviation in heatmap pixels; 0 disables filtering.
        threshold: a joint needs a filtered peak strictly above this (heatmaps are in [0, 1]).
        refine: subpixel refinement, ``"quadratic"`` (log-quadratic Taylor fit, default),
            ``"centroid"`` (weighted centroid) or ``"none"`` (integer peak).
        centroid_radius: half-width ``r`` of the ``(2r+1)^2`` centroid window.
        max_region_frac: a best region larger than this fraction of the map means no peak.
    """

    sigma: float = 1.0
    threshold: float = 0.1
    refine: RefineMethod = "quadratic"
    centroid_radius: int = 2
    max_region_frac: float = 0.25

    def __post_init__(self) -> None:
        def fail(field: str, why: str) -> None:
            raise KeypointConfigError(f"KeypointDecoderConfig.{field}: {why}, got {getattr(self, field)!r}", field)

        if not (is_finite_number(self.sigma) and 0 <= self.sigma <= 20):
            fail("sigma", "must be a number in [0, 20]")
        if not (is_finite_number(self.threshold) and 0 < self.threshold < 1):
            fail("threshold", "must be in (0, 1)")
        if self.refine not in ("quadratic", "centroid", "none"):
            fail("refine", "must be 'quadratic', 'centroid' or 'none'")
        if not (isinstance(self.centroid_radius, numbers.Integral) and not isinstance(self.centroid_radius, bool)
                and 1 <= self.centroid_radius <= 8):
            fail("centroid_radius", "must be an int in [1, 8]")
        if not (is_finite_number(self.max_region_frac) and 0 < self.max_region_frac <= 1):
            fail("max_region_frac", "must be in (0, 1]")
        for f in fields(self):  # checked numpy scalars as Python's: config_to_dict is JSON-ready
            object.__setattr__(self, f.name, plain_scalar(getattr(self, f.name)))


@dataclass(frozen=True, eq=False)
class Keypoints2D:
    """Decoded joints; every array is finite.

    Attributes:
        uv: ``(..., J, 2)`` float64 ``(x, y)`` in heatmap pixels; :data:`MISSING_FILL` where
            not valid.
        confidence: ``(..., J)`` float32 filtered peak value; 0 where not valid.
        valid: ``(..., J)`` bool.
        runner_up: ``(..., J)`` float32 highest peak of any *other* region, or second peak past a valley
            in the best one (module docstring, 5; 0 if none): a
            value close to ``confidence`` flags an ambiguous joint (e.g. left/right).
        runner_up_uv: ``(..., J, 2)`` float64 where that peak is, in the coordinates of ``uv`` and
            refined as it is; :data:`MISSING_FILL` where ``runner_up`` is 0.
    """

    uv: np.ndarray
    confidence: np.ndarray
    valid: np.ndarray
    runner_up: np.ndarray
    runner_up_uv: np.ndarray


# ------------------------------------------------------------------- decoding
def _radius(sigma: float) -> int:
    """Gaussian kernel radius: 3 sigma holds 99.7% of the mass."""
    return int(np.ceil(3.0 * sigma)) if sigma > 0 else 0


def _filter(maps: np.ndarray, sigma: float) -> tuple[np.ndarray, int]:
    """Gaussian-filter ``(N, H, W)`` maps with a zero border; returns the padded result and pad.

    The maps are tiled with ``pad`` zero pixels around each one, so one filter call over
    the tall stack equals a per-map filter with a constant-zero border (and is ~2x faster
    than a Python loop of cv2 calls).
    """
    n, h, w = maps.shape
    radius = _radius(sigma)
    pad = max(radius, 1)
    tiled = np.zeros((n, h + 2 * pad, w + 2 * pad), np.float32)
    tiled[:, pad:pad + h, pad:pad + w] = maps
    if radius:
        kernel = cv2.getGaussianKernel(2 * radius + 1, sigma, cv2.CV_32F)
        flat = tiled.reshape(n * (h + 2 * pad), w + 2 * pad)
        tiled = cv2.sepFilter2D(flat, cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_CONSTANT).reshape(tiled.shape)
    return tiled, pad


def _regions(above: np.ndarray) -> np.ndarray:
    """Labels ``(N, H, W)`` int32 of 8-connected regions; one labelling call for all maps.

    The maps are stacked with a zero row between them so no region spans two maps.
    (``connectedComponentsWithStats`` measured ~8x slower here for the area we need,
    which one numpy count of the chosen region gives.)
    """
    n, h, w = above.shape
    stacked = np.zeros((n, h + 1, w), np.uint8)
    stacked[:, :h] = above
    _, labels = cv2.connectedComponents(stacked.reshape(n * (h + 1), w), connectivity=8, ltype=cv2.CV_32S)
    return labels.reshape(n, h + 1, w)[:, :h]


def _patch3(maps: np.ndarray, pad: int, iy: np.ndarray, ix: np.ndarray, which: np.ndarray | None = None
            ) -> np.ndarray:
    """The 3x3 neighbourhoods ``(N, 3, 3)`` float64 of the given pixels of ``(M, H + 2 pad, W + 2 pad)`` maps,
    pixel ``k`` in map ``which[k]`` (default: map ``k``).

    Indices are clipped, so with ``pad == 0`` an edge pixel repeats itself (callers ignore
    that axis).
    """
    which = np.arange(len(iy)) if which is None else which
    _, h, w = maps.shape
    rows = _clipped_index((iy + pad)[:, None] + np.arange(-1, 2), h)  # (N, 3)
    cols = _clipped_index((ix + pad)[:, None] + np.arange(-1, 2), w)
    # one take of flat indices: the same pixels as maps[which, rows, cols], in a quarter of the numpy calls' time
    flat = (which[:, None] * h + rows)[:, :, None] * w + cols[:, None, :]
    return np.take(maps, flat).astype(np.float64)


def _clipped_index(index: np.ndarray, size: int) -> np.ndarray:
    """Integer indices clipped to ``[0, size - 1]``: ``np.clip``'s values, without its per-call dtype checks (12-25
    us a call on session 71's host, a few dozen calls a pair's decoding)."""
    return np.minimum(np.maximum(index, 0), size - 1)


#: Smallest determinant of a log-quadratic fit's Hessian (negative along x) read as a maximum: a smaller one is a
#: ridge, flat along some direction, whose vertex lies arbitrarily far along it.
_MIN_MAXIMUM_DET = 1e-12


def _newton_log(patch: np.ndarray, edge_x: np.ndarray, edge_y: np.ndarray) -> np.ndarray:
    """Subpixel offsets ``(N, 2)`` (dx, dy) of the maximum of a quadratic fitted to ``log(patch)``.

    One Newton step with the full 2x2 Hessian where it is negative definite, else a
    per-axis parabola; axes flagged in ``edge_x``/``edge_y`` (no outer neighbour) are not
    refined and also drop the cross term.
    """
    # Floor relative to the peak: log(0) would dominate the fit for spiky maps.
    peak = patch[:, 1, 1][:, None, None]
    f = np.log(np.maximum(patch, np.maximum(peak, 1e-30) * 1e-6))
    gx = 0.5 * (f[:, 1, 2] - f[:, 1, 0])
    gy = 0.5 * (f[:, 2, 1] - f[:, 0, 1])
    hxx = f[:, 1, 2] - 2 * f[:, 1, 1] + f[:, 1, 0]
    hyy = f[:, 2, 1] - 2 * f[:, 1, 1] + f[:, 0, 1]
    hxy = 0.25 * (f[:, 2, 2] - f[:, 2, 0] - f[:, 0, 2] + f[:, 0, 0])
    det = hxx * hyy - hxy * hxy
    full = (hxx < 0) & (det > _MIN_MAXIMUM_DET) & ~edge_x & ~edge_y  # negative definite: a true maximum
    safe_det = np.where(full, det, 1.0)
    dx_axis = np.where((hxx < 0) & ~edge_x, -gx / np.where(hxx < 0, hxx, -1.0), 0.0)
    dy_axis = np.where((hyy < 0) & ~edge_y, -gy / np.where(hyy < 0, hyy, -1.0), 0.0)
    dx = np.where(full, -(hyy * gx - hxy * gy) / safe_det, dx_axis)
    dy = np.where(full, -(hxx * gy - hxy * gx) / safe_det, dy_axis)
    # Guard: the peak of a sampled unimodal blob is within ~half a pixel of the maximum pixel.
    return np.clip(np.stack([dx, dy], axis=-1), -1.0, 1.0)


def _climb(maps: np.ndarray, iy: np.ndarray, ix: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Move each pixel ``(iy, ix)`` of its ``(N, H, W)`` map uphill (to its highest 8-neighbour, while that is
    strictly higher) for at most ``steps`` moves: the raw map's maximum next to the filtered map's.

    A pixel not on the map's edge stops one short of it: the fit from there, whose step reaches a pixel,
    still finds a peak on the edge pixel, and one between the two (where the edge pixel, not refined
    across the edge, would be up to half a pixel off)."""
    h, w = maps.shape[1:]
    lo_y, hi_y = np.where(iy == 0, 0, min(1, h - 1)), np.where(iy == h - 1, h - 1, max(h - 2, 0))
    lo_x, hi_x = np.where(ix == 0, 0, min(1, w - 1)), np.where(ix == w - 1, w - 1, max(w - 2, 0))
    rows = np.arange(len(iy))
    for _ in range(steps):
        patch = _patch3(maps, 0, iy, ix).reshape(len(iy), 9)  # clipped: an edge pixel repeats itself, no move
        best = patch.argmax(axis=1)
        dy, dx = np.divmod(best, 3)
        to_y, to_x = np.minimum(np.maximum(iy + dy - 1, lo_y), hi_y), np.minimum(np.maximum(ix + dx - 1, lo_x), hi_x)
        up = maps[rows, to_y, to_x] > maps[rows, iy, ix]  # (a target clipped off the edge may be no higher)
        if not up.any():
            break
        iy, ix = np.where(up, to_y, iy), np.where(up, to_x, ix)
    return iy, ix


def _refine_quadratic(maps: np.ndarray, maxima: np.ndarray, padded: np.ndarray, pad: int, iy: np.ndarray,
                      ix: np.ndarray, sigma: float, which: np.ndarray) -> np.ndarray:
    """Log-quadratic refinement, on the filtered map except near the map edge; returns positions ``(N, 2)`` of
    the pixels ``(iy, ix)``, pixel ``k`` in map ``which[k]`` (``maxima``: each map's maximum, :func:`_scaled_to_one`).

    Where the filter kernel (radius ``ceil(3 sigma)``) reaches past the edge, its zero border
    pulls the filtered peak inwards (0.2-1.2 px at the edge for blobs of sigma 1.5-3 px, 2 px and
    more with a decoder sigma of 2 or more), so those peaks are refined on the raw map, which has no
    such bias but is noisier: from the raw map's own maximum next to the filtered one (the fit's step is
    clipped to a pixel, so starting 2 px off left the joint a pixel off). A peak on the edge pixel itself
    is not refined across the edge (its centre may lie outside the map). A saturated top (:func:`_flat_tops`, at the
    filtered peak or the raw maximum the edge's climb reached) is then placed by its flank instead
    (:func:`_place_flat_tops`): on a plateau this fit takes whichever pixel rounding made highest.
    """
    n, h, w = maps.shape
    top_iy, top_ix = iy, ix  # the filtered peaks, before the edge's climb
    band = _radius(sigma) if sigma > 0 else h + w  # sigma 0: the raw map is all there is
    near = np.minimum(np.minimum(ix, w - 1 - ix), np.minimum(iy, h - 1 - iy)) < band
    patch = _patch3(padded, pad, iy, ix, which)
    if near.any():
        iy, ix = iy.copy(), ix.copy()
        if sigma > 0:  # the filter moved the peak by at most its radius
            iy[near], ix[near] = _climb(maps[which[near]], iy[near], ix[near], _radius(sigma))
        patch[near] = _patch3(maps, 0, iy[near], ix[near], which[near])
    # One fit for all: an axis with no outer neighbour is only flagged on the raw (edge) patches.
    offset = _newton_log(patch, near & ((ix == 0) | (ix == w - 1)), near & ((iy == 0) | (iy == h - 1)))
    flat = _flat_tops(maps, maxima, which, top_iy, top_ix)
    if near.any():  # a plateau by the edge may show its ties at the raw maximum the climb reached instead
        flat[near] |= _flat_tops(maps, maxima, which[near], iy[near], ix[near])
    return _place_flat_tops(maps, padded, pad, which, top_iy, top_ix, flat, np.stack([ix, iy], axis=-1) + offset)


#: A saturated top's flank: the raw pixels below the plateau and above this share of it, within
#: :data:`FLANK_WIDTH` pixels of it, whose log a paraboloid is fitted to.
FLANK_LOW = 0.1
FLANK_WIDTH = 3
#: Fewest flank pixels for the fit (it has six terms).
FLANK_MIN_PIXELS = 8
#: Largest value-weighted RMS residual (heatmap units) of the flank's fit that is one blob's: 0.023 at most for
#: single saturated blobs with noise N(0, 0.02), 0.14-0.18 for two people's plateaus run into one.
FLANK_MAX_RMS = 0.06
#: How far (pixels) past its plateau's bounding box a fitted centre may lie: a saturated blob's centre is on its
#: plateau, or past the map's edge where the edge cuts it (then placed on the edge pixel).
FLANK_REACH = 1.5
#: Where the flank is too small for the fit: the centroid of the filtered map's excess over this share of its peak,
#: over the peak's connected part above that level.
FLAT_TOP_LEVEL = 0.8
#: Pixels of a 3x3 tied at the map's maximum that make a plateau: 2 where that maximum is 1, the top of the
#: heatmaps' range (a sigmoid saturated in float32, a map past 1 scaled by its maximum), 5 below it (a sampled
#: Gaussian ties at most 4 ways, centred between four pixels; the shipped int8 graphs' maps below 1 tie too: flagged
#: at 2 ties, the reference bench (docs/runtime.md) moved from PCK 0.981 / MPJPE 29.1 mm to 0.980 / 29.2 mm).
FLAT_TOP_TIES = 2
FLAT_TOP_TIES_BELOW_ONE = 5
#: The smallest plateau placed by the excess centroid where the flank fit fails: on a smaller one the log-quadratic
#: fit is closer (0.05 px, where the centroid is 0.1-0.2 px off).
EXCESS_MIN_PLATEAU = 5


def _flat_tops(maps: np.ndarray, maxima: np.ndarray, which: np.ndarray, iy: np.ndarray, ix: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: pixel ``k`` of map ``which[k]`` lies on a plateau at that map's maximum (``maxima``, one a map:
    at least :data:`FLAT_TOP_TIES`, or :data:`FLAT_TOP_TIES_BELOW_ONE` for a maximum under 1, pixels of its raw 3x3
    neighbourhood at it): a saturated top (a sigmoid at 1.0 in float32 past a logit of 17, a map past 1 scaled by its
    maximum)."""
    top = maxima[which]
    ties = (_patch3(maps, 0, iy, ix, which) == top[:, None, None]).sum(axis=(1, 2))
    return ties >= np.where(top >= 1.0, FLAT_TOP_TIES, FLAT_TOP_TIES_BELOW_ONE)


def _pixels(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of an ``(H, W)`` mask's pixels, from its flat indices (as :func:`_nonzero_3d`)."""
    return np.divmod(np.flatnonzero(mask), mask.shape[1])


def _plateau(raw: np.ndarray, iy: int, ix: int) -> tuple[np.ndarray, np.ndarray]:
    """The 8-connected plateau at ``raw``'s maximum holding pixel ``(iy, ix)`` (or its nearest one: the filtered peak
    of a plateau's rim may lie just off it), and every pixel at that maximum, ``(H, W)`` bool each."""
    at_top = raw == raw.max()
    _, labels = cv2.connectedComponents(at_top.astype(np.uint8), connectivity=8)
    ys, xs = _pixels(at_top)
    nearest = np.argmin((ys - iy) ** 2 + (xs - ix) ** 2)
    return labels == labels[ys[nearest], xs[nearest]], at_top


def _flank(raw: np.ndarray, plateau: np.ndarray, at_top: np.ndarray) -> np.ndarray | None:
    """``(H, W)`` bool: the plateau's flank (:data:`FLANK_LOW`, :data:`FLANK_WIDTH`); None where another plateau
    lies that near (its flank would join in)."""
    near = cv2.dilate(plateau.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=FLANK_WIDTH) > 0
    if (near & at_top & ~plateau).any():
        return None
    return near & ~plateau & (raw > FLANK_LOW * raw.max())


def _flank_fit(raw: np.ndarray, plateau: np.ndarray, flank: np.ndarray) -> np.ndarray | None:
    """The vertex ``(x, y)`` of a paraboloid fitted (least squares, weighted by value) to the log of the plateau's
    ``flank``: a clipped Gaussian's unclipped samples are exactly Gaussian, so this finds its centre wherever the
    plateau is, on the map's edge too. None where the fit is no single blob's: no maximum, a residual past
    :data:`FLANK_MAX_RMS` (two people's plateaus run into one), or a vertex past :data:`FLANK_REACH`."""
    ys, xs = _pixels(flank)
    py, px = _pixels(plateau)
    y0, x0 = py.mean(), px.mean()  # centred: a well-scaled system
    y, x = ys - y0, xs - x0
    value = raw[ys, xs].astype(np.float64)
    terms = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)
    c = np.linalg.lstsq(terms * value[:, None], np.log(value) * value, rcond=None)[0]
    if np.sqrt(np.mean(np.square(value * (np.log(value) - terms @ c)))) > FLANK_MAX_RMS:
        return None
    hessian = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if not (hessian[0, 0] < 0 and np.linalg.det(hessian) > _MIN_MAXIMUM_DET):
        return None
    vertex = np.linalg.solve(hessian, -c[1:3]) + [x0, y0]
    inside = (px.min() - FLANK_REACH <= vertex[0] <= px.max() + FLANK_REACH
              and py.min() - FLANK_REACH <= vertex[1] <= py.max() + FLANK_REACH)
    return np.clip(vertex, 0.0, [raw.shape[1] - 1, raw.shape[0] - 1]) if inside else None


def _excess_centroid(filtered: np.ndarray, iy: int, ix: int) -> np.ndarray | None:
    """The centroid of ``filtered``'s excess over :data:`FLAT_TOP_LEVEL` of its value at ``(iy, ix)``, over that
    pixel's connected part above the level (a high level: two saturated tops a few cells apart stay two parts);
    None where the part reaches the map's edge (its centroid would be pulled inwards)."""
    excess = filtered - FLAT_TOP_LEVEL * filtered[iy, ix]
    _, labels = cv2.connectedComponents((excess > 0).astype(np.uint8), connectivity=8)
    part = labels == labels[iy, ix]
    if part[0].any() or part[-1].any() or part[:, 0].any() or part[:, -1].any():
        return None
    ys, xs = _pixels(part)
    weight = excess[ys, xs]
    return np.array([(weight * xs).sum(), (weight * ys).sum()]) / weight.sum()


def _place_flat_tops(maps: np.ndarray, padded: np.ndarray, pad: int, which: np.ndarray, iy: np.ndarray,
                     ix: np.ndarray, flat: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``uv`` with each saturated top (``flat``, :func:`_flat_tops`) placed by its flank (:func:`_flank_fit`), or
    where the flank is too small, on a plateau of :data:`EXCESS_MIN_PLATEAU` pixels or more, by its filtered map's
    excess (:func:`_excess_centroid`); where neither holds, as the log-quadratic fit placed it. That fit took the
    filtered plateau's highest pixel, which rounding picks anywhere on it: blobs of sigma 1.5-3 px saturated 1.5- to
    100-fold were up to 2.0 px off inside the map and 3.0 px on its edge (``tests/ghnerf_runtime/test_keypoints.py
    -k saturated``)."""
    flat = np.flatnonzero(flat)
    if not len(flat):
        return uv
    uv = uv.copy()
    h, w = maps.shape[1:]
    for k in flat:  # rare (a saturated map): a few labellings per top
        raw = maps[which[k]].astype(np.float64)
        plateau, at_top = _plateau(raw, iy[k], ix[k])
        flank = _flank(raw, plateau, at_top)
        if flank is None:  # another plateau beside: left to the fit, as is
            continue
        if flank.sum() >= FLANK_MIN_PIXELS:
            placed = _flank_fit(raw, plateau, flank)
        elif plateau.sum() >= EXCESS_MIN_PLATEAU:
            placed = _excess_centroid(padded[which[k], pad:pad + h, pad:pad + w].astype(np.float64), iy[k], ix[k])
        else:
            placed = None
        if placed is not None:
            uv[k] = placed
    return uv


def _refine_centroid(padded: np.ndarray, pad: int, labels: np.ndarray, top: np.ndarray, iy: np.ndarray,
                     ix: np.ndarray, radius: int, which: np.ndarray) -> np.ndarray:
    """Weighted centroid of the peak's region ``top`` inside a window; offsets ``(N, 2)``, pixel ``k`` in map
    ``which[k]``."""
    h, w = labels.shape[1:]
    offs = np.arange(-radius, radius + 1)
    ry = iy[:, None, None] + offs[None, :, None]
    rx = ix[:, None, None] + offs[None, None, :]
    inside = (ry >= 0) & (ry < h) & (rx >= 0) & (rx < w)
    idx_n = which[:, None, None]
    lab = labels[idx_n, np.clip(ry, 0, h - 1), np.clip(rx, 0, w - 1)]
    val = padded[idx_n, np.clip(ry, 0, h - 1) + pad, np.clip(rx, 0, w - 1) + pad].astype(np.float64)
    wgt = np.where(inside & (lab == top[:, None, None]), val, 0.0)
    total = wgt.sum(axis=(1, 2))
    safe = np.where(total > 0, total, 1.0)
    dx = (wgt * offs[None, None, :]).sum(axis=(1, 2)) / safe
    dy = (wgt * offs[None, :, None]).sum(axis=(1, 2)) / safe
    return np.stack([dx, dy], axis=-1)


#: A second maximum inside the best region is a peak of its own (a runner-up) when the filtered map dips, on the
#: straight line from the best peak to it, to at most this fraction of its value. Two people 0.6 m apart at 3 m
#: show a joint's peaks 5.5-8.3 heatmap cells apart in one view, which (the oracle's sigma 1.5, the decoder's 1.0)
#: join above the threshold into one region with a deep valley between them; a blob's shoulder dips little
#: (docs/two-people.md, "Two people 0.6 m apart"; tests/ghnerf_runtime/test_keypoints.py).
RUNNER_UP_DIP = 0.5
#: Points sampled along that line (the maps are at most a few dozen cells across).
_DIP_SAMPLES = 16


def _nonzero_3d(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``np.nonzero`` of an ``(N, H, W)`` mask (the same index arrays, in the same order), from the flat indices:
    numpy's nonzero of a 3-d array steps a multi-index through every element: 0.15 ms for a pair's 50 maps of
    32 x 32 cells on session 61's host, where the flat one and two divisions take 0.005-0.015 ms."""
    _, h, w = mask.shape
    m, rest = np.divmod(np.flatnonzero(mask), h * w)
    y, x = np.divmod(rest, w)
    return m, y, x


def _runner_up_in_region(filtered: np.ndarray, padded: np.ndarray, pad: int, in_top: np.ndarray, top: np.ndarray,
                         iy: np.ndarray, ix: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each map's highest local maximum of ``filtered`` inside its best region (``in_top``) other than the peak
    (``iy``, ``ix``; ``top`` its region's label, 0 where no region passes the threshold) with a valley between them
    (:data:`RUNNER_UP_DIP`): ``(value, y, x)`` per map, value 0 where none. The regions are thresholded, so two
    peaks a little apart share one; the other region's maximum alone missed a second person standing near the first
    (docs/two-people.md, "Two people 0.6 m apart")."""
    n, h, w = filtered.shape
    values = np.zeros(n, np.float32)
    out_y, out_x = np.zeros(n, np.int64), np.zeros(n, np.int64)
    # the 3x3 neighbourhood's maximum, the pixel included (so >= it is a local maximum): one dilation of the tall
    # stack of tiles, each map's own border around it (pad >= 1), a third of the time of eight numpy slices
    tall = padded.reshape(n * padded.shape[1], padded.shape[2])
    neighbours = cv2.dilate(tall, np.ones((3, 3), np.uint8)).reshape(padded.shape)[:, pad:pad + h, pad:pad + w]
    # in_top is the pixels below the threshold where no peak passes it (top label 0): a bump there is no peak
    local = in_top & (top > 0)[:, None, None] & (filtered >= neighbours)
    local[np.arange(n), iy, ix] = False
    m, y, x = _nonzero_3d(local)
    if not len(m):
        return values, out_y, out_x
    t = np.linspace(0.0, 1.0, _DIP_SAMPLES)[None, 1:-1]
    sy = np.rint(iy[m, None] + (y - iy[m])[:, None] * t).astype(np.int64)
    sx = np.rint(ix[m, None] + (x - ix[m])[:, None] * t).astype(np.int64)
    valley = filtered[m[:, None], sy, sx].min(axis=1)
    value = filtered[m, y, x]
    keep = valley <= RUNNER_UP_DIP * value
    m, y, x, value = m[keep], y[keep], x[keep], value[keep]
    order = np.argsort(value, kind="stable")  # the highest last: its assignment wins
    values[m[order]], out_y[m[order]], out_x[m[order]] = value[order], y[order], x[order]
    return values, out_y, out_x


def _scaled_to_one(maps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(N, H, W)`` maps of values >= 0 as float32, each above 1 scaled down by its maximum, and each map's maximum
    after that (``(N,)`` float32, as ``maps.max(axis=(1, 2))`` of the result gives it: x / x is exactly 1 and the cast
    keeps the order), which the flat-top check then need not take again (:func:`decode_keypoints` says why scaled)."""
    maxima = maps.max(axis=(1, 2))
    if (maxima > 1.0).any():
        maps = maps / np.where(maxima > 1.0, maxima, 1.0)[:, None, None]
        maxima = np.minimum(maxima, 1.0)
    return maps.astype(np.float32, copy=False), maxima.astype(np.float32)


def decode_keypoints(heatmaps: np.ndarray, config: KeypointDecoderConfig | None = None) -> Keypoints2D:
    """Decode one keypoint per joint heatmap (single person).

    Args:
        heatmaps: ``(J, H, W)`` or ``(B, J, H, W)`` float (float32 expected; values in
            [0, 1]). Non-finite values make that joint missing.
        config: decoder settings (default :class:`KeypointDecoderConfig`).

    Returns:
        :class:`Keypoints2D` with batch shape ``(J,)`` or ``(B, J)``; ``uv`` in heatmap pixels.

    Raises:
        ShapeError: ``heatmaps`` is not 3- or 4-dimensional with a non-empty map.

    Example:
        >>> yy, xx = np.mgrid[:32, :32]
        >>> hm = np.exp(-((xx - 10.3) ** 2 + (yy - 20.6) ** 2) / (2 * 2.0 ** 2))[None].astype(np.float32)
        >>> kp = decode_keypoints(hm)
        >>> np.round(kp.uv, 2).tolist(), kp.valid.tolist()
        ([[10.3, 20.6]], [True])
    """
    cfg = config if config is not None else KeypointDecoderConfig()
    hm = np.asarray(heatmaps)
    # complex is numeric too, but its cast to float32 below dropped the imaginary part with only a warning
    if (hm.ndim not in (3, 4) or min(hm.shape[-2:]) < 1 or not np.issubdtype(hm.dtype, np.number)
            or np.issubdtype(hm.dtype, np.complexfloating)):
        raise ShapeError(f"heatmaps must be real-valued (J, H, W) or (B, J, H, W), got {hm.dtype} {hm.shape}")
    batch_shape, (h, w) = hm.shape[:-2], hm.shape[-2:]
    maps = hm.reshape(-1, h, w)
    n = len(maps)
    if n == 0:
        empty = np.zeros(batch_shape, np.float32)
        return Keypoints2D(np.zeros(batch_shape + (2,)), empty, empty.astype(bool), empty.copy(),
                           np.zeros(batch_shape + (2,)))

    finite = np.isfinite(maps).all(axis=(1, 2))
    if not finite.all():  # keep NaN/Inf out of the filter; those joints are dropped below
        maps = np.where(finite[:, None, None], maps, 0.0)
    # heatmaps are probabilities: a model that strays outside [0, 1] (huge values overflow the filter to
    # inf) must not report a confidence outside it. A map above 1 is scaled down by its maximum, not
    # clipped: clipping flattened a blob's top into a plateau whose first pixel became the peak (2.3 px
    # off for a blob of peak 255, sigma 2). Scaled before the float32 cast, which turned a finite float64
    # value past 3.4e38 into inf and so dropped its joint instead.
    maps, maxima = _scaled_to_one(np.maximum(maps, 0.0))

    padded, pad = _filter(maps, cfg.sigma)
    filtered = padded[:, pad:pad + h, pad:pad + w]
    flat_idx = filtered.reshape(n, -1).argmax(axis=1)
    iy, ix = np.divmod(flat_idx, w)
    peak = filtered[np.arange(n), iy, ix]

    above = filtered > cfg.threshold
    labels = _regions(above)
    top = labels[np.arange(n), iy, ix]  # 0 when the peak is not above the threshold
    in_top = labels == top[:, None, None]
    area = in_top.sum(axis=(1, 2))
    valid = finite & (peak > cfg.threshold) & (area <= cfg.max_region_frac * h * w)

    # Runner-up peak: only maps with another region (or a second peak inside the peak's own) need the (full-map)
    # masked max, taken where it is.
    others = above & ~in_top
    runner_up = np.zeros(n, np.float32)
    inner, inner_y, inner_x = _runner_up_in_region(filtered, padded, pad, in_top, top, iy, ix)
    multi = np.flatnonzero(others.any(axis=(1, 2)) | (inner > 0))
    which = np.arange(n)
    if len(multi):
        masked = (filtered[multi] * others[multi]).reshape(len(multi), -1)
        ry, rx = np.divmod(masked.argmax(axis=1), w)
        runner_up[multi] = masked[np.arange(len(multi)), ry * w + rx]
        # a second peak inside the best region, where higher than any other region's (module docstring, 5)
        use = inner[multi] > runner_up[multi]
        ry, rx = np.where(use, inner_y[multi], ry), np.where(use, inner_x[multi], rx)
        runner_up[multi] = np.maximum(runner_up[multi], inner[multi])
        # refined in the peaks' own call, after them: one set of numpy calls whatever the number of maps
        which, iy, ix = np.concatenate([which, multi]), np.concatenate([iy, ry]), np.concatenate([ix, rx])
        top = np.concatenate([top, labels[multi, ry, rx]])

    if cfg.refine == "quadratic":
        uv = _refine_quadratic(maps, maxima, padded, pad, iy, ix, cfg.sigma, which)
    elif cfg.refine == "centroid":
        uv = np.stack([ix, iy], axis=-1) + _refine_centroid(padded, pad, labels, top, iy, ix, cfg.centroid_radius,
                                                            which)
    else:
        uv = np.stack([ix, iy], axis=-1).astype(np.float64)

    runner_up = np.where(finite, runner_up, 0.0).astype(np.float32)
    runner_uv = np.full((n, 2), MISSING_FILL)
    if len(multi):
        runner_uv[multi] = uv[n:]
        runner_uv[runner_up == 0] = MISSING_FILL  # (a map with a non-finite value has none)
        uv = uv[:n]
    uv = np.where(valid[:, None], uv, MISSING_FILL)
    conf = np.where(valid, peak, 0.0).astype(np.float32)
    return Keypoints2D(uv.reshape(batch_shape + (2,)), conf.reshape(batch_shape), valid.reshape(batch_shape),
                       runner_up.reshape(batch_shape), runner_uv.reshape(batch_shape + (2,)))


def decode_blocks(rendered: np.ndarray, blocks, config: KeypointDecoderConfig | None = None) -> Keypoints2D:
    """Decode heatmaps rendered for a block of grid cells per view; ``uv`` in the whole grid's cells.

    Args:
        rendered: ``(V, R, J)`` heatmaps of each view's rays, row-major in its block.
        blocks: ``V`` blocks ``(r0, c0, rows, cols)`` of one size (``rays.common_blocks``).
        config: decoder settings.

    Each block is decoded alone: scattered onto the grid, the unrendered zeros around it would pull a peak near
    its border inward (up to 0.7 cells for the default filter, whose edge handling applies only at a map's own
    edge). ``max_region_frac`` is then a fraction of the block, of what was looked at, so a flooded map stays
    "no peak" however few rays were rendered.
    """
    rows, cols = blocks[0][2], blocks[0][3]
    if any((b[2], b[3]) != (rows, cols) for b in blocks) or len(rendered) != len(blocks):
        raise ShapeError(f"{len(rendered)} views of rendered heatmaps for blocks {list(blocks)}: one block of one "
                         "size per view")
    # in their own dtype: decode_keypoints scales values past 1 before its float32 cast (a float64 1e39 cast
    # here overflowed to inf and dropped its joint)
    maps = np.stack([np.asarray(r).reshape(rows, cols, -1).transpose(2, 0, 1) for r in rendered])
    kp = decode_keypoints(np.ascontiguousarray(maps), config)
    corner = np.array([[b[1], b[0]] for b in blocks], np.float64)[:, None, :]  # (V, 1, (c0, r0))
    return replace(kp, uv=np.where(kp.valid[..., None], kp.uv + corner, kp.uv),
                   runner_up_uv=np.where(kp.runner_up[..., None] > 0, kp.runner_up_uv + corner, kp.runner_up_uv))


# ---------------------------------------------------------------- coordinates
def _sizes(heatmap_size, model_size) -> tuple[np.ndarray, np.ndarray]:
    def wh(name, size):
        s = np.asarray(size, dtype=np.float64).reshape(-1)
        if s.size == 1:
            s = np.repeat(s, 2)
        if s.shape != (2,) or not np.all((s >= 1) & (s < np.inf)):  # inf mapped every point to -0.5
            raise ShapeError(f"{name} must be a positive int or (width, height), got {size!r}")
        return s
    return wh("heatmap_size", heatmap_size), wh("model_size", model_size)


def heatmap_to_model_pixels(uv: np.ndarray, heatmap_size, model_size) -> np.ndarray:
    """Heatmap pixels ``(..., 2)`` -> model-input pixels (pixel-centre convention).

    Args:
        uv: ``(..., 2)`` ``(x, y)`` heatmap pixels.
        heatmap_size: heatmap ``(width, height)`` or one int (square).
        model_size: model input ``(width, height)`` or one int.

    Example:
        >>> heatmap_to_model_pixels(np.array([0.0, 31.0]), 32, 128).tolist()
        [1.5, 125.5]
    """
    uv = check_last_dim("uv", uv, 2)
    hs, ms = _sizes(heatmap_size, model_size)
    return (uv + 0.5) * (ms / hs) - 0.5


def model_to_heatmap_pixels(uv: np.ndarray, heatmap_size, model_size) -> np.ndarray:
    """Model-input pixels ``(..., 2)`` -> heatmap pixels (inverse of :func:`heatmap_to_model_pixels`)."""
    uv = check_last_dim("uv", uv, 2)
    hs, ms = _sizes(heatmap_size, model_size)
    return (uv + 0.5) * (hs / ms) - 0.5


def _valid_like(valid, mapped: np.ndarray) -> np.ndarray:
    valid = np.asarray(valid, dtype=bool)
    if valid.shape != mapped.shape[:-1]:
        raise ShapeError(f"valid must have shape {mapped.shape[:-1]}, got {valid.shape}")
    return valid


def _keep_fill(mapped: np.ndarray, valid) -> np.ndarray:
    if valid is None:
        return mapped
    return np.where(_valid_like(valid, mapped)[..., None], mapped, MISSING_FILL)


def model_to_image_pixels(uv: np.ndarray, camera: Camera, roi: Roi, model_size: int, *, distort: bool = True,
                          valid=None, roll_deg: float = 0.0) -> np.ndarray:
    """Model-input pixels ``(..., 2)`` -> pixels of the full camera frame.

    Goes through the model input's pinhole camera (:func:`crop_camera`) to normalised
    coordinates, then through the real lens. ``distort=False`` gives undistorted pixels
    (the ideal pinhole camera with the original ``K``, as ``Camera.undistort_pixels``).
    Tip: to triangulate, you may skip this and pass model pixels with ``crop_camera``
    cameras directly; both are exact.

    Args:
        uv: ``(..., 2)`` model-input pixels.
        camera: the full-resolution camera the ROI was cut from.
        roi: the ROI of this frame.
        model_size: model input side ``S``.
        distort: return distorted (raw frame) pixels.
        valid: optional ``(...)`` bool; entries not valid come back as :data:`MISSING_FILL`.
        roll_deg: the model input was rotated so (``crop_camera``'s argument).

    Returns:
        ``(..., 2)`` float64. With ``distort``, a point past the lens model's fold (a square crop
        can reach past it; :meth:`Camera.within_lens`) comes back as :data:`MISSING_FILL` too: no
        pixel of the frame shows it.
    """
    uv = check_last_dim("uv", uv, 2)
    crop = crop_camera(camera, roi, model_size, roll_deg)
    safe = uv if valid is None else np.where(np.asarray(valid, bool)[..., None], uv, 0.0)
    xy = camera_normalized(crop.pixels_to_normalized(safe), crop, camera)
    if distort:
        inside = camera.within_lens(xy)
        if not inside.all():  # (the lens model of a far or non-finite point overflowed, with numpy warnings)
            xy = np.where(inside[..., None], xy, 0.0)
            valid = inside if valid is None else _valid_like(valid, xy) & inside
    mapped = camera.normalized_to_pixels(xy, distort=distort)
    return _keep_fill(mapped, valid)


def heatmap_to_image_pixels(uv: np.ndarray, camera: Camera, roi: Roi, model_size: int, heatmap_size, *,
                            distort: bool = True, valid=None, roll_deg: float = 0.0) -> np.ndarray:
    """Heatmap pixels ``(..., 2)`` -> full-frame pixels (:func:`heatmap_to_model_pixels`, then
    :func:`model_to_image_pixels`); see the latter for the arguments."""
    model_uv = heatmap_to_model_pixels(uv, heatmap_size, model_size)
    return model_to_image_pixels(model_uv, camera, roi, model_size, distort=distort, valid=valid,
                                 roll_deg=roll_deg)
