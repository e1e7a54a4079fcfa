"""``ghcal``: calibrate the two-camera rig with a printed ChArUco board and write the rig file.

Workflow (docs/calibration.md)::

    ghcal board --out board/                        # board/board.png to print, board/board.json its definition
    ghcal capture --url depthai:// --board board/board.json --out capture/          # 20 views, moving the board
    ghcal capture --url depthai:// --board board/board.json --out capture/ --floor  # one view, board on the floor
    ghcal solve --board board/board.json --images capture/ --floor-view floor --out rig.json
    ghcal check --rig rig.json --board board/board.json --images capture/        # later: does it still fit?

``ghcal synth --out synth/`` renders the views a careful user would take, of a known rig, so the
tool can be tried (and is tested) without cameras. A rig calibrated with another tool comes in (and goes
out) through ``ghcal import`` / ``ghcal export`` (OpenCV FileStorage YAML/XML/JSON, anipose
``calibration.toml``; docs/rig-file.md, "Importing and exporting")::

    ghcal import calibration.toml --units-to-metres 0.001 --camera-height 1.4 --pitch 10 --out rig.json
    ghcal export --rig rig.json --out rig.yml

Exit status: 0 on success (warnings are printed, not fatal), 2 for an error the user fixes (the
message names the file, folder, camera or key); 130 after Ctrl-C, 143 after SIGTERM, each with one line
(``capture``: 0 when it kept views, as its normal end; 2 when a ``record+`` take recorded with it failed as it
closed, since session 75, also where a stop lands after the cameras' close: ``RecordedTake``; 2 for an error that
ended it, also where a stop lands as that error leaves: ``error_leaving``).
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import signal
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np

from calibration.board import BoardSpec, load_board, png_with_dpi
from calibration.capture import (CAMERAS_FILE, IMAGE_SUFFIXES, camera_folders, check_camera_name, earlier_size,
                                 earlier_views, list_images, next_view_number, read_camera_order, read_folder,
                                 write_camera_order)
from calibration.check import (FLOOR_VIEW, CheckLimits, check_failures, check_rig, exchanged_fit, exchanged_report,
                               floor_unmeasured, sized_as_exchanged)
from calibration.detect import (PATTERN_CHECK_MARKERS, BoardDetector, BoardView, board_mismatch, markers_in_view,
                               mirrored_corners, mirrored_words)
from calibration.errors import BoardError, CalibrationError, CaptureError
from calibration.image_sizes import camera_image_sizes, mixed_sizes_problem
from calibration.render import SYNTH_BOARD, calibration_views, synth_rig
from calibration.solve import LENS_MODELS, MIN_VIEWS, REPEAT_PX, repeated_views, solve_rig, typed_pitch_warning
from calibration.synth_views import (image_digest, images_not_written, read_synth_views, remove_earlier_views,
                                     write_synth_views)
from ghnerf_runtime.cli.counts import bounded_count, image_size, non_negative_count, positive_count
from ghnerf_runtime.cli.error_leaving import ErrorLeaving, status_keeping_the_error
from ghnerf_runtime.cli.output_path import dangling_link_words, existing_ancestor, same_file, unwritable_reason
from ghnerf_runtime.cli.recorded_take import RecordedTake, status_saying_a_failed_take
from ghnerf_runtime.cli.rig_messages import log_on_stderr, rig_messages_on_stderr
from ghnerf_runtime.cli.sigterm import (closed_with_stops_deferred, exit_status, sigterm_as_interrupt, stop_signal,
                                      stop_signals_deferred, stop_signals_noted, stop_words)
from ghnerf_runtime.errors import RigFileError, RuntimeErrorBase
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.rig_file import (CAMERA_HEIGHT_RANGE_M, camera_height_warning, checked_rig_text,
                                     lens_fold_warning, load_rig, log_warnings_and_notes,
                                     volume_reach_problem_from, write_bytes_atomic, write_text_atomic)
from ghnerf_runtime.path_check import user_path

__all__ = ["main", "build_parser"]

PROG = "ghcal"


class UsageError(CalibrationError):
    """A command-line value the user fixes."""


#: ``capture --floor``: the board counts as lying still while its corners stay this close to where they
#: were when it came to rest (median and 90th percentile over the corners, pixels).
STILL_MEDIAN_PX = 0.3
STILL_P90_PX = 1.5
#: ``capture`` (hand-held views): the board counts as held still within these; looser than the floor's,
#: for a hand's tremor, tight enough that a board swept through the view (blurred, and seen at two
#: places by cameras that are not triggered together) never passes.
HELD_MEDIAN_PX = 1.0
HELD_P90_PX = 2.5
#: ``capture``: seconds without an image pair before it says so (once, until pairs come again).
STALL_NOTE_S = 5.0
#: What the joint stream's HELLO carries (firmware_host.protocol.constants; this package may not import it).
MAX_RIG_ID_LEN = 32
MAX_CAMERA_NAME_LEN = 16
#: The board definition ``ghcal synth`` writes beside its views, and ``solve`` / ``check`` look for there.
BOARD_FILE = "board.json"
#: The rig ``ghcal synth`` rendered its views of, written beside them.
TRUTH_RIG_FILE = "truth_rig.json"
#: ``board``: a square must be this many pixels for its marker to be drawn (``BoardSpec.image``), and the print
#: at most this many megapixels (a mistyped --dpi 100000 asked for terabytes).
MIN_PX_PER_SQUARE = 20
MAX_BOARD_MEGAPIXELS = 400
#: ``synth --count``/``--edge-count`` and ``capture --count``: at most this many views. 15-20 solve a pair
#: (the defaults); a mistyped ``--count 100000000`` had no end short of a full disk.
MAX_VIEWS = 100


def _stream_name(text: str, limit: int, what: str) -> str:
    if not (0 < len(text) <= limit and text.isascii() and text.isprintable()):
        raise UsageError(f"{what} {text!r} must be printable ASCII of 1-{limit} characters (the joint stream "
                         "announces it)")
    return text


def _board(path: str | None) -> BoardSpec:
    """``board``, ``capture``: the given board, else the default (they print or detect it; ``synth`` renders a larger
    one by default, ``calibration.render.SYNTH_BOARD``)."""
    return load_board(path) if path else BoardSpec()


def _board_source(path: str | None) -> str:
    return path if path else "the default board (no --board)"


def _describe(board: BoardSpec) -> str:
    return (f"{board.squares_x}x{board.squares_y} squares of {1000 * board.square_m:g} mm, markers of "
            f"{1000 * board.marker_m:g} mm, {board.dictionary}")


def _measuring_board(given: str | None, images: str, recorded: BoardSpec | None = None) -> tuple[BoardSpec, str]:
    """``solve`` / ``check``: the board and where it came from: ``--board``, else ``board.json`` beside the
    images, else (``check``) the board the rig records. Never the default board: its 80 mm squares
    scaled the whole rig silently when ``--board`` was forgotten."""
    if not Path(images).is_dir():  # before the board: a mistyped folder is not a missing board
        raise UsageError(f"--images {images}: no such folder of calibration images (one subfolder per camera)")
    if given:
        return load_board(given), given
    beside = Path(images) / BOARD_FILE
    if beside.is_file():
        return load_board(beside), f"{beside} (beside the images)"
    if recorded is not None:
        return recorded, "the one the rig file records"
    raise UsageError(f"no board: pass --board FILE, the board.json that 'ghcal board' wrote with the square size "
                     f"measured on the print ({beside} does not exist)")


def _calibration_record(rig) -> dict:
    """What ``solve`` recorded in the rig's metadata (empty for rigs from elsewhere or older ones)."""
    record = rig.metadata.get("calibration")
    return record if isinstance(record, dict) else {}


def _recorded_board(rig, rig_path: str) -> BoardSpec | None:
    data = _calibration_record(rig).get("board")
    return None if data is None else BoardSpec.from_dict(data, path=f"{rig_path}: metadata.calibration.board")


def _recorded_floor_view(rig, rig_path: str) -> str | None:
    """The floor view ``solve`` levelled from (``metadata.calibration.floor_view``), None where it recorded none
    (levelled with --camera-height) or the rig is not ghcal's. A value that is no view name is refused: it fell
    back to ``floor`` without a word, so the levelling was checked on another view than the rig's, or not at
    all, and the floor is the only figure a rig tilted on its mount shows in (``--floor-view`` overrides it)."""
    record = _calibration_record(rig)
    value = record.get("floor_view")
    if value is None:
        return None
    if not isinstance(value, str) or not value or any(c in value for c in "/\\"):
        raise RigFileError(f"{value!r} is not a view name (a file name without its suffix, as given to 'ghcal "
                           "solve --floor-view'; null for a rig levelled with --camera-height): correct the rig "
                           "file, or pass --floor-view NAME", path=rig_path, field="metadata.calibration.floor_view")
    return value


def _recorded_thickness(rig, rig_path: str) -> float:
    """The floor board's thickness ``solve`` levelled with (0 where it recorded none: other rigs): checked with
    another, the floor view of the very images solved from lay that difference off the floor, and a 30 mm board
    failed the check. A value that is no thickness ``solve`` takes is refused: it was read as 0 without a word,
    so a rig levelled on a 30 mm board (typed "0.03", or 30 for millimetres) was blamed for lying 30 mm off."""
    value = _calibration_record(rig).get("board_thickness_m")
    if value is None:
        return 0.0
    if (isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
            or not 0.0 <= value <= 0.1):
        raise RigFileError(f"{value!r} is not a board thickness (a number of metres in [0, 0.1], as given to 'ghcal "
                           "solve --board-thickness'; 0 for a board lying flat): correct the rig file, or pass "
                           "--board-thickness METRES", path=rig_path, field="metadata.calibration.board_thickness_m")
    return float(value)


def _existing_capture(out: Path) -> Path | None:
    """Something in ``out`` that ``synth`` would overwrite or mix its views with: a board or camera-order
    file, or an image at the top or in a camera folder."""
    if not out.is_dir():
        return None
    for name in (BOARD_FILE, CAMERAS_FILE):
        if (out / name).exists():
            return out / name
    for path in sorted(out.iterdir()):
        inside = sorted(path.iterdir()) if path.is_dir() else [path]
        for item in inside:
            if item.suffix.lower() in IMAGE_SUFFIXES:
                return item
    return None


def _output_folder(out: Path, what: str) -> None:
    """``--out`` of ``board``, ``synth`` and ``capture``: a folder that is, or can be made, and takes new files.
    Checked before the work (``synth`` renders for half a minute, ``capture`` opens the cameras), and said with
    the flag: a file given for it stopped them after that work with OSError's bare ``[Errno 17] File exists``."""
    dangling = dangling_link_words(out)
    if dangling is not None:  # mkdir said only "[Errno 17] File exists"
        raise UsageError(f"--out {out}: {dangling} or give another folder")
    base = existing_ancestor(out)
    if not base.is_dir():
        raise UsageError(f"--out {out}: {base} is a file; give a folder for {what}")
    reason = unwritable_reason(base)
    if reason is not None:
        raise UsageError(f"--out {out}: cannot write {what} in {base} ({reason})")


