"""Novel views: a virtual camera, the rays inside the subject, and the rendered image.

The virtual camera is either one *between* the two rig cameras (rotation slerped, intrinsics
interpolated linearly, the second camera's fitted to the first's image size with square pixels kept;
the centre on the line between theirs or on an orbit round the pivot :func:`novel_pivot` picks:
:func:`interpolate_camera`) or any given calibrated camera.
Like the sources, it is cropped to the subject (:func:`novel_target`) and rendered at the model
resolution (``S x S``, e.g. 128x128) -- the "reduced resolution" of the novel view -- every
``stride`` pixels. Only the rays inside the projected subject box are rendered; the rest is the
contract's background (black).

Graph use (:func:`render_novel_view`): ``volume`` with the one novel camera as target (B = 1),
then ``render_rgb`` (colour only) or ``render`` (colour and heatmaps). The encoder outputs of
the pair are reused from the keypoint path. With ``silhouette_stride`` the render graph runs
twice: a coarse pass over the box (every 4th pixel) finds the cells the subject covers, and the
fine pass renders only those, since the person fills a fraction of the box. With
``interior_stride`` the fine pass renders the subject's interior sparser (every 2nd pixel, filled
in bilinearly) and only its edge cells at full density, in the same graph run.

numpy, OpenCV; the session is passed in (never created here).
"""
from __future__ import annotations

import numbers
import time
from dataclasses import dataclass
from typing import Any, Mapping

import cv2
import numpy as np

from ghnerf_runtime.body25 import LIMBS
from ghnerf_runtime.config import NOVEL_PATHS, NovelViewConfig
from ghnerf_runtime.contract import near_far_from_box, target_inputs
from ghnerf_runtime.errors import ConfigError, DepthRangeError, GeometryError
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.orbit import axes_angle_deg, axes_pivot, in_front, orbit_centre, orbit_pivot
from ghnerf_runtime.plain_values import converts_to_finite_float, is_true_false
from ghnerf_runtime.preprocess import crop_camera, roi_from_volume
from ghnerf_runtime.rays import (
    block_ray_uv,
    box_block,
    cells_ray_uv,
    full_block,
    refine_cells,
    scatter_block,
    scatter_cells,
)
from ghnerf_runtime.tracking import box_corners

__all__ = ["AUTO_ORBIT_MIN_ANGLE_DEG", "HALF_TURN_BAND_DEG", "NovelViewRequest", "NovelView", "slerp_rotation", "novel_pivot",
           "interpolate_camera", "fit_intrinsics",
           "novel_target", "check_strides", "render_novel_view", "opaque_colour", "draw_skeleton", "skeleton_overlay",
           "heatmap_overlay"]

#: ``novel_view.path`` "auto" orbits when the cameras' optical axes are more than this many degrees apart. At 60
#: the line's halfway camera is 13 % nearer the pivot than the two ends (1 - cos 30 degrees; 29 % at 90, 50 % at
#: 120, all the way at 180), and every rig the documented novel-view figures come from is below it (the
#: simulator's default 23, ``RigPlacement.random``'s at most 45, docs/examples/rig.json 0.3), so they keep the
#: line (docs/novel-view.md, "Between the cameras: a line or an orbit").
AUTO_ORBIT_MIN_ANGLE_DEG = 60.0

#: Two cameras whose rotations are within this many degrees of a half turn apart (two upright cameras facing each
#: other across the subject, whatever their tilt) turn the view between them by :func:`slerp_rotation`'s fixed
#: rule, not the shorter way: their calibrations scatter by tenths of a degree either side of 180, and the shorter
#: way flipped with them (the view going round the subject's other side after a recalibration). The way taken is
#: at most this much longer than the other.
HALF_TURN_BAND_DEG = 1.0

#: The rig's up (y is down, gravity), forward and right: the turn's axis at a half turn points along the positive
#: end of the one it is nearest (:func:`slerp_rotation`).
_HALF_TURN_AXES = (np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))


