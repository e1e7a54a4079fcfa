"""``ghnerf-run``: joints from two images (or two videos) of a calibrated rig, as JSON.

Examples::

    ghnerf-run --rig rig.json --images left.png right.png --out joints.json
    ghnerf-run --rig rig.json --videos left.mp4 right.mp4 --out joints.jsonl \\
        --novel-view novel.mp4 --overlay overlay.mp4
    ghnerf-run --rig rig.json --images l.png r.png --model-dir /opt/models/edge128 --method volumetric

Images are given in the rig file's camera order (its first two cameras). Output: one JSON
object per frame pair (``docs/runtime.md``: ``joint_names``, ``joints_3d`` as
``[x, y, z, confidence]`` metres in the rig frame, ``joints_2d`` per camera name as
``[u, v, confidence]`` pixels of the original image, ``missing``, ``timing_ms``...). A ``.json``
output holds a list of those objects, written whole when the run ends (atomically; a run stopped by an
error or Ctrl-C writes the pairs it finished, and one that finished none leaves an earlier file as it
was); ``.jsonl`` (and stdout) one object per line as each pair is done. Missing joints have confidence
0 and coordinates 0; no NaN is ever written.

Exit status: 0 on success, 2 for a usage, config, rig, model or input error (the message names
the file and what is wrong).
"""
from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Iterable, Iterator, Sequence

import cv2
import numpy as np

from ghnerf_runtime.cli.model_folder import model_dir_source, named_by_source
from ghnerf_runtime.cli.output_path import OutputPathError, model_file_clash, output_clash, ready_output, same_file
from ghnerf_runtime.cli.rig_messages import rig_notes_let_through
from ghnerf_runtime.cli.sigterm import exit_status, sigterm_as_interrupt, stop_signal, stop_signals_deferred
from ghnerf_runtime.config import HEATMAP_SOURCES, NOVEL_PATHS, THREE_D_METHODS, EstimatorConfig, config_to_dict, \
    load_config
from ghnerf_runtime.errors import FrameError, GeometryError, ImageWriteError, ModelError, ModelLoadError, \
    RuntimeErrorBase
from ghnerf_runtime.estimator import Estimator, PairResult, check_model_files
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.image_files import read_image_or_none, unread_because
from ghnerf_runtime.image_write import write_image_atomic
from ghnerf_runtime.novel_view import NovelViewRequest, draw_skeleton
from ghnerf_runtime.pipeline import NovelViewPipeline
from ghnerf_runtime.rig_file import load_rig, write_text_atomic
from ghnerf_runtime.skeleton_prior import FILE_NAME as PRIOR_FILE
from ghnerf_runtime.video_files import is_still_image, read_as_stored
from ghnerf_runtime.path_check import user_path

log = logging.getLogger("ghnerf-run")

__all__ = ["main", "build_parser", "overlay_image"]


