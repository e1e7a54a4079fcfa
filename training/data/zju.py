"""ZJU-MoCap format: read a subject folder, and write one (for tests and for exporting simulated data).

Layout of one subject (as distributed by the ZJU-MoCap authors and read by Neural Body
and ENeRF; learned from their public loaders, no code copied)::

    <subject>/annots.npy          np.save of a dict (needs allow_pickle: load trusted files only)
        ["cams"]["K"]  list of C (3, 3) intrinsics, pixels
        ["cams"]["R"]  list of C (3, 3) rotations world -> camera (a (3,) / (3, 1) Rodrigues
                       vector is accepted too)
        ["cams"]["T"]  list of C (3, 1) translations world -> camera, **millimetres**
                       (converted here to metres: t = T / 1000)
        ["cams"]["D"]  list of C (5, 1) OpenCV distortion k1 k2 p1 p2 k3
        ["ims"]        list of F frames, each {"ims": [C image paths relative to <subject>],
                       optional "kpts2d": (C, 25, 3) BODY_25 x, y, confidence in the
                       *distorted* image pixels}
    <subject>/<image path>        e.g. Camera_B1/000000.jpg (CoreView_313/315 use other names)
    <subject>/mask/<image path with .png>       subject mask, non-zero = person
    <subject>/mask_cihp/<image path with .png>  CIHP part labels, non-zero = person

Optional, SMPL-free extras read when present:

* ``keypoints3d/<frame:06d>.json``: EasyMocap 3D keypoints, a list of
  ``{"id": int, "keypoints3d": [[x, y, z, confidence] x 25]}`` in **metres** in the same
  world frame as the cameras (BODY_25 order; the first person is used; extra hand/face
  rows beyond 25 are ignored). ``<frame>`` is the 0-based index into ``ims``.
* ``keypoints2d/<image path with .json>``: 2D keypoints of one image when ``annots.npy``
  has no ``kpts2d``: either OpenPose output (``{"people": [{"pose_keypoints_2d": [75
  numbers]}]}``) or EasyMocap annotations (``{"annots": [{"keypoints": [[x, y, c] x 25]}]}``
  or a bare list of such persons). Distorted image pixels.

SMPL parameters and vertices are not needed (the subject box comes from the joints; see
``training.data.zju_samples``).
"""
from __future__ import annotations

import json
import logging
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.geometry import Camera
from ghnerf_runtime.geometry.camera import DIST_LENGTHS
from ghnerf_runtime.geometry.rig import MIN_BASELINE_M
from ghnerf_runtime.image_files import read_image_or_none, unread_because
from training.data.errors import DatasetError

log = logging.getLogger(__name__)

ANNOTS = "annots.npy"
MM_PER_M = 1000.0
MASK_DIRS = ("mask", "mask_cihp")