@dataclass(frozen=True)
class NovelViewRequest:
    """What to render for one pair.

    Attributes:
        alpha: position between the rig's cameras (0 = first, 1 = second) when ``camera`` is
            ``None``.
        camera: a given virtual camera (rig frame, any size; distortion is ignored).
        overlay: ``"none"``, ``"skeleton"`` (the pair's 3D joints projected and drawn) or
            ``"heatmap"`` (rendered joint heatmaps blended in; needs ``novel_view.heatmaps``).
    """

    alpha: float = 0.5
    camera: Camera | None = None
    overlay: str = "none"

    def __post_init__(self) -> None:
        if self.camera is not None and not isinstance(self.camera, Camera):
            # caught here, not as an AttributeError deep in the estimator's worker
            raise GeometryError(f"NovelViewRequest.camera must be a Camera or None, got {type(self.camera).__name__}")
        if self.camera is None and not (isinstance(self.alpha, numbers.Real) and not isinstance(self.alpha, bool)):
            # np.isfinite raised a bare TypeError for None or "0.5"; True passed as 1
            raise GeometryError(f"NovelViewRequest.alpha must be a number in [-1, 2], got {self.alpha!r}")
        if self.camera is None and not (np.isfinite(self.alpha) and -1.0 <= self.alpha <= 2.0):
            raise GeometryError(f"NovelViewRequest.alpha must be in [-1, 2], got {self.alpha!r}")
        if self.overlay not in ("none", "skeleton", "heatmap"):
            raise GeometryError(f"NovelViewRequest.overlay must be 'none', 'skeleton' or 'heatmap', "
                                f"got {self.overlay!r}")


@dataclass(frozen=True, eq=False)
class NovelView:
    """A rendered novel view.

    Attributes:
        image: ``(S, S, 3)`` uint8 BGR (with the overlay, if requested).
        camera: the pinhole camera of ``image`` (rig frame).
        depth: ``(S / stride, S / stride)`` float32 rendered depth (0 outside the rendered rays).
        heat: ``(S, S)`` float32 max over joints of the rendered heatmaps, in [0, 1], or ``None``.
        rays: number of rays rendered.
    """

    image: np.ndarray
    camera: Camera
    depth: np.ndarray
    heat: np.ndarray | None
    rays: int


# ------------------------------------------------------------------ cameras
def _quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=np.float64)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = np.zeros(4)
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    q = np.asarray(q, dtype=np.float64)
    return q / np.linalg.norm(q)


def _matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _half_turn_sign(qa: np.ndarray, qb: np.ndarray) -> float:
    """+1 or -1: the sign of ``qb`` that makes the slerp from ``qa`` turn the camera right-handed about the rig axis
    nearest the turn's axis (``_HALF_TURN_AXES``: up, then forward, then right, on a tie)."""
    mid = _matrix(qa + qb)  # halfway along the slerp from qa to qb (dot >= 0 or not: no sign flip here)
    M = mid.T @ _matrix(qa)  # the camera's turn in the rig frame, from its rotation at qa to the halfway one
    axis = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])  # 2 sin(angle) times the axis
    along = [float(np.dot(axis, ref)) for ref in _HALF_TURN_AXES]
    return 1.0 if along[int(np.argmax(np.abs(along)))] >= 0.0 else -1.0


def _true_false(alpha: object) -> bool:
    """Whether ``alpha`` is True/False, or a 0-d array of one: ``math.isfinite`` reads them as 1.0 or 0.0 (session
    73 to 74), which ``estimate``'s capture time refuses too; two isinstance checks for a float."""
    return is_true_false(alpha) or (isinstance(alpha, np.ndarray) and alpha.dtype.kind == "b")


