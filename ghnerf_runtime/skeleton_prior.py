"""The learnt skeleton prior: a small network that turns the two views' 2D joints into a whole 3D skeleton.

Triangulation alone trusts each joint's two 2D peaks: a joint hidden in one view is missing, and a
joint both views place wrongly alike (or along the epipolar line) lands wrongly in depth. The prior
(``skeleton_prior.onnx`` beside the model's graphs, trained by ``python -m training.skeleton_prior``
on the model's own 2D errors over the synthetic training split) sees all joints at once: it refines
the triangulated ones, places the hidden ones where the rest of the body says they are, and
predicts each joint's expected error, which gates what is reported (``joints3d.max_prior_error_m``).

Its inputs are built here, in numpy, the same way for training and on the device
(:func:`prior_inputs`): in a *canonical frame* (origin on the floor below the subject, y down as in
the rig frame, z along the horizontal line of sight from the cameras' midpoint to the subject), so
the network sees the same thing wherever the rig stands and whichever way it turns. Per joint:
the triangulated point (and whether there is one), both views' peak values, reprojection errors,
the rays' angle, each view's ray direction and whether it decoded the joint. Per pair: the camera
centres, the baseline and the subject's distance.

onnxruntime and numpy only; never torch.
"""
from __future__ import annotations

import errno
import hashlib
import stat
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ghnerf_runtime.body25 import FLIP_INDEX, NUM_JOINTS
from ghnerf_runtime.errors import GeometryError, ModelContractError, ModelLoadError, ModelRunError, ShapeError
from ghnerf_runtime.geometry.kept_terms import read_only, same_bits, terms_of
from ghnerf_runtime.geometry.triangulation import TwoViewCameras, TwoViewSolution, triangulate_two_views
from ghnerf_runtime.joints3d import sorted_median
from ghnerf_runtime.onnx_file import non_finite_output, open_onnx_file, ort_reason

__all__ = ["FEATURE_VERSION", "MAX_JOINT_FROM_ROOT_M", "JOINT_FEATURES", "CONTEXT_FEATURES", "FILE_NAME",
           "META_PREFIX", "INPUTS", "OUTPUTS", "CanonicalFrame", "PriorCameras",
           "PriorInputs", "SkeletonEstimate", "SkeletonPrior", "prior_inputs", "mirror_inputs",
           "MIN_CHECK_JOINTS", "disagreement_m"]

#: Bump when the meaning of a feature changes: a file trained on other features is refused.
FEATURE_VERSION = 2  # 2: DLT points farther than MAX_JOINT_FROM_ROOT_M from the root are not triangulated
#: Per-joint features: X(3) triangulated, ok, conf0, conf1, reproj0/5, reproj1/5, ray angle/10,
#: ray0 (3), ray1 (3), decoded0, decoded1.
JOINT_FEATURES = 17
#: Per-pair features: the two camera centres (6), baseline (m), subject distance (m).
CONTEXT_FEATURES = 8
FILE_NAME = "skeleton_prior.onnx"
META_PREFIX = "ghnerf_skeleton."
INPUTS = ("joint_features", "context")
OUTPUTS = ("joints", "log_error")
#: The batches :meth:`SkeletonPrior.answer` runs for one pair: with its mirror (``flip_test``) and without.
WARMUP_BATCHES = (2, 1)
# A good triangulation has a small reprojection error; a root from a few such joints is robust.
_ROOT_MAX_REPROJECTION_PX = 3.0
_REPROJECTION_CLIP_PX = 20.0
_DEFAULT_DISTANCE_M = 2.5  # no joint at all: a guess this far along the cameras' mean heading
# No joint lies farther than this from the body's robust centre (the synthetic bodies' joints: within
# 1.4 m of their geometric median, 1.3 m of the pelvis; 2 m leaves room for taller people and the root's
# own error, and still drops the wild points, which lie 10 m to 1 km away).
MAX_JOINT_FROM_ROOT_M = 2.0
#: :func:`disagreement_m` needs this many triangulated joints: fewer say too little about the whole body (held
#: out, every pair has 9 or more, docs/runtime.md "The skeleton prior").
MIN_CHECK_JOINTS = 5


