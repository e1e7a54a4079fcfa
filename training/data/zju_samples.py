"""ZJU-MoCap frames -> the shared :class:`~training.data.sample.Sample` structure, and conversion to the cache.

A sample is one frame seen by one *view set*: camera indices whose first two are the
sources and the rest novel targets (ZJU-MoCap's 21-23 cameras stand on a circle, so
e.g. ``(0, 3, 1, 2)``: sources 45 degrees apart, targets between them). Each view is
preprocessed **exactly as the runtime does** (``build_undistort_crop_maps`` +
``apply_crop_maps``: undistort, crop, area-reduce, resize in one remap) around a ROI from
the joints, so the crops are the same kind of image the device feeds the model.

* **3D joints**: ``keypoints3d/`` when present (EasyMocap, metres); otherwise triangulated
  from the 2D keypoints of *all* cameras (``triangulate_robust``, confidence-weighted; their
  calibrations only: no image of a camera outside the view set is read);
  ``joints_3d_valid`` says which are known.
* **2D joints** (``joints_2d_from``): ``"auto"`` projects the 3D joints into the crop when
  enough are valid (multi-view consistent targets; ``visible`` = valid, in front and inside
  the crop; occlusion is unknown), else maps the view's 2D keypoints (undistort, then the
  ROI transform; ``visible`` = confidence > ``min_confidence`` and inside the crop).
* **Mask**: the mask file through the same remap (bilinear), thresholded at 0.5. A missing one
  stops a conversion unless ``mask_fallback`` (the other mask folder's file) or
  ``skip_missing_masks`` (leave the sample out, counted) says otherwise.
* **Depth**: none (``has_depth`` False, depth 0).
* **Subject box**: the valid 3D joints' box grown by ``bbox_margin_m`` (joints lie inside
  the body; hands, head top and feet reach ~0.1-0.2 m beyond them).
* Coordinates stay in the dataset's world frame (metres; ZJU's is z-up, which the model
  does not care about).
"""
from __future__ import annotations

import logging
import math
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterator, Sequence

import cv2
import numpy as np