# ------------------------------------------------------------------ reading
def _numeric(value, path: Path, where: str) -> np.ndarray:
    """``value`` as a float64 array; anything else (strings, ragged lists, dicts) names ``where`` in ``path``."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise DatasetError(path, f"{where}: not a numeric array ({e})") from e


def _is_list(value) -> bool:
    return isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.ndim >= 1)


def _as_rotation(value, path: Path, c: int) -> np.ndarray:
    R = _numeric(value, path, f"cams.R[{c}]")
    if R.size == 3:  # Rodrigues vector
        R = cv2.Rodrigues(R.reshape(3, 1))[0]
    if R.shape != (3, 3):
        raise DatasetError(path, f"cams.R[{c}] must be a 3x3 rotation or a Rodrigues 3-vector, got shape {R.shape}")
    return R


#: Camera centres all closer together than this (m) are taken for a T in the wrong unit: T in metres read as
#: millimetres shrinks a rig a thousandfold (ZJU-MoCap's ring of several metres to a few millimetres). It is the
#: runtime's shortest stereo baseline, so no usable rig is refused: a two-camera rig of a few centimetres (the
#: example rig's 7.5 cm, written by ``write_zju_format``) is read, and any rig under 10 m in metres is caught.
MIN_CAMERA_SPREAD_M = MIN_BASELINE_M


def parse_cameras(annots: dict, path: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
    """``[(K, R, t_metres, D), ...]`` per camera from ``annots["cams"]`` (errors name ``path``)."""
    cams = annots.get("cams")
    if not isinstance(cams, dict) or not all(k in cams for k in ("K", "R", "T", "D")):
        raise DatasetError(path, "annots['cams'] must be a dict with K, R, T and D lists")
    for k in ("K", "R", "T", "D"):
        if not _is_list(cams[k]):
            raise DatasetError(path, f"cams.{k} must be a list with one entry per camera, got {cams[k]!r:.80}")
    counts = {k: len(cams[k]) for k in ("K", "R", "T", "D")}
    if len(set(counts.values())) != 1 or counts["K"] == 0:
        raise DatasetError(path, f"cams lists must be non-empty and of equal length, got {counts}")
    out = []
    # every camera's shapes are checked here, when the file is opened: a bad entry of a camera no view set uses
    # yet would otherwise surface only when (and if) a sample first needs it
    for c in range(counts["K"]):
        K = _numeric(cams["K"][c], path, f"cams.K[{c}]")
        T = _numeric(cams["T"][c], path, f"cams.T[{c}]")
        D = _numeric(cams["D"][c], path, f"cams.D[{c}]")
        if K.shape != (3, 3):
            raise DatasetError(path, f"cams.K[{c}] must be a 3x3 intrinsic matrix, got shape {K.shape}")
        if T.size != 3 or T.ndim > 2:
            raise DatasetError(path, f"cams.T[{c}] must be a 3-vector ((3,) or (3, 1)), got shape {T.shape}")
        if D.size not in DIST_LENGTHS or D.ndim > 2:
            raise DatasetError(path, f"cams.D[{c}] must hold {', '.join(map(str, DIST_LENGTHS[:-1]))} or "
                                     f"{DIST_LENGTHS[-1]} OpenCV distortion coefficients, got shape {D.shape}")
        out.append((K, _as_rotation(cams["R"][c], path, c), T.reshape(-1) / MM_PER_M, D.reshape(-1)))
    centres = np.array([-R.T @ t for _, R, t, _ in out])
    # the largest distance between two centres (not one axis' extent: a pair on a diagonal spans less per axis)
    spread = float(np.linalg.norm(centres[:, None] - centres[None], axis=-1).max()) if len(out) > 1 else np.inf
    if spread < MIN_CAMERA_SPREAD_M:  # a copy already in metres, read as millimetres: every camera at the origin
        raise DatasetError(path, f"cams.T: the {len(out)} camera centres lie within {1000 * spread:.2f} mm of one "
                                 f"another once read as millimetres (ZJU-MoCap stores T in mm; no usable rig is "
                                 f"under {1000 * MIN_CAMERA_SPREAD_M:g} mm): is this copy's T in metres? Multiply "
                                 "it by 1000")
    return out


#: Joint counts of the EasyMocap skeletons whose first 25 joints are BODY_25's, in its order: body25, bodyhand
#: (+ 2 x 21 hand joints) and bodyhandface (+ 70 face points). Any other count is another skeleton (Halpe's 26,
#: SMPL-X's 55, COCO-WholeBody's 133: COCO's order first), whose first 25 joints were read as BODY_25's.
BODY25_FIRST_COUNTS = (NUM_JOINTS, NUM_JOINTS + 42, NUM_JOINTS + 42 + 70)


def _body25_first(count: int) -> bool:
    return count in BODY25_FIRST_COUNTS


def _unread_words(kind: str, path: Path, flags: int) -> str:
    """The error of an image or mask that did not read: what the file is where it says (a JPEG 2000 TIFF, which was
    "missing or unreadable" as a corrupt file is), else "missing or unreadable"."""
    cause = unread_because(path, flags)
    return f"missing or unreadable {kind}" if cause is None else f"cannot read the {kind}: {cause}"


def _read_json(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise DatasetError(path, f"unreadable JSON: {e}") from e


def parse_keypoints2d_json(data, path: Path) -> np.ndarray | None:
    """``(25, 3)`` x, y, confidence of the first person in an OpenPose or EasyMocap 2D file."""
    if isinstance(data, dict) and "people" in data:
        people = data["people"]
        if not isinstance(people, list) or not all(isinstance(p, dict) for p in people):
            raise DatasetError(path, f"'people' must be a list of OpenPose person objects, got {people!r:.80}")
        if not people:
            return None
        flat = _numeric(people[0].get("pose_keypoints_2d", []), path, "people[0].pose_keypoints_2d")
        if flat.size != 3 * NUM_JOINTS:  # OpenPose keeps hands and face apart: 405 values are BODY_135's
            raise DatasetError(path, f"pose_keypoints_2d has {flat.size} values, expected {3 * NUM_JOINTS} (BODY_25 "
                                     "x, y, confidence)")
        return flat.reshape(NUM_JOINTS, 3)
    persons = data.get("annots") if isinstance(data, dict) else data
    if not isinstance(persons, list):
        raise DatasetError(path, "neither OpenPose ('people') nor EasyMocap ('annots' list) keypoints")
    if not persons:
        return None
    if not isinstance(persons[0], dict):
        raise DatasetError(path, f"person 0 must be an object with 'keypoints', got {persons[0]!r:.80}")
    kp = _numeric(persons[0].get("keypoints", persons[0].get("keypoints2d", [])), path, "annots[0].keypoints")
    if kp.ndim != 2 or not _body25_first(kp.shape[0]) or kp.shape[1] < 3:
        raise DatasetError(path, f"keypoints must be (25, 3) BODY_25 x, y, confidence (or EasyMocap's "
                                 f"{BODY25_FIRST_COUNTS[1:]} joints with hands, face), got {kp.shape}")
    return kp[:NUM_JOINTS, :3]


class ZjuSequence:
    """One ZJU-MoCap subject folder.

    Args:
        root: the subject folder (holding ``annots.npy``).
        mask_dir: ``"mask"`` or ``"mask_cihp"``.
        mask_fallback: where ``mask_dir`` lacks an image's mask, use the other folder's (real copies miss a
            few masks of one kind or the other); :meth:`mask_path` says which file is read.

    Raises:
        DatasetError: ``annots.npy`` is missing or malformed (the message names it); later
            calls name the image, mask or keypoint file they could not read.
    """

    def __init__(self, root: str | Path, *, mask_dir: str = "mask", mask_fallback: bool = False) -> None:
        self.root = Path(root)
        if mask_dir not in MASK_DIRS:
            raise DatasetError(self.root, f"mask_dir must be one of {MASK_DIRS}, got {mask_dir!r}")
        self.mask_dir = mask_dir
        self.mask_fallback = bool(mask_fallback)
        path = self.root / ANNOTS
        if not path.is_file():
            raise DatasetError(path, "missing: not a ZJU-MoCap subject folder")
        try:
            annots = np.load(path, allow_pickle=True).item()
        except (OSError, ValueError, AttributeError, EOFError, pickle.UnpicklingError) as e:
            raise DatasetError(path, f"unreadable annots (expected np.save of a dict): {e}") from e
        if not isinstance(annots, dict):
            raise DatasetError(path, f"must hold a dict, got {type(annots).__name__}")
        self._calib = parse_cameras(annots, path)
        ims = annots.get("ims")
        if not isinstance(ims, (list, tuple, np.ndarray)) or len(ims) == 0:
            raise DatasetError(path, "annots['ims'] must be a non-empty list of frames")
        for f, frame in enumerate(ims):
            paths = frame.get("ims") if isinstance(frame, dict) else None
            # a string has a length too: check the entries are paths
            if not _is_list(paths) or len(paths) != len(self._calib) or not all(isinstance(p, str) for p in paths):
                raise DatasetError(path, f"ims[{f}] must be a dict whose 'ims' lists {len(self._calib)} image paths, "
                                         f"got {paths if isinstance(frame, dict) else frame!r:.80}")
        self._ims = list(ims)
        self._annots_path = path
        self._cameras: dict[int, Camera] = {}

    @property
    def num_frames(self) -> int:
        return len(self._ims)

    @property
    def num_cameras(self) -> int:
        return len(self._calib)

    def _check(self, frame: int, cam: int | None = None) -> None:
        if not 0 <= frame < self.num_frames:
            raise IndexError(f"frame {frame} out of range ({self.num_frames} frames in {self._annots_path})")
        if cam is not None and not 0 <= cam < self.num_cameras:
            raise IndexError(f"camera {cam} out of range ({self.num_cameras} cameras in {self._annots_path})")

    def relative_image_path(self, frame: int, cam: int) -> str:
        self._check(frame, cam)
        return str(self._ims[frame]["ims"][cam])

    def image_path(self, frame: int, cam: int) -> Path:
        return self.root / self.relative_image_path(frame, cam)

    def mask_path(self, frame: int, cam: int) -> Path:
        """The mask file of the image: under ``mask_dir``, or with ``mask_fallback`` under the other mask folder
        when only that one has it (a mask missing from both is named under ``mask_dir``)."""
        rel = Path(self.relative_image_path(frame, cam)).with_suffix(".png")
        path = self.root / self.mask_dir / rel
        if self.mask_fallback and not path.is_file():
            other = self.root / next(d for d in MASK_DIRS if d != self.mask_dir) / rel
            if other.is_file():
                return other
        return path

    def read_image(self, frame: int, cam: int) -> np.ndarray:
        """``(H, W, 3)`` uint8 **BGR** (as OpenCV reads it), its pixels as stored."""
        path = self.image_path(frame, cam)
        # as stored, whatever its EXIF orientation (image_files): the annots' calibration and the mask are of the
        # stored pixel grid
        image = read_image_or_none(path, cv2.IMREAD_COLOR)
        if image is None:
            raise DatasetError(path, _unread_words("image", path, cv2.IMREAD_COLOR))
        return image

    def read_mask(self, frame: int, cam: int) -> np.ndarray:
        """``(H, W)`` bool, True where the mask file is non-zero (its colour channels: a re-saved RGBA mask's
        opaque alpha would make it all person)."""
        path = self.mask_path(frame, cam)
        mask = read_image_or_none(path, cv2.IMREAD_UNCHANGED)
        if mask is None:
            raise DatasetError(path, _unread_words("mask", path, cv2.IMREAD_UNCHANGED))
        return (mask if mask.ndim == 2 else mask[..., :3].max(axis=-1)) != 0

    def camera(self, cam: int, frame: int = 0) -> Camera:
        """Camera ``cam`` (metres); its image size is read once, from the first frame asked for (not always
        frame 0: a copy without a camera's first images still converts the frames it has)."""
        self._check(frame, cam)
        if cam not in self._cameras:
            K, R, t, D = self._calib[cam]
            h, w = self.read_image(frame, cam).shape[:2]
            try:
                self._cameras[cam] = Camera(self._camera_name(cam), w, h, K, D, R, t)
            except ValueError as e:
                raise DatasetError(self._annots_path, f"camera {cam}: {e}") from e
        return self._cameras[cam]

    def ray_camera(self, cam: int) -> Camera:
        """Camera ``cam`` for ray geometry alone (projection, undistortion of points, triangulation), read
        without an image: the camera of :meth:`camera` once an image gave its size, else one whose size is a
        nominal one from K's principal point. Triangulating a frame's joints from every camera's keypoints so
        needs no image of the cameras no view set uses (a partial copy may lack them). Never crop with it."""
        self._check(0, cam)
        if cam in self._cameras:
            return self._cameras[cam]
        K, R, t, D = self._calib[cam]
        # the size only bounds the image (crops, fold checks), which ray geometry does not look at
        w, h = (max(1, int(np.ceil(2 * (v + 0.5)))) if np.isfinite(v) else 1 for v in (K[0, 2], K[1, 2]))
        try:
            return Camera(self._camera_name(cam), w, h, K, D, R, t)
        except ValueError as e:
            raise DatasetError(self._annots_path, f"camera {cam}: {e}") from e

    def _camera_name(self, cam: int) -> str:
        return Path(self.relative_image_path(0, cam)).parent.name or f"cam{cam}"

    def calibration(self, cam: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(K, R, t_metres, D)`` as stored (no image read)."""
        self._check(0, cam)
        return self._calib[cam]

    def keypoints2d(self, frame: int) -> np.ndarray | None:
        """``(C, 25, 3)`` x, y, confidence (distorted pixels; confidence 0 = missing), or None."""
        self._check(frame)
        kp = self._ims[frame].get("kpts2d")
        if kp is not None:
            kp = _numeric(kp, self._annots_path, f"ims[{frame}]['kpts2d']")
            if kp.ndim != 3 or kp.shape[0] != self.num_cameras or kp.shape[1] < NUM_JOINTS or kp.shape[2] < 3:
                raise DatasetError(self._annots_path, f"ims[{frame}]['kpts2d'] must be (C, 25, 3), got {kp.shape}")
            return kp[:, :NUM_JOINTS, :3]
        out = np.zeros((self.num_cameras, NUM_JOINTS, 3))
        found = False
        for c in range(self.num_cameras):
            path = (self.root / "keypoints2d" / self.relative_image_path(frame, c)).with_suffix(".json")
            if path.is_file():
                kp = parse_keypoints2d_json(_read_json(path), path)
                if kp is not None:
                    out[c], found = kp, True
        return out if found else None

    def keypoints3d_path(self, frame: int) -> Path:
        return self.root / "keypoints3d" / f"{frame:06d}.json"

    def joints_3d(self, frame: int) -> np.ndarray | None:
        """``(25, 4)`` x, y, z (metres), confidence from ``keypoints3d/``, or None when absent."""
        self._check(frame)
        path = self.keypoints3d_path(frame)
        if not path.is_file():
            return None
        data = _read_json(path)
        if not isinstance(data, list):
            raise DatasetError(path, "must be an EasyMocap list of {'id', 'keypoints3d'} persons")
        if not data:
            return None
        if not isinstance(data[0], dict):
            raise DatasetError(path, f"person 0 must be an {{'id', 'keypoints3d'}} object, got {data[0]!r:.80}")
        kp = _numeric(data[0].get("keypoints3d", []), path, "[0].keypoints3d")
        if kp.ndim != 2 or not _body25_first(kp.shape[0]) or kp.shape[1] not in (3, 4):
            raise DatasetError(path, f"keypoints3d must be (25, 4) BODY_25 x, y, z, confidence (or EasyMocap's "
                                     f"{BODY25_FIRST_COUNTS[1:]} joints with hands, face), got {kp.shape}")
        if kp.shape[1] == 3:
            kp = np.concatenate([kp, np.ones((len(kp), 1))], axis=1)
        return kp[:NUM_JOINTS]


# ------------------------------------------------------------------ writing
@dataclass(frozen=True, eq=False)
class ZjuFrame:
    """One frame to write: per camera image (BGR uint8) and mask (bool), optional keypoints.

    Attributes:
        images: C ``(H, W, 3)`` uint8 BGR images (distorted, as the cameras saw them).
        masks: C ``(H, W)`` bool masks.
        kpts2d: ``(C, 25, 3)`` x, y, confidence in distorted pixels, or None.
        joints_3d: ``(25, 4)`` x, y, z (metres), confidence, or None.
    """

    images: Sequence[np.ndarray]
    masks: Sequence[np.ndarray]
    kpts2d: np.ndarray | None = None
    joints_3d: np.ndarray | None = None


def write_zju_format(root: str | Path, cameras: Sequence[Camera], frames: Sequence[ZjuFrame], *,
                     image_ext: str = ".jpg", mask_dir: str = "mask") -> Path:
    """Write a ZJU-MoCap subject folder (layout in the module docstring) and return ``root``.

    Images go to ``Camera_B<c+1>/<frame:06d><image_ext>`` (``.jpg`` as in the real set;
    ``.png`` for a lossless round trip), masks (0/255) to ``<mask_dir>/Camera_B<c+1>/<frame:06d>.png``,
    ``kpts2d`` into ``annots.npy`` and ``joints_3d`` to ``keypoints3d/<frame:06d>.json``.
    Translations are written in millimetres.
    """
    root = Path(root)
    if mask_dir not in MASK_DIRS:
        raise ValueError(f"mask_dir must be one of {MASK_DIRS}, got {mask_dir!r}")
    root.mkdir(parents=True, exist_ok=True)
    dist = [np.pad(np.asarray(c.dist, dtype=np.float64), (0, max(0, 5 - len(c.dist))))[:5] for c in cameras]
    for c, cam in enumerate(cameras):
        if np.any(np.asarray(cam.dist)[5:] != 0):
            raise ValueError(f"camera {cam.name!r}: ZJU-MoCap stores 5 distortion coefficients, got {len(cam.dist)}")
    cams = {
        "K": [np.array(c.K, dtype=np.float64) for c in cameras],
        "R": [np.array(c.R, dtype=np.float64) for c in cameras],
        "T": [np.array(c.t, dtype=np.float64).reshape(3, 1) * MM_PER_M for c in cameras],
        "D": [d.reshape(5, 1) for d in dist],
    }
    ims = []
    for f, frame in enumerate(frames):
        if len(frame.images) != len(cameras) or len(frame.masks) != len(cameras):
            raise ValueError(f"frame {f}: need one image and one mask per camera ({len(cameras)})")
        paths = []
        for c, (image, mask) in enumerate(zip(frame.images, frame.masks)):
            rel = f"Camera_B{c + 1}/{f:06d}{image_ext}"
            _write_image(root / rel, image)
            _write_image((root / mask_dir / rel).with_suffix(".png"), np.where(mask, 255, 0).astype(np.uint8))
            paths.append(rel)
        entry: dict = {"ims": paths}
        if frame.kpts2d is not None:
            entry["kpts2d"] = np.asarray(frame.kpts2d, dtype=np.float64)
        ims.append(entry)
        if frame.joints_3d is not None:
            path = root / "keypoints3d" / f"{f:06d}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            rows = np.asarray(frame.joints_3d, dtype=np.float64).tolist()
            path.write_text(json.dumps([{"id": 0, "keypoints3d": rows}]))
    np.save(root / ANNOTS, {"cams": cams, "ims": ims}, allow_pickle=True)
    return root


def _write_image(path: Path, image: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"{path}: could not write image")


__all__ = ["ANNOTS", "MM_PER_M", "ZjuSequence", "ZjuFrame", "write_zju_format", "parse_cameras", "parse_keypoints2d_json"]