def slerp_rotation(R_a: np.ndarray, R_b: np.ndarray, alpha: float) -> np.ndarray:
    """Spherical linear interpolation of two rotation matrices (rig -> camera; shortest arc).

    Two rotations within :data:`HALF_TURN_BAND_DEG` of a half turn apart have two arcs of nearly one length; the
    shorter flips with a calibration's last digits, so there the camera turns right-handed about whichever of the
    rig's up (-y), forward (+z) and right (+x) is nearest the turn's axis: for two upright cameras facing each
    other, counterclockwise seen from above (the view leaves the first camera to its right).

    Raises:
        GeometryError: ``alpha`` is not a finite number (True/False is none: it was read as 1 or 0).

    Example:
        >>> from ghnerf_runtime.geometry import look_at
        >>> Ra, _ = look_at((-1, 0, 0), (0, 0, 3)); Rb, _ = look_at((1, 0, 0), (0, 0, 3))
        >>> R = slerp_rotation(Ra, Rb, 0.5)
        >>> np.round(R @ R.T, 9).tolist() == np.eye(3).tolist(), np.round(R[2], 6).tolist()
        (True, [0.0, 0.0, 1.0])
        >>> Ra, _ = look_at((-3, 0, 3), (0, 0, 3)); Rb, _ = look_at((3, 0, 3), (0, 0, 3))  # facing each other
        >>> np.round(slerp_rotation(Ra, Rb, 0.5)[2], 6).tolist()  # halfway: looking forward (+z), from z < 3
        [0.0, 0.0, 1.0]
    """
    if _true_false(alpha) or not converts_to_finite_float(alpha):  # a NaN gave a NaN rotation without a word
        raise GeometryError(f"slerp_rotation: alpha must be a finite number, got {alpha!r}")
    qa, qb = _quat(R_a), _quat(R_b)
    dot = float(np.dot(qa, qb))
    if abs(dot) < np.sin(np.radians(HALF_TURN_BAND_DEG) / 2.0):  # |dot| is the cosine of half the turn
        sign = _half_turn_sign(qa, qb)
        qb, dot = sign * qb, sign * dot
    elif dot < 0:
        qb, dot = -qb, -dot
    if dot > 0.9995:  # nearly equal: linear interpolation is exact enough and stable
        q = qa + alpha * (qb - qa)
    else:
        theta = np.arccos(np.clip(dot, -1.0, 1.0))
        q = (np.sin((1 - alpha) * theta) * qa + np.sin(alpha * theta) * qb) / np.sin(theta)
    return _matrix(q)


def novel_pivot(cam_a: Camera, cam_b: Camera, path: str, subject: np.ndarray | None = None) -> np.ndarray | None:
    """The point a camera between ``cam_a`` and ``cam_b`` orbits under ``novel_view.path``, or ``None`` for the line.

    ``"line"``: ``None``. ``"auto"``: ``None`` unless the optical axes are more than
    :data:`AUTO_ORBIT_MIN_ANGLE_DEG` apart, then as ``"orbit"``: given ``subject`` (the subject's centre, rig
    frame), the point nearest both optical axes and, along the direction they fix badly, nearest the subject
    (:func:`~ghnerf_runtime.geometry.orbit.subject_pivot`: on the subject for axes near antiparallel, where
    the axes' nearest point runs metres along them for an axis a centimetre off), moved onto the subject when it
    is not at it (:func:`~ghnerf_runtime.geometry.orbit.orbit_pivot`: over 0.5 m from it, wholly from 1 m, as
    for cameras side by side toed in past 60 degrees, whose axes cross in front of the subject); without it, the
    axes' nearest point (:func:`~ghnerf_runtime.geometry.orbit.axes_pivot`; none for parallel axes). When that
    point is behind either camera, ``subject``; when that is missing or behind one too, ``None`` (the line: no
    orbit has the subject in front of both ends).

    Raises:
        ConfigError: ``path`` is not one of ``"line"``, ``"orbit"``, ``"auto"`` (named as ``novel_view.path``).
    """
    if path not in NOVEL_PATHS:
        raise ConfigError(f"must be one of {list(NOVEL_PATHS)}, got {path!r}", key="novel_view.path")
    if path == "line" or (path == "auto" and not axes_angle_deg(cam_a, cam_b) > AUTO_ORBIT_MIN_ANGLE_DEG):
        return None
    axes = axes_pivot(cam_a, cam_b) if subject is None else orbit_pivot(cam_a, cam_b, subject)
    for point in (axes, subject):
        if point is not None and in_front(cam_a, point) and in_front(cam_b, point):
            return np.array(point, dtype=np.float64)
    return None


