"""The novel view's fog matted out: background wherever the body proxy says no person can be.

The model leaves coloured haze around the subject: floor and wall colours the sources show behind
the person, rendered at depths where nothing is. Masked PSNR does not see it; anyone
looking at the picture does. The body proxy of the pair's 3D joints (``ghnerf_runtime.body_proxy``)
says where the person is to a few centimetres, so every pixel further than ``margin_m`` from the
proxy's silhouette fades to the background over ``feather_m`` (metres at the proxy's median depth,
so the matte scales with the subject's size in the view, not with the resolution).

What it costs: subject pixels the proxy misses by more than the margin (loose clothes, hair, a
wrong joint) fade too. A joint that was not found leaves its part out of the proxy (no ears, no
head), so the matte also keeps a sphere around the nearest found joint up its chain, as large as an
average adult's part hanging below it can reach (:func:`reach_spheres`). Where the proxy and the
picture disagree (less than ``min_support`` of the proxy's pixels show the subject in the picture,
as when the joints are wrong) nothing is matted, nor without the neck and the mid-hip.
Measured in docs/novel-view.md, "Matting out the fog".

numpy, OpenCV.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ghnerf_runtime.body25 import JOINT_INDEX, JOINT_NAMES, LIMBS, NUM_JOINTS
from ghnerf_runtime.errors import ShapeError
from ghnerf_runtime.geometry.camera import Camera

__all__ = ["ProxyMatte", "proxy_matte", "reach_spheres"]

#: Each joint's parent in the BODY_25 tree (rooted at the neck).
PARENT: dict[int, int] = {child: parent for parent, child in LIMBS}
#: Bone lengths from each joint's parent, metres, a generous average adult (rounded up).
BONE_M: dict[str, float] = {
    "Nose": 0.25, "REye": 0.05, "LEye": 0.05, "REar": 0.10, "LEar": 0.10,
    "RShoulder": 0.20, "LShoulder": 0.20, "RElbow": 0.32, "LElbow": 0.32, "RWrist": 0.29, "LWrist": 0.29,
    "MidHip": 0.55, "RHip": 0.12, "LHip": 0.12, "RKnee": 0.46, "LKnee": 0.46, "RAnkle": 0.45, "LAnkle": 0.45,
    "RHeel": 0.09, "LHeel": 0.09, "RBigToe": 0.18, "LBigToe": 0.18, "RSmallToe": 0.06, "LSmallToe": 0.06,
}
#: What hangs beyond a joint that has no child joint (a hand, a toe, the head round an ear or eye), metres.
LEAF_M: dict[str, float] = {"RWrist": 0.22, "LWrist": 0.22, "REar": 0.14, "LEar": 0.14, "REye": 0.14,
                            "LEye": 0.14, "RHeel": 0.06, "LHeel": 0.06, "RSmallToe": 0.06, "LSmallToe": 0.06,
                            "RBigToe": 0.06, "LBigToe": 0.06}
#: Girth added to every reach (a limb's radius and loose clothes), metres.
REACH_GIRTH_M = 0.12


def _extent_below(j: int) -> float:
    """How far (metres) the body reaches beyond joint ``j`` through its children."""
    children = [c for p, c in LIMBS if p == j]
    own = LEAF_M.get(JOINT_NAMES[j], 0.0)
    return max([own] + [BONE_M[JOINT_NAMES[c]] + _extent_below(c) for c in children])


#: Per joint: the body's reach beyond it (its subtree and the leaf beyond).
EXTENT_M: tuple[float, ...] = tuple(_extent_below(j) for j in range(NUM_JOINTS))


def reach_spheres(joints: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the parts of missing joints can be: for each joint not found (whose parent chain has a found
    joint), a sphere at the nearest found ancestor, of radius the bones down to the missing joint plus
    what hangs below it plus :data:`REACH_GIRTH_M`. ``(K, 3)`` centres and ``(K,)`` radii (metres)."""
    j = np.asarray(joints, np.float64)
    ok = np.asarray(valid, bool) & np.isfinite(j).all(axis=-1)
    centres, radii = [], []
    for k in np.flatnonzero(~ok):
        reach, a = EXTENT_M[k], k
        while a in PARENT and not ok[a]:
            reach += BONE_M[JOINT_NAMES[a]]
            a = PARENT[a]
        if ok[a]:
            centres.append(j[a])
            radii.append(reach + REACH_GIRTH_M)
    return np.asarray(centres, np.float64).reshape(-1, 3), np.asarray(radii, np.float64)