from ghnerf_runtime.body25 import NUM_JOINTS
from ghnerf_runtime.cli.sigterm import stop_signals_deferred
from ghnerf_runtime.geometry import Camera, triangulate_robust
from ghnerf_runtime.preprocess import (
    Roi, apply_crop_maps, build_undistort_crop_maps, crop_camera, roi_from_joints,
)
from training.data.cache import (
    MANIFEST, new_manifest, read_manifest, shard_name, shard_plan, write_manifest, write_shard, writer_lock,
)
from training.data.errors import DataConfigError, DatasetError
from training.data.sample import NUM_SOURCES, Sample, ViewData
from training.data.zju import MASK_DIRS, ZjuSequence

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ZjuConfig:
    """How ZJU-MoCap frames become samples.

    Attributes:
        resolution: crop side ``S`` (multiple of 8).
        view_sets: camera index tuples, sources first (at least 2 cameras each, same length).
        frames: ``(start, stop, step)`` over ``annots["ims"]``; ``stop = -1`` means all.
        margin_frac: ROI margin (``roi_from_joints``).
        min_roi_size: smallest ROI side, full-image pixels.
        joints_2d_from: ``"auto"``, ``"keypoints3d"`` (projected 3D joints) or ``"kpts2d"``.
        min_confidence: 2D keypoints with confidence at or below this are missing.
        bbox_margin_m: growth of the joints' box into the subject box.
        mask_dir: ``"mask"`` or ``"mask_cihp"``.
        mask_fallback: an image whose mask ``mask_dir`` lacks takes the other mask folder's
            (``mask_cihp/`` for ``mask/``, and back); the sample's metadata names the mask files read.
        skip_missing_masks: leave out the samples with a view whose mask is missing (after the
            fallback), counted and logged at the end of a conversion; off, the first missing mask
            stops the conversion, naming the file.
    """

    resolution: int = 128
    view_sets: tuple[tuple[int, ...], ...] = ((0, 3, 1, 2),)
    frames: tuple[int, int, int] = (0, -1, 1)
    margin_frac: float = 0.25
    min_roi_size: int = 64
    joints_2d_from: str = "auto"
    min_confidence: float = 0.1
    bbox_margin_m: float = 0.2
    mask_dir: str = "mask"
    mask_fallback: bool = False
    skip_missing_masks: bool = False

    def __post_init__(self) -> None:
        def fail(name: str, message: str) -> None:
            raise DataConfigError(f"ZjuConfig.{name}", message)

        if isinstance(self.resolution, bool) or not isinstance(self.resolution, int) or not 32 <= self.resolution <= 512 \
                or self.resolution % 8:
            fail("resolution", f"must be a multiple of 8 in [32, 512], got {self.resolution!r}")
        sets = self.view_sets
        if not sets or not all(isinstance(s, (tuple, list)) and len(s) >= NUM_SOURCES and len(set(s)) == len(s)
                               and all(isinstance(c, int) and c >= 0 for c in s) for s in sets) \
                or len({len(s) for s in sets}) != 1:
            fail("view_sets", f"must be tuples of >= {NUM_SOURCES} distinct camera indices, all of one length, got {sets!r}")
        if len(self.frames) != 3 or not all(isinstance(v, int) for v in self.frames) or self.frames[2] < 1 \
                or self.frames[0] < 0:
            fail("frames", f"must be (start >= 0, stop or -1, step >= 1), got {self.frames!r}")
        for name, lo, hi in (("margin_frac", 0.0, 2.0), ("min_confidence", 0.0, 1.0), ("bbox_margin_m", 0.0, 1.0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and lo <= v <= hi):
                fail(name, f"must be a number in [{lo}, {hi}], got {v!r}")
        if self.joints_2d_from not in ("auto", "keypoints3d", "kpts2d"):
            fail("joints_2d_from", f"must be 'auto', 'keypoints3d' or 'kpts2d', got {self.joints_2d_from!r}")
        if self.mask_dir not in ("mask", "mask_cihp"):
            fail("mask_dir", f"must be 'mask' or 'mask_cihp', got {self.mask_dir!r}")
        for name in ("mask_fallback", "skip_missing_masks"):
            if not isinstance(getattr(self, name), bool):
                fail(name, f"must be true or false, got {getattr(self, name)!r}")

    @property
    def view_names(self) -> tuple[str, ...]:
        n = len(self.view_sets[0])
        return tuple(f"src{i}" for i in range(NUM_SOURCES)) + tuple(f"novel{i}" for i in range(n - NUM_SOURCES))

    def frame_indices(self, num_frames: int) -> range:
        start, stop, step = self.frames
        return range(start, num_frames if stop < 0 else min(stop, num_frames), step)

    def to_json(self) -> dict:
        d = asdict(self)
        d["view_sets"] = [list(s) for s in self.view_sets]
        d["frames"] = list(self.frames)
        return d


def _frame_joints(seq: ZjuSequence, frame: int, kp2d: np.ndarray | None, config: ZjuConfig) -> tuple[np.ndarray, np.ndarray, str]:
    """``(25, 3)`` joints, ``(25,)`` valid and where they came from."""
    j3 = seq.joints_3d(frame)
    if j3 is not None:
        valid = (j3[:, 3] > 0) & np.all(np.isfinite(j3[:, :3]), axis=1)
        return np.where(valid[:, None], j3[:, :3], 0.0), valid, "keypoints3d"
    if kp2d is not None:
        # every camera's keypoints, but no image: a partial copy lacks the images of cameras no view set uses
        cams = [seq.ray_camera(c) for c in range(seq.num_cameras)]
        weights = np.where(kp2d[..., 2] > config.min_confidence, kp2d[..., 2], 0.0)
        result = triangulate_robust(kp2d[..., :2], cams, weights)
        return result.points, result.valid, "triangulated"
    return np.zeros((NUM_JOINTS, 3)), np.zeros(NUM_JOINTS, dtype=bool), "none"


def _view_roi(camera: Camera, joints: np.ndarray, valid: np.ndarray, kp: np.ndarray | None, mask: np.ndarray,
              config: ZjuConfig, where: Path) -> Roi:
    roi = None
    if valid.sum() >= 3:
        roi = roi_from_joints(camera, joints, valid.astype(float), config.margin_frac, config.min_roi_size)
    if roi is None and kp is not None:
        roi = roi_from_joints(camera, kp[:, :2], kp[:, 2], config.margin_frac, config.min_roi_size,
                              min_confidence=config.min_confidence)
    if roi is None:
        ys, xs = np.nonzero(mask)
        if len(xs) == 0:
            raise DatasetError(where, "no joints and an empty mask: cannot place the crop")
        corners = np.array([[xs.min(), ys.min()], [xs.max(), ys.max()]], dtype=np.float64)
        roi = roi_from_joints(camera, corners, np.ones(2), config.margin_frac, config.min_roi_size, min_joints=2)
    if roi is None:
        raise DatasetError(where, "the subject lies outside the image")
    return roi


def zju_view(seq: ZjuSequence, frame: int, cam_index: int, name: str, joints: np.ndarray, valid: np.ndarray,
             kp2d: np.ndarray | None, config: ZjuConfig) -> ViewData:
    """One crop view of camera ``cam_index`` at ``frame`` (see the module docstring)."""
    S = config.resolution
    camera = seq.camera(cam_index, frame)
    image = seq.read_image(frame, cam_index)
    mask_full = seq.read_mask(frame, cam_index)
    if image.shape[:2] != (camera.height, camera.width):
        raise DatasetError(seq.image_path(frame, cam_index),
                           f"image {image.shape[:2]} differs from the camera's {camera.height}x{camera.width} "
                           "(its other frames' size)")
    if mask_full.shape != image.shape[:2]:  # the mask is the odd one: name it
        raise DatasetError(seq.mask_path(frame, cam_index),
                           f"mask {mask_full.shape} differs from its image {image.shape[:2]}")
    kp = None if kp2d is None else kp2d[cam_index]
    roi = _view_roi(camera, joints, valid, kp, mask_full, config, seq.mask_path(frame, cam_index))
    maps = build_undistort_crop_maps(camera, roi, S)
    crop = cv2.cvtColor(apply_crop_maps(image, maps), cv2.COLOR_BGR2RGB)
    mask = apply_crop_maps(np.where(mask_full, 255, 0).astype(np.uint8), maps) >= 128
    crop_cam = crop_camera(camera, roi, S)

    use_3d = config.joints_2d_from == "keypoints3d" or (config.joints_2d_from == "auto" and valid.sum() >= 3)
    if use_3d:
        uv, z = crop_cam.project(np.where(valid[:, None], joints, 0.0))
        ok = valid & (z > 0) & np.all(np.isfinite(uv), axis=-1)
    elif kp is not None:
        und = camera.undistort_pixels(kp[:, :2]) if camera.has_distortion else kp[:, :2]
        uv = roi.image_to_model(und, S)
        ok = (kp[:, 2] > config.min_confidence) & np.all(np.isfinite(uv), axis=-1)
    else:
        uv, ok = np.zeros((NUM_JOINTS, 2)), np.zeros(NUM_JOINTS, dtype=bool)
    inside = np.all((uv >= -0.5) & (uv < S - 0.5), axis=-1)
    return ViewData(
        name=name, image=np.ascontiguousarray(crop), mask=mask, depth=np.zeros((S, S), np.float16), has_depth=False,
        joints_2d=np.where(ok[:, None], uv, 0.0).astype(np.float32), visible=ok & inside,
        K=crop_cam.K.copy(), R=crop_cam.R.copy(), t=crop_cam.t.copy(), roi=roi, roi_from_volume=False,
        full_K=camera.K.copy(), full_size=camera.size,
    )


def zju_sample(seq: ZjuSequence, frame: int, view_set: Sequence[int], config: ZjuConfig) -> Sample:
    """The sample of ``frame`` seen by the cameras ``view_set`` (sources first)."""
    kp2d = seq.keypoints2d(frame)
    if config.joints_2d_from == "kpts2d" and kp2d is None:
        raise DatasetError(seq.root, f"frame {frame}: joints_2d_from='kpts2d' but there are no 2D keypoints")
    joints, valid, origin = _frame_joints(seq, frame, kp2d, config)
    if config.joints_2d_from == "keypoints3d" and origin != "keypoints3d":
        raise DatasetError(seq.keypoints3d_path(frame), "joints_2d_from='keypoints3d' but the file is missing")
    if valid.sum() >= 2:
        pts = joints[valid]
        bbox = np.stack([pts.min(0) - config.bbox_margin_m, pts.max(0) + config.bbox_margin_m])
    else:
        raise DatasetError(seq.keypoints3d_path(frame), "too few 3D joints (keypoints3d or triangulated 2D "
                                                        "keypoints) to bound the subject")
    names = config.view_names
    views = tuple(zju_view(seq, frame, c, names[i], joints, valid, kp2d, config) for i, c in enumerate(view_set))
    metadata = {
        "source": "zju", "root": str(seq.root), "frame": int(frame), "cameras": [int(c) for c in view_set],
        "camera_names": [seq.camera(c).name for c in view_set], "joints_3d_source": origin,
        "images": [seq.relative_image_path(frame, c) for c in view_set],
        "masks": [str(seq.mask_path(frame, c).relative_to(seq.root)) for c in view_set],
    }
    return Sample(views, joints, valid, bbox, metadata)


@dataclass(frozen=True)
class SamplePlan:
    """The ``(frame, view_set)`` samples a conversion makes, and those it leaves out for a missing mask."""

    samples: list[tuple[int, tuple[int, ...]]]
    skipped: list[tuple[int, tuple[int, ...], list[Path]]]  # frame, view set, the missing mask files


def plan_zju_samples(seq: ZjuSequence, config: ZjuConfig) -> SamplePlan:
    """Every frame x view set of ``config``; with ``skip_missing_masks``, those whose views all have a mask
    file (``seq.mask_path``, so after its fallback) apart from the skipped ones."""
    samples, skipped = [], []
    for frame in config.frame_indices(seq.num_frames):
        for view_set in config.view_sets:
            item = (frame, tuple(view_set))
            missing = [seq.mask_path(frame, c) for c in view_set] if config.skip_missing_masks else []
            missing = [m for m in missing if not m.is_file()]
            if missing:
                skipped.append((*item, missing))
            else:
                samples.append(item)
    return SamplePlan(samples, skipped)


def iter_zju_samples(seq: ZjuSequence, config: ZjuConfig) -> Iterator[Sample]:
    for frame, view_set in plan_zju_samples(seq, config).samples:
        yield zju_sample(seq, frame, view_set, config)


def check_folders(seq: ZjuSequence, config: ZjuConfig) -> None:
    """Refuse a subject folder without the image folders of the view sets' cameras, or without a mask folder to
    read, naming the folder: checked before anything converts, where the first sample's read would name only
    one file in it (a copy unpacked without one camera, or with its masks under the other folder's name).

    Raises:
        DatasetError: the missing folder, and what names it (``annots.npy``'s image paths, ``mask_dir``).
    """
    for cam in sorted({c for view_set in config.view_sets for c in view_set}):
        folders: dict[Path, int] = {}  # each folder the camera's images are in (ZJU-MoCap: one), and a frame naming it
        for frame in config.frame_indices(seq.num_frames):
            folders.setdefault(seq.image_path(frame, cam).parent, frame)
        for folder, frame in folders.items():
            if not folder.is_dir():
                raise DatasetError(folder, f"missing: the images folder of camera {cam} (annots.npy's ims[{frame}] "
                                           f"names {seq.relative_image_path(frame, cam)})")
    other = next(d for d in MASK_DIRS if d != config.mask_dir)
    if not (seq.root / config.mask_dir).is_dir() and not (config.mask_fallback and (seq.root / other).is_dir()):
        hint = (f"; this copy has {other}/: choose it with mask_dir={other!r}" if (seq.root / other).is_dir()
                else f" (nor {other}/)")
        raise DatasetError(seq.root / config.mask_dir, f"missing: the mask folder (mask_dir={config.mask_dir!r}){hint}")


def convert_zju(subject: str | Path, out: str | Path, config: ZjuConfig, *, split: str = "train",
                shard_size: int = 64) -> int:
    """Convert one ZJU-MoCap subject into split ``split`` of the cached dataset ``out``; returns the count.

    Several subjects go into one dataset as several splits (``train_313``, ``train_315``...;
    combine them with ``torch.utils.data.ConcatDataset``). The split is rewritten whole and
    atomically: the shards are written into ``<split>.tmp-<pid>`` and swapped in once every
    sample converted, so a conversion that fails midway (a missing mask, say) leaves the
    previous split as it was. The split's manifest entry records the settings that made it
    (``source_config``); the top-level ``source_config`` of a ZJU dataset is the latest conversion's.
    With ``config.skip_missing_masks`` the samples lacking a mask are left out (the count returned is
    of those converted); their number goes into the split's entry (``skipped_missing_masks``) and a
    warning at the end lists their frames.

    Raises:
        DataConfigError: a bad ``split``, ``shard_size`` or camera index (the message names it).
        DatasetError: the subject folder or ``out``'s manifest is unusable (the message names the file; a
            missing images or mask folder is named before anything converts: :func:`check_folders`), or
            another process is writing ``out`` (``cache.writer_lock``).
    """
    if not isinstance(split, str) or not split or not split.replace("_", "").isalnum():
        raise DataConfigError("split", f"must be an identifier, got {split!r}")
    if isinstance(shard_size, bool) or not isinstance(shard_size, int) or not 1 <= shard_size <= 100_000:
        raise DataConfigError("shard_size", f"must be an int in [1, 100000], got {shard_size!r}")
    seq = ZjuSequence(subject, mask_dir=config.mask_dir, mask_fallback=config.mask_fallback)
    for view_set in config.view_sets:
        if max(view_set) >= seq.num_cameras:
            raise DataConfigError("ZjuConfig.view_sets", f"camera {max(view_set)} does not exist "
                                                         f"({seq.num_cameras} cameras in {seq.root})")
    if not config.frame_indices(seq.num_frames):  # an empty split replaced a converted one, exit 0
        raise DataConfigError("ZjuConfig.frames", f"selects none of the {seq.num_frames} frames in {seq.root} "
                                                  f"(0 to {seq.num_frames - 1}), got {config.frames}")
    check_folders(seq, config)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with writer_lock(out):  # one writer per folder: two conversions at once would drop a split's entry
        return _convert(seq, subject, out, config, split, shard_size)


def another_layout_words(manifest: dict, config: ZjuConfig) -> str:
    """Why a dataset folder cannot take this conversion's split, with both values: every split of a folder has one
    resolution and one set of views (the trainer and the evaluation read any split with the folder's)."""
    had, want = (manifest["resolution"], len(manifest["view_names"])), (config.resolution, len(config.view_names))
    return (f"holds {had[0]} px scenes of {had[1]} views (resolution, view_names); this conversion makes {want[0]} px "
            f"scenes of {want[1]} views (--res, --view-set): convert into another --out, or with the folder's")


def _convert(seq: ZjuSequence, subject: str | Path, out: Path, config: ZjuConfig, split: str,
             shard_size: int) -> int:
    source_config = {"zju": config.to_json()}
    if (out / MANIFEST).exists():
        manifest = read_manifest(out)
        if manifest["resolution"] != config.resolution or manifest["view_names"] != list(config.view_names):
            raise DatasetError(out / MANIFEST, another_layout_words(manifest, config))
    else:
        manifest = new_manifest(resolution=config.resolution, view_names=config.view_names, source="zju",
                                source_config=source_config)
    _recover_a_half_swapped_split(out, manifest, split)
    # leftovers of an interrupted conversion of this split (split names have no dot: no other split matches)
    for stale in [*out.glob(f"{split}.tmp-*"), *out.glob(f"{split}.old-*")]:
        log.info("removing %s, left by an interrupted conversion", stale)
        shutil.rmtree(stale, ignore_errors=True)

    plan = plan_zju_samples(seq, config)
    count = len(plan.samples)
    if plan.skipped and not count:  # every sample lacks a mask: more likely the wrong mask_dir than a sparse copy
        raise DatasetError(plan.skipped[0][2][0], f"missing mask: every one of the {len(plan.skipped)} samples "
                                                  f"lacks one (is mask_dir={config.mask_dir!r} the copy's folder?)")
    tmp = out / f"{split}.tmp-{os.getpid()}"
    try:
        tmp.mkdir()
        samples = (zju_sample(seq, frame, view_set, config) for frame, view_set in plan.samples)
        for k, first, n in shard_plan(count, shard_size):
            write_shard(tmp / shard_name(k), [next(samples) for _ in range(n)], first)
            log.info("%s: shard %d written (%d samples)", split, k, n)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)  # the old split (if any) was never touched
        raise

    entry = {"count": count, "shard_size": shard_size,
             "spec": {"name": split, "source": "zju", "subject": str(subject)}, "source_config": source_config,
             **({"skipped_missing_masks": len(plan.skipped)} if config.skip_missing_masks else {})}
    old = out / f"{split}.old-{os.getpid()}"
    swapped = False
    try:
        # a stop landing between the two renames left no split at all, and the next run deleted the old one
        # (taken for a leftover): held until the new split and its entry are in place, then raised
        with stop_signals_deferred(only_raising=True):
            _swap_in(out, split, tmp, old, manifest, entry, source_config)
            swapped = True
    except KeyboardInterrupt as e:
        if swapped:  # raised after the swap: the new split is the one kept
            setattr(e, _SPLIT_REPLACED, True)
            shutil.rmtree(old, ignore_errors=True)
        raise
    shutil.rmtree(old, ignore_errors=True)
    if plan.skipped:  # said last, after the shard lines, so it is not scrolled away
        frames = sorted({f for f, _, _ in plan.skipped})
        log.warning("%s: %d of %d samples skipped for a missing mask (frames %s%s; first missing: %s)", split,
                    len(plan.skipped), count + len(plan.skipped), ", ".join(map(str, frames[:20])),
                    ", ..." if len(frames) > 20 else "", plan.skipped[0][2][0])
    return count