@dataclass(frozen=True)
class CanonicalFrame:
    """Rig frame -> canonical frame, ``X_c = R (X - origin)`` (batched: ``(N, 3, 3)``, ``(N, 3)``)."""

    rotation: np.ndarray
    origin: np.ndarray

    def to_canonical(self, points: np.ndarray) -> np.ndarray:
        """``(N, K, 3)`` rig-frame points in the canonical frame."""
        return np.einsum("nij,nkj->nki", self.rotation, points - self.origin[:, None])

    def to_rig(self, points: np.ndarray) -> np.ndarray:
        """``(N, K, 3)`` canonical points back in the rig frame."""
        return np.einsum("nji,nkj->nki", self.rotation, points) + self.origin[:, None]


@dataclass(frozen=True)
class PriorInputs:
    """What the network eats (float32) and the frame its answers come back in."""

    joint_features: np.ndarray  # (N, J, JOINT_FEATURES)
    context: np.ndarray  # (N, CONTEXT_FEATURES)
    frame: CanonicalFrame
    triangulated: np.ndarray  # (N, J) bool: a DLT point from both views


def _centres(P: np.ndarray) -> np.ndarray:
    """Camera centres ``(..., 3)`` of ``(..., 3, 4)`` projection matrices (their right null space)."""
    _, _, vt = np.linalg.svd(P)
    c = vt[..., -1, :]
    return c[..., :3] / c[..., 3:]


def _geometric_median(points: np.ndarray, iterations: int = 20) -> np.ndarray:
    """Robust centre of ``(K, 3)`` points (Weiszfeld); unlike a per-axis median it turns with the points.

    Always ``iterations`` steps: Weiszfeld converges slowly, and the prior was trained on these centres
    (stopping at a small step moved a few by centimetres)."""
    c = points.mean(0)
    for _ in range(iterations):
        d = points - c
        w = 1.0 / np.maximum(np.sqrt(np.einsum("ij,ij->i", d, d)), 1e-6)
        c = (w @ points) / w.sum()
    return c