def _volume(text: str | None) -> WorkingVolume | None:
    if text is None:
        return None
    try:
        values = [float(v) for v in text.split(",")]
        if len(values) != 6:
            raise ValueError
        return WorkingVolume(np.array(values[:3]), np.array(values[3:]))
    except (ValueError, RuntimeErrorBase) as e:
        raise UsageError(f"--volume must be six numbers xmin,ymin,zmin,xmax,ymax,zmax (metres, rig frame), "
                         f"min < max, got {text!r}") from e


def _solve_volume(text: str | None) -> WorkingVolume | None:
    """``solve``'s ``--volume``, checked before the detection by the rig file's reach rule, seen from the rig frame's
    origin: the solved cameras are not known yet, and stand within a few metres of it (on the floor below the pair)."""
    volume = _volume(text)
    if volume is None:
        return None
    origin = Camera("origin", 640, 480, K=np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]))
    if problem := volume_reach_problem_from(volume, [origin]):
        raise UsageError(f"--volume {text}: {problem}")
    return volume


def _cameras(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [n for n in text.split(",") if n]
    if len(names) != 2 or len(set(names)) != 2:
        raise UsageError(f"--cameras must name two cameras, FIRST,SECOND, got {text!r}")
    return names


def _refuse_reversed_order(cameras: list[str] | None, recorded: list[str] | None, images: str) -> None:
    """Refuse ``--cameras`` naming the capture's two cameras in the other order than its ``cameras.json``. The rig
    file's first camera is the one the rig source opens first (``opencv://?first=``), so the reversed order bound
    each camera's lens and pose to the other one's images, and the rig file loaded without a word."""
    if cameras is None or recorded is None or cameras == recorded or sorted(cameras) != sorted(recorded):
        return
    raise UsageError(f"--cameras {','.join(cameras)} reverses the order {Path(images) / CAMERAS_FILE} records "
                     f"({','.join(recorded)}: {recorded[0]!r} is the camera the rig source opened first, "
                     f"opencv://?first=), so the rig file would give each camera the other's lens and pose. Leave "
                     "--cameras out; to make the other camera the first on purpose, swap first= and second= in the "
                     f"rig URL and edit {CAMERAS_FILE} to match")


# ------------------------------------------------------------------ board
def cmd_board(args: argparse.Namespace) -> int:
    board = _board(args.board)
    out = Path(args.out)
    _output_folder(out, "the board")
    out.mkdir(parents=True, exist_ok=True)
    px = int(round(board.square_m / 0.0254 * args.dpi))
    if px < MIN_PX_PER_SQUARE:  # the markers' cells would not be drawn
        raise UsageError(f"--dpi {args.dpi}: a square of {1000 * board.square_m:g} mm would be {px} px; at least "
                         f"{MIN_PX_PER_SQUARE} are needed: --dpi {math.ceil(MIN_PX_PER_SQUARE * 0.0254 / board.square_m)} "
                         "or more")
    megapixels = (board.squares_x + 1) * (board.squares_y + 1) * px * px / 1e6  # the margins add a square
    if megapixels > MAX_BOARD_MEGAPIXELS:
        raise UsageError(f"--dpi {args.dpi}: the print would be {megapixels:.0f} megapixels (at most "
                         f"{MAX_BOARD_MEGAPIXELS}); 300 dpi is plenty for a board")
    image = board.image(px_per_square=px, margin_px=px // 2)
    png, spec = out / "board.png", out / "board.json"
    kept = _board_file_kept(spec, board, args.force)
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise UsageError(f"{png}: cannot encode the image")
    # the PNG says its dpi (printed at 100 %, to scale); written aside and renamed, so a Ctrl-C while the print's
    # megabytes are written leaves the earlier board.png, not a cut-off one
    write_bytes_atomic(png, png_with_dpi(encoded.tobytes(), args.dpi))
    if not kept:
        write_text_atomic(spec, json.dumps(board.to_dict(), indent=2) + "\n")
    w_cm, h_cm = (100 * image.shape[1] / args.dpi * 0.0254, 100 * image.shape[0] / args.dpi * 0.0254)
    # a square is a whole number of pixels: at a low dpi the print's squares differ from square_m
    printed_mm = 1000 * px / args.dpi * 0.0254
    print(f"wrote {png} ({image.shape[1]}x{image.shape[0]} px at {args.dpi} dpi) and "
          + (f"left {spec} as it is (it defines this board)" if kept else f"{spec}"))
    print(f"print it at {args.dpi} dpi, 100 % scale (no 'fit to page'): {w_cm:.1f} x {h_cm:.1f} cm with its margin; "
          f"{board.squares_x}x{board.squares_y} squares of {printed_mm:.2f} mm"
          + (f" ({px} px each; the board file says {1000 * board.square_m:g} mm)"
             if abs(printed_mm / (1000 * board.square_m) - 1) > 0.001 else ""))
    print(f"then measure a square with a ruler and put the measured size in {spec} (square_m, and marker_m "
          "scaled alike); glue the print to something flat and rigid")
    return 0


def _board_file_kept(spec: Path, board: BoardSpec, force: bool) -> bool:
    """Whether ``board`` leaves the ``board.json`` at ``spec`` as it is: it defines ``board`` already. Written back,
    ``board --board OUT/board.json --out OUT`` replaced the file the user measured and typed in with its own layout
    (until session 74).

    :raises UsageError: without ``force``, a file there that does not load or defines another board.
    """
    if not spec.exists():
        return False
    try:
        same = load_board(spec) == board
    except CalibrationError as e:  # said why: it was called "another board", its fault not named
        if force:
            return False
        raise UsageError(f"{e} (the board.json in --out, not loaded: it may hold the square size measured on "
                         "the print): fix it, or pass --force to replace it") from e
    if not same and not force:
        # it may hold the square size measured on the print: overwritten with the defaults, every
        # later solve would be scaled wrong
        raise UsageError(f"{spec} exists and defines another board (measured on the print?): give it as "
                         f"--board {spec} to print it again, or --force to replace it")
    return same


# ------------------------------------------------------------------ synth
def cmd_synth(args: argparse.Namespace) -> int:
    board = load_board(args.board) if args.board else SYNTH_BOARD  # large enough to be read lying on the floor
    rig = load_rig(args.rig) if args.rig else synth_rig()
    for cam in rig.pair:
        check_camera_name(cam.name)
    out = Path(args.out)
    _output_folder(out, "the views")  # before the half minute of rendering
    found = _existing_capture(out)
    if found is not None and not args.force:  # real captures, or their measured board.json, overwritten
        raise UsageError(f"{out} already holds views or a board ({found}): render into a new folder "
                         "(--out synth/), or pass --force to write over it")
    for camera in (cam.name for cam in rig.pair):  # a camera's folder taken by a file, found before rendering too
        if (out / camera).exists() and not (out / camera).is_dir():
            raise UsageError(f"--out {out}: {out / camera} is a file, where the views of camera {camera!r} go")
    # made before the rendering: the rig's text is checked, and an input among them found (_unchanged_inputs)
    texts = {out / TRUTH_RIG_FILE: checked_rig_text(rig, out / TRUTH_RIG_FILE),
             out / BOARD_FILE: json.dumps(board.to_dict(), indent=2) + "\n"}
    unchanged = _unchanged_inputs(texts, {"--rig": args.rig, "--board": args.board})
    earlier = read_synth_views(out) if args.force else {}  # a record that does not read stops before the rendering
    t0 = time.monotonic()
    views = calibration_views(rig, board, count=args.count, edge_count=args.edge_count, seed=args.seed)
    written: dict[str, dict[str, str]] = {}
    for camera, images in views.items():
        (out / camera).mkdir(parents=True, exist_ok=True)
        written[camera] = {f"{name}.png": _write_png(out / camera / f"{name}.png", image)
                           for name, image in images.items()}
    removed = remove_earlier_views(out, earlier, written)  # the earlier run's views beyond this one's: not mixed in
    write_synth_views(out, written)
    for path, text in texts.items():
        if path not in unchanged:
            write_text_atomic(path, text)
    if not args.rig:  # (a --rig file's warnings and notes were said as it loaded)
        log_warnings_and_notes(rig, out / TRUTH_RIG_FILE)
    write_camera_order(out, [cam.name for cam in rig.pair], replace=True)
    total = len(next(iter(views.values())))
    gone = f"; removed {len(removed)} images of the earlier ghcal synth run" if removed else ""
    print(f"rendered {total} image pairs (a floor view among them) of rig {rig.rig_id!r} into {out} in "
          f"{time.monotonic() - t0:.1f} s; its rig: {out / TRUTH_RIG_FILE}, board: {out / BOARD_FILE}{gone}")
    left = images_not_written(out, [cam.name for cam in rig.pair], written)
    if left:
        print(f"warning: {len(left)} images there are not this run's and were left ({_first_few(left)}): ghcal solve "
              f"on {out} reads them with its views; remove them, or render into a new folder", file=sys.stderr)
    return 0


def _write_png(path: Path, image: np.ndarray) -> str:
    """Write ``image`` as the PNG ``path``; returns the SHA-256 of its bytes (``synth_views.json`` records it)."""
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise UsageError(f"{path}: cannot encode the image")
    data = encoded.tobytes()
    try:
        path.write_bytes(data)
    except OSError as e:
        raise UsageError(f"{path}: cannot write the image ({e.strerror or e})") from e
    return image_digest(data)


def _first_few(paths: Sequence[Path], shown: int = 3) -> str:
    """``paths`` named, the first ``shown`` of them, and how many more."""
    words = ", ".join(str(p) for p in paths[:shown])
    return words if len(paths) <= shown else f"{words} and {len(paths) - shown} more"


def _unchanged_inputs(texts: Mapping[Path, str], inputs: Mapping[str, str | None]) -> set[Path]:
    """The files of ``texts`` (path -> the text ``synth`` writes there) that are one of ``inputs`` (flag -> path;
    ``None`` for one not given) and hold that text already: left as they are, the write a no-op.

    ``synth --rig synth/truth_rig.json --out synth --force`` wrote back the rig it read: re-rendering in place is fine,
    but a rig or board file in other words (edited by hand, or by an older version) was replaced by synth's own.

    :raises UsageError: an input whose text would change, naming the flag, the file and the clash.
    """
    unchanged = set()
    for flag, given in inputs.items():
        for path, text in texts.items():
            if given is None or not same_file(path, given):
                continue
            if Path(given).read_bytes() != text.encode("utf-8"):
                raise UsageError(f"{flag} {given} is {path}, which synth writes, and written back its text would "
                                 f"change (synth writes its own layout of what it read): give --out another folder, "
                                 f"or copy {flag}'s file elsewhere and give the copy")
            unchanged.add(path)
    return unchanged


# ------------------------------------------------------------------ capture
# Capture stamps are whole nanoseconds read as float seconds: frame 3 of a 10 fps video minus frame 0 came to
# 0.29999999999999993 s for about half of the frame numbers, and a pose held exactly --still-s was not yet held.
CAPTURE_TIME_SLACK_S = 1e-6


def _sooner_than(elapsed_s: float, wanted_s: float) -> bool:
    """Whether ``elapsed_s`` of capture time falls short of ``wanted_s``, beyond the stamps' rounding."""
    return elapsed_s < wanted_s - CAPTURE_TIME_SLACK_S


def _still_since(view: BoardView | None, reference: BoardView | None, *, median_px: float = STILL_MEDIAN_PX,
                 p90_px: float = STILL_P90_PX) -> bool:
    """Whether ``view`` shows the board where ``reference`` did: robust to detection jitter (a corner or
    two rebuilt from flickering markers), strict about drift (compared with the start, not the last frame)."""
    if view is None or reference is None:
        return False
    ids = np.intersect1d(view.ids, reference.ids)
    if ids.size < 0.8 * len(reference):
        return False
    moves = np.linalg.norm(view.corners[np.searchsorted(view.ids, ids)]
                           - reference.corners[np.searchsorted(reference.ids, ids)], axis=1)
    return float(np.median(moves)) < median_px and float(np.percentile(moves, 90)) < p90_px


def _held_since(found: list[BoardView | None], reference: list[BoardView | None]) -> bool:
    """Every camera sees the board as it did in ``reference`` (held still), or missed it both times."""
    return all((v is None and r is None) or _still_since(v, r, median_px=HELD_MEDIAN_PX, p90_px=HELD_P90_PX)
               for v, r in zip(found, reference))


def _largest_move_px(view: BoardView | None, last: BoardView | None) -> float | None:
    """The largest displacement of a corner both views found (None: nothing to compare)."""
    if view is None or last is None:
        return None
    ids = np.intersect1d(view.ids, last.ids)
    if ids.size == 0:
        return None
    here = view.corners[np.searchsorted(view.ids, ids)]
    there = last.corners[np.searchsorted(last.ids, ids)]
    return float(np.max(np.linalg.norm(here - there, axis=1)))


def _write_view(folders: list[Path], name: str, images: Sequence[np.ndarray]) -> None:
    """Both images of a view as ``FOLDER/NAME.png``, each written aside and renamed into place only once both
    are: a capture stopped (Ctrl-C) or killed while writing left half a pair, or a cut-off PNG that stopped the
    solve ("not a readable image"). The caller holds the stop signals over it (the two renames are two steps); a
    kill between them leaves one camera's image, which the solve names ("no namesake in the other folder")."""
    staged: list[tuple[Path, Path]] = []
    try:
        for folder, image in zip(folders, images):
            ok, encoded = cv2.imencode(".png", image)
            if not ok:
                raise CaptureError(f"{folder / name}.png: cannot encode the image")
            tmp = folder / f".{name}.png.tmp"  # not an image suffix: never read as a view
            tmp.write_bytes(encoded.tobytes())
            staged.append((tmp, folder / f"{name}.png"))
        for tmp, final in staged:
            os.replace(tmp, final)
    finally:
        for tmp, _ in staged:
            tmp.unlink(missing_ok=True)


def every_frame_of_two_videos(url: str) -> str:
    """``url`` with ``policy=all`` added where it plays two video files (``opencv://``) and names no ``policy``,
    also wrapped (``record+opencv://...``: any wrapper of :data:`drivers.wrappers.WRAPPERS`).

    A capture from recordings is not live: under the driver's default ``latest`` the videos play on at their
    rate, and a host whose board detection is slower than a held pose skips it (fewer views, without a word).
    Live cameras, other schemes and a URL that chooses its ``policy`` are left as they are; a URL that does not
    parse is too (opening it reports the error). Before session 66 a wrapped URL kept ``latest``: recording the
    calibration while capturing it (``record+``) dropped the held poses and the take's frames alike."""
    from drivers.backends.opencv import is_video_file
    from drivers.errors import RigConfigError
    from drivers.wrappers import innermost_url
    from drivers.url import RigUrl

    try:
        # the wrappers' options share the query with the backend's, so the option added reaches the backend
        parsed = RigUrl.parse(innermost_url(url))
    except RigConfigError:
        return url
    specs = [parsed.options.get(option) for option in ("first", "second")]
    if parsed.scheme != "opencv" or "policy" in parsed.options or not all(specs):
        return url
    if not all(is_video_file(spec) for spec in specs):
        return url
    return url + ("&" if "?" in url else "?") + "policy=all"


def cmd_capture(args: argparse.Namespace) -> int:
    import drivers

    board = _board(args.board)
    out = Path(args.out)
    # before the cameras are opened (seconds for an OAK): a folder it cannot write, or another session's views
    _output_folder(out, "the views")
    earlier = earlier_views(out)
    if earlier and not args.floor and not args.append:
        # mixed silently with a session from before the rig was moved, its pairs were dropped by the
        # solve as "not taken at the same instant", or outvoted the new ones
        names = sorted({p.stem for p in earlier})
        raise UsageError(f"{out} already holds {len(names)} views from an earlier capture ({names[0]}-{names[-1]}): "
                         "capture into a new folder, or pass --append to add to them (the cameras not moved since)")
    url = every_frame_of_two_videos(args.url)
    if url != args.url:
        print(f"{PROG}: note: reading every frame of the two videos (policy=all added to --url: a capture slower "
              "than the videos would skip held poses); add policy=latest to play them at their rate",
              file=sys.stderr)
    source = drivers.create_rig_source(url)
    take = RecordedTake(source, PROG)
    # a stop landing after the cameras' close, before the take's check or in the summary, was said "the capture did
    # not finish", 130 or 143, of a take that failed; one landing as an error left, in the error's place
    return status_keeping_the_error(lambda leaving: status_saying_a_failed_take(
        lambda: _capture_and_summarise(args, board, out, earlier, source, take, leaving), take))


def _capture_and_summarise(args: argparse.Namespace, board: BoardSpec, out: Path, earlier: Sequence[Path],
                           source, take: RecordedTake, leaving: ErrorLeaving) -> int:
    """The capture from ``source`` (a ``drivers.RigSource``), opened here and closed however the capture ends: the
    views kept into ``out``, after the ``earlier`` ones, then its last line; the exit status. An error on its way out
    is noted in ``leaving`` as it leaves the reading."""
    import drivers
    from drivers.base import log as rig_source_log
    from drivers.url import redact_url

    detector = BoardDetector(board)
    count = 1 if args.floor else args.count
    kept, ended, last_kept_at = 0, False, -1e9
    skipped, read_failed = 0, False  # frames the rig could not deliver; one since the last pair
    last_views: list[BoardView | None] = [None, None]
    steady_since = 0.0  # when the board came to rest (read only once ``resting`` is set)
    resting: list[BoardView | None] = [None, None]  # --floor: the views where the board came to rest
    holding: list[BoardView | None] = [None, None]  # the views where the hand-held board stopped
    holding_since = 0.0
    # until the board is first seen, every STALL_NOTE_S: a board file with another marker dictionary finds no
    # marker at all, and the capture ran its --max-seconds without a word
    board_seen, mismatch_check_at = False, -math.inf
    markers_said = False  # the board's markers seen, the board never: said once
    shown_url = redact_url(args.url)  # a camera URL may carry a password (rtsp://user:pass@..., token=)
    read_to_its_end = False  # the capture ended without a stop (caught below) or an error on its way out
    stopped: KeyboardInterrupt | None = None  # Ctrl-C or SIGTERM: the capture's normal end, said after the close
    # the first stop of a capture that read to its end, landing before the close: raised once the take is closed
    late_stops: list[KeyboardInterrupt] = []
    # entered as the reading ends (a stop, an error, its end), left once the cameras are closed: a stop landing just
    # before the close (outside its deferral) skipped it, the take left complete: false. A second Ctrl-C or SIGTERM
    # just after it ended the capture "did not finish", 130 or 143, in place of the first stop's views kept (0):
    # noted and dropped; the first stop of a capture that read to its end is noted (late_stops) and raised
    stops_held = contextlib.ExitStack()
    try:
        # what the open warns and notes of the rig (a take's, a device's calibration, sim://'s) is logged by the
        # source, not the rig file: shown as main shows a loaded rig's, its notes too (Python showed the warnings)
        with log_on_stderr(rig_source_log):
            source.open()
        cams = [check_camera_name(c.name) for c in source.rig.pair]
        folders = [out / cam for cam in cams]
        for cam, folder in zip(cams, folders):  # mkdir said only "[Errno 17] File exists", after cameras.json
            if (dangling := dangling_link_words(folder)) is not None:  # exists() says no: the link's target does not
                raise UsageError(f"--out {out}: {dangling}, or give another folder")
            if folder.exists() and not folder.is_dir():
                raise UsageError(f"--out {out}: {folder} is a file, where camera {cam!r}'s images go: move it away "
                                 "or give another folder")
        if args.floor and not args.force and any((f / f"{FLOOR_VIEW}{suffix}").exists()
                                                 for f in folders for suffix in IMAGE_SUFFIXES):
            raise UsageError(f"{out} already has a floor view: pass --force to replace it")
        out.mkdir(parents=True, exist_ok=True)
        write_camera_order(out, cams)  # the stream's order: solve keeps it (folder names may sort the other way)
        for folder in folders:
            folder.mkdir(parents=True, exist_ok=True)
        number = next_view_number(folders)
        replaced = {FLOOR_VIEW} if args.floor and args.force else set()
        # the views already there (--append, --floor): one of another size is another rig or resolution
        sizes = [earlier_size(folder, skip=replaced) for folder in folders]
        print(f"capturing from {shown_url} (cameras {cams}) into {out}"
              + (f", after the {len({p.stem for p in earlier})} views there (numbered from {number:03d})"
                 if earlier and not args.floor
                 else "") + ": "
              + (f"lay the board flat on the floor, face up, where both cameras see it, and leave it "
                 f"({args.steady_s:g} s still)" if args.floor else
                 f"{count} views; move the board between them: near and far, tilted, into each image's corners, "
                 "mostly where both cameras see it"))
        deadline = time.monotonic() + args.max_seconds
        last_pair_at, stall_said = time.monotonic(), False
        while kept < count and time.monotonic() < deadline:
            try:
                pair = source.read(timeout_s=2.0)
            except drivers.RigTimeoutError:
                # a camera that stops delivering without a disconnect (a hung USB camera) kept the capture
                # waiting up to --max-seconds (10 minutes) without a word
                if not stall_said and time.monotonic() - last_pair_at >= STALL_NOTE_S:
                    print(f"{PROG}: no image pair from {shown_url} for {time.monotonic() - last_pair_at:.0f} s: is a "
                          "camera stalled or unplugged? (waiting up to --max-seconds; Ctrl-C ends the capture)",
                          file=sys.stderr)
                    stall_said = True
                continue
            except drivers.EndOfStream:
                ended = True
                break
            except drivers.DriverError as e:  # a camera unplugged or failed: say what the session kept
                # A frame the rig could not deliver (a corrupt image in a replay:// take) is raised once and the
                # next read goes on, as ghnerf-demo and the daemon read on: one such frame ended the capture and
                # lost the take's views after it. A camera gone (RigDisconnectedError: the live backends' unplug),
                # cameras of another size than the rig's (FrameSizeError), a record+ take no longer written
                # (RecordingError) or a second failure before a pair (a backend that failed for good raises
                # its error at every read) still end it.
                if (isinstance(e, drivers.RigOperationError) and not read_failed
                        and not isinstance(e, (drivers.RigDisconnectedError, drivers.FrameSizeError,
                                               drivers.RecordingError))):
                    read_failed, skipped = True, skipped + 1
                    print(f"{PROG}: skipped a frame the rig could not deliver: {e}", file=sys.stderr)
                    continue
                again = " (the second frame in a row the rig could not deliver)" if read_failed else ""
                raise CaptureError(f"{shown_url}: {e}{again}; "
                                   + (f"the {kept} view(s) kept before it are whole pairs in {out}: capture the rest "
                                      "with --append once the camera is back" if kept else "no view was kept")
                                   + _skipped_note(skipped)) from e
            read_failed = False
            last_pair_at, stall_said = time.monotonic(), False
            for cam, image, there in zip(cams, pair.images, sizes):  # (not `earlier`: the views listed above)
                if there is not None and (image.shape[1], image.shape[0]) != there[1]:
                    # views of another rig or resolution: the solve refused the mix after the session
                    raise CaptureError(
                        f"{there[0]} is {there[1][0]}x{there[1][1]}, but camera {cam!r} of {shown_url} delivers "
                        f"{image.shape[1]}x{image.shape[0]}: the views in {out} are of another rig or resolution, and "
                        "the solve refuses a camera's images at two sizes: capture into a new folder")
            now = pair.timestamps_ns[0] * 1e-9  # capture time: a replay may run faster than real time
            found = []
            for cam, image in zip(cams, pair.images):
                try:
                    found.append(detector.detect(image))
                except BoardError as e:  # squares swapped, or the other pattern: said with the camera and the file
                    raise CaptureError(f"{shown_url}, camera {cam!r}: {_board_source(args.board)}: {e}") from e
            board_seen = board_seen or any(v is not None for v in found)
            if not board_seen and now >= mismatch_check_at:
                mismatch_check_at = now + STALL_NOTE_S
                for cam, image in zip(cams, pair.images):
                    if (error := board_mismatch(board, image)) is not None:
                        raise CaptureError(f"{shown_url}, camera {cam!r}: {_board_source(args.board)}: {error}") from error
                    if corners := mirrored_corners(board, image):  # the camera's mistake, not the board file's
                        raise CaptureError(f"{shown_url}, camera {cam!r}: {mirrored_words(corners)}")
                    markers = 0 if markers_said else markers_in_view(board, image)
                    if markers >= PATTERN_CHECK_MARKERS:
                        # a board file with another number of squares than the print (8x6 for 9x6) finds
                        # the markers and no corner: the capture waited out --max-seconds without a word
                        print(f"{PROG}: camera {cam!r} sees {markers} {board.dictionary} markers but not the board "
                              f"{_board_source(args.board)} describes ({_describe(board)}): does it describe the "
                              "print (squares_x counts the squares along board.png's width)? Is the board near and "
                              "sharp enough? (waiting up to --max-seconds; Ctrl-C ends the capture)", file=sys.stderr)
                        markers_said = True
            if args.floor:
                # Both cameras, and the board lying still: not the board carried into place.
                if all(_still_since(v, r) for v, r in zip(found, resting)):
                    if _sooner_than(now - steady_since, args.steady_s):
                        continue
                else:
                    resting = found if all(v is not None for v in found) else [None, None]
                    steady_since = now
                    continue
            else:
                if all(v is None for v in found):
                    holding = [None, None]
                    continue
                # Held still for --still-s in both cameras: a view taken mid-sweep is blurred, and
                # cameras not triggered together see the board at two places
                if not _held_since(found, holding):
                    holding, holding_since = found, now
                    continue
                if _sooner_than(now - holding_since, args.still_s) or _sooner_than(now - last_kept_at, args.interval_s):
                    continue
                moves = [_largest_move_px(v, last) for v, last in zip(found, last_views)]
                known = [m for m in moves if m is not None]
                # a camera that sees the board now and did not in the last kept pair (glare, a hand over it)
                # adds a view, and the first pair of this pose both cameras see: kept however little it moved
                newly_seen = any(v is not None and last is None for v, last in zip(found, last_views))
                if known and max(known) < args.min_move_px and not newly_seen:
                    continue  # the board has not moved or turned: the same view again adds nothing
                last_views = found
            name = FLOOR_VIEW if args.floor else f"{number:03d}"
            number += 1
            # a stop landing between the two renames left one camera's image of the view (half a pair, which the
            # solve counts for that lens alone): held until the pair is in place and counted, then raised
            with stop_signals_deferred():
                _write_view(folders, name, pair.images)  # both, so a view one camera missed stays a pair
                if args.floor:  # --force: the view replaced may have been a .jpg; two floors stop the solve
                    for folder in folders:
                        for stale in (folder / f"{name}{suffix}" for suffix in IMAGE_SUFFIXES if suffix != ".png"):
                            stale.unlink(missing_ok=True)
                kept += 1
            last_kept_at = now
            print(f"  {name}: " + ", ".join(f"{cam} {0 if v is None else len(v)} corners" for cam, v in zip(cams, found)))
        read_to_its_end = True
        stops_held.enter_context(stop_signals_noted(late_stops))
    except KeyboardInterrupt as e:  # Ctrl-C, or SIGTERM (main): said below, once the cameras are closed
        stops_held.enter_context(stop_signals_deferred(then_raise=False))
        if read_to_its_end:  # it landed as the noting above began: the late stop of a capture that kept its views
            late_stops.append(e)
        else:
            stopped = e
    except Exception as error:  # main says it (exit 2), once the cameras are closed, whatever stop lands meanwhile
        leaving.held(error, stops_held)
        raise
    finally:
        # a Ctrl-C or SIGTERM that lands in the close waits for it, as ghnerf-demo's does: raised there it tore the
        # close, a depthai device or a record+ take's manifest left half-closed (timeout's SIGTERM as --max-seconds
        # ran out, a second Ctrl-C pressed after the one that stopped the capture). It is raised once the close is
        # done only when it is the first stop: one caught above (the views kept said, 0) or an error on its way
        # is the one reported
        # the take checked first; a record+ take's failure is said before main says an error on its way
        # (status_saying_a_failed_take)
        with stops_held:
            late_stop = closed_with_stops_deferred(source.close, then_raise=read_to_its_end)
        late_stop = next(iter(late_stops), late_stop)  # the first to land
    if late_stop is not None and take.failure() is None:  # main says it (130, 143); a failed take is said below, 2
        raise late_stop
    if stopped is not None:
        status = _say_stopped(stopped, kept, out, skipped)
    elif kept < count:
        why = ("the stream ended" if ended else "--max-seconds ran out") + ("" if board_seen else
                                                                          ", and the board was in no image")
        print(f"{PROG}: kept {kept} of {count} views: {why}{_skipped_note(skipped)}", file=sys.stderr)
        status = 2 if kept == 0 else 0
    else:
        print(f"kept {kept} view(s) in {out}{_skipped_note(skipped)}")
        status = 0
    if take.say_failure():  # the views are whole, the take recorded with them is not: 0 said both were
        return 2
    return status


def _say_stopped(stop: KeyboardInterrupt, kept: int, out: Path, skipped: int) -> int:
    """A capture ended by Ctrl-C or SIGTERM said, as its exit status: 0 with views kept (its normal end), else the
    shell's figure for the signal."""
    how = "" if stop_signal(stop) == signal.SIGINT else f" ({stop_words(stop)})"
    if kept == 0:  # stopping a capture is its normal end, but one that kept nothing did not succeed
        print(f"{PROG}: stopped{how} before any view was kept in {out}{_skipped_note(skipped)}", file=sys.stderr)
        return exit_status(stop)
    print(f"stopped{how}: kept {kept} view(s) in {out}{_skipped_note(skipped)}")
    return 0


def _skipped_note(skipped: int) -> str:
    """The capture's last line's count of the frames it went past (each named on stderr as it came)."""
    return f"; skipped {skipped} frame(s) the rig could not deliver" if skipped else ""


# ------------------------------------------------------------------ solve
def cmd_solve(args: argparse.Namespace) -> int:
    if (args.floor_view is None) == (args.camera_height is None):
        raise UsageError("give --floor-view NAME (a view of the board lying on the floor) or --camera-height M "
                         "(the first camera's height above the floor, with --pitch and --roll)")
    if args.floor_view is not None and (args.pitch is not None or args.roll is not None):
        raise UsageError("--pitch and --roll go with --camera-height; a floor view measures them")
    if args.camera_height is not None and args.board_thickness:
        raise UsageError("--board-thickness goes with --floor-view")
    out = _output_path(args.out, "--out", "rig file")  # found now, not after the detection and the solve
    report_path = _output_path(args.report or out.with_name(out.stem + ".report.json"),
                               "--report" if args.report else "report", "report file")
    if same_file(report_path, out):  # the report written over the rig it describes
        raise UsageError(f"--report {report_path} is the rig file (--out {out}): give the report another path")
    previous = {out: _previous_path(out, "--out"), report_path: _previous_path(report_path, "--report")}
    _check_kept_apart(previous, {"--out": out, "--report": report_path})
    board_path = Path(args.board) if args.board else Path(args.images) / BOARD_FILE
    _refuse_out_among_inputs({"--out": out, "--report": report_path}, {"the board file read (--board)": board_path})
    _stream_name(args.rig_id, MAX_RIG_ID_LEN, "--rig-id")
    volume = _solve_volume(args.volume)  # before any image is read, as the rig file would refuse it after the solve
    cameras = _cameras(args.cameras)
    recorded = read_camera_order(args.images)
    _refuse_reversed_order(cameras, recorded, args.images)
    ordered = cameras is not None or recorded is not None
    board, where = _measuring_board(args.board, args.images)
    cameras = list(camera_folders(args.images, cameras))  # the order, read once
    for name in cameras:  # before the detection, which takes a while
        _stream_name(name, MAX_CAMERA_NAME_LEN, "camera name (its folder)")
    print(f"board: {where}: {_describe(board)}")
    found = read_folder(board, args.images, cameras)
    views, missed = found.views, found.missed
    names = tuple(views)
    _say_unread(found.unread, sys.stdout)
    if args.floor_view is not None:
        _refuse_unread_floor(found.unread, args.floor_view, "level with --camera-height M --pitch DEG --roll DEG")
    if not ordered:
        print(f"note: no {Path(args.images) / CAMERAS_FILE} (written by 'ghcal capture'): the pair's order is the "
              f"folder names sorted, {names[0]!r} first; the first must be the camera the rig source opens first "
              "(opencv://?first=): if it is not, pass --cameras FIRST,SECOND")
    for cam in names:
        extra = (f"; no board in {', '.join(missed[cam])}" if missed[cam] else "") + (
            f"; {len(found.unread[cam])} unreadable, passed over" if found.unread[cam] else "")
        print(f"{cam}: the board found in {len(views[cam])} of {len(views[cam]) + len(missed[cam])} images{extra}")
    _refuse_mixed_sizes(camera_image_sizes(Path(args.images), names, views),
                        "Solved as they are, a camera's views at two sizes cannot share one lens")
    _refuse_exchanged_sizes(out, views, Path(args.images))
    blind = [cam for cam in names if not views[cam]]
    if blind:  # said as such: it was blamed on the floor view, or on too few views ("15-30 is usual")
        raise UsageError(f"camera {blind[0]!r} found the board in none of its "
                         f"{_images_counted(len(missed[blind[0]]), len(found.unread[blind[0]]))} "
                         f"({Path(args.images) / blind[0]}): does {where} describe the print ({_describe(board)}; "
                         "squares_x counts them along board.png's width)? Is the board in "
                         "view, sharp, and without glare?")
    # an unreadable image is a view taken: its namesake is no lonely image
    _check_pairing(args.images, names, views, {c: missed[c] + list(found.unread[c]) for c in names}, args.floor_view)
    repeats = _drop_repeated_images(args.images, views, args.floor_view)  # after the pairing: a copy is no lonely image
    if args.floor_view is not None and not any(args.floor_view in views[c] for c in names):
        if any(args.floor_view in missed[c] for c in names):  # taken, and the board not found in it
            raise UsageError(f"--floor-view {args.floor_view!r}: neither camera found the board in that view (lying "
                             "on the floor it is seen small and edge-on: lay it nearer the cameras, use a larger "
                             "board, or level with --camera-height M --pitch DEG --roll DEG instead)")
        raise UsageError(f"--floor-view {args.floor_view!r}: neither camera's folder has an image of that name "
                         "(ghcal capture --floor names it 'floor')")
    solution = solve_rig(board, views, names, lens=args.lens, floor_view=args.floor_view,
                         board_thickness_m=args.board_thickness, camera_height_m=args.camera_height,
                         pitch_deg=args.pitch or 0.0, roll_deg=args.roll or 0.0, volume=volume,
                         rig_id=args.rig_id, tangential=not args.no_tangential)
    # the rig file's text made (and checked) first; then the previous rig and report kept (copies: rig.prev.json,
    # rig.report.prev.json), then the report, so the rig file is never newer than its report; if the rig file's
    # write then fails, the new report is left beside the old rig
    for cam in names:  # the views passed over, recorded as the report's reader cannot see the run's warnings
        solution.report["cameras"][cam]["repeated_views"] = repeats[cam]
        solution.report["cameras"][cam]["unreadable_views"] = sorted(found.unread[cam])
    text = checked_rig_text(solution.rig, out)
    kept = {path: _keep_previous(path, prev) for path, prev in previous.items()}
    write_text_atomic(report_path, json.dumps(solution.report, indent=1) + "\n")
    write_text_atomic(out, text)
    r = solution.report
    for cam in names:
        c = r["cameras"][cam]
        print(f"{cam}: reprojection {c['rms_px']:.3f} px rms over {c['views']} views, corners over "
              f"{c['coverage']:.0%} of the image, f {c['K'][0][0]:.1f} px")
    p, lv = r["pair"], r["levelling"]
    held = "" if p["board_distance_m"] is None else \
        f", the board held a median {p['board_distance_m']:.2f} m from {names[0]}"  # the scale check's figure
    print(f"pair: reprojection {p['rms_px']:.3f} px rms over {p['views']} views, baseline {1000 * p['baseline_m']:.1f} mm, "
          f"convergence {p['convergence_deg']:.2f} deg{held}")
    how = "the height and tilt given" if lv["method"] == "measured" else lv["method"]
    print(f"levelled by {how}: {lv['camera']} {lv['camera_height_m']:.3f} m above the floor, "
          f"pitch {lv['pitch_deg']:.2f} deg, roll {lv['roll_deg']:.2f} deg")
    for warning in r["warnings"]:
        print(f"warning: {warning}")
    log_warnings_and_notes(solution.rig, out, leave_out=_fold_warnings_said(solution.rig))
    _say_kept(kept)
    print(f"wrote {out} and {report_path}")
    return 0


def _images_counted(readable: int, unreadable: int) -> str:
    """A camera's images as counted in words: "5 images", or "5 readable images (2 more unreadable)" where some
    were passed over (:func:`_say_unread`); the count said only the readable ones before session 75."""
    return f"{readable} images" if not unreadable else f"{readable} readable images ({unreadable} more unreadable)"


def _say_unread(unread: Mapping[str, Mapping[str, str]], stream) -> None:
    """A warning for each image ``solve`` or ``check`` passes over as unreadable (:func:`read_folder`), as they say
    the images without the board: the run goes on with the others, and its own checks refuse too few."""
    for reasons in unread.values():
        for reason in reasons.values():
            print(f"warning: {reason}; passed over", file=stream)


def _refuse_unread_floor(unread: Mapping[str, Mapping[str, str]], floor_view: str, other: str) -> None:
    """Refuse a floor view that does not read in a camera: the levelling rests on that one view, so ``solve`` does
    not pass it over as another view; ``check`` refuses it only where ``--floor-view`` names it (else a note says
    the floor went unchecked, as for a missing one). ``other`` is the command's other way."""
    for reasons in unread.values():
        if floor_view in reasons:
            raise UsageError(f"floor view {floor_view!r}: {reasons[floor_view]}: take it again (ghcal capture --floor "
                             f"--force), or {other}")


def _replaced_rig(out: Path):
    """The rig file at ``out`` that ``solve`` is to replace, loaded; None where there is none, or one that does not
    load (it is replaced whatever it holds). Read without its warnings: they are the old calibration's, and logged
    here they read as the new one's."""
    if not out.is_file():
        return None
    try:
        return load_rig(out, warn=False)
    except RigFileError:
        return None


def _refuse_mixed_sizes(sizes: Mapping[str, Mapping[str, tuple[Path, tuple[int, int]]]], why: str) -> None:
    """Refuse a camera whose images are not all one size, the board found in them or not (``sizes`` from
    :func:`~calibration.image_sizes.camera_image_sizes`): checked from the images alone, so also where ``solve``'s
    ``--out`` holds no rig file; ``why`` is the command's reason (``solve``'s lens, ``check``'s rig file).

    :raises UsageError: naming each odd image's file, its size and its camera's usual one.
    """
    problem = mixed_sizes_problem(sizes)
    if problem is not None:
        raise UsageError(f"{problem}. {why}")


def _refuse_exchanged_sizes(out: Path, views: dict, images: Path) -> None:
    """Refuse views whose folders hold each the other camera's images, said from the sizes of the rig file ``solve``
    would replace (:func:`~calibration.check.sized_as_exchanged`, as ``check`` says it): solved as they were, the
    rig gave each camera the other's lens, image size and pose, and replaced the rig that fit the cameras.

    :raises UsageError: naming both folders, both sizes, the rig file and the fix.
    """
    replaced = _replaced_rig(out)
    if replaced is None or not sized_as_exchanged(replaced, views):
        return
    raise UsageError(f"{_exchanged_sizes_evidence(replaced, str(out), images)} ({out} being the rig file this solve "
                     "would replace). Exchange the two folders' images (a tool that named the cameras the other way "
                     "round), then solve again: solved from them as they are, the rig would give each camera the "
                     "other's lens, image size and pose. If the cameras were exchanged on purpose (first= and second= "
                     f"swapped in the rig URL), give --out another path, or move {out} away first")


def _fold_warnings_said(rig: Rig) -> set[str]:
    """The rig file's words for the lens folds ``solve`` warned of (``solution.report``'s ``fold_warning``, one for
    each camera of the pair whose lens folds inside its image)."""
    return {lens_fold_warning(cam) for cam in rig.pair if cam.fold_inside_image()}


def _height_warnings_said(rig: Rig) -> set[str]:
    """The rig file's words for a camera's height, which ``import``'s "not levelled" warning says already: in the
    calibration tool's frame the first camera stands at its origin, "0.00 m above the floor", and the fix each
    names is the same (import again with --camera-height)."""
    return {warning for cam in rig.cameras if (warning := camera_height_warning(cam))}


def _say_kept(kept: dict[Path, Path | None]) -> None:
    for path, prev in kept.items():
        if prev is not None:
            print(f"kept the previous {path} as {prev}")


def _drop_repeated_images(images: str, views: dict, floor_view: str | None) -> dict[str, dict[str, str]]:
    """Count once the images of a camera that show the board at the same pose as an earlier one (a copy, a re-saved
    JPEG, a frame grabbed twice), saying how many and which: each weighed its pose once more in the lens's fit, and
    one copied into a single camera's folder made a pair "not taken at the same instant", not said as a copy.
    Returns camera -> dropped view -> the earlier view kept, for the report."""
    dropped = {}
    for cam, named in views.items():
        repeats = repeated_views(named, skip=floor_view)
        dropped[cam] = repeats
        if not repeats:
            continue
        files = list_images(Path(images) / cam)
        said = [f"{files[name].name} (as {files[same].name})" for name, same in repeats.items()]
        print(f"note: {Path(images) / cam}: {len(said)} image(s) show the board at the same pose as an earlier one "
              f"(every corner within {REPEAT_PX:g} px: a copy, a re-saved image, a frame grabbed twice): "
              f"{', '.join(said[:4])}{', ...' if len(said) > 4 else ''}; dropped, each pose counted once")
        for name in repeats:
            del named[name]
    return dropped


def _check_pairing(images: str, names: Sequence[str], views: dict, missed: dict, floor_view: str | None) -> None:
    """Say which images have no namesake in the other camera's folder: a pair is the two images of one name,
    so another tool's naming (``left_000.png`` beside ``right_000.png``) left no pair at all, and the solve
    said only "hold it where both cameras see it".

    :raises UsageError: fewer than :data:`~calibration.solve.MIN_VIEWS` names in both folders.
    """
    taken = {cam: (set(views[cam]) | set(missed[cam])) - {floor_view} for cam in names}
    a, b = names
    shared = taken[a] & taken[b]
    lonely = {cam: sorted(taken[cam] - shared) for cam in names}
    if not any(lonely.values()):
        return
    def listed(cam: str) -> str:
        some = lonely[cam]
        return f"{len(some)} of {cam!r} ({', '.join(some[:4])}{', ...' if len(some) > 4 else ''})"
    said = (f"images pair by file name ({a}/000.png with {b}/000.png): "
            + " and ".join(listed(cam) for cam in names if lonely[cam]) + " have no namesake in the other folder")
    if len(shared) < MIN_VIEWS:
        raise UsageError(f"{images}: {said}, and only {len(shared)} name(s) are in both (at least {MIN_VIEWS} pairs are "
                         "needed): name each pair's two images alike")
    print(f"note: {said}: they count for that camera's lens only")


# ------------------------------------------------------------------ import / export
#: The foreign formats by file suffix (``--format`` names one for other suffixes).
FORMAT_SUFFIXES = {".toml": "anipose", ".yml": "opencv", ".yaml": "opencv", ".xml": "opencv", ".json": "opencv"}


def _format_of(path: Path, given: str | None, flag: str) -> str:
    """The format of ``path``: ``given``, else its suffix's (the one before ``.gz``, or ``.gz`` and a digit:
    OpenCV's gzipped files, of any case). An ``--out`` OpenCV would not open by its name (``rig.yml.gz9``,
    ``rig.yml.GZ``) is refused."""
    from calibration.formats.opencv_yaml import GZIP_SUFFIX, format_suffix, gzip_name_problem, gzipped

    fmt = given or FORMAT_SUFFIXES.get(format_suffix(path))
    if fmt is None:
        suffix = format_suffix(path) + (path.suffix if gzipped(path) else "")
        raise UsageError(f"{flag} {path}: cannot tell the format from the suffix {suffix!r} (one of "
                         f"{', '.join(sorted(FORMAT_SUFFIXES))}, OpenCV's also gzipped as .yml.gz...): pass --format "
                         "opencv or anipose")
    if fmt == "anipose" and gzipped(path):  # an export wrote plain TOML under the name, an import read gzip as TOML
        raise UsageError(f"{flag} {path}: anipose files are plain TOML, not gzipped ({GZIP_SUFFIX} goes with OpenCV "
                         "FileStorage files only): give a .toml name")
    # after the format: a rig.toml.GZ is no anipose name at all, not one to spell rig.toml.gz
    if flag == "--out" and (problem := gzip_name_problem(path)):
        raise UsageError(f"{flag} {path}: {problem}")
    return fmt


def _output_path(text: str | Path, flag: str, what: str) -> Path:
    """A file a command will write: its folder must exist and take a new file, and it must not be a folder
    or a file made read-only. Checked before the work: a solve found it out only when writing, after it."""
    out = Path(text)
    if not out.parent.is_dir():
        raise UsageError(f"{flag} {out}: no such folder for the {what} ({out.parent})")
    if out.is_dir():
        raise UsageError(f"{flag} {out}: is a folder; give the {what}'s path")
    target = Path(os.path.realpath(out)) if out.is_symlink() else out  # written through a link, as save_rig does
    reason = unwritable_reason(target.parent)
    if reason is not None:
        raise UsageError(f"{flag} {out}: cannot write the {what} in {target.parent} ({reason})")
    if target.exists() and not os.access(target, os.W_OK):  # replaced by a rename, but read-only on purpose
        raise UsageError(f"{flag} {out}: the file exists and is read-only; make it writable or give another path")
    return out


def _previous_path(out: Path, flag: str) -> Path:
    """Where ``solve`` and ``import`` keep the file ``out`` held before they replace it: ``<stem>.prev<suffix>``
    beside it (``rig.json``: ``rig.prev.json``). A recalibration that came out worse can then be undone,
    without a --force to remember (``board`` and ``synth`` ask for one: what they replace is not theirs to
    keep). Checked before the work, as :func:`_output_path` checks ``out``. A gzipped OpenCV file keeps the suffix
    before ``.gz`` too (``rig.yml.gz``: ``rig.prev.yml.gz``, whose format import tells from its name)."""
    from calibration.formats.opencv_yaml import gzipped

    suffix = "".join(out.suffixes[-2:]) if gzipped(out) else out.suffix
    prev = out.with_name(f"{out.name[:len(out.name) - len(suffix)]}.prev{suffix}")
    if out.exists() and (prev.is_dir() or (prev.exists() and not os.access(prev, os.W_OK))):
        raise UsageError(f"{flag} {out}: the file it holds is kept as {prev} before it is replaced, but that is "
                         f"{'a folder' if prev.is_dir() else 'read-only'}: move it away or give another path")
    return prev


def _refuse_out_among_inputs(outputs: Mapping[str, Path], inputs: Mapping[str, Path]) -> None:
    """Refuse an output path that is one of the run's input files (``same_file``: ``./b.json`` is ``b.json``, and so is
    a hard link to it), before anything is written: ``import a.yml --extrinsics b.json --out b.json`` replaced the
    extrinsics it read.
    ``outputs``: flag -> path; ``inputs``: what the input is ("the file being imported") -> path."""
    for flag, out in outputs.items():
        for what, path in inputs.items():
            if same_file(out, path):
                raise UsageError(f"{flag} {out} is {what} ({path}): give {flag} another path")


def _check_kept_apart(previous: dict[Path, Path], others: dict[str, Path]) -> None:
    """Refuse a run where a previous file would be kept on top of another file it reads or writes
    (``--report rig.prev.json``; ``import calib.prev.yml --out calib.yml`` copied the old rig over its input), however
    named (``same_file``: through links, a hard link included)."""
    for out, prev in previous.items():
        for flag, path in others.items():
            if same_file(path, prev):
                raise UsageError(f"{flag} {path} is where the previous {out} is kept ({prev}): give another path")


def _keep_previous(out: Path, prev: Path) -> Path | None:
    """Copy ``out``, when it exists, to ``prev`` (atomically, replacing an older one) before a new ``out`` takes
    its name; the copy's path, or ``None`` when there was nothing to keep. Copied, not renamed: a daemon reading
    ``out`` never finds it missing."""
    if not out.exists():
        return None
    write_bytes_atomic(prev, out.read_bytes())
    return prev


def _is_rig_file(path: Path) -> bool:
    """A JSON file in our own rig format (given to ``import`` by mistake: it names no OpenCV key)."""
    from ghnerf_runtime.rig_file import FORMAT

    if path.suffix.lower() != ".json" or not path.is_file():
        return False
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (OSError, ValueError, RecursionError):
        return False  # the reader names what is wrong with it
    return isinstance(data, dict) and data.get("format") == FORMAT


def _declared_units(path: Path) -> float | None:
    """``[metadata] units_to_metres`` of an anipose file our exporter wrote (others do not say); the reader checks
    an argument against it, but requires one."""
    from calibration.formats.anipose_toml import load_toml

    # A file that is no TOML to read is named as the reader names it: a mistyped name, a folder, an empty file or
    # one cut off mid-edit was told to pass --units-to-metres, and named only once a unit was given.
    meta = load_toml(path).get("metadata")
    if meta is not None and not isinstance(meta, dict):  # metadata = 5 was passed over as no unit recorded
        raise RigFileError(f"must be a table ([metadata]), got {meta!r}", path=str(path), field="metadata")
    if meta is None or "units_to_metres" not in meta:
        return None
    units = meta["units_to_metres"]
    # named here: the reader's own check comes after this value has been taken as the argument (an error
    # naming neither file nor key), and a string unit read as none recorded
    if isinstance(units, bool) or not isinstance(units, (int, float)) or not (math.isfinite(units) and units > 0):
        raise RigFileError(f"must be a positive number of metres per unit, got {units!r}", path=str(path),
                           field="metadata.units_to_metres")
    return float(units)


def cmd_import(args: argparse.Namespace) -> int:
    from calibration.common_view import common_view_warning
    from calibration.formats import read_anipose_toml, read_opencv_rig
    from calibration.level import level_rig

    source = Path(args.file)
    out = _output_path(args.out, "--out", "rig file")
    _refuse_out_among_inputs({"--out": out}, {"the file being imported": source} |
                             ({"the extrinsics read (--extrinsics)": Path(args.extrinsics)} if args.extrinsics else {}))
    previous = {out: _previous_path(out, "--out")}
    _check_kept_apart(previous, {"FILE": source} | ({"--extrinsics": Path(args.extrinsics)} if args.extrinsics else {}))
    if args.camera_height is None and (args.pitch is not None or args.roll is not None):
        raise UsageError("--pitch and --roll go with --camera-height (the first camera's height above the floor)")
    if args.rig_id is not None:
        _stream_name(args.rig_id, MAX_RIG_ID_LEN, "--rig-id")
    fmt = _format_of(source, args.format, "FILE")
    if fmt == "opencv" and _is_rig_file(source):
        raise UsageError(f"{source} is a rig file already (docs/rig-file.md): use it as it is, no import needed")
    volume = _volume(args.volume)
    if fmt == "anipose":
        units = args.units_to_metres if args.units_to_metres is not None else _declared_units(source)
        if units is None:
            raise UsageError(f"{source}: anipose files do not record the unit of their translations: pass "
                             "--units-to-metres (0.001 for a board measured in millimetres, 1 for metres)")
        if args.extrinsics or args.image_size:
            raise UsageError("--extrinsics and --image-size go with OpenCV files; anipose files carry both")
        rig = read_anipose_toml(source, units_to_metres=units, volume=None if
                                args.camera_height is not None else volume, rig_id=args.rig_id)
    else:
        rig = read_opencv_rig(source, extrinsics_path=args.extrinsics, image_size=args.image_size,
                              volume=None if args.camera_height is not None else volume, rig_id=args.rig_id,
                              units_to_metres=args.units_to_metres)
    for cam in rig.pair:  # the joint stream announces them
        _stream_name(cam.name, MAX_CAMERA_NAME_LEN, f"{source}: camera name")
    _stream_name(rig.rig_id, MAX_RIG_ID_LEN, f"{source}: rig id (--rig-id sets another)")
    if args.camera_height is not None:
        rig = level_rig(rig, camera_height_m=args.camera_height, pitch_deg=args.pitch or 0.0,
                        roll_deg=args.roll or 0.0, volume=volume)
    # made before the previous file is kept: a rig the reader refuses (a --volume past MAX_DEPTH_M) was refused by
    # save_rig after the copy, which replaced the older kept copy with the file left as it was
    text = checked_rig_text(rig, out)
    kept = {out: _keep_previous(out, previous[out])}
    write_text_atomic(out, text)
    a, b = rig.pair
    units = rig.metadata.get("source", {}).get("units_to_metres")
    print(f"{source} ({fmt}): cameras {a.name!r} {a.width}x{a.height} and {b.name!r} {b.width}x{b.height}, "
          f"baseline {1000 * float(np.linalg.norm(a.center - b.center)):.1f} mm"
          + (f" (file units x {units:g} m)" if units is not None else ""))
    # a unit the file does not show (stereo_calib's board squares read as metres) leaves a pair sharing no view
    if warning := common_view_warning(rig):
        print(f"warning: {warning}")
    recorded = rig.metadata.get("levelled")
    said: set[str] = set()  # the rig file's warnings said above in other words
    if args.camera_height is not None:
        print(f"levelled: {a.name} {args.camera_height:g} m above the floor, pitch {args.pitch or 0.0:g} deg, "
              f"roll {args.roll or 0.0:g} deg")
        warning = typed_pitch_warning(args.pitch or 0.0, a.name)  # as solve warns: 80 typed for 10 passed silently
        if warning:
            print(f"warning: {warning}")
    elif isinstance(recorded, dict):  # our own export of a levelled rig: the file says so and its poses agree
        print(f"levelled already (the file records it, and its poses agree): {recorded['reference']} "
              f"{recorded['camera_height_m']:.3f} m above the floor, pitch {recorded['pitch_deg']:.2f} deg, "
              f"roll {recorded['roll_deg']:.2f} deg")
    else:
        mismatch = rig.metadata.get("source", {}).get("levelling_mismatch")
        print("warning: not levelled: the rig frame is the calibration tool's own"
              + (f" ({mismatch})" if mismatch else "")
              + ", and the runtime reads y as down with the floor at y = 0 (the skeleton prior, upright crops, the "
              "working volume): import again with --camera-height M (and --pitch, --roll) of the first camera")
        said = _height_warnings_said(rig)
    log_warnings_and_notes(rig, out, leave_out=said)
    _say_kept(kept)
    print(f"wrote {out}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from calibration.formats import dumps_anipose_toml, dumps_opencv_rig, write_opencv_text
    from calibration.formats.opencv_yaml import gzipped

    rig = load_rig(args.rig)
    out = _output_path(args.out, "--out", "export")
    if same_file(out, args.rig):
        raise UsageError(f"--out {out} is the rig file (--rig): give the export another path")
    # kept as import and solve keep theirs: an export over the anipose or OpenCV file a rig was imported from
    # replaced the other tool's own calibration, in its own frame, without a copy
    previous = {out: _previous_path(out, "--out")}
    _check_kept_apart(previous, {"--rig": Path(args.rig)})
    fmt = _format_of(out, args.format, "--out")
    if fmt == "anipose":
        if args.units_to_metres is None:
            raise UsageError("anipose files do not record the unit of their translations: pass --units-to-metres "
                             "(0.001 to write millimetres, 1 for metres), the unit the reading tool expects")
    # made before the file it replaces is kept: a rig the format cannot hold (a skew) replaced the kept copy, the
    # other tool's own calibration, with a copy of the file this export then left as it was
    text = (dumps_anipose_toml(rig, units_to_metres=args.units_to_metres) if fmt == "anipose" else
            dumps_opencv_rig(rig, out, units_to_metres=1.0 if args.units_to_metres is None else args.units_to_metres))
    kept = {out: _keep_previous(out, previous[out])}
    (write_opencv_text if fmt == "opencv" else write_text_atomic)(out, text)  # opencv: gzipped for a .gz name
    _say_kept(kept)
    packed = ", gzipped" if fmt == "opencv" and gzipped(out) else ""
    print(f"wrote {out} ({fmt}{packed}, cameras {', '.join(repr(c.name) for c in rig.cameras)})")
    return 0


# ------------------------------------------------------------------ check
def cmd_check(args: argparse.Namespace) -> int:
    rig = load_rig(args.rig)
    recorded = _recorded_board(rig, args.rig)
    board, where = _measuring_board(args.board, args.images, recorded)
    if recorded is not None and not math.isclose(board.square_m, recorded.square_m, rel_tol=1e-9):
        # the scale check would blame the rig for the board file's square size
        raise UsageError(f"the board from {where} has squares of {1000 * board.square_m:g} mm, but {args.rig} was "
                         f"solved with squares of {1000 * recorded.square_m:g} mm (metadata.calibration.board): check "
                         "with the board it was solved with, or calibrate again")
    record_floor = None if args.floor_view is not None else _recorded_floor_view(rig, args.rig)
    floor_view = args.floor_view or record_floor or FLOOR_VIEW
    thickness = args.board_thickness if args.board_thickness is not None else _recorded_thickness(rig, args.rig)
    print(f"board: {where}: {_describe(board)}", file=sys.stderr if args.json else sys.stdout)
    names = [c.name for c in rig.pair]
    missing = [n for n in names if not (Path(args.images) / n).is_dir()]
    if missing:  # said as what it likely is: the views of another rig, not a lost folder
        held = read_camera_order(args.images, check_folders=False) or sorted(
            p.name for p in Path(args.images).iterdir() if p.is_dir() and not p.name.startswith("."))
        raise UsageError(f"{args.images} holds views of the cameras {held}, but {args.rig} is the rig of the cameras "
                         f"{names} (no folder {missing[0]!r}): views of another rig? check them with its rig file")
    found = read_folder(board, args.images, names)
    views, missed = found.views, found.missed
    _say_unread(found.unread, sys.stderr if args.json else sys.stdout)
    if args.floor_view is not None:  # asked for by name: an error, as a name with no image is; else a note below
        _refuse_unread_floor(found.unread, floor_view, "pass --floor-view NAME for another")
    limits = CheckLimits(max_px=args.max_px, max_scale_error=args.max_scale_error, max_floor_mm=args.max_floor_mm)
    sizes = camera_image_sizes(Path(args.images), names, views)
    rig_sizes = ", ".join(f"{cam.name!r} {cam.width}x{cam.height}" for cam in rig.pair)
    # first, as solve: each camera's images one size, the exchange below (told by its board views) holds of them all
    _refuse_mixed_sizes(sizes, f"A camera's images are checked at its size in {args.rig}: {rig_sizes}")
    if sized_as_exchanged(rig, views):
        raise UsageError(_exchanged_sizes_words(rig, args.rig, board, views, Path(args.images), limits, thickness,
                                                floor_view))
    _refuse_sizes_unlike_the_rig(rig, args.rig, sizes)

    def taken(name: str) -> bool:
        return any(name in views[c] or name in missed[c] for c in views)

    # an image that does not read is a floor view taken (warned of above): the note below says why it went unmeasured
    floor_taken = taken(floor_view) or any(floor_view in found.unread[c] for c in names)
    if args.floor_view is not None and not floor_taken:
        # a mistyped name passed silently, and with it a rig tilted on its mount, which only the floor shows
        raise UsageError(f"--floor-view {args.floor_view!r}: neither camera's folder in {args.images} has an image "
                         "of that name")
    recorded_where = f"{args.rig}: metadata.calibration.floor_view {record_floor!r}, the view solve levelled from"
    if record_floor is not None and not floor_taken and taken(FLOOR_VIEW):
        # the floor view that 'ghcal capture --floor' takes was there, and went unmeasured behind a note
        raise UsageError(f"{recorded_where}, names no image in {args.images}, which has a floor view {FLOOR_VIEW!r}: "
                         f"pass --floor-view {FLOOR_VIEW} to measure it (or --floor-view NAME for another)")
    report = check_rig(rig, board, views, board_thickness_m=thickness, floor_view=floor_view)
    if not report["pairs"]:
        raise UsageError(f"{args.images}: no image pair in which both cameras found the board")
    report["unreadable_views"] = {cam: sorted(found.unread[cam]) for cam in names}  # --json's reader sees no warning
    if "floor" not in report:
        print(f"note: the levelling is not checked (a rig tilted on its mount passes): "
              + ((floor_unmeasured(report, views, floor_view, missed=missed, root=args.images, unread=found.unread)
                  or f"neither camera found the board in floor view {floor_view!r}") if floor_taken else
                 f"no floor view {floor_view!r} in {args.images} ("
                 + (f"{recorded_where}; " if record_floor is not None else "") + "--floor-view NAME names another)"),
              file=sys.stderr if args.json else sys.stdout)
    rms = report["reprojection_px_rms"]
    print(json.dumps(report, indent=1, allow_nan=False) if args.json else
          f"{report['pairs']} pairs: reprojection "
          + ("not measured" if rms is None else f"{rms:.3f} px rms (p95 {report['reprojection_px_p95']:.3f})")
          + ", scale "
          + ("not measured (no neighbouring corners)" if report["scale"] is None else f"{report['scale']:.4f} of the board's")
          + (f", floor view {floor_view!r} {report['floor']['height_mm_median']:+.1f} mm off the floor"
             if "floor" in report else "")
          + (f", {report['untriangulated']} of {report['corners']} corners not triangulated"
             if report["untriangulated"] else ""))
    reasons = check_failures(report, limits)
    if reasons and (exchanged := exchanged_fit(rig, board, views, limits, board_thickness_m=thickness,
                                               floor_view=floor_view)) is not None:
        print(f"{PROG}: the rig does not fit these views: {'; '.join(reasons)}. " + _exchanged_words(
            exchanged, Path(args.images), names), file=sys.stderr)
        return 1
    if reasons:
        print(f"{PROG}: the rig does not fit these views: {'; '.join(reasons)}. A camera moved, or the views are "
              "of another rig: calibrate again", file=sys.stderr)
        return 1
    return 0


def _refuse_sizes_unlike_the_rig(rig: Rig, rig_path: str,
                                 sizes: Mapping[str, Mapping[str, tuple[Path, tuple[int, int]]]]) -> None:
    """Refuse an image of another size than its camera's in ``rig_path``, the board found in it or not (``sizes``
    from :func:`~calibration.image_sizes.camera_image_sizes`, each camera's images found one size first, as
    ``solve`` finds them). Before session 69 only the images the board was found in were compared: a stray image
    went unsaid.

    :raises UsageError: naming an image's file, its size and the size it should have.
    """
    for cam in rig.pair:
        for path, size in sizes[cam.name].values():
            if size != cam.size:
                raise UsageError(f"{path}: the image is {size[0]}x{size[1]}, camera {cam.name!r} of {rig_path} "
                                 f"{cam.width}x{cam.height}")


def _scale_figure(report: Mapping) -> str:
    """A check report's scale as said beside its reprojection: None where no two neighbouring corners were measured,
    which :func:`check_failures` lets through (``:.4f`` of it was a TypeError)."""
    return "not measured" if report.get("scale") is None else f"{report['scale']:.4f}"


def _exchanged_words(report: dict, images: Path, names: Sequence[str]) -> str:
    """What to do where the rig fits the views with its two cameras' images exchanged (:func:`exchanged_fit`)."""
    a, b = names
    return (f"It fits them with the two cameras' images exchanged (reprojection {report['reprojection_px_rms']:.3f} "
            f"px rms, scale {_scale_figure(report)}): {images / a} holds the images of camera {b!r}, and "
            f"{images / b} those of {a!r}. Exchange the two folders' images (a tool that named the cameras the other "
            "way round), then check again; solved from them as they are, the rig would give each camera the other's "
            "lens and pose")


def _exchanged_sizes_words(rig, rig_path: str, board: BoardSpec, views: dict, images: Path, limits: CheckLimits,
                           thickness: float, floor_view: str) -> str:
    """The error for folders whose images are each the other camera's size (:func:`sized_as_exchanged`): the
    sizes as the evidence, and whether the rig fits the views exchanged (within ``limits``)."""
    report = exchanged_report(rig, board, views, board_thickness_m=thickness, floor_view=floor_view)
    reasons = check_failures(report, limits) if report["pairs"] else ["no pair to measure"]
    fit = (f"exchanged, the rig fits them (reprojection {report['reprojection_px_rms']:.3f} px rms, scale "
           f"{_scale_figure(report)})"
           if not reasons else
           f"exchanged, the rig does not fit them either ({'; '.join(reasons)}): calibrate again once they are")
    return (f"{_exchanged_sizes_evidence(rig, rig_path, images)}; {fit}. Exchange the two folders' images (a tool "
            "that named the cameras the other way round), then check again")


def _exchanged_sizes_evidence(rig, rig_path: str, images: Path) -> str:
    """The sizes that show the folders exchanged (:func:`sized_as_exchanged`), one wording for ``check`` and
    ``solve``: each folder, the size of its images, and the camera of ``rig_path`` whose size that is."""
    a, b = rig.pair
    return (f"the folders look exchanged: every image in {images / a.name} is {b.width}x{b.height}, the size of "
            f"camera {b.name!r} in {rig_path}, and every image in {images / b.name} {a.width}x{a.height}, camera "
            f"{a.name!r}'s")


# ------------------------------------------------------------------ main
def _number(text: str) -> float:
    """``text`` as a float, or argparse's usage error saying so (a bare ValueError read "invalid parse value")."""
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None


def _finite(lo: float, hi: float):
    def parse(text: str) -> float:
        value = _number(text)
        if not (math.isfinite(value) and lo <= value <= hi):
            raise argparse.ArgumentTypeError(f"must be a number in [{lo:g}, {hi:g}], got {text}")
        return value
    return parse


def _seconds(text: str) -> float:
    value = _number(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return value


def _add_tilt(p: argparse.ArgumentParser) -> None:
    """``--pitch`` / ``--roll``: the first camera's tilt, given with ``--camera-height`` (solve, import)."""
    p.add_argument("--pitch", type=_finite(-90.0, 90.0),
                   help="with --camera-height: degrees below the horizon (default 0)")
    p.add_argument("--roll", type=_finite(-180.0, 180.0),
                   help="with --camera-height: degrees about the optical axis (default 0)")


def _add_volume(p: argparse.ArgumentParser, frame: str) -> None:
    """``--volume``: the working volume given in ``frame`` (solve, import), one help for both commands."""
    # argparse reads a value starting with '-' ("-1.5,...") as an option: the help shows the '=' form
    p.add_argument("--volume", help=f"working volume xmin,ymin,zmin,xmax,ymax,zmax (m, {frame}); a value that starts "
                                    "with '-' needs '=': --volume=-1.5,0,2,1.5,2,5")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                 epilog="Guide: docs/calibration.md")
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("board", help="write the board to print and its definition")
    p.add_argument("--out", type=user_path, required=True, help="folder for board.png and board.json")
    p.add_argument("--board", type=user_path, help="a board definition to start from (default: 9x6 squares of 80 mm)")
    p.add_argument("--dpi", type=positive_count, default=300, help="print resolution (default 300)")
    p.add_argument("--force", action="store_true", help="replace a board.json in --out that defines another board")
    p.set_defaults(run=cmd_board)

    p = sub.add_parser("synth", help="render the calibration views of a known rig (no cameras needed)")
    p.add_argument("--out", type=user_path, required=True)
    p.add_argument("--rig", type=user_path, help="the rig to film (default: a 0.6 m pair at 1.8 m pitched 23 degrees "
                                                        "down, calibration.render.synth_rig)")
    p.add_argument("--board", type=user_path, help="the board to render (default: 9x6 squares of 120 mm, "
                                                   "calibration.render.SYNTH_BOARD); written to OUT/board.json")
    p.add_argument("--force", action="store_true",
                   help="write into a folder that already holds views, board.json or cameras.json; the earlier "
                        "synth run's images that this one does not write again are removed (synth_views.json "
                        "lists them), no other file")
    p.add_argument("--count", type=bounded_count(1, MAX_VIEWS), default=15,
                   help=f"views both cameras see (default 15, at most {MAX_VIEWS})")
    p.add_argument("--edge-count", type=bounded_count(0, MAX_VIEWS), default=6,
                   help=f"views per camera in its image corners (default 6, at most {MAX_VIEWS})")
    p.add_argument("--seed", type=non_negative_count, default=0)
    p.set_defaults(run=cmd_synth)

    p = sub.add_parser("capture", help="save image pairs in which a camera sees the board (both images)")
    p.add_argument("--url", required=True, help="rig URL (depthai://, replay://DIR, ...)")
    p.add_argument("--board", type=user_path, help="the board to look for (default: 9x6 squares of 80 mm); solve and check "
                                   "still need its measured board.json")
    p.add_argument("--out", type=user_path, required=True, help="folder: one subfolder per camera, and cameras.json, the order "
                                                "the rig source gives the cameras in (solve keeps it)")
    p.add_argument("--count", type=bounded_count(1, MAX_VIEWS), default=20,
                   help=f"views to keep (default 20, at most {MAX_VIEWS})")
    p.add_argument("--floor", action="store_true",
                   help="keep one view named 'floor': the board lying still on the floor, seen by both cameras")
    p.add_argument("--steady-s", type=_seconds, default=1.0, help="--floor: how long the board must lie still")
    p.add_argument("--force", action="store_true", help="--floor: replace an existing floor view")
    p.add_argument("--append", action="store_true",
                   help="add views to a folder that holds an earlier capture's (the cameras not moved since)")
    p.add_argument("--interval-s", type=_seconds, default=1.0, help="at least this long between kept views")
    p.add_argument("--still-s", type=_seconds, default=0.3,
                   help="how long the hand-held board must be held still before its view is kept (default 0.3)")
    p.add_argument("--min-move-px", type=_seconds, default=40.0,
                   help="a corner must move (or the board turn) this far between kept views (default 40 px)")
    p.add_argument("--max-seconds", type=_seconds, default=600.0)
    p.set_defaults(run=cmd_capture)

    p = sub.add_parser("solve", help="solve the rig from a folder of views and write the rig file")
    p.add_argument("--images", type=user_path, required=True, help="folder with one subfolder per camera")
    p.add_argument("--board", type=user_path, help="the board's definition, measured on the print (default: IMAGES/board.json; "
                                   "without either, an error)")
    p.add_argument("--out", type=user_path, required=True, help="rig file to write (docs/rig-file.md)")
    p.add_argument("--report", type=user_path, help="report JSON (default: OUT with .report.json; not OUT itself)")
    p.add_argument("--cameras", help="FIRST,SECOND: the pair in rig order (default: the order IMAGES/cameras.json "
                                     "records, else the two subfolders, sorted)")
    p.add_argument("--lens", choices=sorted(LENS_MODELS), default="standard")
    p.add_argument("--no-tangential", action="store_true",
                   help="hold the tangential terms p1, p2 at exactly 0 (OpenCV's CALIB_ZERO_TANGENT_DIST), with any "
                        "--lens: for views whose fitted p1/p2 fold the lens model inside the image")
    p.add_argument("--floor-view", help="the view (file name without suffix) of the board lying on the floor")
    p.add_argument("--board-thickness", type=_finite(0.0, 0.1), default=0.0, help="metres, for the floor view")
    p.add_argument("--camera-height", type=_finite(*CAMERA_HEIGHT_RANGE_M),
                   help="instead of a floor view: the first camera above the floor, m")
    _add_tilt(p)
    _add_volume(p, "rig frame")
    p.add_argument("--rig-id", default="rig")
    p.set_defaults(run=cmd_solve)

    p = sub.add_parser("check", help="check a rig file against new views of the board")
    p.add_argument("--rig", type=user_path, required=True)
    p.add_argument("--board", type=user_path, help="the board's definition (default: IMAGES/board.json, else the board the rig "
                                   "records); its square size must be the one the rig was solved with")
    p.add_argument("--images", type=user_path, required=True)
    p.add_argument("--floor-view", help="the view of the board lying on the floor (default: the rig's, as given "
                                        "to solve, else 'floor')")
    p.add_argument("--board-thickness", type=_finite(0.0, 0.1),
                   help="metres, for the floor view (default: the one given to solve, as recorded, else 0)")
    p.add_argument("--max-px", type=_finite(0.01, 100.0), default=CheckLimits.max_px,
                   help=f"largest acceptable reprojection rms (default {CheckLimits.max_px:g} px)")
    p.add_argument("--max-scale-error", type=_finite(0.0001, 1.0), default=CheckLimits.max_scale_error, help="default 0.01 (1 %%)")
    p.add_argument("--max-floor-mm", type=_finite(0.1, 10000.0), default=CheckLimits.max_floor_mm,
                   help=f"the floor view's height off the floor (default {CheckLimits.max_floor_mm:g})")
    p.add_argument("--json", action="store_true", help="print the full report")
    p.set_defaults(run=cmd_check)

    p = sub.add_parser("import", help="write a rig file from another tool's calibration (OpenCV, anipose)")
    p.add_argument("file", type=user_path, help="OpenCV FileStorage .yml/.yaml/.xml/.json, each also gzipped as "
                                ".yml.gz or .yml.gz1-9... (our multi-camera layout or stereo_calib's intrinsics.yml) "
                                "or anipose calibration.toml")
    p.add_argument("--out", type=user_path, required=True, help="rig file to write (docs/rig-file.md)")
    p.add_argument("--format", choices=("opencv", "anipose"), help="default: from FILE's suffix")
    p.add_argument("--units-to-metres", type=_finite(1e-9, 1e9),
                   help="metres per unit of the file's translations (0.001: millimetres); required for anipose "
                        "and stereo_calib files, which do not say (an anipose file ghcal export wrote records it)")
    p.add_argument("--extrinsics", type=user_path, help="stereo_calib's extrinsics.yml, when R and T are not in FILE")
    # counts.image_size, as the other tools' --size: int() took '1_280' and other scripts' digits ('\u0663')
    p.add_argument("--image-size", type=image_size,
                   help="WIDTHxHEIGHT for cameras whose entry states no image size (the others keep theirs; where "
                        "every camera states one, one that states another is refused)")
    p.add_argument("--camera-height", type=_finite(*CAMERA_HEIGHT_RANGE_M),
                   help="level the rig: the first camera's height above the floor, m (without it the rig keeps "
                        "the file's frame: levelled where the file records a levelling its poses show, as ghcal "
                        "export writes for a levelled rig; else the tool's own, and a warning says so)")
    _add_tilt(p)
    _add_volume(p, "in the written rig's frame")
    p.add_argument("--rig-id", help="default: the file's, else its name")
    p.set_defaults(run=cmd_import)

    p = sub.add_parser("export", help="write a rig file for another tool (OpenCV FileStorage, anipose)")
    p.add_argument("--rig", type=user_path, required=True)
    p.add_argument("--out", type=user_path, required=True,
                   help=".yml/.yaml/.xml/.json (OpenCV FileStorage; gzipped with .gz after it: rig.yml.gz, not "
                        ".GZ, which OpenCV reads as plain text, nor .gz9, its name for rig.yml.gz at level 9) or "
                        ".toml (anipose)")
    p.add_argument("--format", choices=("opencv", "anipose"), help="default: from --out's suffix")
    p.add_argument("--units-to-metres", type=_finite(1e-9, 1e9),
                   help="metres per unit of the written translations (OpenCV: default 1, recorded in the file; "
                        "anipose: required, as its files do not say)")
    p.set_defaults(run=cmd_export)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    # SIGTERM (timeout, a wrapper's stop button, systemd) stops every command as Ctrl-C does: the capture closes
    # its cameras and says what it kept, the others say they did not finish; by default it killed them without
    # a word (exit 143 from the shell, the cameras never closed)
    try:
        # a rig loaded (check, export, synth --rig) or written (solve, import, synth: log_warnings_and_notes where
        # it is made, not first when it is next loaded) shows its notes beside its warnings, each a bare line on
        # stderr: with no logging set up, Python showed the warnings only
        with sigterm_as_interrupt(), rig_messages_on_stderr():
            return int(args.run(args))
    except (CalibrationError, RuntimeErrorBase, OSError) as e:
        # RuntimeErrorBase: a bad rig file (RigFileError) or geometry; OSError: a folder we cannot write
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # synth renders for about half a minute, solve detects and solves: no traceback
        print(f"{PROG}: stopped ({stop_words(e)}); the {args.command} did not finish", file=sys.stderr)
        return exit_status(e)  # the shell's figures for a death by the signal: 130, 143
    except Exception as e:  # noqa: BLE001 - a driver error in capture: one line, not a traceback
        import drivers

        if isinstance(e, drivers.DriverError):
            print(f"{PROG}: error: {e}", file=sys.stderr)
            return 2
        raise


if __name__ == "__main__":
    sys.exit(main())