_SPLIT_REPLACED = "zju_split_replaced"  # set on a stop raised once the new split was in place


def split_replaced(stop: KeyboardInterrupt) -> bool:
    """Whether the Ctrl-C (or SIGTERM) that stopped :func:`convert_zju` came once its new split was in place (held
    over the swap, raised after it): the split is then the new one, else the one before the conversion."""
    return getattr(stop, _SPLIT_REPLACED, False)


#: The manifest's key for the entries of splits being swapped: taken out of ``splits`` (a loader never pairs the
#: old entry with new shards) and kept here until the new entry is written, for the next run to put back with the
#: old shards when a conversion was killed during the swap.
REPLACING = "replacing_splits"


def _swap_in(out: Path, split: str, tmp: Path, old: Path, manifest: dict, entry: dict, source_config: dict) -> None:
    """Put the converted shards ``tmp`` in place of split ``split``, and ``entry`` in its manifest; the old split
    goes to ``old``, for the caller to delete."""
    split_dir = out / split
    if split in manifest["splits"]:
        # a crash during the swap then leaves the split absent from the splits, never old entry + new shards; its
        # entry is kept aside for the next run (_recover_a_half_swapped_split)
        entry_before = manifest["splits"].pop(split)
        if split_dir.exists():  # shards gone: kept aside, a kill after the rename-in paired it with the new ones
            manifest.setdefault(REPLACING, {})[split] = entry_before
        write_manifest(out, manifest)
    if split_dir.exists():
        os.replace(split_dir, old)
    os.replace(tmp, split_dir)
    manifest["splits"][split] = entry
    _drop_aside(manifest, split)
    if manifest.get("source") == "zju":  # (another source's top-level settings are its own: generate checks them)
        manifest["source_config"] = source_config
    write_manifest(out, manifest)