def _mean_heading(P: np.ndarray, det_sign: np.ndarray | None = None) -> np.ndarray:
    """``(N, 3)`` unit horizontal direction the two cameras of each pair look along on average (the mean of
    their principal rays, the third row of each ``P[:, :3]`` turned towards the scene, with y dropped);
    rig +z where the cameras look straight up or down, or opposite ways.

    It places the body centre when no joint is triangulated, so that turning the rig turns that guess
    (and so the canonical frame and every feature) with it, as it does when joints are triangulated.
    The guess used to be rig +z, whatever the rig's heading. The change alters the features of such pairs
    only, and :data:`FEATURE_VERSION` stays 2 (files trained before it are still accepted): pairs with no
    triangulated joint are rare, and the presence gate usually stops them before the prior runs.

    ``det_sign``: the ``(N, 2, 1)`` signs of the left 3x3 blocks' determinants, where the caller has them."""
    M = P[..., :3]
    if det_sign is None:
        det_sign = np.sign(np.linalg.det(M))[..., None]
    axis = M[..., 2, :] * det_sign  # (N, 2, 3) towards the scene
    axis = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    d = axis.mean(1) * [1.0, 0.0, 1.0]
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    return np.where(n > 1e-6, d / np.maximum(n, 1e-12), [0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class PriorCameras:
    """What :func:`prior_inputs` derives from the ``(N, 2, 3, 4)`` crop cameras alone (read-only arrays): the
    matrices ``P`` (a copy), the camera centres ``(N, 2, 3)`` and their midpoints ``(N, 3)``, the cameras' mean
    heading ``(N, 3)``, the inverses of the left 3x3 blocks ``(N, 2, 3, 3)`` and the sign of their determinants
    ``(N, 2, 1, 1)`` (a ray's way to the scene); and, built with :meth:`from_two_view`, each pair's two-view solver
    terms (None from :meth:`from_P`), which :func:`prior_inputs` then solves each pair's peaks in.

    Build them with :meth:`from_P` (or :meth:`from_two_view`, where the caller keeps the two-view terms too) and
    pass them to :func:`prior_inputs` (``cameras=``) to skip recomputing them: the estimator keeps its crop
    cameras' for as long as the crop keeps its cameras. The inputs are the same to the bit with them or without.
    """

    P: np.ndarray
    centres: np.ndarray
    mid: np.ndarray
    heading: np.ndarray
    inverse: np.ndarray
    towards_scene: np.ndarray
    two_view: tuple[TwoViewCameras, ...] | None = None

    @classmethod
    def from_P(cls, P) -> "PriorCameras":
        """The terms of ``P`` (the operations :func:`prior_inputs` ran on every call before).

        Raises:
            ShapeError: ``P`` is not ``(N, 2, 3, 4)``.
        """
        P = np.array(P, dtype=np.float64)  # (a copy: the caller's array may change later; these terms may not)
        if P.ndim != 4 or P.shape[1:] != (2, 3, 4):
            raise ShapeError(f"P (N, 2, 3, 4) expected for the prior's camera terms, got {P.shape}")
        C = _centres(P)
        M = P[..., :3]
        cams = cls(P, C, C.mean(1), _mean_heading(P), np.linalg.inv(M), np.sign(np.linalg.det(M))[..., None, None])
        read_only(cams.P, cams.centres, cams.mid, cams.heading, cams.inverse, cams.towards_scene)
        return cams

    @classmethod
    def from_two_view(cls, pairs: Sequence[TwoViewCameras]) -> "PriorCameras":
        """The terms of the pairs whose two-view solver terms are ``pairs`` (one
        :class:`~ghnerf_runtime.geometry.triangulation.TwoViewCameras` per pair): the same to the bit as
        :meth:`from_P` of their matrices, the inverses and the determinants' signs taken from them instead of
        computed again, and kept for :func:`prior_inputs` to solve each pair's peaks in.

        Raises:
            ShapeError: no pair given.
        """
        pairs = tuple(pairs)
        if not pairs:
            raise ShapeError("PriorCameras.from_two_view: at least one pair's two-view terms expected, got none")
        P = np.stack([t.P for t in pairs])
        # depth_scale is sign(det) / |m3|, |m3| > 0 for a regular block: its sign is the determinant's
        det_sign = np.stack([np.sign(t.depth_scale) for t in pairs])  # (N, 2, 1)
        C = _centres(P)
        cams = cls(P, C, C.mean(1), _mean_heading(P, det_sign), np.stack([t.Minv for t in pairs]),
                   det_sign[..., None], pairs)
        read_only(cams.P, cams.centres, cams.mid, cams.heading, cams.inverse, cams.towards_scene)
        return cams

    def is_for(self, P) -> bool:
        """Whether these are the terms of the matrices ``P`` (the same values to the bit, whatever the array)."""
        return same_bits(self.P, P)


def _solve_of(solutions: Sequence[TwoViewSolution | None] | None, pairs: int) -> list[TwoViewSolution | None]:
    """One earlier two-view solve (or None) per pair (``None``: none at all)."""
    if solutions is None:
        return [None] * pairs
    if len(solutions) != pairs:
        raise ShapeError(f"solutions: one per pair expected ({pairs}), got {len(solutions)}")
    return list(solutions)


def _kept_two_view(P: np.ndarray, cameras: PriorCameras | None) -> list[TwoViewCameras | None]:
    """The two-view terms of each pair of the ``(N, 2, 3, 4)`` ``P`` that ``cameras`` hold
    (:meth:`PriorCameras.from_two_view`), else None for each.

    Raises:
        GeometryError: ``cameras`` of other matrices than ``P`` (asked here, before they are solved in).
    """
    if cameras is None or cameras.two_view is None:
        return [None] * len(P)
    return list(terms_of(P, cameras, PriorCameras.from_P, "prior's camera terms").two_view)


def prior_inputs(uv_model: np.ndarray, confidence: np.ndarray, valid: np.ndarray, P: np.ndarray, *,
                 max_joint_from_root_m: float = MAX_JOINT_FROM_ROOT_M, cameras: PriorCameras | None = None,
                 solutions: Sequence[TwoViewSolution | None] | None = None) -> PriorInputs:
    """The prior's inputs from decoded 2D peaks (the same, to the bit, whether ``cameras`` and ``solutions`` are
    given or not).

    Args:
        uv_model: ``(N, 2, J, 2)`` peaks in model-input (crop) pixels; anything where not ``valid``.
        confidence: ``(N, 2, J)`` peak values.
        valid: ``(N, 2, J)`` decoded.
        P: ``(N, 2, 3, 4)`` the crop cameras' pinhole projections (rig frame -> model pixels).
        max_joint_from_root_m: a DLT point farther than this from the body's robust centre is not a
            triangulation (the features of version 1 are those of ``inf``: for measuring old files only).
        cameras: ``PriorCameras.from_P(P)`` (or ``from_two_view``) computed earlier (computed here when not
            given); where they hold two-view terms, a pair without a solve (``solutions``) is solved in them.
        solutions: per pair, an earlier two-view solve in these crop cameras
            (:func:`~ghnerf_runtime.joints3d.solve_two_view_peaks`) or None: used whole where it solved the
            peaks and weights the inputs triangulate, else for its camera terms.

    Raises:
        ShapeError: wrong shapes. GeometryError: a singular or non-finite camera, or ``cameras`` or a solve of
        other matrices.
    """
    uv = np.asarray(uv_model, np.float64)
    conf = np.asarray(confidence, np.float64)
    P = np.asarray(P, np.float64)
    if uv.ndim != 4 or uv.shape[1] != 2 or uv.shape[-1] != 2:
        raise ShapeError(f"uv_model must be (N, 2, J, 2), got {uv.shape}")
    N, _, J, _ = uv.shape
    if conf.shape != (N, 2, J) or np.shape(valid) != (N, 2, J) or P.shape != (N, 2, 3, 4):
        raise ShapeError(f"confidence/valid must be {(N, 2, J)} and P {(N, 2, 3, 4)}, got {conf.shape}, "
                         f"{np.shape(valid)}, {P.shape}")
    solved = _solve_of(solutions, N)
    dec = np.asarray(valid, bool) & np.isfinite(uv).all(-1) & np.isfinite(conf)
    uv = np.where(dec[..., None], uv, 0.0)
    conf = np.where(dec, np.clip(conf, 0.0, 1.0), 0.0)
    # cameras differ per pair: one DLT per pair (weights: peak values; a decoded joint counts a little at least),
    # through the two-view solver (triangulate_dlt's results in a third of the numpy calls: this runs every pair)
    X, ok = np.zeros((N, J, 3)), np.zeros((N, J), bool)
    rep, ang = np.zeros((N, J, 2)), np.zeros((N, J))
    weights = np.where(dec, np.maximum(conf, 1e-3), 0.0)
    kept = _kept_two_view(P, cameras)
    for i in range(N):
        earlier = solved[i]
        r = triangulate_two_views(uv[i], P[i], weights[i], solution=earlier,
                                  cameras=kept[i] if earlier is None else earlier.cameras)
        X[i], ok[i], rep[i], ang[i] = r.points, r.valid, r.reprojection_error, r.ray_angle_deg
    ok = ok & dec.all(1) & np.isfinite(X).all(-1)
    rep, ang = np.nan_to_num(rep), np.nan_to_num(ang)

    # (after the solves: a singular matrix is the solver's GeometryError)
    cams = terms_of(P, cameras, PriorCameras.from_P, "prior's camera terms")
    C, mid = cams.centres, cams.mid
    root = mid + _DEFAULT_DISTANCE_M * cams.heading  # no joint triangulated: a guess ahead of the cameras
    for i in range(N):
        good = ok[i] & (rep[i].max(-1) < _ROOT_MAX_REPROJECTION_PX)
        pick = good if good.sum() >= 3 else ok[i]
        if pick.any():
            root[i] = _geometric_median(X[i][pick])
    # A DLT point far from the body is no measurement of a joint (nearly parallel rays through two wrong
    # peaks: up to a kilometre away with a short baseline); as a feature it threw the prior's answer metres
    # off. It counts as not triangulated: the rays still say where the joint may be.
    ok = ok & (np.linalg.norm(np.where(ok[..., None], X, 0.0) - root[:, None], axis=-1) <= max_joint_from_root_m)
    X = np.where(ok[..., None], X, 0.0)
    rep = np.where(ok[..., None], rep, 0.0)
    ang = np.where(ok, ang, 0.0)
    fwd = root - mid
    fwd[:, 1] = 0.0
    n = np.linalg.norm(fwd, axis=-1, keepdims=True)
    fwd = np.where(n > 1e-6, fwd / np.maximum(n, 1e-12), [0.0, 0.0, 1.0])
    R = np.zeros((N, 3, 3))
    R[:, 1] = [0.0, 1.0, 0.0]
    R[:, 2] = fwd
    R[:, 0] = np.cross(R[:, 1], R[:, 2])
    origin = root * [1.0, 0.0, 1.0]  # keep the height above the floor
    frame = CanonicalFrame(R, origin)

    Xc = np.where(ok[..., None], frame.to_canonical(X), 0.0)
    uvh = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1)
    rays = np.einsum("nvij,nvkj->nvki", cams.inverse, uvh)
    rays = rays * cams.towards_scene  # towards the scene whatever P's scale
    rays /= np.maximum(np.linalg.norm(rays, axis=-1, keepdims=True), 1e-12)
    rays = np.einsum("nij,nvkj->nvki", R, rays) * dec[..., None]
    features = np.concatenate([Xc, ok[..., None], conf.transpose(0, 2, 1),
                               np.clip(rep, 0.0, _REPROJECTION_CLIP_PX) / 5.0, ang[..., None] / 10.0,
                               rays[:, 0], rays[:, 1], dec.transpose(0, 2, 1)], -1)
    context = np.concatenate([frame.to_canonical(C).reshape(N, 6), np.linalg.norm(C[:, 0] - C[:, 1], axis=-1)[:, None],
                              n], -1)
    return PriorInputs(features.astype(np.float32), context.astype(np.float32), frame, ok)


def mirror_inputs(joint_features: np.ndarray, context: np.ndarray, joints: np.ndarray | None = None):
    """The same pair seen in a mirror (canonical x -> -x, left and right joints swapped): training's
    augmentation, and a symmetry the tests check. Works on numpy or torch tensors ``(N, J, F)``, ``(N, C)``,
    ``(N, J, 3)``."""
    f = joint_features[:, list(FLIP_INDEX)] * 1.0
    for col in (0, 9, 12):  # x of the point and of both rays
        f[..., col] = -f[..., col]
    c = context * 1.0
    c[:, 0] = -c[:, 0]
    c[:, 3] = -c[:, 3]
    if joints is None:
        return f, c
    j = joints[:, list(FLIP_INDEX)] * 1.0
    j[..., 0] = -j[..., 0]
    return f, c, j


def disagreement_m(points: np.ndarray, triangulated_points: np.ndarray, triangulated: np.ndarray) -> float | None:
    """How far the prior's skeleton lies from the triangulation: the median distance (m) between ``points``
    ``(J, 3)`` and ``triangulated_points`` ``(J, 3)`` over the joints ``triangulated`` ``(J,)`` (those both views
    found and agree on, :func:`ghnerf_runtime.joints3d.triangulate_joints`); ``None`` with fewer than
    :data:`MIN_CHECK_JOINTS` of them.

    The prior learnt upright people 2.2-4 m from the rig; on other poses (lying, upside down) it answers a
    near-upright skeleton and its expected error stays small, while the triangulation follows the peaks. The
    median, not the mean: the prior exists to overrule the few joints whose two peaks are wrong alike.
    """
    pts = np.asarray(points, np.float64)
    tri = np.asarray(triangulated_points, np.float64)
    if pts.ndim != 2 or pts.shape[-1] != 3 or tri.shape != pts.shape or np.shape(triangulated) != pts.shape[:1]:
        raise ShapeError(f"points and triangulated_points must be (J, 3) and triangulated (J,), got {pts.shape}, "
                         f"{tri.shape}, {np.shape(triangulated)}")
    use = np.asarray(triangulated, bool) & np.isfinite(pts).all(-1) & np.isfinite(tri).all(-1)
    if int(use.sum()) < MIN_CHECK_JOINTS:
        return None
    return float(sorted_median(np.linalg.norm(pts[use] - tri[use], axis=-1)))


@dataclass(frozen=True)
class SkeletonEstimate:
    """The prior's answer for ``N`` pairs: ``points`` ``(N, J, 3)`` rig frame (m), ``expected_error_m``
    ``(N, J)`` (the network's own estimate of its error), ``triangulated`` ``(N, J)``."""

    points: np.ndarray
    expected_error_m: np.ndarray
    triangulated: np.ndarray


#: What ``stat`` raises for a missing file (no such file, a file where a folder should be): "not there". Not
#: ``Path.is_file``, which answers False for these and for a link loop itself (ELOOP, below, was never reached)
_MISSING = frozenset({errno.ENOENT, errno.ENOTDIR})
#: ... and for a name no file can have (longer than the file system takes, a link loop): "no such name". Any other
#: error (permission, I/O) is the file system's, said as it is.
_NO_SUCH_NAME = frozenset({errno.ENAMETOOLONG, errno.EINVAL, errno.ELOOP})


class SkeletonPrior:
    """A loaded ``skeleton_prior.onnx``: :meth:`estimate` runs it on decoded 2D peaks.

    Raises (at :meth:`load`): :class:`ModelLoadError` for a missing or unreadable file,
    :class:`ModelContractError` for a file of another feature version, joint count or I/O.
    """

    def __init__(self, session, path: Path, metadata: dict[str, str]) -> None:
        self._session = session
        self.path = path
        self.metadata = metadata

    @classmethod
    def load(cls, path: str | Path, threads: int = 1) -> "SkeletonPrior":
        path = Path(path)
        sess, meta = open_onnx_file(path, threads, "skeleton prior")
        version = meta.get(META_PREFIX + "feature_version")
        if version != str(FEATURE_VERSION):
            raise ModelContractError(f"feature version {version!r}; this runtime builds version {FEATURE_VERSION}",
                                     path=str(path), key=META_PREFIX + "feature_version")
        if meta.get(META_PREFIX + "num_joints") != str(NUM_JOINTS):
            raise ModelContractError(f"{meta.get(META_PREFIX + 'num_joints')!r} joints, the runtime has {NUM_JOINTS}",
                                     path=str(path), key=META_PREFIX + "num_joints")
        ins = {i.name: i.shape for i in sess.get_inputs()}
        outs = {o.name for o in sess.get_outputs()}
        for name, width in zip(INPUTS, (JOINT_FEATURES, CONTEXT_FEATURES)):
            if name not in ins or len(ins[name]) != (3 if name == INPUTS[0] else 2) or ins[name][-1] != width:
                raise ModelContractError(f"input {name!r} of width {width} expected, the file has {ins}",
                                         path=str(path), key=name)
        if not set(OUTPUTS) <= outs:
            raise ModelContractError(f"outputs {list(OUTPUTS)} expected, the file has {sorted(outs)}",
                                     path=str(path), key=OUTPUTS[0])
        return cls(sess, path, meta)

    def check_encoder(self, folder: Path) -> None:
        """Refuse a prior whose encoder file in ``folder`` is not the one it was trained on.

        The prior learns one encoder's 2D errors (docs/training.md, "The skeleton prior"): beside another
        encoder it would correct mistakes that encoder does not make. Files that do not record their
        encoder (``encoder_file``, ``encoder_sha256``) are taken as they are.

        Raises:
            ModelContractError: the recorded encoder file is missing or has other bytes.
            ModelLoadError: it cannot be looked for (a folder this user may not search, an I/O error) or read.
        """
        name = self.metadata.get(META_PREFIX + "encoder_file")
        digest = self.metadata.get(META_PREFIX + "encoder_sha256")
        if not name or not digest:
            return
        encoder = Path(folder) / name
        fix = (f"retrain it on this encoder (python -m training.skeleton_prior --model-dir {folder} ...) or run "
               f"without it (joints3d.skeleton_prior: off)")
        if not self._encoder_present(encoder, name, folder):
            raise ModelContractError(f"was trained on the 2D joints of {name}, which {folder} does not have: {fix}",
                                     path=str(self.path), key=META_PREFIX + "encoder_file")
        try:
            actual = hashlib.sha256(encoder.read_bytes()).hexdigest()
        except OSError as e:  # a file the service's user may not read: was a bare PermissionError
            raise ModelLoadError(f"cannot read the encoder file {name} this prior was trained on, to check it: "
                                 f"{e.strerror or e}", path=str(encoder)) from None
        if actual != digest:
            raise ModelContractError(f"was trained on the 2D joints of {name} with sha256 {digest[:12]}..., and "
                                     f"{encoder} is another file (sha256 {actual[:12]}...): {fix}",
                                     path=str(self.path), key=META_PREFIX + "encoder_sha256")

    def _encoder_present(self, encoder: Path, name: str, folder: Path) -> bool:
        """Whether ``encoder`` (the file ``name`` recorded in this prior) is a file in ``folder``.

        Raises:
            ModelContractError: ``name`` is one no file can have (was a bare OSError).
            ModelLoadError: naming ``encoder`` and the operating system's reason, where looking for it failed
                otherwise (a folder this user may not search, an I/O error): it was read as "no such name".
        """
        try:
            return stat.S_ISREG(encoder.stat().st_mode)
        except OSError as e:
            if e.errno in _MISSING:
                return False
            if e.errno in _NO_SUCH_NAME:
                raise ModelContractError(f"names the encoder file {name[:60]!r}{'...' if len(name) > 60 else ''}, "
                                         f"which no file in {folder} can be ({e.strerror or e})",
                                         path=str(self.path), key=META_PREFIX + "encoder_file") from None
            raise ModelLoadError(f"cannot look for the encoder file {name} this prior was trained on, to check it: "
                                 f"{e.strerror or e}", path=str(encoder)) from None

    def estimate(self, uv_model: np.ndarray, confidence: np.ndarray, valid: np.ndarray,
                 P: Sequence | np.ndarray, flip_test: bool = True, *, cameras: PriorCameras | None = None,
                 solutions: Sequence[TwoViewSolution | None] | None = None) -> SkeletonEstimate:
        """The skeleton of ``N`` pairs (shapes as :func:`prior_inputs`; one pair may drop the ``N``; ``cameras``
        and ``solutions`` as there, of the ``N`` pairs: one pair's are for ``N = 1``).

        ``flip_test``: also run the mirrored pairs (:func:`mirror_inputs`, in the same batch) and average
        both answers, mirrored back: the network is only nearly mirror-symmetric, and the average of the two
        is better than either (held out: 41.1 -> 40.3 mm over every joint, docs/runtime.md)."""
        single = np.ndim(uv_model) == 3
        if single:
            uv_model, confidence, valid = uv_model[None], confidence[None], valid[None]
            P = np.asarray([np.asarray(getattr(c, "P", c), np.float64) for c in P])[None]
        out = self.answer(prior_inputs(uv_model, confidence, valid, np.asarray(P, np.float64), cameras=cameras,
                                       solutions=solutions), flip_test)
        if single:
            return SkeletonEstimate(out.points[0], out.expected_error_m[0], out.triangulated[0])
        return out

    def warm_up(self) -> float:
        """Run the network once at each batch the estimator runs, one pair with its mirror
        (``joints3d.prior_flip_test``) and without, so that the first pair does not pay onnxruntime's first run of
        a shape (0.8-6 ms against 0.5 after in a one-off timing on session 68's host); returns its milliseconds.
        An answer holding NaN or infinite values is a :class:`ModelRunError` (weights that hold them)."""
        t0 = time.perf_counter()
        for batch in WARMUP_BATCHES:
            feeds = (np.zeros((batch, NUM_JOINTS, JOINT_FEATURES), np.float32),
                     np.zeros((batch, CONTEXT_FEATURES), np.float32))
            try:
                outs = self._session.run(list(OUTPUTS), dict(zip(INPUTS, feeds)))
            except Exception as e:  # onnxruntime's pybind exceptions, named as a pair's run names them
                raise ModelRunError(f"skeleton prior failed its warm-up run (batch {batch}): {type(e).__name__}: "
                                    f"{ort_reason(e, 200)}", path=str(self.path)) from e
            # as the graphs' warm-up (ModelSession._warm_run): NaN weights answer NaN to every pair, which answer()
            # takes as no estimate, so the prior dropped out of every pair without a word
            if (non_finite := non_finite_output(zip(OUTPUTS, outs))) is not None:
                raise ModelRunError(f"skeleton prior returned NaN or infinite values in {non_finite[0]!r} at its "
                                    f"warm-up run (batch {batch}): its weights hold NaN or infinite values (a run "
                                    "that diverged?); train it again", path=str(self.path))
        return 1e3 * (time.perf_counter() - t0)

    def answer(self, inputs: PriorInputs, flip_test: bool = True) -> SkeletonEstimate:
        """The network's answer to built inputs (:meth:`estimate` without the building)."""
        features, context = inputs.joint_features, inputs.context
        if flip_test:
            mirrored = mirror_inputs(features, context)
            features, context = np.concatenate([features, mirrored[0]]), np.concatenate([context, mirrored[1]])
        try:
            joints, log_error = self._session.run(list(OUTPUTS), dict(zip(INPUTS, (features, context))))
        except Exception as e:
            raise ModelRunError(f"skeleton prior failed: {type(e).__name__}: {ort_reason(e, 200)}",
                                path=str(self.path)) from e
        joints = joints.astype(np.float64)
        err = np.exp(np.clip(log_error.astype(np.float64), -12.0, 5.0))
        if flip_test:
            n = len(inputs.context)
            back = np.argsort(FLIP_INDEX)  # FLIP_INDEX is its own inverse; argsort says so without assuming it
            mirrored_joints = joints[n:, back] * np.array([-1.0, 1.0, 1.0])
            joints = 0.5 * (joints[:n] + mirrored_joints)
            err = 0.5 * (err[:n] + err[n:, back])
        points = inputs.frame.to_rig(joints)
        bad = ~np.isfinite(points).all(-1) | ~np.isfinite(err)
        points = np.where(bad[..., None], 0.0, points)
        err = np.where(bad, np.inf, err)
        return SkeletonEstimate(points, err, inputs.triangulated)
