"""Region of interest and the undistort + crop + resize of camera frames for the model.

The model sees a square, undistorted (ideal pinhole) crop of each camera image,
resized to ``out_size x out_size``. Everything here works in **undistorted
image pixels**: pixel coordinates of the ideal pinhole camera with the original
``K`` (what ``Camera.undistort_pixels`` returns). A :class:`Roi` is an integer
square in that space; :func:`crop_camera` is the pinhole camera of the model
input; :func:`build_undistort_crop_maps` makes the remap tables that sample the
distorted frame directly, so one ``cv2.remap`` does undistort, crop and resize.

Clamp / pad policy
    A ROI is the bounding box of what should be seen (the projected working
    volume, or the tracked joints), first **intersected with the image** (the
    bounding box of the real pixels' undistorted footprint: nothing outside it
    can be seen),
    then made **square** around the centre of that intersection with side
    ``max(width, height)``. The square is kept even where it leaves the image;
    those model-input pixels are **zeros** (black padding, ``cv2.BORDER_CONSTANT``).
    Keeping the square keeps the model input's aspect ratio and its ``K``
    honest; shifting the square back inside the image would be an alternative,
    but it moves the subject off-centre for no gain.

    Both are choices (``RoiConfig.edge_crop`` and ``pad_fill``; docs/runtime.md,
    "A person at the frame's edge"): a tracked box may instead be squared whole
    (``"centre"``: the person centred, more black) or that square moved inside
    the image (``"shift"``); and the padding may repeat the frame's nearest edge
    pixel (``pad_fill="edge"``, a clamp of the remap tables) instead of zeros, or
    repeat it fading into the crop's in-frame mean colour over ``pad_fade`` crop
    sides (``"fade"``: the same clamp, and a blend by weights fixed per crop
    window, the mean taken per frame). Measured with the shipped model, the
    framing changes little and the black itself is what costs: the edge alone
    helps beside the person but not once the edge cuts through the body (it
    smears the body across the band); faded into the mean it helps at every cut,
    so the runtime's default (``RoiConfig.pad_fill``) is ``"fade"`` for a model
    trained without frame padding and ``"black"`` for one trained with it (its
    contract's ``frame_padding``); these functions keep zeros unless asked (the
    training crops' ``frame_padding``).

Anti-aliasing
    Bilinear remapping aliases when the ROI is much larger than ``out_size``.
    When the scale ``roi.size / out_size`` is ``s``, the touched window of the
    frame is first reduced by ``L = round(log2 s)`` halvings with
    ``cv2.INTER_AREA`` (2x2 box averages; together an exact ``2^L x 2^L`` box
    filter, what ``cv2.resize(..., INTER_AREA)`` does for integer factors), and
    the maps address that reduced window. The residual bilinear scale is then
    within [0.71, 1.41], where bilinear aliasing is mild. A box is a weaker
    low-pass than a Gaussian pyramid (``cv2.pyrDown``), but measured ~3x cheaper
    (0.12 ms against 0.34 ms for 640x480 -> 160x120 on the 2-core test box),
    and the bilinear remap adds its own smoothing. Window sides are kept
    multiples of ``2^L`` because OpenCV's INTER_AREA is ~10x slower on odd sizes;
    where the frame's side is not one, the window passes the frame's edge and is
    padded by repeating it (what lies past the edge still shows zeros).

Supersampling (``supersample = f > 1``, the estimator's ``roi.supersample``)
    The synthetic training crops are rendered at ``f S x f S`` point samples of the crop
    camera and reduced with ``INTER_AREA`` (``training/data/views.py``, ``f = 2``). The
    box + bilinear path above is blurrier than that: on the bench rigs' tracked crops
    (scale 2-3) a training crop blurred by a Gaussian of sigma 0.4-0.7 model pixels
    matches it best. With ``f > 1`` the maps sample the crop camera at ``f S``
    (bilinear, after ``L = floor(log2(roi.size / (f S)))`` box steps, so the bilinear step
    stays within 1-2 reduced pixels) and ``apply_crop_maps`` reduces the result by
    ``f x f`` box means, as training did: the crops then differ from the training
    crops of the same camera by 0.2-0.9 levels (mean absolute) instead of 0.3-1.2, and
    without the blur.

Speed
    Maps are built by ``cv2.initUndistortRectifyMap`` (same lens model as
    :class:`~ghnerf_runtime.geometry.Camera`) when ``K`` has no skew, and from
    ``Camera.normalized_to_pixels`` otherwise; the two agree to 1e-3 px (tested).
    Building takes ~0.4 ms against ~1.6 ms (S = 128). Maps are also converted once
    to OpenCV's fixed-point format (1/32 px sample positions), which halves the
    remap time: ~0.1-0.2 ms per 640x480 frame, ~0.25 ms with normalisation.

Pure functions; numpy and OpenCV only.
"""
from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass, replace

import cv2
import numpy as np

from ghnerf_runtime.contract import Normalisation
from ghnerf_runtime.errors import GeometryError, ShapeError
from ghnerf_runtime.geometry.camera import LENS_REACH, Camera, check_last_dim, image_rotation
from ghnerf_runtime.geometry.rig import WorkingVolume
from ghnerf_runtime.plain_values import whole_valued_or_none

__all__ = [
    "Roi", "CropMaps", "roi_from_volume", "roi_from_joints", "crop_camera", "build_undistort_crop_maps",
    "apply_crop_maps", "preprocess_image", "undistorted_image_bounds", "upright_roll_deg",
    "camera_normalized", "EDGE_CROPS", "PAD_FILLS",
]