def _drop_aside(manifest: dict, split: str) -> dict | None:
    """Take ``split``'s entry kept aside during a swap out of ``manifest``; None where there is none."""
    aside = manifest.get(REPLACING, {})
    entry = aside.pop(split, None) if isinstance(aside, dict) else None
    if not aside:
        manifest.pop(REPLACING, None)
    return entry


def _recover_a_half_swapped_split(out: Path, manifest: dict, split: str) -> None:
    """Put back the split a conversion killed during its swap (SIGKILL, a power cut: no signal hold stops those)
    left half-swapped, rather than delete its old shards as a leftover: the old shards (``<split>.old-<pid>``, or
    ``<split>`` where the kill came before the first rename) with the entry kept aside. A failure of this
    conversion then leaves the split as it was before the killed one. Without an entry kept aside (the split was
    not in the manifest), an old folder with no ``<split>`` beside it is put back alone."""
    olds = sorted(out.glob(f"{split}.old-*"), key=lambda p: p.stat().st_mtime)
    entry = _drop_aside(manifest, split)
    if entry is None and ((out / split).exists() or not olds):
        return
    if olds:
        if (out / split).exists():  # the new shards, renamed in before the kill, have no entry: the old ones stay
            shutil.rmtree(out / split)
        os.replace(olds[-1], out / split)
    if entry is not None:
        if (out / split).is_dir():
            manifest["splits"][split] = entry
        write_manifest(out, manifest)
    log.warning("%s: left half-swapped by a conversion killed during its swap: the split before it put back%s",
                out / split, "" if entry is not None else " (it had no manifest entry)")


__all__ = ["split_replaced", "ZjuConfig", "SamplePlan", "zju_sample", "zju_view", "plan_zju_samples", "iter_zju_samples", "check_folders",
           "convert_zju"]