def _discs(shape: tuple[int, int], camera: Camera, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``shape`` (the camera's ``(H, W)``) bool: the pixels whose ray meets one of the spheres (rig-frame
    centres, radii in metres).

    Exact per pixel, not a disc of radius ``f r / z``: a near sphere's outline is much larger (``f r /
    sqrt(z^2 - r^2)`` on the axis) and an off-axis one's an ellipse. A unit ray ``v`` meets the sphere
    round ``c`` (camera frame) where ``v . c >= sqrt(|c|^2 - r^2)``: all of the view for a sphere round
    the camera, none for one wholly behind it. Pixels past a lens model's reach (NaN rays) meet nothing.
    """
    out = np.zeros(shape, bool)
    if not len(centres):
        return out
    c = camera.to_camera(centres)
    tangent2 = np.sum(c * c, axis=-1) - np.asarray(radii, np.float64) ** 2  # squared tangent length
    if np.any(tangent2 <= 0):  # the camera is inside a sphere: every ray meets it
        out[:] = True
        return out
    # each pixel's ray d = (x, y, 1) at its centre (integer coordinates, as the proxy's depth)
    if camera.has_distortion:  # through the lens model: NaN past its reach, which meets nothing
        xy = camera.pixels_to_normalized(camera.pixel_grid())
        x, y = xy[..., 0], xy[..., 1]
    else:  # K^-1 (u, v, 1), from a row and a column (a few hundred microseconds at 256^2)
        kinv = np.linalg.inv(camera.K)
        u, v = np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64)[:, None]
        x, y = kinv[0, 0] * u + (kinv[0, 1] * v + kinv[0, 2]), kinv[1, 1] * v + kinv[1, 2]
    norm2 = x * x + (y * y + 1.0)
    with np.errstate(invalid="ignore"):  # NaN rays compare False
        for ck, tk in zip(c, tangent2):
            dot = ck[0] * x + (ck[1] * y + ck[2])  # d . c >= sqrt(tangent2) |d|, squared
            out |= (dot >= 0) & (dot * dot >= tk * norm2)
    return out


@dataclass(frozen=True, eq=False)
class ProxyMatte:
    """The matted view.

    Attributes:
        image: ``(H, W, 3)`` uint8 BGR.
        weight: ``(H, W)`` float32 in [0, 1], how much of the picture each pixel kept (all ones when
            nothing was matted).
        applied: whether the matte ran (the proxy covers the view and the picture agrees with it).
    """

    image: np.ndarray
    weight: np.ndarray
    applied: bool


def proxy_matte(image_bgr: np.ndarray, camera: Camera, depth: np.ndarray, region: np.ndarray,
                background: float, margin_m: float = 0.08, feather_m: float = 0.15,
                min_support: float = 0.5, joints: np.ndarray | None = None,
                valid: np.ndarray | None = None) -> ProxyMatte:
    """Fade ``image_bgr`` to ``background`` away from the proxy's silhouette (module docstring).

    Args:
        image_bgr: ``(H, W, 3)`` uint8, the view at pinhole ``camera``.
        depth: ``(H, W)`` the proxy's camera-z depth in the view (``proxy_depth(body, camera)``; 0
            where it covers nothing).
        region: ``(H, W)`` bool, where the picture shows the subject
            (``proxy_blend.subject_region``).
        background: the model's background value in [0, 1] (finite; past it, black or white).
        margin_m: pixels within this distance of the silhouette keep the picture (metres).
        feather_m: beyond the margin the picture fades linearly to the background over this
            distance (metres; 0: a hard edge).
        min_support: the share of the proxy's pixels the picture must show as the subject for the
            matte to run, in [0, 1].
        joints, valid: the ``(25, 3)`` joints the proxy was built from and which were found: the parts
            of missing ones are kept within their reach (:func:`reach_spheres`), and without the neck or
            the mid-hip nothing is matted. Default: every part is in the proxy.
    """
    image = np.asarray(image_bgr)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ShapeError(f"image must be uint8 (H, W, 3), got {image.dtype} {image.shape}")
    if image.shape[:2] != (camera.height, camera.width):
        raise ShapeError(f"image {image.shape[:2]} does not match its camera {(camera.height, camera.width)}")
    depth, region = np.asarray(depth), np.asarray(region, bool)
    for name, plane in (("depth", depth), ("region", region)):
        if plane.shape != image.shape[:2]:
            raise ShapeError(f"{name} must be {image.shape[:2]}, got {plane.shape}")
    if not (np.isfinite(margin_m) and margin_m >= 0 and np.isfinite(feather_m) and feather_m >= 0):
        raise ValueError(f"margin_m and feather_m must be finite and >= 0, got {margin_m!r}, {feather_m!r}")
    if not 0.0 <= min_support <= 1.0:  # NaN too: it failed every support test, so the matte always ran
        raise ValueError(f"min_support must be within [0, 1], got {min_support!r}")
    if not np.isfinite(background):
        raise ValueError(f"background must be finite, got {background!r}")
    covered = np.isfinite(depth) & (depth > 0)
    keep_all = np.ones(image.shape[:2], np.float32)
    if not covered.any() or region[covered].mean() < min_support:
        return ProxyMatte(image, keep_all, False)
    if joints is not None:
        found = np.ones(NUM_JOINTS, bool) if valid is None else np.asarray(valid, bool)
        found = found & np.isfinite(np.asarray(joints, np.float64)).all(axis=-1)
        if not found[[JOINT_INDEX["Neck"], JOINT_INDEX["MidHip"]]].all():
            return ProxyMatte(image, keep_all, False)
        kept = covered | _discs(covered.shape, camera, *reach_spheres(joints, found))
    else:
        kept = covered
    # Distances in metres at the proxy's median depth, not the margins in pixels: pixels per metre is
    # f / depth, which overflowed to inf for a denormal depth (1e-308), and inf / inf made the weight NaN.
    # A tiny depth now gives metres per pixel of 0: every pixel within the margin, nothing matted.
    m_per_px = float(np.median(depth[covered])) / (float(np.sqrt(camera.K[0, 0])) * float(np.sqrt(camera.K[1, 1])))
    m_per_px = min(m_per_px, float(np.finfo(np.float64).max))  # a huge depth over a tiny focal length: not inf
    distance = cv2.distanceTransform((~kept).astype(np.uint8), cv2.DIST_L2, 5)  # px to the silhouette
    with np.errstate(over="ignore"):  # a huge m_per_px: inf metres, beyond any feather (weight 0)
        beyond_m = distance.astype(np.float64) * m_per_px - margin_m  # 0 px stays 0 m: never 0 * inf
    weight = (beyond_m <= 0).astype(np.float32) if feather_m <= 0 else \
        np.clip(1.0 - beyond_m / feather_m, 0.0, 1.0).astype(np.float32)
    if weight.min() >= 1.0:
        return ProxyMatte(image, weight, True)
    bg = np.float32(background * 255.0)
    out = bg + weight[..., None] * (image.astype(np.float32) - bg)
    # clipped: a contract's background past [0, 1] (only its finiteness is checked) wrapped round in uint8,
    # where the rendered view clips it (novel_view)
    return ProxyMatte(np.round(np.clip(out, 0.0, 255.0)).astype(np.uint8), weight, True)