class UsageError(RuntimeErrorBase):
    """Bad command-line input (unreadable image, mismatched videos...)."""


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="ghnerf-run", description=__doc__.split("\n\n")[0],
                                 epilog="Schema and examples: docs/runtime.md")
    ap.add_argument("--rig", type=user_path, help="rig file (docs/rig-file.md); required unless --validate-config")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--images", type=user_path, nargs=2, metavar=("FIRST", "SECOND"), help="one image per camera, rig order")
    src.add_argument("--videos", type=user_path, nargs=2, metavar=("FIRST", "SECOND"), help="one video per camera, rig order")
    ap.add_argument("--out", type=user_path, default="-", help="joints output: .json (a list, written atomically at the end; a run "
                                               "stopped early keeps the pairs it finished), .jsonl or - (stdout, "
                                               "one object per line as each pair is done; a device or pipe such "
                                               "as /dev/stdout too); any other suffix is refused; default -")
    ap.add_argument("--config", type=user_path, help="estimator config (JSON, docs/runtime.md); flags below override it")
    ap.add_argument("--model-dir", type=user_path, help="model folder (default: the config's, else ./models)")
    ap.add_argument("--precision", choices=("auto", "fp32", "int8"),
                    help="graph file precision (session.precision; int8 runs a graph's fp32 file, with a warning, "
                         "where the folder has no int8 one)")
    ap.add_argument("--method", choices=THREE_D_METHODS, help="3D joint method")
    ap.add_argument("--heatmap-source", choices=HEATMAP_SOURCES,
                    help="rendered (GHNeRF render_heat) or encoder (the encoder's 2D heatmaps; faster)")
    ap.add_argument("--flip-test", action=argparse.BooleanOptionalAction, default=None,
                    help="encoder heatmaps: also run the encoder on the mirrored crops and average "
                         "(heatmaps.flip_test, on by default: +0.016 PCK and -12 mm MPJPE on 30 held-out-like "
                         "sequences, +0.9 ms per pair on a fast 2-core host, +4-6 ms on a slower one; "
                         "docs/runtime.md); --no-flip-test turns it off")
    ap.add_argument("--skeleton-prior", choices=("auto", "on", "off"),
                    help="triangulation: the learnt skeleton prior (joints3d.skeleton_prior; auto, the default, uses "
                         "the model folder's skeleton_prior.onnx when it has one: docs/runtime.md)")
    ap.add_argument("--max-prior-error", type=float, metavar="M",
                    help="skeleton prior: report a joint only when its expected error is at most M metres "
                         "(joints3d.max_prior_error_m, default 0.15; refused where the settings turn the prior off, "
                         "warned of where the model folder has none)")
    ap.add_argument("--smoothing", action=argparse.BooleanOptionalAction, default=None,
                    help="videos: One Euro smoothing of the 3D joints on the frames' times (smoothing.enabled, on "
                         "by default: less jitter and a lower MPJPE on the bench, docs/runtime.md); --no-smoothing "
                         "reports each pair's raw joints")
    ap.add_argument("--refine-cold-start", action=argparse.BooleanOptionalAction, default=None,
                    help="run a cold pair (no track yet) again on the subject it found (tracking.refine_cold_start): "
                         "on by default (a still pair, a video's first pair; docs/runtime.md); "
                         "--no-refine-cold-start reports the working volume's crop")
    ap.add_argument("--threads", type=int, help="onnxruntime intra-op threads")
    ap.add_argument("--novel-view", type=user_path, metavar="PATH", help="also render a novel view: .png (last frame) or .mp4")
    ap.add_argument("--novel-alpha", type=float, help="novel camera between the rig cameras: 0 = first, "
                                                      "1 = second (default 0.5), on the line between them or an "
                                                      "orbit round the subject (novel_view.path); -1..2 "
                                                      "extrapolates, refused where the focal length (or, on an "
                                                      "orbit, the distance to its pivot) would reach 0")
    ap.add_argument("--novel-overlay", choices=("none", "skeleton", "heatmap"), help="drawn on the novel view "
                                                                                     "(default none)")
    ap.add_argument("--novel-path", choices=NOVEL_PATHS, help="how the view between the cameras moves "
                                                              "(novel_view.path; default from the config: auto, "
                                                              "an orbit where the cameras' axes are over 60 "
                                                              "degrees apart, else the line)")
    ap.add_argument("--novel-stride", type=int, choices=(1, 2, 4), help="render every n-th novel-view pixel")
    ap.add_argument("--overlay", type=user_path, metavar="PATH", help="both input frames with the 2D joints drawn: .png or .mp4")
    ap.add_argument("--max-frames", type=int, help="stop after this many pairs (videos; at least 1)")
    ap.add_argument("--validate-config", action="store_true",
                    help="check the config (and the model folder --model-dir or session.model_dir names: a folder "
                         "holding the files the settings need, by name; none loaded), print it, exit")
    ap.add_argument("-v", "--verbose", action="store_true")
    return ap