def interpolate_camera(cam_a: Camera, cam_b: Camera, alpha: float, name: str = "novel", *,
                       pivot: np.ndarray | None = None) -> Camera:
    """A pinhole camera between two cameras: slerped rotation, lerped intrinsics, the centre on the line between
    theirs or, with ``pivot``, on the orbit round it.

    The image size is ``cam_a``'s; ``cam_b``'s intrinsics are first fitted into it by one uniform scale
    (:func:`fit_intrinsics`: its pixels stay square when the two images' shapes differ, e.g. one camera
    mounted on its side). Lens distortion is dropped (a virtual camera is ideal). ``alpha`` outside [0, 1]
    extrapolates. ``pivot`` (rig frame, in front of both cameras; :func:`novel_pivot` picks it): the camera is
    as far from it as the lerp of the two cameras' distances and sees it where their views of it lerp
    (:func:`~ghnerf_runtime.geometry.orbit.orbit_centre`), so it does not cut through a subject the two face
    across; ``None``: the centre is lerped (the straight line).

    Raises:
        GeometryError: the extrapolated focal length (or distance to ``pivot``) is not positive (``alpha`` too
            far out for two cameras whose focal lengths, or distances to it, differ more than twofold), or
            ``pivot`` is behind a camera.
    """
    K_b = cam_b.K if cam_b.size == cam_a.size else fit_intrinsics(cam_b, cam_a.width, cam_a.height)
    R = slerp_rotation(cam_a.R, cam_b.R, alpha)
    if pivot is None:
        centre = (1 - alpha) * cam_a.center + alpha * cam_b.center
    else:
        centre = orbit_centre(cam_a, cam_b, R, alpha, pivot)
    K = (1 - alpha) * cam_a.K + alpha * K_b
    K[2] = [0.0, 0.0, 1.0]
    K[1, 0] = 0.0
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise GeometryError(f"novel-view alpha {alpha} (--novel-alpha, NovelViewRequest.alpha) extrapolates the "
                            f"focal lengths of cameras {cam_a.name!r} and {cam_b.name!r} to fx {K[0, 0]:.1f}, "
                            f"fy {K[1, 1]:.1f} px; keep it nearer [0, 1]")
    return Camera(name, cam_a.width, cam_a.height, K, np.zeros(5), R, -R @ centre)


def fit_intrinsics(camera: Camera, width: int, height: int) -> np.ndarray:
    """``camera``'s K for a ``width x height`` image: scaled by one factor so the whole image fits, centred.

    Unlike :meth:`Camera.resized` (a factor per axis), pixels keep their aspect: a 480x640 camera fitted to
    640x480 is scaled by 0.75 and shows its view in the middle 360 columns, not squeezed. Centres follow the
    pixel-centre convention of :meth:`Camera.resized`: ``u' = s (u - (W_b - 1) / 2) + (W - 1) / 2``; for
    images of one shape this is :meth:`Camera.resized`'s K.
    """
    s = min(width / camera.width, height / camera.height)
    centre_b = np.array([(camera.width - 1) / 2, (camera.height - 1) / 2])
    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    A = np.eye(3)
    A[:2, :2] *= s
    A[:2, 2] = centre - s * centre_b
    return A @ camera.K


def novel_target(camera: Camera, box: np.ndarray, size: int, crop_to_subject: bool = True) -> Camera:
    """The ``size x size`` pinhole camera the novel view is rendered with.

    ``crop_to_subject``: the square crop of ``camera``'s image showing the box (as the sources
    are cropped); otherwise the whole image resized (non-square pixels if the image is not square).
    """
    cam = camera.without_distortion() if camera.has_distortion else camera
    if crop_to_subject:
        try:
            return crop_camera(cam, roi_from_volume(cam, box_corners(box)), size)  # keeps the name
        except GeometryError:
            pass  # the box is not in view: show the whole image (it will be background)
    return cam.resized(size, size)