#: How a tracked box past the image's edge is cropped (``roi_from_joints``; module docstring).
EDGE_CROPS = ("clip", "centre", "shift")
#: What a crop shows past the frame's edge (``build_undistort_crop_maps``; module docstring).
PAD_FILLS = ("black", "edge", "fade")

#: Nearest camera depth (metres) used when clipping a box that reaches behind the camera.
NEAR_PLANE = 0.05
_BOX_EDGES = tuple((a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit)  # 12 edges of a cube


# ---------------------------------------------------------------------------- ROI
@dataclass(frozen=True)
class Roi:
    """A square crop window, in undistorted image pixels of one camera.

    It covers the pixel centres ``x0 .. x0 + size - 1`` and ``y0 .. y0 + size - 1``
    (it may extend past the image; see the module docstring for the padding policy).
    The crop -> model transform scales by ``out_size / size`` with the pixel-centre
    convention of ``Camera.resized``:
    ``u_model = (u - x0 + 0.5) * out_size / size - 0.5``.

    Attributes:
        x0, y0: top-left pixel centre (integers, may be negative).
        size: side length in pixels (>= 1).
    """

    x0: int
    y0: int
    size: int

    def __post_init__(self) -> None:
        for name in ("x0", "y0", "size"):
            value = getattr(self, name)
            whole = whole_valued_or_none(value)  # 100.0 taken: windows are placed in floating point
            if whole is None:
                raise GeometryError(f"Roi.{name} must be an integer, got {value!r}")
            object.__setattr__(self, name, whole)
        if self.size < 1:
            raise GeometryError(f"Roi.size must be >= 1, got {self.size}")

    def scale(self, out_size: int) -> float:
        """Model pixels per image pixel."""
        return _check_out_size(out_size) / self.size

    def affine(self, out_size: int) -> np.ndarray:
        """``(2, 3)`` matrix mapping undistorted image pixels to model-input pixels."""
        s = self.scale(out_size)
        return np.array([[s, 0.0, (0.5 - self.x0) * s - 0.5], [0.0, s, (0.5 - self.y0) * s - 0.5]])

    def image_to_model(self, uv: np.ndarray, out_size: int) -> np.ndarray:
        """Undistorted image pixels ``(..., 2)`` -> model-input pixels ``(..., 2)``."""
        uv = check_last_dim("uv", uv, 2)
        s = self.scale(out_size)
        return (uv - [self.x0, self.y0] + 0.5) * s - 0.5

    def model_to_image(self, uv: np.ndarray, out_size: int) -> np.ndarray:
        """Model-input pixels ``(..., 2)`` -> undistorted image pixels ``(..., 2)``.

        Example:
            >>> Roi(100, 50, 256).model_to_image(np.array([63.5, 63.5]), 128).tolist()
            [227.5, 177.5]
        """
        uv = check_last_dim("uv", uv, 2)
        s = self.scale(out_size)
        return (uv + 0.5) / s - 0.5 + [self.x0, self.y0]


def _check_out_size(out_size: int) -> int:
    whole = whole_valued_or_none(out_size)
    if whole is None or whole < 1:
        raise GeometryError(f"out_size must be a positive integer, got {out_size!r}")
    return whole


def undistorted_image_bounds(camera: Camera, samples_per_side: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Bounding box ``(lo, hi)`` of the image's footprint in undistorted pixels.

    The image border (pixel edges, ``-0.5 .. W - 0.5``) is sampled and undistorted; with
    barrel distortion the footprint is larger than ``W x H``, with pincushion smaller.
    """
    w, h = camera.width, camera.height
    xs = np.linspace(-0.5, w - 0.5, samples_per_side)
    ys = np.linspace(-0.5, h - 0.5, samples_per_side)
    border = np.concatenate([
        np.stack([xs, np.full_like(xs, -0.5)], -1), np.stack([xs, np.full_like(xs, h - 0.5)], -1),
        np.stack([np.full_like(ys, -0.5), ys], -1), np.stack([np.full_like(ys, w - 0.5), ys], -1),
    ])
    und = camera.undistort_pixels(border) if camera.has_distortion else border
    # A lens model that folds over before the image's edge cannot undistort the border there (NaN):
    # the footprint is then what it can undistort.
    und = und[np.all(np.isfinite(und), axis=-1)]
    if len(und) == 0:
        raise GeometryError(
            f"camera {camera.name!r}: its lens model (distortion {np.asarray(camera.dist).tolist()}) cannot "
            "undistort any point of the image border; check the calibration"
        )
    return und.min(axis=0), und.max(axis=0)


@functools.lru_cache(maxsize=32)
def _cached_image_bounds(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    # Cameras are immutable (and hash by identity), so the footprint is computed once per camera
    # instead of on every tracked pair: it undistorts 256 border points.
    lo, hi = undistorted_image_bounds(camera)
    lo.setflags(write=False)
    hi.setflags(write=False)
    return lo, hi


def _square_roi(lo: np.ndarray, hi: np.ndarray, camera: Camera, min_size: int = 1) -> Roi:
    """Intersect the box ``[lo, hi]`` with the image footprint, then square it (see module doc)."""
    img_lo, img_hi = _cached_image_bounds(camera)
    lo, hi = np.maximum(lo, img_lo), np.minimum(hi, img_hi)
    if np.any(hi < lo):
        raise GeometryError(f"camera {camera.name!r}: the region {lo.tolist()}..{hi.tolist()} lies outside the image")
    return _square(0.5 * (lo + hi), float(np.max(hi - lo)), min_size)


def _square_size(side: float, min_size: int = 1) -> int:
    """The side in whole pixels of :func:`_square`'s square for a box of ``side`` pixels."""
    # +1: integer rounding of the corner may shift the window by up to half a pixel each way.
    return max(int(math.ceil(side)) + 1, int(min_size), 1)


def _square(centre: np.ndarray, side: float, min_size: int = 1) -> Roi:
    """The integer square of at least ``side`` (and ``min_size``) pixels around ``centre``."""
    size = _square_size(side, min_size)
    x0, y0 = (int(math.floor(c - (size - 1) / 2 + 0.5)) for c in centre)
    return Roi(x0, y0, size)


def _check_edge_crop(edge_crop: str) -> str:
    if edge_crop not in EDGE_CROPS:
        raise GeometryError(f"edge_crop must be one of {EDGE_CROPS}, got {edge_crop!r}")
    return edge_crop


def _roi_of_points(uv: np.ndarray, camera: Camera, *, margin_frac: float = 0.0, min_size: int = 1,
                   roll_deg: float = 0.0, edge_crop: str = "clip") -> Roi:
    """The square ROI showing the undistorted pixels ``uv`` ``(N, 2)``, its box grown by ``margin_frac``
    of its longer side. With ``roll_deg`` the crop is rotated so about its centre (``crop_camera``), so
    the square is sized and centred on the points' extent seen that way: a body standing upright in the
    rotated crop fits it, where the sensor's own box would cut its head and feet. ``edge_crop``: how a box
    past the image's edge is cropped (module docstring, "Clamp / pad policy")."""
    _check_edge_crop(edge_crop)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    img_lo, img_hi = _cached_image_bounds(camera)
    if roll_deg % 360.0 == 0.0 and edge_crop == "clip":
        grow = margin_frac * float(np.max(hi - lo))
        return _square_roi(lo - grow, hi + grow, camera, min_size=min_size)
    if np.any(np.minimum(hi, img_hi) < np.maximum(lo, img_lo)):
        raise GeometryError(f"camera {camera.name!r}: the region {lo.tolist()}..{hi.tolist()} lies outside the image")
    turn = image_rotation(roll_deg)  # as Camera.rotated turns the crop
    # "clip": nothing outside the image can be seen, so the box is what the image shows of the points;
    # otherwise the whole box, as the training crops frame the whole person (training/data/synthetic.py)
    seen = (np.clip(uv, img_lo, img_hi) if edge_crop == "clip" else uv) @ turn.T
    lo, hi = seen.min(axis=0), seen.max(axis=0)
    side = float(np.max(hi - lo)) * (1 + 2 * margin_frac)
    centre = turn.T @ (0.5 * (lo + hi))
    if edge_crop == "shift":
        # the rotated square's axis-aligned half-extent, of the square made (min_size and the rounding's pixel
        # too: sized from the box alone, a small person's square grown to min_size still left the frame)
        half = 0.5 * _square_size(side, min_size) * np.abs(turn).sum(axis=1)
        room_lo, room_hi = img_lo + half, img_hi - half
        centre = np.where(room_lo <= room_hi, np.clip(centre, room_lo, np.maximum(room_lo, room_hi)),
                          0.5 * (img_lo + img_hi))
    return _square(centre, side, min_size)


def roi_from_volume(camera: Camera, volume: WorkingVolume | np.ndarray, margin: float = 0.0, *,
                    roll_deg: float = 0.0) -> Roi:
    """The square ROI that shows a box (the working volume) in one camera.

    The box (grown by ``margin`` metres on every side) is clipped against the camera's near
    plane (``NEAR_PLANE`` metres in front of it), so a box reaching behind the camera is
    handled: its visible part projects to a large region, which the image bounds then clip.
    The projected bounding box is intersected with the image and squared (module docstring).

    Args:
        camera: the full-resolution camera.
        volume: a :class:`WorkingVolume`, or box corners ``(N, 3)`` in the rig frame (the box
            used is their axis-aligned bounding box).
        margin: metres added to every side of the box.
        roll_deg: the crop will be rotated so (``crop_camera``): size the square for it.

    Returns:
        :class:`Roi` in undistorted pixels.

    Raises:
        GeometryError: the box is entirely behind the camera or outside the image.
        ShapeError: ``volume`` corners are not ``(N, 3)``.
    """
    if isinstance(volume, WorkingVolume):
        lo, hi = volume.min_corner, volume.max_corner
    else:
        corners = np.asarray(volume, dtype=np.float64)
        if corners.ndim != 2 or corners.shape[1] != 3 or len(corners) == 0:
            raise ShapeError(f"volume corners must have shape (N, 3), got {corners.shape}")
        lo, hi = corners.min(axis=0), corners.max(axis=0)
    if not (np.isfinite(margin) and np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise GeometryError("volume corners and margin must be finite")
    with np.errstate(over="ignore", invalid="ignore"):
        lo, hi = lo - margin, hi + margin
        bits = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
        pc = camera.to_camera(np.where(bits == 1, hi, lo))  # (8, 3) camera frame
    if not np.all(np.isfinite(pc)):  # corners near 1e308: grown or turned into the camera's frame, inf
        raise GeometryError(f"camera {camera.name!r}: the volume from {lo.tolist()} to {hi.tolist()} (margin "
                            f"{margin}) is too large for float64")

    z = pc[:, 2]
    pts = [pc[z >= NEAR_PLANE]]
    for a, b in _BOX_EDGES:  # where an edge crosses the near plane, keep the crossing point
        if (z[a] >= NEAR_PLANE) != (z[b] >= NEAR_PLANE):
            f = (NEAR_PLANE - z[a]) / (z[b] - z[a])
            pts.append((pc[a] + f * (pc[b] - pc[a]))[None])
            pts[-1][0, 2] = NEAR_PLANE  # exactly: with corners of 1e15 m rounding left it 0 or below (x / 0)
    pts = np.concatenate(pts)
    if len(pts) == 0:
        raise GeometryError(f"camera {camera.name!r}: the volume is entirely behind the camera")
    # Clipping the rays to +-1e9 (normalised) cannot change their box's overlap with the image (a few
    # normalised units wide) and keeps the pixels finite: an inf there met K's zero skew as 0 * inf = NaN.
    uv = camera.normalized_to_pixels(np.clip(pts[:, :2] / pts[:, 2:], -1e9, 1e9), distort=False)
    return _roi_of_points(uv, camera, roll_deg=roll_deg)


def roi_from_joints(camera: Camera, joints: np.ndarray, confidences: np.ndarray, margin_frac: float = 0.2,
                    min_size: int = 64, *, min_confidence: float = 0.0, min_joints: int = 3,
                    roll_deg: float = 0.0, edge_crop: str = "clip") -> Roi | None:
    """A square ROI around joints of the previous frame (tracking).

    Args:
        camera: the full-resolution camera.
        joints: ``(J, 3)`` rig-frame joints (metres), or ``(J, 2)`` **distorted** image
            pixels (decoded keypoints mapped back to the image).
        confidences: ``(J,)``; joints with confidence ``> min_confidence`` and finite
            coordinates (and, for 3D joints, in front of the camera) are used.
        margin_frac: the joints' bounding box grows by this fraction of its longer side on
            every side before squaring.
        min_size: smallest ROI side, pixels.
        min_confidence: see ``confidences``.
        min_joints: fewer usable joints than this gives ``None``.
        roll_deg: the crop will be rotated so (``crop_camera``): size the square for it.
        edge_crop: a box past the image's edge: ``"clip"`` (clipped to the image, squared round what is
            left), ``"centre"`` (squared round the whole box, the part past the edge black) or ``"shift"``
            (the whole box's square moved inside the image); module docstring, "Clamp / pad policy".

    Returns:
        A :class:`Roi`, or ``None`` when too few joints are usable or they lie outside the
        image: fall back to :func:`roi_from_volume`.
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim != 2 or joints.shape[1] not in (2, 3):
        raise ShapeError(f"joints must have shape (J, 2) or (J, 3), got {joints.shape}")
    conf = np.asarray(confidences, dtype=np.float64)
    if conf.shape != joints.shape[:1]:
        raise ShapeError(f"confidences must have shape ({len(joints)},), got {conf.shape}")
    if not (np.isfinite(margin_frac) and margin_frac >= 0):
        raise GeometryError(f"margin_frac must be >= 0, got {margin_frac}")
    if not np.isfinite(min_size):  # was a bare "cannot convert float NaN to integer"
        raise GeometryError(f"min_size must be a finite number of pixels, got {min_size}")
    image_rotation(roll_deg)  # a roll that is not finite is named here: the None below means "too few joints"
    _check_edge_crop(edge_crop)

    ok = (conf > min_confidence) & np.all(np.isfinite(joints), axis=1)
    if joints.shape[1] == 3:
        uv, depth = camera.project(np.where(ok[:, None], joints, 0.0), distort=False)
        ok &= (depth > NEAR_PLANE) & np.all(np.isfinite(uv), axis=1)  # NaN: a pixel past float64's range
    else:
        uv = camera.undistort_pixels(np.where(ok[:, None], joints, 0.0)) if camera.has_distortion else joints
        ok &= np.all(np.isfinite(uv), axis=1)  # beyond the lens model's reach
    if int(ok.sum()) < max(int(min_joints), 1):
        return None
    try:
        return _roi_of_points(uv[ok], camera, margin_frac=margin_frac, min_size=min_size, roll_deg=roll_deg,
                              edge_crop=edge_crop)
    except GeometryError:
        return None


# ------------------------------------------------------------------ upright crops
def upright_roll_deg(camera: Camera) -> float:
    """Degrees to rotate ``camera``'s picture (counterclockwise, about its centre) to make it upright:
    the rig's down (+y, gravity) pointing down the picture, as in the model's training views.

    A camera mounted level gives 0, upside down (a ceiling mount) 180, on its side +-90; a crooked
    mount anything between. A camera looking straight up or down has no upright: 0.
    """
    dx, dy = camera.R[0, 1], camera.R[1, 1]  # the rig's +y in the camera frame, seen in the image
    if math.hypot(dx, dy) < 1e-6:
        return 0.0
    # Rotating the picture by a turns (dx, dy) into (cos a dx + sin a dy, -sin a dx + cos a dy).
    return math.degrees(math.atan2(-dx, dy))


def camera_normalized(xy: np.ndarray, crop: Camera, camera: Camera) -> np.ndarray:
    """Normalised coordinates ``(..., 2)`` of ``crop`` (a crop of ``camera``, maybe rotated: the same
    centre) -> those of ``camera``: the same rays."""
    if crop.R is camera.R:  # not rotated (the crop shares the camera's R): the same coordinates
        return xy
    rel = camera.R @ crop.R.T
    d = xy @ rel[:, :2].T + rel[:, 2]
    return d[..., :2] / d[..., 2:3]


# ------------------------------------------------------------------ crop camera
def crop_camera(camera: Camera, roi: Roi, out_size: int, roll_deg: float = 0.0) -> Camera:
    """The pinhole camera of the model input: undistorted, cropped to ``roi``, resized, and rotated
    ``roll_deg`` counterclockwise about the crop's centre (:func:`upright_roll_deg`: a camera mounted
    upside down, on its side or crooked still shows the model an upright person).

    Its ``project`` gives model-input pixels; its ``K`` is what the model graphs take.

    Example:
        >>> cam = Camera("c", 640, 480, [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]], [-0.1, 0.01, 0, 0])
        >>> crop = crop_camera(cam, Roi(160, 80, 320), 128)
        >>> crop.size, crop.has_distortion, np.round(crop.K[:2], 6).ravel().tolist()
        ((128, 128), False, [200.0, 0.0, 63.5, 0.0, 200.0, 63.5])
    """
    out_size = _check_out_size(out_size)
    crop = camera.without_distortion().cropped(roi.x0, roi.y0, roi.size, roi.size).resized(out_size, out_size)
    return crop.rotated(roll_deg)


# ------------------------------------------------------------------------- maps
@dataclass(frozen=True, eq=False)
class CropMaps:
    """Remap tables for one camera and ROI (they depend on nothing else: cache them).

    ``map_x``/``map_y`` address the frame window ``image[y0:y1, x0:x1]`` after ``level``
    2x INTER_AREA reductions, with the pixel-centre convention
    (``u_level = (u - x0 + 0.5) / 2^level - 0.5``). With ``level == 0`` the window is the
    whole frame and the maps are plain distorted-frame pixel coordinates, usable directly
    as ``cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR)``.

    Attributes:
        map_x, map_y: ``(S, S)`` float32.
        level: 2x reductions applied to the window before the remap (0 = none).
        window: ``(x0, y0, x1, y1)`` of the frame region that is read, pixels; ``x1``/``y1`` pass the
            frame's edge (its edge repeated) where the frame's side is not a multiple of ``2^level``.
        image_size: ``(width, height)`` the frame must have.
        fixed: the same maps in OpenCV's fixed-point format (``cv2.convertMaps``), which
            :func:`apply_crop_maps` uses because it remaps ~2x faster.
        inside: ``(S, S)`` bool, the model pixels that sample the frame (the others are the
            padding of a crop reaching past the frame's edge, whatever the fill); ``None``: all of them.
    """

    map_x: np.ndarray | None
    map_y: np.ndarray | None
    level: int
    window: tuple[int, int, int, int]
    image_size: tuple[int, int]
    fixed: tuple[np.ndarray, np.ndarray]
    inside: np.ndarray | None = None
    supersample: int = 1
    """The maps are ``(f S, f S)``; :func:`apply_crop_maps` reduces the remapped crop by ``f x f``
    box means (module docstring, "Supersampling"); ``inside`` is ``(S, S)``, the pixels all of whose
    samples show the frame."""
    side: int | None = None
    """``S``, kept by :meth:`compact` (whose maps have no float tables to read it from)."""
    fade: tuple[slice, slice, np.ndarray, np.ndarray] | None = None
    """``pad_fill="fade"``: the rows and columns of the ``(S, S)`` model pixels that hold the padding, and there
    the weights of the remapped crop and of its in-frame (``inside``) mean colour, which :func:`apply_crop_maps`
    blends per frame; ``None``: the remapped crop as it is."""

    @property
    def out_size(self) -> int:
        return self.side if self.side is not None else int(self.map_x.shape[0]) // self.supersample

    def compact(self) -> "CropMaps":
        """The same maps without the float tables (``map_x``/``map_y`` None): :func:`apply_crop_maps` reads
        only the fixed-point ones, and a cache of 32 supersampled tables per camera held ~57 MB, 60 % of it
        float tables."""
        return replace(self, map_x=None, map_y=None, side=self.out_size)


_OUTSIDE = -1e6  # a map coordinate far off any frame: cv2.remap's constant border (0)
#: Frame dtypes both of OpenCV's steps (INTER_AREA resize, remap) take.
_FRAME_DTYPES = (np.uint8, np.uint16, np.int16, np.float32, np.float64)


def _lens_maps(camera: Camera, crop: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Distorted frame pixels ``(S, S)`` x2 sampled by each pixel of the pinhole ``crop`` camera."""
    # the limit within_lens and project use (radial fold, or nearer by tangential/prism terms; cached per lens)
    skewed, folds = camera.K[0, 1] != 0.0, camera.lens_limit < LENS_REACH
    # each crop pixel's ray in the camera's normalised coordinates (the crop is a pinhole: exact)
    xy = camera_normalized(crop.pixels_to_normalized(crop.pixel_grid()), crop, camera) if skewed or folds else None
    if not skewed:
        # OpenCV's own implementation of the same lens model; no skew support, hence the test. A rotated
        # crop is a rectification: R takes the camera's frame to the crop's.
        dist = camera.dist if camera.dist.size else None
        rectify = None if crop.R is camera.R else crop.R @ camera.R.T
        map_x, map_y = cv2.initUndistortRectifyMap(camera.K, dist, rectify, crop.K, crop.size, cv2.CV_32FC1)
    else:
        src = camera.normalized_to_pixels(xy, distort=True)
        map_x, map_y = src[..., 0].astype(np.float32), src[..., 1].astype(np.float32)
    if folds:
        # Past the lens model's fold, the forward model maps back onto the image (a mirrored ring of
        # the picture, or duplicated content where tangential or prism terms fold it): show nothing there
        # instead, as outside the frame.
        outside = ~camera.within_lens(xy)
        map_x[outside] = map_y[outside] = _OUTSIDE
    # A crop far off the frame (or a short focal length) sends the lens polynomial past float32: inf or NaN,
    # which the window below cannot round to a pixel (OverflowError). Nothing of the frame is seen there.
    lost = ~(np.isfinite(map_x) & np.isfinite(map_y))
    if lost.any():
        map_x[lost] = map_y[lost] = _OUTSIDE
    return map_x, map_y


def _aligned_span(lo: int, hi: int, limit: int, factor: int) -> tuple[int, int]:
    """``[lo, hi)`` clipped to ``[0, limit)`` and grown to a multiple of ``factor``.

    The span stays inside the frame where it fits; where it does not (a window as wide as a frame
    whose side is not a multiple of ``factor``), it starts at 0 and ends past ``limit``: the reader
    pads the frame there by repeating its edge, so the box steps' last pixel is frame alone, rather than
    dropping the frame pixels that do not fill a box.
    """
    lo, hi = max(lo, 0), min(hi, limit)
    if hi - lo < factor:
        lo, hi = 0, limit
    span = -(-(hi - lo) // factor) * factor
    if lo + span <= limit:
        return lo, lo + span
    if hi - span >= 0:
        return hi - span, hi
    return 0, span


def build_undistort_crop_maps(camera: Camera, roi: Roi, out_size: int, *, antialias: bool = True,
                              roll_deg: float = 0.0, supersample: int = 1, pad_fill: str = "black",
                              pad_fade: float = 0.1) -> CropMaps:
    """Maps for one ``cv2.remap`` that undistorts, crops and resizes a frame in one pass.

    Each model-input pixel centre goes through :func:`crop_camera` to normalised
    coordinates and through the real lens (``camera.normalized_to_pixels(distort=True)``,
    or OpenCV's identical ``initUndistortRectifyMap`` when ``K`` has no skew) to the
    distorted frame pixel it samples. With ``antialias`` the frame window is first reduced
    by ``round(log2(roi.size / out_size))`` 2x box steps (module docstring).

    Args:
        camera: the full-resolution camera (with distortion).
        roi: crop window in undistorted pixels.
        out_size: model input side ``S``.
        antialias: allow the box pre-reduction.
        roll_deg: rotate the crop counterclockwise about its centre, as
            ``crop_camera(..., roll_deg)`` does its camera.
        supersample: sample the crop at ``supersample x`` the resolution and box-reduce it, as the
            synthetic training crops were made (module docstring); 1: one sample per pixel.
        pad_fill: what the crop shows past the frame's edge: ``"black"`` (zeros), ``"edge"`` (the frame's
            nearest edge pixel repeated outward) or ``"fade"`` (that edge pixel fading to the crop's mean
            colour); module docstring, "Clamp / pad policy". ``inside`` is the same whatever the fill.
        pad_fade: ``"fade"``: how far past the frame's edge, in crop sides, the repeated edge has faded into
            the mean (linearly; 0: the mean straight past the edge).

    Returns:
        :class:`CropMaps` for :func:`apply_crop_maps` / :func:`preprocess_image`.
    """
    out_size = _check_out_size(out_size)
    f = _check_out_size(supersample)
    if pad_fill not in PAD_FILLS:
        raise GeometryError(f"pad_fill must be one of {PAD_FILLS}, got {pad_fill!r}")
    if isinstance(pad_fade, bool) or not (isinstance(pad_fade, numbers.Real) and 0.0 <= pad_fade <= 1.0):
        raise GeometryError(f"pad_fade must be a number of crop sides in [0, 1], got {pad_fade!r}")
    map_x, map_y = _lens_maps(camera, crop_camera(camera, roi, out_size * f, roll_deg))
    lost = map_x <= _OUTSIDE / 2  # past the lens model's reach: no frame pixel to repeat (0, or "fade"'s mean)
    fade = None
    if pad_fill == "fade":  # how far past the frame each sample lies, in crop sides (frame pixels, as yet)
        beyond = _distance_past_frame(map_x, map_y, camera.size)
        fade = _fade_weights(np.where(lost, np.inf, beyond / roi.size), pad_fade, f)

    if not antialias:
        level = 0
    elif f == 1:
        level = max(0, int(round(math.log2(roi.size / out_size))))
    else:  # the bilinear step stays within 1-2 reduced pixels: no blur beyond what the f x f box means add
        level = max(0, int(math.floor(math.log2(roi.size / (out_size * f)))))
    factor = 2 ** level
    if level == 0 or min(camera.width, camera.height) < factor:
        inside = _inside(map_x, map_y, camera.size, f)
        level, window, size = 0, (0, 0, camera.width, camera.height), camera.size
        shown = (map_x, map_y)
    else:
        # Reduce only the touched window (+ one reduced pixel of context for the bilinear taps).
        pad = 2 * factor
        touched = map_x > _OUTSIDE / 2
        if not touched.any():
            touched[...] = True
        # (a crop wholly within the lens model's reach, the usual one, skips the masked copies: the same extremes)
        tx, ty = (map_x, map_y) if touched.all() else (map_x[touched], map_y[touched])
        x0, x1 = _aligned_span(int(np.floor(tx.min())) - pad, int(np.ceil(tx.max())) + pad + 1, camera.width,
                               factor)
        y0, y1 = _aligned_span(int(np.floor(ty.min())) - pad, int(np.ceil(ty.max())) + pad + 1, camera.height,
                               factor)
        past = None
        if x1 > camera.width or y1 > camera.height:
            # The window's edge-repeating padding is not frame: what lies past the frame's edge shows zeros, as
            # everywhere else outside it (a clamping fill below shows the frame's edge there instead).
            past = (map_x > camera.width - 0.5) | (map_y > camera.height - 0.5)
        map_x = ((map_x - x0 + 0.5) / factor - 0.5).astype(np.float32, copy=False)
        map_y = ((map_y - y0 + 0.5) / factor - 0.5).astype(np.float32, copy=False)
        window, size = (x0, y0, x1, y1), ((x1 - x0) // factor, (y1 - y0) // factor)
        # `inside` as under black whatever the fill: the window's edge-repeating padding is not frame
        shown = (map_x, map_y) if past is None else (np.where(past, _OUTSIDE, map_x), np.where(past, _OUTSIDE, map_y))
        inside = _inside(*shown, size, f)
    if inside is not None and pad_fill != "black":  # from the maps before `past`: the window's padding is the edge
        map_x, map_y = _clamped(map_x, map_y, lost, size)
    else:
        map_x, map_y = (m.astype(np.float32, copy=False) for m in shown)
    return CropMaps(map_x, map_y, level, window, camera.size, cv2.convertMaps(map_x, map_y, cv2.CV_16SC2), inside,
                    f, fade=None if inside is None else fade)


#: Below this block side, numpy sums a block's row from left to right; from 8 on its inner loop is unrolled (another
#: order), so :func:`_block_means` leaves such blocks to numpy's own reduction.
_SEQUENTIAL_SUM_BELOW = 8


def _block_means(values: np.ndarray, f: int) -> np.ndarray:
    """The means of the ``f x f`` blocks of the square ``(f n, f n)`` float ``values``: the same to the bit as
    ``values.reshape(n, f, n, f).mean(axis=(1, 3))`` (each block's rows summed left to right, then the row sums
    top to bottom, then divided by ``f * f``), in whole-plane adds of strided views: numpy's reduction over two
    small axes at once took ~0.9 ms for a 256-pixel crop's (session 67), the adds ~0.06 ms."""
    if f == 1 or f >= _SEQUENTIAL_SUM_BELOW:
        n = values.shape[0] // f
        return values.reshape(n, f, n, f).mean(axis=(1, 3))
    total = None
    for i in range(f):
        row = values[i::f, 0::f].copy()
        for j in range(1, f):
            row += values[i::f, j::f]
        total = row if total is None else total + row
    return total / (f * f)


def _block_all(mask: np.ndarray, f: int) -> np.ndarray:
    """Whether every pixel of each ``f x f`` block of the square boolean ``(f n, f n)`` ``mask`` is set:
    ``mask.reshape(n, f, n, f).all(axis=(1, 3))`` in strided ANDs (~1.1 ms -> ~0.05 ms for a 256-pixel crop's)."""
    out = mask[0::f, 0::f].copy()
    for i in range(f):
        for j in range(f):
            if i or j:
                out &= mask[i::f, j::f]
    return out


def _distance_past_frame(map_x: np.ndarray, map_y: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """How far each sample ``(map_x, map_y)`` lies past the ``(width, height)`` frame's pixel centres (0 inside):
    ``np.hypot`` of the offsets to the nearest frame pixel, the same numbers taken cheaper. ``np.hypot`` over a whole
    256-pixel crop took ~0.7 ms, and most samples lie inside the frame or past one edge only, where one offset is 0
    and the C standard's ``hypot(x, 0)`` is ``|x|`` (C99 Annex F), which ``|dx| + |dy|`` gives exactly; the hypot
    is kept for the samples past a corner (and for non-finite offsets paired with a non-zero one). A window wholly
    inside the frame, the usual tracked one, is told by the maps' extremes (NaN fails the test) and is all 0."""
    if (map_x.min() >= 0 and map_x.max() <= size[0] - 1 and map_y.min() >= 0 and map_y.max() <= size[1] - 1):
        return np.zeros(np.broadcast_shapes(map_x.shape, map_y.shape), np.result_type(map_x, map_y))
    dx = map_x - np.clip(map_x, 0, size[0] - 1)
    dy = map_y - np.clip(map_y, 0, size[1] - 1)
    beyond = np.abs(dx) + np.abs(dy)
    corner = (dx != 0) & (dy != 0)
    if corner.any():
        beyond[corner] = np.hypot(dx[corner], dy[corner])
    return beyond


def _fade_weights(beyond: np.ndarray, reach: float, f: int) -> tuple[slice, slice, np.ndarray, np.ndarray]:
    """The "fade" fill's blend, fixed per crop window (``CropMaps.fade``): the box of ``(S, S)`` model pixels
    that holds every one not wholly frame, and there the float32 weights of the remapped crop (1 inside the frame,
    falling linearly to 0 at ``reach`` crop sides past its edge; 0 past the lens model's reach; box means of the
    ``f x f`` samples, as ``apply_crop_maps`` reduces them) and of the crop's mean (the rest)."""
    w = np.clip(1.0 - beyond / reach, 0.0, 1.0) if reach > 0 else (beyond <= 0).astype(np.float64)
    w = _block_means(w, f).astype(np.float32, copy=False)
    rows, cols = np.flatnonzero((w < 1).any(axis=1)), np.flatnonzero((w < 1).any(axis=0))
    if rows.size == 0:
        rows = cols = np.zeros(1, int)
    box = slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)
    return box[0], box[1], w[box], 1.0 - w[box]


def _clamped(map_x: np.ndarray, map_y: np.ndarray, lost: np.ndarray, size: tuple[int, int]):
    """The maps with every sample the lens reaches moved onto the nearest pixel of the ``(width, height)``
    source: past the frame's edge the crop repeats that edge (the "edge" pad fill) instead of showing 0."""
    cx = np.where(lost, map_x, np.clip(map_x, 0, size[0] - 1)).astype(np.float32, copy=False)
    cy = np.where(lost, map_y, np.clip(map_y, 0, size[1] - 1)).astype(np.float32, copy=False)
    return cx, cy


def _inside(map_x: np.ndarray, map_y: np.ndarray, size: tuple[int, int], supersample: int = 1) -> np.ndarray | None:
    """Model pixels whose bilinear taps (of every one of their ``supersample x supersample`` samples) all lie
    in the ``(width, height)`` source (``None``: every one)."""
    inside = (map_x >= 0) & (map_x <= size[0] - 1) & (map_y >= 0) & (map_y <= size[1] - 1)
    if supersample > 1:
        inside = _block_all(inside, supersample)
    return None if inside.all() else inside


def apply_crop_maps(image: np.ndarray, maps: CropMaps) -> np.ndarray:
    """Undistort + crop + resize a frame: ``(H, W[, C])`` -> ``(S, S[, C])``, same dtype (a ``(H, W, 1)``
    frame gives ``(S, S, 1)``).

    Model pixels that fall outside the frame show the maps' ``pad_fill`` (0, the frame's edge, or that edge
    fading into the crop's in-frame mean: padding policy, module docstring); those whose lens mapping
    overflows (a crop far off the frame) have no edge to repeat: 0, or the mean under ``"fade"``.

    Raises:
        ShapeError: ``image`` is not of the maps' size, has other than 1 to 4 channels, or a dtype OpenCV
            cannot remap (uint8, uint16, int16, float32 and float64 are taken).
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or (image.shape[1], image.shape[0]) != maps.image_size:
        raise ShapeError(f"image must have shape ({maps.image_size[1]}, {maps.image_size[0]}[, C]) "
                         f"for these maps, got {image.shape}")
    if image.ndim == 3 and not 1 <= image.shape[2] <= 4:  # OpenCV's error named neither the image nor the count
        raise ShapeError(f"image must have 1 to 4 channels, got shape {image.shape}")
    if image.dtype not in _FRAME_DTYPES:
        raise ShapeError(f"image dtype must be one of {[np.dtype(d).name for d in _FRAME_DTYPES]}, got {image.dtype}")
    x0, y0, x1, y1 = maps.window
    src = image[y0:y1, x0:x1]
    if x1 > image.shape[1] or y1 > image.shape[0]:  # the box steps' window reaches past the frame (_aligned_span)
        src = cv2.copyMakeBorder(src, 0, y1 - y0 - src.shape[0], 0, x1 - x0 - src.shape[1], cv2.BORDER_REPLICATE)
    for _ in range(maps.level):
        src = cv2.resize(src, (src.shape[1] // 2, src.shape[0] // 2), interpolation=cv2.INTER_AREA)
    out = cv2.remap(src, maps.fixed[0], maps.fixed[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                    borderValue=0)
    if maps.supersample > 1:  # f x f box means (exact for an integer factor), as the training crops were reduced
        out = cv2.resize(out, (maps.out_size, maps.out_size), interpolation=cv2.INTER_AREA)
    if image.ndim == 3 and out.ndim == 2:  # OpenCV drops a single channel's axis: (H, W, 1) -> (S, S, 1)
        out = out[:, :, None]
    if maps.fade is not None:
        out = _faded(out, maps.fade, maps.inside)
    return out


def _faded(crop: np.ndarray, fade: tuple[slice, slice, np.ndarray, np.ndarray], inside: np.ndarray) -> np.ndarray:
    """The "fade" fill: ``crop`` (its padding the repeated frame edge) blended into its in-frame mean colour by
    the maps' weights (``CropMaps.fade``), within the box that holds the padding (a weight of 1 leaves a pixel
    exactly as it was). Numpy over that box measured ~2x faster than gathering the padded pixels by index."""
    rows, cols, w, rest = fade
    if crop.ndim == 3:
        w, rest = w[:, :, None], rest[:, :, None]
    mean = np.asarray(cv2.mean(crop, mask=inside.astype(np.uint8))[:crop.shape[2] if crop.ndim == 3 else 1])
    blend = crop[rows, cols] * w
    blend += (mean if crop.ndim == 3 else mean[0]) * rest  # (no frame pixel in the crop: a mean of 0)
    crop[rows, cols] = np.rint(blend) if np.issubdtype(crop.dtype, np.integer) else blend
    return crop


def preprocess_image(image_bgr: np.ndarray, maps: CropMaps, normalisation: Normalisation) -> np.ndarray:
    """A BGR uint8 frame -> the model's ``(3, S, S)`` float32 input.

    Steps: :func:`apply_crop_maps`; channel order per ``normalisation.channel_order``
    (``"RGB"`` flips the BGR frame); ``uint8 / 255`` scaled to ``normalisation.value_range``;
    then ``(x - mean) / std`` unless ``normalisation.mean_std_in_graph`` (the model does it).

    Args:
        image_bgr: ``(H, W, 3)`` uint8 frame, OpenCV BGR order, of the maps' image size.
        maps: from :func:`build_undistort_crop_maps`.
        normalisation: from the model contract.

    Returns:
        ``(3, S, S)`` float32, C-contiguous.
    """
    image_bgr = np.asarray(image_bgr)
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3 or image_bgr.dtype != np.uint8:
        raise ShapeError(f"image_bgr must be a uint8 (H, W, 3) BGR frame, got {image_bgr.dtype} {image_bgr.shape}")
    order = normalisation.channel_order
    if order not in ("RGB", "BGR"):
        raise GeometryError(f"normalisation.channel_order must be 'RGB' or 'BGR', got {order!r}")
    lo, hi = (float(v) for v in normalisation.value_range)
    # Fold range and mean/std into one per-channel affine map: x = a * pixel + b.
    a = np.full(3, (hi - lo) / 255.0)
    b = np.full(3, lo)
    if not normalisation.mean_std_in_graph:
        mean, std = np.asarray(normalisation.mean, float), np.asarray(normalisation.std, float)
        a, b = a / std, (b - mean) / std
    planes = cv2.split(apply_crop_maps(image_bgr, maps))  # 3 x (S, S) uint8, B G R
    if order == "RGB":
        planes = planes[::-1]
    # Per-plane multiply-add into the CHW output: ~8x faster than a strided numpy transpose.
    out = np.empty((3,) + planes[0].shape, np.float32)
    for c, plane in enumerate(planes):
        np.multiply(plane, np.float32(a[c]), out=out[c], casting="unsafe")
        out[c] += np.float32(b[c])
    return out