def _check_args(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """What argparse cannot say: no flag is accepted and then ignored."""
    if not args.validate_config:
        if not args.rig:
            ap.error("the following arguments are required: --rig")
        if not (args.images or args.videos):
            ap.error("one of the arguments --images --videos is required")
    if not args.novel_view:
        given = [f for f, v in (("--novel-alpha", args.novel_alpha), ("--novel-overlay", args.novel_overlay),
                                ("--novel-path", args.novel_path), ("--novel-stride", args.novel_stride))
                 if v is not None]
        if given:
            ap.error(f"{', '.join(given)} without --novel-view: there is no novel view to apply it to")
    if args.smoothing is not None and args.images and not args.validate_config:  # (there it sets what is printed)
        ap.error(f"--{'' if args.smoothing else 'no-'}smoothing applies to --videos (--images is one pair, nothing "
                 "to smooth)")
    if args.max_frames is not None:
        if args.images:
            ap.error("--max-frames applies to --videos (--images is one pair)")
        if args.max_frames < 1:
            ap.error(f"--max-frames must be at least 1, got {args.max_frames}")
    if (refusal := _out_kind_refusal(args.out)) is not None:
        ap.error(refusal)
    pair = args.images or args.videos
    if pair and same_file(*pair):  # each camera's view in one picture: the joints came out, wrong
        ap.error(f"{'--images' if args.images else '--videos'}: {pair[0]} and {pair[1]} are one file; give each "
                 "camera's own, in the rig file's camera order")
    clash = output_clash({"--out": None if args.out in (None, "-") else args.out, "--overlay": args.overlay,
                          "--novel-view": args.novel_view},
                         {"--rig": args.rig, "--config": args.config,
                          **{f"{flag} ({which})": path for flag, pair in (("--images", args.images),
                                                                           ("--videos", args.videos))
                             for which, path in zip(("first", "second"), pair or ())}})
    if clash:  # --out rig.json replaced the calibration with the joints, --overlay left.png the capture
        ap.error(clash)
    if args.novel_alpha is None:
        args.novel_alpha = 0.5
    if args.novel_overlay is None:
        args.novel_overlay = "none"
    if args.novel_view:
        _check_novel_alpha(ap, args.novel_alpha)


#: ``--out``'s file kinds, by suffix (any case): a list written whole at the end, or a line per pair.
OUT_SUFFIXES = (".json", ".jsonl")


def _out_kind_refusal(out: str | None) -> str | None:
    """Why ``--out`` names no kind ghnerf-run writes, or None: ``-``, a ``.json`` or ``.jsonl`` file, or an existing
    device or pipe (``/dev/stdout``, a FIFO: written a line per pair, as stdout is). ``--out joints.csv`` was
    written as JSON lines under a name promising CSV; a folder is left to :func:`ready_output`, which names it."""
    if out in (None, "-") or Path(out).suffix.lower() in OUT_SUFFIXES:
        return None
    if os.path.exists(out) and not os.path.isfile(out):
        return None  # a character device or a FIFO: no name to promise a format (a folder: ready_output says so)
    suffix = Path(out).suffix
    kind = f"suffix {suffix!r}" if suffix else "no suffix"
    return (f"--out {out}: {kind}; give a {' or '.join(OUT_SUFFIXES)} file (a JSON list, or one object per "
            "line) or - (stdout)")


def _check_novel_alpha(ap: argparse.ArgumentParser, alpha: float) -> None:
    """The request's own check, said before the model loads and naming the flag: --novel-alpha 3 (or nan) was
    refused only at the first pair, as NovelViewRequest.alpha."""
    try:
        NovelViewRequest(alpha=alpha)
    except GeometryError as e:
        ap.error(f"--novel-alpha {alpha}: {e}")


def _config(args) -> EstimatorConfig:
    cfg = load_config(args.config) if args.config else EstimatorConfig()
    session = cfg.session
    if args.model_dir:
        session = replace(session, model_dir=args.model_dir)
    if args.precision:
        session = replace(session, precision=args.precision)
    if args.threads is not None:  # 0 too: the config's check names it
        session = replace(session, threads=args.threads)
    cfg = replace(cfg, session=session)
    if args.method:
        cfg = replace(cfg, joints3d=replace(cfg.joints3d, method=args.method))
    if args.heatmap_source:
        cfg = replace(cfg, heatmaps=replace(cfg.heatmaps, source=args.heatmap_source))
    if args.flip_test is not None:
        cfg = replace(cfg, heatmaps=replace(cfg.heatmaps, flip_test=args.flip_test))
    if args.smoothing is not None:
        cfg = replace(cfg, smoothing=replace(cfg.smoothing, enabled=args.smoothing))
    if args.skeleton_prior:
        cfg = replace(cfg, joints3d=replace(cfg.joints3d, skeleton_prior=args.skeleton_prior))
    refine = args.refine_cold_start if args.refine_cold_start is not None else (True if args.images else None)
    if refine is not None:
        cfg = replace(cfg, tracking=replace(cfg.tracking, refine_cold_start=refine))
    if args.max_prior_error is not None:
        cfg = replace(cfg, joints3d=replace(cfg.joints3d, max_prior_error_m=args.max_prior_error))
    if args.novel_view:
        nv = replace(cfg.novel_view, enabled=True, heatmaps=cfg.novel_view.heatmaps or args.novel_overlay == "heatmap")
        if args.novel_stride:
            nv = replace(nv, stride=args.novel_stride)
        if args.novel_path:
            nv = replace(nv, path=args.novel_path)
        cfg = replace(cfg, novel_view=nv)
    return cfg


def _check_input_file(path: str, kind: str) -> None:
    """A missing file or a folder said as such: OpenCV prints a "findDecoder" warning of its own for a missing
    image, and a video it cannot open was only "cannot open the video", whatever the reason."""
    if not os.path.exists(path):
        raise UsageError(f"{path}: no such file")
    if os.path.isdir(path):
        raise UsageError(f"{path}: a folder, not {kind}")


def _read_image(path: str) -> np.ndarray:
    _check_input_file(path, "an image")
    img = read_image_or_none(path, cv2.IMREAD_COLOR)  # as stored, whatever its EXIF orientation (image_files)
    if img is None:
        # a JPEG 2000 TIFF was read as a black image, a float TIFF was "not a format OpenCV reads", which it is
        if (cause := unread_because(path, cv2.IMREAD_COLOR)) is not None:
            raise UsageError(f"{path}: cannot take the image: {cause}")
        raise UsageError(f"{path}: cannot read the image (not a format OpenCV reads, or unreadable)")
    return img


def _check_still_sizes(paths: Sequence[str], cameras: Sequence[Camera]) -> None:
    """``--images``: each still whose header gives another size than its camera's is refused before any decode
    (:func:`_check_header_size`); a missing file or a folder is named first, as its read would."""
    for path, camera in zip(paths, cameras):
        _check_input_file(path, "an image")
        _check_header_size(path, camera)


def _check_header_size(path: str, camera: Camera) -> None:
    """Refuses an image whose header gives another size than the rig file's for ``camera``, read without decoding
    it: an 8000x6000 still was decoded whole (about 400 MB) only for the estimator to refuse its size. A header that
    gives no size (another format, a malformed one) is left to the decode and the estimator.

    :raises UsageError: naming the file, the camera and both sizes, in the estimator's words.
    """
    from drivers.backends.recording_format import header_size  # tool only: the runtime library never imports drivers

    size = header_size(Path(path))
    w, h = camera.size
    if size is not None and tuple(size) != (w, h):
        raise UsageError(f"{path}: camera {camera.name!r}: expected a ({h}, {w}, 3) uint8 BGR image (the rig file's "
                         f"{w}x{h}), its header gives {size[0]}x{size[1]} (not decoded)")


class _TimedPair(tuple):
    """Two frames and ``time_s``, the first video's presentation time of them (seconds; ``None``: unknown)."""

    time_s: float | None = None


def _pair_time(cap) -> float | None:
    """The presentation time of the frame ``cap`` just read, seconds; ``None`` where the backend gives none."""
    t = cap.get(cv2.CAP_PROP_POS_MSEC) / 1e3
    return t if math.isfinite(t) else None


def _open_video(path: str):
    """``path`` opened as a ``cv2.VideoCapture`` reading frames as stored; released again when it cannot be. A still
    image is refused: FFmpeg opens a PNG or JPEG as a one-frame video, and the run reported that one pair, exit 0,
    as a clip (or, beside a real video, one pair and "videos end at different frames")."""
    if is_still_image(path):
        raise UsageError(f"--videos {path}: a still image, not a video; give a still pair as --images FIRST SECOND")
    cap = cv2.VideoCapture(path)
    try:
        if not cap.isOpened():  # why, checked only now: OpenCV also opens image-sequence patterns (left_%04d.png)
            _check_input_file(path, "a video")
            raise UsageError(f"{path}: cannot open the video (not a format OpenCV reads, or unreadable)")
        read_as_stored(cap, path)  # a phone's rotation metadata ignored, as an image's EXIF orientation is
    except BaseException:
        cap.release()
        raise
    return cap


def _pairs(args) -> Iterable[tuple[np.ndarray, np.ndarray]]:
    """The input pairs: the two stills, read when the first pair is asked for, or the two videos' frames
    (:class:`_VideoPairs`: the videos opened now)."""
    if args.images:
        return _still_pair(args.images)
    return _VideoPairs(args.videos, args.max_frames)


def _still_pair(paths: Sequence[str]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    yield _read_image(paths[0]), _read_image(paths[1])


def _open_videos(paths: Sequence[str]) -> list:
    """Each video opened (:func:`_open_video`); the ones opened before are released again when the next does not
    open (the first was left to the garbage collector: a file descriptor and a decoder thread held until then)."""
    caps: list = []
    try:
        for path in paths:
            caps.append(_open_video(path))
    except BaseException:
        for cap in caps:
            cap.release()
        raise
    return caps


def _frame_rate(cap) -> float:
    """The rate a video's container states; 30 fps where it states none usable (0, NaN, negative, inf): the pairs'
    times (tracking.max_gap_s) and the written videos assume 30 fps then."""
    fps = cap.get(cv2.CAP_PROP_FPS)
    return fps if math.isfinite(fps) and fps > 0 else 30.0


class _VideoPairs:
    """``--videos``: the two videos, each opened once, here (the run opened the first a second time only to read
    its rate), paired frame by frame as they are read; ``fps`` is the first one's rate (:func:`_frame_rate`).
    :meth:`close` releases them (so does the end of an iteration)."""

    def __init__(self, paths: Sequence[str], max_frames: int | None) -> None:
        self._caps = _open_videos(paths)
        self.fps = _frame_rate(self._caps[0])
        self._max_frames = max_frames

    def __iter__(self) -> Iterator[_TimedPair]:
        try:
            n = 0
            while self._max_frames is None or n < self._max_frames:
                frames = [cap.read() for cap in self._caps]
                ok = [f[0] for f in frames]
                if not any(ok):
                    return
                if not all(ok):
                    log.warning("videos end at different frames; stopping at pair %d", n)
                    return
                pair = _TimedPair((frames[0][1], frames[1][1]))
                pair.time_s = _pair_time(self._caps[0])
                yield pair
                n += 1
        finally:
            self.close()

    def close(self) -> None:
        for cap in self._caps:
            cap.release()


def overlay_image(images, result: PairResult) -> np.ndarray:
    """Both frames side by side with each camera's decoded 2D joints drawn (BGR uint8)."""
    panels = []
    for img, name in zip(images, result.joints_2d):
        scale = max(1, round(max(img.shape[:2]) / 480))
        panels.append(draw_skeleton(img, result.joints_2d[name], ~result.missing_2d[name], thickness=2 * scale))
    h = max(p.shape[0] for p in panels)
    panels = [cv2.copyMakeBorder(p, 0, h - p.shape[0], 0, 0, cv2.BORDER_CONSTANT, value=0) for p in panels]
    return np.hstack(panels)


class _Sink:
    """A PNG (the last frame wins) or an MP4 that grows frame by frame."""

    def __init__(self, path: str, flag: str = "output") -> None:
        try:  # its folder made, or a bad place named, now: not after the whole run
            self.path = path = str(ready_output(path, flag))
        except OutputPathError as e:
            raise UsageError(str(e)) from None
        self.flag = flag  # named in a later error: which of --novel-view and --overlay could not be written
        self.video = Path(path).suffix.lower() in (".mp4", ".avi", ".mkv")
        if not self.video and not cv2.haveImageWriter(path):  # said now, not after the whole run
            raise UsageError(f"{flag} {path}: cannot write an image of this kind; give .png, .jpg or .mp4")
        self.writer = None
        self.fps = 30.0  # the input's rate, set by _run once the inputs are open (before the first frame)
        self.last = None
        self.frames = 0
        self.blank = 0  # frames written black: pairs with no novel view
        self.last_blank = False

    def add(self, image: np.ndarray, blank: bool = False) -> None:
        self.frames += 1
        self.blank += blank
        self.last_blank = blank
        if not self.video:
            self.last = image
            return
        if self.writer is None:
            self.writer = cv2.VideoWriter(self.path, cv2.VideoWriter_fourcc(*"mp4v"), self.fps,
                                          (image.shape[1], image.shape[0]))
            if not self.writer.isOpened():
                raise UsageError(f"{self.flag} {self.path}: cannot write a video here")
        self.writer.write(image)

    def blank_words(self) -> str | None:
        """What the output shows black, for a warning (None: nothing): a black --novel-view with exit 0 and no
        word looked like a broken render, not a pair that showed nobody."""
        if self.video and self.blank:
            return f"{self.flag} {self.path}: {self.blank} of {self.frames} frame(s) black"
        if not self.video and self.last_blank:
            return f"{self.flag} {self.path}: black"
        return None

    def close(self) -> None:
        if self.writer is not None:
            self.writer.release()
        if self.last is not None:
            self._write_image()

    def _write_image(self) -> None:
        """The last frame encoded in memory, then put in place atomically: imwrite truncated the file first, so a
        full disk left an earlier run's image cut short (and OpenCV said no more than False)."""
        try:
            write_image_atomic(self.path, self.last)
        except ImageWriteError as e:
            raise UsageError(f"{self.flag} {self.path}: {e.reason}") from None


def _write_all(fd: int, data: bytes) -> None:
    """``data`` written to ``fd`` whole (``os.write`` may write part of it)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


class _JsonLines:
    """``--out`` as ``.jsonl``: a line per pair, written as each is done, the file opened at the first (an input
    that does not open leaves an earlier file as it was). A line that cannot be written (a full disk) is cut off
    again, so the file holds whole lines only, and the error names --out and how many pairs it holds: it was
    OSError's bare "[Errno 28] No space left on device", the last line left half written."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.file = None
        self.lines = 0
        self.size = 0  # bytes of whole lines written
        self.failed: str | None = None  # the error, said again for any later pair: no line past a gap

    def write(self, obj: dict) -> None:
        if self.failed is not None:
            raise UsageError(self.failed)
        data = (json.dumps(obj, allow_nan=False) + "\n").encode("utf-8")
        try:
            if self.file is None:
                self.file = open(self.path, "wb", buffering=0)
            _write_all(self.file.fileno(), data)
        except OSError as e:
            self._cut_back()
            self.failed = (f"--out {self.path}: cannot write pair {obj.get('sequence')}'s line "
                           f"({e.strerror or e}); it holds the {self.lines} pair(s) before it, whole")
            raise UsageError(self.failed) from None
        self.lines += 1
        self.size += len(data)

    def _cut_back(self) -> None:
        """The file back to its whole lines (a device such as /dev/full cannot be cut: left as it is)."""
        if self.file is None:
            return
        try:
            os.ftruncate(self.file.fileno(), self.size)
        except OSError:
            pass

    def close(self) -> None:
        if self.file is not None:
            self.file.close()


def _ready(path: str, flag: str) -> str:
    """``path`` checked and its folder made before the model loads (:func:`ready_output`)."""
    try:
        return str(ready_output(path, flag))
    except OutputPathError as e:
        raise UsageError(str(e)) from None


def _model_dir_source(args, cfg: EstimatorConfig) -> str | None:
    """What named the model folder (:func:`model_dir_source`): ``--model-dir``, the ``--config``'s key, or None."""
    return model_dir_source(args.model_dir, args.config, cfg.session.model_dir)


def _check_named_model_folder(args, cfg: EstimatorConfig) -> None:
    """``--validate-config``: the model folder that ``--model-dir`` or the config's ``session.model_dir`` names is a
    folder holding the files the settings need (:func:`check_model_files`; nothing loaded). A ``--model-dir`` naming
    a file or no folder passed, exit 0, and the run then stopped on it. The default ``./models``, named by neither,
    is left to the run, which says which option names the folder: a config is checked on a machine without the
    model too.

    :raises UsageError: naming the option (or the config file's key) and its value.
    """
    if not (where := _model_dir_source(args, cfg)):
        return
    try:
        check_model_files(cfg)
    except ModelError as e:
        raise UsageError(named_by_source(where, e, cfg.session.model_dir)) from None


def _refuse_flags_the_settings_ignore(args, cfg: EstimatorConfig) -> None:
    """A flag whose setting the others (or the --config) turn off: it ran, exit 0, the flag without effect.

    :raises UsageError: naming the flag and the setting that turns it off.
    """
    if args.flip_test is not None and cfg.heatmaps.source != "encoder":
        raise UsageError(f"--{'' if args.flip_test else 'no-'}flip-test with heatmaps.source "
                         f"{cfg.heatmaps.source!r}: the flip test runs on the encoder's heatmaps only")
    prior_off = cfg.joints3d.skeleton_prior == "off" or cfg.joints3d.method != "triangulate"
    if args.max_prior_error is not None and prior_off:
        why = (f"joints3d.method {cfg.joints3d.method!r}" if cfg.joints3d.method != "triangulate"
               else "joints3d.skeleton_prior 'off'")
        raise UsageError(f"--max-prior-error with {why}: no skeleton prior runs, so there is nothing to apply it to")


def _say_a_prior_flag_without_a_prior(args, cfg: EstimatorConfig, estimator) -> None:
    """A warning, once at load, where ``--max-prior-error`` is given and no skeleton prior runs after all:
    ``joints3d.skeleton_prior`` 'auto' and a model folder without the prior's file, known only now (the settings
    that turn the prior off are refused before: :func:`_refuse_flags_the_settings_ignore`). It ran, exit 0, the
    flag without effect and without a word. Not refused: a script's flag should survive a change of model folder."""
    if args.max_prior_error is None or getattr(estimator, "skeleton_prior", None) is not None:
        return
    log.warning("--max-prior-error %g has no effect: the model folder %s has no %s, so no skeleton prior runs "
                "(joints3d.skeleton_prior 'auto'; plain triangulation)", args.max_prior_error,
                cfg.session.model_dir, PRIOR_FILE)


def _refuse_model_file_outputs(args, cfg: EstimatorConfig) -> None:
    """No output over a file of the model folder (:func:`model_file_clash`): ``--out
    models/ghnerf/skeleton_prior.json`` replaced the prior's settings with the joints."""
    outputs = {"--out": None if args.out == "-" else args.out, "--overlay": args.overlay,
               "--novel-view": args.novel_view}
    where = _model_dir_source(args, cfg) or f"the default, {cfg.session.model_dir}"
    if clash := model_file_clash(outputs, cfg.session.model_dir, where):
        raise UsageError(clash)


def _run(args) -> int:
    cfg = _config(args)
    _refuse_flags_the_settings_ignore(args, cfg)
    if args.validate_config:
        _check_named_model_folder(args, cfg)
        print(json.dumps(config_to_dict(cfg), indent=2))
        return 0
    _refuse_model_file_outputs(args, cfg)
    to_stdout = args.out == "-"
    out_path = None if to_stdout else _ready(args.out, "--out")
    rig = load_rig(args.rig)
    if args.images:  # before the model loads, as the outputs' places are checked
        _check_still_sizes(args.images, rig.pair)
    try:
        estimator = Estimator.from_config(rig, cfg)
    except ModelLoadError as e:
        # worded as --validate-config words it: a file given as --model-dir was "m.json: is not a folder
        # (session.model_dir names ...)", naming a key the user never typed
        if where := _model_dir_source(args, cfg):
            raise UsageError(named_by_source(where, e, cfg.session.model_dir)) from None
        if Path(cfg.session.model_dir).exists():
            raise
        # the default ./models (no --model-dir, no session.model_dir in --config), run from outside the repository:
        # say which option names the folder
        also = f" or session.model_dir in {args.config}" if args.config else ""
        raise UsageError(f"{e}; pass --model-dir{also} (the repository's models/ holds the shipped model)") from None
    log.info("model %s", json.dumps(estimator.session.describe()))
    _say_a_prior_flag_without_a_prior(args, cfg, estimator)
    request = NovelViewRequest(alpha=args.novel_alpha, overlay=args.novel_overlay) if args.novel_view else None
    novel = _Sink(args.novel_view, flag="--novel-view") if args.novel_view else None
    overlay = _Sink(args.overlay, flag="--overlay") if args.overlay else None
    as_list = not to_stdout and Path(out_path).suffix.lower() == ".json"
    # .jsonl / stdout: a line per pair as it is done (_JsonLines); .json: one list, written whole at the end (below)
    lines = None if to_stdout or as_list else _JsonLines(out_path)
    frames: list[dict] = []
    done = False
    held: dict[int, list[np.ndarray]] = {}  # the pairs in flight, for their overlay
    # each video pair's time as given to the estimator, written beside its joints: with a variable frame rate the
    # sequence number does not say when a pair was filmed (a still pair has none: null)
    times: dict[int, float | None] = {}

    def emit(result) -> None:
        images = held.pop(result.sequence)
        obj = result.to_json()
        pair_time = times.pop(result.sequence, None)
        obj = {"sequence": obj["sequence"],
               "time_s": None if pair_time is None else round(float(pair_time), 6), **obj}
        if as_list:
            frames.append(obj)
        elif lines is not None:
            lines.write(obj)
        else:
            sys.stdout.write(json.dumps(obj, allow_nan=False) + "\n")
            sys.stdout.flush()
        if novel is not None:
            # A pair whose frames were rejected, or that found nobody, has no novel view: keep the video in step
            # with black (said at the end: _say_blank_novel_views).
            blank = result.novel_view is None
            novel.add(np.zeros((estimator.size, estimator.size, 3), np.uint8) if blank else result.novel_view.image,
                      blank=blank)
        if overlay is not None:
            overlay.add(overlay_image(images, result))
        log.info("pair %d: %d/25 joints, %.1f ms", result.sequence, result.num_found, result.timing_ms["total"])

    pairs = _pairs(args)  # the videos opened here, once; their rate read there (after the outputs' places, as ever)
    fps = getattr(pairs, "fps", 30.0)  # stills (or a stand-in iterator): no rate; 30 fps, as for a video without one
    for sink in (novel, overlay):
        if sink is not None:
            sink.fps = fps  # used from its first frame on
    try:
        # Each pair's novel view is finished while the next pair is estimated (the same numbers, more pairs per
        # second: docs/runtime.md, "The novel view alongside the keypoints"); without one, a pair comes out at once.
        with NovelViewPipeline(estimator) as pipe:
            try:
                t = None
                for seq, images in enumerate(pairs):
                    held[seq] = images
                    # the frames' own presentation time where the video gives one after the last pair's: a variable
                    # frame rate (a phone's video), or a container whose rate reads 1000 fps, made seq / fps a wrong
                    # step, and smoothing (tracking.max_gap_s too) runs on the step; else the last time plus a frame
                    shown = getattr(images, "time_s", None)
                    t = shown if shown is not None and (t is None or shown > t) else 0.0 if t is None else t + 1 / fps
                    times[seq] = t if args.videos else None
                    try:
                        finished = pipe.submit(images, sequence=seq, novel_view=request, timestamp_s=t)
                    except FrameError as e:
                        names = args.images or args.videos
                        raise UsageError(f"{names[0]}, {names[1]}: {e}") from e
                    for result in finished:
                        emit(result)
            except (Exception, KeyboardInterrupt) as e:
                if not isinstance(e, BrokenPipeError):
                    with stop_signals_deferred(then_raise=False):  # the stop (or error) on its way is the one said
                        _emit_in_flight(pipe, held, emit)
                raise
            for result in pipe.flush():
                emit(result)
        done = True
        _say_blank_novel_views(novel)
    finally:
        # a Ctrl-C pressed again while the outputs are written is held back (a stop already on its way is the one
        # reported; after a finished run, it is raised once they are whole)
        with stop_signals_deferred(then_raise=done):
            _close_outputs(pairs, as_list, out_path, frames, done, lines, (novel, overlay))
    return 0


def _say_blank_novel_views(novel: _Sink | None) -> None:
    """A warning where --novel-view shows black: no view for a pair that shows nobody (the presence gate) or
    whose frames the frame check rejected (docs/runtime.md, "Compute only what the scene requires")."""
    words = novel.blank_words() if novel is not None else None
    if words is not None:
        log.warning("%s: no novel view for a pair that shows nobody or whose frames were rejected (the pair's "
                    "\"missing\" and \"frame_reason\" say which)", words)


def _close_outputs(pairs, as_list: bool, out_path: str | None, frames: list[dict], done: bool, out_file,
                   sinks) -> None:
    """The inputs released and the outputs written whole: the ``.json`` list or the ``.jsonl`` file, then the
    videos and images (closed whatever the joints' write raised)."""
    close_pairs = getattr(pairs, "close", None)  # _pairs' generator; any iterator of pairs will do
    if close_pairs is not None:
        close_pairs()  # the videos' captures released now, not when the generator is collected later
    try:
        if as_list:
            _write_list(out_path, frames, done)
        elif out_file is not None:
            out_file.close()
    finally:
        for sink in sinks:
            if sink is not None:
                sink.close()


def _emit_in_flight(pipe: NovelViewPipeline, held: dict, emit) -> None:
    """On a stop (an error in the next pair, Ctrl-C): the pair whose view was being finished is one the run
    finished, written as one by one it was before the next pair began (dropped, a stop lost it). Only the next
    pair in order: a pair after one whose view failed is not written past the gap; the first error stands."""
    try:
        in_flight = pipe.flush()
    except Exception:  # its view failed as well: the error already on its way is the one reported
        return
    for result in in_flight:
        if result.sequence == min(held, default=None):
            emit(result)


def _write_list(path: str, frames: list[dict], done: bool) -> None:
    """The ``.json`` list, replacing the file atomically (an earlier file stays whole until the new one is): a
    run stopped by an error or Ctrl-C keeps the pairs it finished (a shorter list; the exit status is not 0),
    and one that finished none leaves an earlier file as it was."""
    if not (done or frames):
        return
    write_text_atomic(path, json.dumps(frames, allow_nan=False) + "\n")  # the rig file's writer: fsynced
    if not done:
        print(f"ghnerf-run: stopped early; the {len(frames)} pair(s) finished are in {path}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    _check_args(ap, args)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    # SIGTERM (timeout, systemd, docker) stops a run as Ctrl-C does: the outputs are closed whole
    try:
        # the rig file's notes (INFO) shown without --verbose too, beside its warnings: a rig that cuts a standing
        # person loaded without a word otherwise
        with sigterm_as_interrupt(), rig_notes_let_through():
            return _run(args)
    except KeyboardInterrupt as e:
        print(f"ghnerf-run: stopped ({stop_signal(e).name}); the outputs hold the pairs finished", file=sys.stderr)
        return exit_status(e)  # the shell's figure for a death by that signal: 130, 143
    except BrokenPipeError:  # `ghnerf-run ... | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at exit's flush
        return 0
    except (RuntimeErrorBase, OSError) as e:
        print(f"ghnerf-run: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