# ------------------------------------------------------------------ rendering
def check_strides(config: NovelViewConfig, size: int) -> None:
    """Raise :class:`ConfigError` naming the field unless every stride in use divides the model's ``size``.

    The grids of the passes are scattered into one another and resized back to ``size``; a grid that does not
    tile the image (``silhouette_stride`` 6 at 128: 21 cells refined to 126 pixels) fails mid-render.
    """
    for name in ("stride", "silhouette_stride", "interior_stride"):
        value = getattr(config, name)
        if value and size % value:
            raise ConfigError(f"must divide the model resolution {size}, got {value}", key=f"novel_view.{name}")


def _near_far_in_view(camera: Camera, box: np.ndarray, margin: float) -> np.ndarray | None:
    """The near/far of the subject box for ``camera``, or None when the box is wholly behind it (a requested
    camera facing away). A non-finite box is an error, not an empty view, and so is one farther from the camera
    than float32 resolves (:class:`DepthRangeError`: its near/far overflowed to inf at 1e200 m)."""
    if not np.isfinite(box).all():
        raise GeometryError(f"novel view: the subject box is not finite: {np.asarray(box).tolist()}")
    try:
        return near_far_from_box(camera, box_corners(box), margin)
    except DepthRangeError:
        raise
    except GeometryError:  # finite and within reach, so: behind the near plane
        return None


def render_novel_view(session: Any, env: Mapping[str, np.ndarray], camera: Camera, box: np.ndarray,
                      config: NovelViewConfig, *, near_far_margin: float = 0.1, want_heat: bool = False,
                      timing: dict | None = None) -> NovelView:
    """Render the novel view at ``camera`` (already the ``S x S`` target, :func:`novel_target`).

    Args:
        session: a :class:`~ghnerf_runtime.session.ModelSession` with ``volume`` and ``render_rgb``
            (or ``render`` when heatmaps are wanted) loaded.
        env: the pair's encoder outputs and source inputs (``images``, ``feat_*``, ``src_P``,
            ``src_centers``).
        camera: the target camera at the contract resolution.
        box: ``(2, 3)`` subject box (near/far and the rendered rays).
        config: stride, rays in the box only.
        want_heat: render heatmaps too (``render`` graph).
        timing: if given, ``novel_volume`` / ``novel_render`` / ``novel_compose`` ms are added.
    """
    contract = session.contract
    S = contract.height
    check_strides(config, S)
    t0 = time.perf_counter()
    feeds = dict(env)
    feeds.update(target_inputs([camera], S, contract.width))
    near_far = _near_far_in_view(camera, box, near_far_margin)
    if near_far is not None:
        feeds["near_far"] = near_far[None]
        feeds.update(session.run("volume", feeds))
    t1 = time.perf_counter()
    stride = config.stride
    gh, gw = S // stride, contract.width // stride
    if near_far is None:  # the subject is behind this camera: no ray of it, whatever rays_in_box_only says
        block = None
    else:
        block = box_block(camera, box, stride, margin_cells=1) if config.rays_in_box_only else full_block(gh, gw)
    graph = "render" if want_heat else "render_rgb"
    cells, sparse, rays = None, None, 0
    if block is not None:
        cells = np.zeros((gh, gw), bool)
        cells[block[0]:block[0] + block[2], block[1]:block[1] + block[3]] = True
        in_box = cells.copy()
        if config.coarse_pass:
            silhouette, rays = _silhouette_cells(session, graph, feeds, camera, box, config)
            sparse = _split_interior(silhouette, config) if config.interior_pass else None
            if sparse is not None:
                silhouette = silhouette & ~sparse.interior
            cells &= refine_cells(silhouette, config.silhouette_stride // stride)
    edge = cells if cells is not None and cells.any() else None
    groups = [(edge, stride)] if edge is not None else []
    if sparse is not None:
        groups.append((sparse.rays, config.interior_stride))
    if not groups:  # the subject is not in view: nothing to render
        rgb = np.full((gh, gw, 3), contract.background, np.float32)
        depth = np.zeros((gh, gw), np.float32)
        heat = np.zeros((gh, gw), np.float32) if want_heat else None
    else:
        # One graph run for the edge rays and the interior's sparse rays together.
        feeds["ray_uv"] = np.concatenate([cells_ray_uv(m, s) for m, s in groups])[None]
        out = session.run(graph, feeds)
        colour = opaque_colour(out["rgb"][0], out["acc"][0], contract.background, config.opaque_at)
        # A failed ray (NaN, inf) is made the fill here, before the bilinear upsampling and interior filling
        # below: there a NaN spread to every pixel the ray reaches (a 4x4 hole of heat at stride 2).
        channels = {"rgb": (_finite(colour, contract.background), contract.background),
                    "depth": (_finite(out["depth"][0], 0.0), 0.0)}
        if want_heat:
            # sigmoid responses lie in [0, 1], as the colour does (clipped below): a graph that answers past them
            # (1e30) gave NovelView.heat past them too, where the keypoint path clips the same values
            channels["heat"] = (np.clip(_finite(out["heatmaps"][0], 0.0), 0.0, 1.0).max(axis=-1), 0.0)
        n_edge = 0 if edge is None else int(edge.sum())
        inside = None if sparse is None else \
            refine_cells(sparse.interior, config.silhouette_stride // stride) & in_box
        images = {}
        for key, (values, fill) in channels.items():
            image = scatter_cells(values[:n_edge], edge, fill) if edge is not None else \
                np.full((gh, gw) + values.shape[1:], fill, np.float32)
            if sparse is not None:
                coarse = scatter_cells(values[n_edge:], sparse.rays, fill)
                filled = cv2.resize(coarse, (gw, gh), interpolation=cv2.INTER_LINEAR)
                image[inside] = filled[inside]
            images[key] = image
        rgb, depth, heat = images["rgb"], images["depth"], images.get("heat")
        rays += sum(int(m.sum()) for m, _ in groups)
    t2 = time.perf_counter()
    rgb = np.clip(rgb, 0.0, 1.0)  # finite: a failed ray was made the background above (nothing, not black)
    if stride > 1:
        rgb = cv2.resize(rgb, (contract.width, S), interpolation=cv2.INTER_LINEAR)
        if heat is not None:
            heat = cv2.resize(heat, (contract.width, S), interpolation=cv2.INTER_LINEAR)
    image = np.ascontiguousarray((rgb[..., ::-1] * 255.0 + 0.5).astype(np.uint8))  # RGB -> BGR
    if timing is not None:
        timing["novel_volume"] = 1e3 * (t1 - t0)
        timing["novel_render"] = 1e3 * (t2 - t1)
        timing["novel_compose"] = 1e3 * (time.perf_counter() - t2)
    return NovelView(image, camera, depth.astype(np.float32), None if heat is None else heat.astype(np.float32), rays)


def _finite(values: np.ndarray, fill: float) -> np.ndarray:
    """``values`` with NaN and +-inf replaced by ``fill`` (what a ray that rendered nothing shows)."""
    return np.nan_to_num(values, nan=fill, posinf=fill, neginf=fill)


def opaque_colour(rgb: np.ndarray, acc: np.ndarray, background: float, opaque_at: float) -> np.ndarray:
    """Rays' colour with the opacity rescaled so that ``opaque_at`` counts as opaque.

    ``rgb`` ``(R, 3)`` is the composite over ``background`` with accumulated opacity ``acc``
    ``(R,)``. The foreground ``rgb - (1 - acc) * background`` divided by ``acc`` is the colour the
    ray hit; it is shown with opacity ``min(acc / opaque_at, 1)``. ``opaque_at`` 1 returns ``rgb``.
    """
    if opaque_at >= 1.0:
        return rgb
    acc = np.clip(np.nan_to_num(acc, nan=0.0), 0.0, 1.0)[:, None]
    fg = rgb - (1.0 - acc) * background
    shown = np.minimum(acc / opaque_at, 1.0)
    return fg / np.maximum(acc, opaque_at) + (1.0 - shown) * background


@dataclass(frozen=True)
class _Interior:
    """The silhouette's interior (coarse grid) and the sparse cells rendered to fill it in."""

    interior: np.ndarray
    rays: np.ndarray


def _split_interior(silhouette: np.ndarray, config: NovelViewConfig) -> _Interior | None:
    """Interior coarse cells (all eight neighbours are the subject; the image border counts as outside)
    and the ``interior_stride`` cells that bilinear filling of them reads: those of the interior and
    its one-cell ring, which lies inside the silhouette by construction. ``None`` when there is no
    interior (a small or thin subject): every subject cell is then an edge cell.
    """
    m = silhouette.astype(np.uint8)
    kernel = np.ones((3, 3), np.uint8)
    interior = cv2.erode(m, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
    if not interior.any():
        return None
    ring = cv2.dilate(interior.astype(np.uint8), kernel).astype(bool)
    return _Interior(interior, refine_cells(ring, config.silhouette_stride // config.interior_stride))


def _silhouette_cells(session: Any, graph: str, feeds: dict, camera: Camera, box: np.ndarray,
                      config: NovelViewConfig) -> tuple[np.ndarray, int]:
    """The coarse pass: cells of the ``silhouette_stride`` grid whose colour is not the background (dilated).

    The test is on the composited colour, not the opacity: a ray whose colour is the background's
    adds nothing to the picture however opaque the model made it (the shipped model fills its box
    with opaque black, docs/runtime.md), and a cell left out is drawn as background, so what is
    lost is bounded by ``silhouette_min_diff`` at the coarse rays.

    Returns the ``(S / cs, S / cs)`` mask and the number of coarse rays rendered.
    """
    cs = config.silhouette_stride
    S, W = session.contract.height, session.contract.width
    mask = np.zeros((S // cs, W // cs), bool)
    block = box_block(camera, box, cs, margin_cells=1) if config.rays_in_box_only else full_block(*mask.shape)
    if block is None:
        return mask, 0
    coarse = dict(feeds, ray_uv=block_ray_uv(block, cs)[None])
    rgb = np.nan_to_num(session.run(graph, coarse)["rgb"][0])
    diff = np.abs(rgb - session.contract.background).max(axis=-1)
    mask = scatter_block(diff, block, *mask.shape, 0.0) >= config.silhouette_min_diff
    if config.silhouette_dilate and mask.any():
        k = 2 * config.silhouette_dilate + 1
        mask = cv2.dilate(mask.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool)
    return mask, block[2] * block[3]


# ------------------------------------------------------------------ overlays
def draw_skeleton(image: np.ndarray, uv: np.ndarray, valid: np.ndarray, *, color=(0, 255, 0),
                  joint_color=(0, 0, 255), thickness: int = 1) -> np.ndarray:
    """Draw BODY_25 limbs between valid joints ``(J, 2)`` (pixels) on a copy of a BGR image.

    Joints are drawn inside a window three times the image's size around it (``(-w, 2w) x (-h, 2h)``, so
    that the integers OpenCV draws with stay small); a limb to a joint beyond it is cut at the window's
    edge, not left out (a close view whose hand lies far off the picture still shows the forearm).
    """
    out = np.array(image, copy=True)
    pts = np.asarray(uv, dtype=np.float64)
    ok = np.asarray(valid, bool) & np.all(np.isfinite(pts), axis=-1)
    h, w = out.shape[:2]
    window = (-w, 2 * w, -h, 2 * h)
    near = ok & (pts[:, 0] > -w) & (pts[:, 0] < 2 * w) & (pts[:, 1] > -h) & (pts[:, 1] < 2 * h)
    p = np.rint(np.where(near[:, None], pts, 0)).astype(int)
    for a, b in LIMBS:
        if near[a] and near[b]:
            ends = (p[a], p[b])
        elif ok[a] and ok[b]:
            ends = _clip_segment(pts[a], pts[b], window)
            if ends is None:
                continue
        else:
            continue
        cv2.line(out, tuple(int(v) for v in ends[0]), tuple(int(v) for v in ends[1]), color, thickness, cv2.LINE_AA)
    for j in np.flatnonzero(near):
        cv2.circle(out, tuple(int(v) for v in p[j]), max(1, thickness + 1), joint_color, -1, cv2.LINE_AA)
    return out


def _clip_segment(a: np.ndarray, b: np.ndarray, window: tuple[float, float, float, float]
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """The part of the segment ``a``-``b`` (pixels) inside ``window`` ``(x0, x1, y0, y1)``, rounded to whole
    pixels, or ``None``. In float64 before any integer is made: a joint just in front of the camera plane
    projects to 1e12 px and more. Each cut point is measured from the segment's nearer end (a cut next to
    ``b`` reckoned as ``a + t d`` with ``t`` near 1 would lose ``b``'s digits to ``a``'s size)."""
    d = b - a
    if not np.all(np.isfinite(d)):
        return None
    t0, t1 = _liang_barsky(a, d, window)
    if not t0 < t1:
        return None
    s0, s1 = _liang_barsky(b, -d, window)  # the same cut from b's end: s0 = 1 - t1, s1 = 1 - t0
    start = a + t0 * d if t0 <= 0.5 else b - s1 * d
    end = a + t1 * d if t1 <= 0.5 else b - s0 * d
    return np.rint(start).astype(int), np.rint(end).astype(int)


def _liang_barsky(a: np.ndarray, d: np.ndarray, window: tuple[float, float, float, float]) -> tuple[float, float]:
    """Parameters ``(t0, t1)`` of the part of ``a + t d``, ``0 <= t <= 1``, inside ``window``; empty when
    ``t0 >= t1`` (Liang-Barsky)."""
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], a[0] - window[0]), (d[0], window[1] - a[0]), (-d[1], a[1] - window[2]),
                 (d[1], window[3] - a[1])):
        if p == 0.0:  # parallel to this edge: wholly inside or wholly outside it
            if q < 0.0:
                return 1.0, 0.0
        elif p < 0.0:
            t0 = max(t0, q / p)
        else:
            t1 = min(t1, q / p)
    return t0, t1


def skeleton_overlay(image: np.ndarray, camera: Camera, points: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The valid rig-frame joints ``(J, 3)`` projected into pinhole ``camera`` and drawn (:func:`draw_skeleton`).

    Joints no pixel shows (behind or on the camera plane: ``Camera.project`` gives them NaN) are left out,
    never drawn at a placeholder pixel."""
    uv, depth = camera.project(points, distort=False)
    return draw_skeleton(image, uv, np.asarray(valid, bool) & (depth > 0))


def heatmap_overlay(image: np.ndarray, heat: np.ndarray, weight: float = 0.5) -> np.ndarray:
    """Blend a ``(H, W)`` heatmap in [0, 1] (JET colours) over a BGR image of the same size.

    Raises:
        ValueError: ``weight`` is not within [0, 1] (outside it the blend leaves 0..255 and wraps round in uint8).
    """
    if not 0.0 <= weight <= 1.0:  # False for NaN too
        raise ValueError(f"heatmap_overlay: weight must be within [0, 1], got {weight!r}")
    heat = np.clip(np.nan_to_num(np.asarray(heat, np.float32)), 0.0, 1.0)
    if heat.shape != image.shape[:2]:
        heat = cv2.resize(heat, (image.shape[1], image.shape[0]), interpolation=cv2.INTER_LINEAR)
    colour = cv2.applyColorMap((heat * 255).astype(np.uint8), cv2.COLORMAP_JET)
    alpha = (weight * heat)[..., None]
    return np.round(image * (1 - alpha) + colour * alpha).astype(np.uint8)  # rounded: truncation darkened it
