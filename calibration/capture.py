"""Calibration images on disk: one folder per camera, a pair shares its file name.

Layout (what ``ghcal capture`` writes and ``ghcal solve`` reads)::

    DIR/left/000.png  DIR/right/000.png     # one pair: both cameras at the same instant
    DIR/left/001.png  DIR/right/001.png
    DIR/left/floor.png DIR/right/floor.png  # optional: the board lying on the floor
    DIR/cameras.json                        # {"cameras": ["left", "right"]}: the stream's order

Images may be PNG, JPEG, BMP or TIFF, grey or colour, 8 or 16 bits (a 16-bit one scaled by its 99.9th percentile:
:func:`~calibration.detect.white_level16`); a name present in one folder only is still used for that
camera's intrinsics. ``cameras.json`` keeps the order the rig source gave the cameras in: the first
is the one a driver opens as its first device (``opencv://?first=``), so the solved rig must list it
first too, whatever the names sort as (``names=right,left``).
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

import cv2

from calibration.board import BoardSpec
from calibration.detect import BoardDetector, BoardView, board_mismatch, mirrored_corners, mirrored_words
from calibration.errors import BoardError, CaptureError
from ghnerf_runtime.image_files import read_image_or_none, unread_because
from ghnerf_runtime.json_keys import first_repeat, loads_remembering
from ghnerf_runtime.rig_file import write_text_atomic

__all__ = ["IMAGE_SUFFIXES", "CAMERAS_FILE", "FolderViews", "camera_folders", "list_images", "detect_folder",
           "read_folder", "check_camera_name",
           "earlier_views", "earlier_size", "next_view_number", "read_camera_order", "stored_size",
           "write_camera_order"]

CAMERAS_FILE = "cameras.json"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")
_NUMBERED = re.compile(r"^(\d+)$")


def check_camera_name(name: str, fix: str = "rename the camera in the rig file") -> str:
    """A camera name used as a folder name: letters, digits, ``_ - .``, not starting with a dot.

    :raises CaptureError: another name (``..`` or one with ``/`` would write outside the folder), with ``fix``.
    """
    if not _SAFE_NAME.match(name):
        raise CaptureError(f"camera name {name!r} cannot be a folder name (letters, digits, '_', '-', '.'; "
                           f"not starting with '.'): {fix}")
    return name


def next_view_number(folders: Iterable[Path]) -> int:
    """One past the highest numbered view in any of ``folders`` (so a new session never overwrites)."""
    numbers = [int(m[1]) for folder in folders if folder.is_dir() for p in folder.iterdir()
               if p.suffix.lower() in IMAGE_SUFFIXES and (m := _NUMBERED.match(p.stem))]
    return max(numbers, default=-1) + 1


def earlier_views(root: str | os.PathLike) -> list[Path]:
    """The numbered views (``000.png``...) already in ``root``'s camera folders: an earlier session's,
    which a new one would be mixed with (the floor view is not counted: it is taken on its own)."""
    root = Path(root)
    if not root.is_dir():
        return []
    return sorted(p for folder in root.iterdir() if folder.is_dir() and not folder.name.startswith(".")
                  for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and _NUMBERED.match(p.stem))


def earlier_size(folder: Path, *, skip: Iterable[str] = ()) -> tuple[Path, tuple[int, int]] | None:
    """An image already in a camera's ``folder`` and its ``(width, height)``; None when it holds none.

    A session appended (or a floor view added) at another size than the views there was kept without a word, and
    the solve then refused the mix: the cameras of another rig, or opened at another resolution. One image stands
    for the folder: the solve names each image of another size (:mod:`calibration.image_sizes`). Views named in
    ``skip`` do not count (a floor view being replaced).
    """
    images = list_images(folder) if folder.is_dir() else {}
    for name, path in images.items():
        if name in skip:
            continue
        size = stored_size(path)
        if size is not None:  # an unreadable one is the solve's to name
            return path, size
    return None


def stored_size(path: Path) -> tuple[int, int] | None:
    """An image's ``(width, height)`` as stored, by replay's reader of sizes (``drivers.backends.recording_format.
    image_size``: from its header where it gives one, else decoded; a camera's 8000x6000 still was decoded whole,
    about 400 MB, for its size alone); None for one replay does not decode, which the detection refuses too, naming
    it (a TIFF of 32-bit samples, float or integer: "the board is found in 8- or 16-bit images only"). Until session
    69 this decoded such a TIFF itself, unchanged, and ``earlier_size`` took its size as the folder's."""
    from drivers.backends.recording_format import image_size  # a backend's module: imported when a size is asked

    size = image_size(path)
    return (int(size[0]), int(size[1])) if isinstance(size, tuple) else None


def write_camera_order(root: str | os.PathLike, names: Iterable[str], *, replace: bool = False) -> None:
    """Record the pair's order (the rig source's) in ``root/cameras.json``, atomically.

    :raises CaptureError: ``root`` already records another order and not ``replace`` (a second session
        from a source that orders the cameras otherwise: which one is first?).
    """
    names = [check_camera_name(n) for n in names]
    path = Path(root) / CAMERAS_FILE
    if path.exists() and not replace:
        recorded = read_camera_order(root, check_folders=False)
        if recorded != names:
            raise CaptureError(f"{path} records the cameras {recorded}, this source gives {names}: capture into "
                               "another folder (or remove the folder's views and cameras.json)")
        return
    write_text_atomic(path, json.dumps({"cameras": names}) + "\n")


def read_camera_order(root: str | os.PathLike, *, check_folders: bool = True) -> list[str] | None:
    """The pair's order recorded in ``root/cameras.json``; None without the file.

    :raises CaptureError: an unreadable file, or (``check_folders``) a camera it names without a folder.
    """
    path = Path(root) / CAMERAS_FILE
    if not path.is_file():
        return None
    try:
        # JsonTextError (a ValueError): not JSON, nested past MAX_JSON_DEPTH (129 levels read as a wrong layout
        # before) or an integer past 4300 digits; the other ValueError: not UTF-8
        # utf-8-sig: edited in Notepad (docs: edit it to match a swapped rig URL), it starts with a byte-order mark,
        # which was refused as invalid JSON
        data = loads_remembering(path.read_text(encoding="utf-8-sig"))
    except (OSError, ValueError) as e:
        raise CaptureError(f"{path}: cannot read the camera order ({e})") from e
    if (repeated := first_repeat(data)) is not None:
        # JSON keeps the last: a swapped order typed in above the old line (docs: edit cameras.json to match a
        # swapped rig URL) was undone by it, and the pair solved in the old order without a word
        raise CaptureError(f"{path}: the key {repeated!r} is given twice (JSON keeps the last): keep one")
    names = data.get("cameras") if isinstance(data, dict) else None
    if (not isinstance(names, list) or len(names) != 2 or not all(isinstance(n, str) for n in names)
            or len(set(names)) != 2):  # strings first: a list entry is unhashable
        raise CaptureError(f"{path}: must be {{\"cameras\": [FIRST, SECOND]}}, two different names, got {data!r}")
    for name in names:  # the file named, and its own fix: "rename the camera in the rig file" named neither
        check_camera_name(name, fix=f"{path} names the pair's two folders, in the order the rig source opens them")
    missing = [n for n in names if not (Path(root) / n).is_dir()] if check_folders else []
    if missing:
        raise CaptureError(f"{path} names the cameras {names}, but {root} has no folder {missing[0]!r}: restore it, "
                           "or pass --cameras FIRST,SECOND")
    return names


def camera_folders(root: str | os.PathLike, cameras: Iterable[str] | None = None) -> dict[str, Path]:
    """Camera name -> its folder under ``root``, in rig order: ``cameras``, else the order ``root/cameras.json``
    records, else the two subfolders sorted.

    :raises CaptureError: a missing folder, or not exactly two subfolders when the order is not known.
    """
    root = Path(root)
    if not root.is_dir():
        raise CaptureError(f"{root}: no such folder of calibration images")
    if cameras is None:
        cameras = read_camera_order(root)
    if cameras is None:
        found = sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
        if len(found) != 2:
            raise CaptureError(f"{root}: expected one subfolder per camera (two), found {found}; "
                               "name the pair with --cameras FIRST,SECOND")
        cameras = found
    out = {}
    for name in cameras:
        # the name of a folder, or given with --cameras: there is no rig file to rename it in
        folder = root / check_camera_name(name, fix=f"the camera folders of {root} name the pair (rename the folder), "
                                                    "or --cameras FIRST,SECOND does")
        if not folder.is_dir():
            raise CaptureError(f"{folder}: no such folder (camera {name!r})")
        out[name] = folder
    return out


def list_images(folder: Path) -> dict[str, Path]:
    """View name (file stem) -> image path; hidden files (``.NAME``) are not views.

    Hidden as camera folders are: macOS writes a ``._000.png`` of metadata beside each image copied to a
    USB stick or network share, and each stopped the solve as "not a readable image", one at a time.
    """
    images = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file() and not path.name.startswith("."):
            if path.stem in images:
                raise CaptureError(f"{folder}: two images named {path.stem!r} ({images[path.stem].name}, {path.name})")
            images[path.stem] = path
    return images


#: How a board image is read: grey at the file's own depth, as stored (image_files.read_image_or_none: a phone's
#: still tagged "turn a quarter" was calibrated turned while earlier_size and replay:// took it as stored).
READ_GREY = cv2.IMREAD_ANYDEPTH


@dataclass(frozen=True)
class FolderViews:
    """What :func:`read_folder` found in a capture: ``views`` (camera -> view name -> the board's corners),
    ``missed`` (camera -> names of images without the board) and ``unread`` (camera -> view name -> why its image
    does not read: the path and the reason, as said to the user)."""

    views: dict[str, dict[str, BoardView]]
    missed: dict[str, list[str]]
    unread: dict[str, dict[str, str]]


def read_folder(board: BoardSpec, root: str | os.PathLike, cameras: Iterable[str] | None = None) -> FolderViews:
    """Detect the board in every image that reads, passing over (and recording) one that does not: ``ghcal solve``
    and ``check`` say each and go on, as they go on past an image without the board (since session 74: one cut-off
    copy stopped them). Images are read as grey at their own depth (8 or 16 bits; 16-bit ones scaled by
    :func:`~calibration.detect.grey8`).

    :raises CaptureError: a camera folder without images, or of which no image reads (the first named, with why:
        a format or compression OpenCV does not decode is every image's); an image of the board printed with the
        other chessboard pattern (named, with the ``legacy_pattern`` to set).
    """
    detector = BoardDetector(board)
    found = FolderViews({}, {}, {})
    for camera, folder in camera_folders(root, cameras).items():
        images = list_images(folder)
        if not images:
            raise CaptureError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
        views, missed, unread = found.views.setdefault(camera, {}), found.missed.setdefault(camera, []), \
            found.unread.setdefault(camera, {})
        for name, path in images.items():
            # grey at the file's own depth: IMREAD_GRAYSCALE cut a 16-bit file to its top 8 bits, all but
            # black for a 10- or 12-bit camera's frame (the detector scales it: detect.grey8)
            image = read_image_or_none(path, READ_GREY)
            if image is None:
                unread[name] = f"{path}: not a readable image{_why_unreadable(path)}"
                continue
            try:
                view = detector.detect(image)
            except (BoardError, CaptureError) as e:
                raise CaptureError(f"{path}: {e}") from e
            if view is None:
                missed.append(name)
            else:
                views[name] = view
        if len(unread) == len(images):
            raise CaptureError(f"camera {camera!r}: none of its {len(images)} image(s) reads: "
                               f"{next(iter(unread.values()))}")
        if not views:
            _name_board_mismatch(board, [images[n] for n in missed])
    return found


def detect_folder(board: BoardSpec, root: str | os.PathLike, cameras: Iterable[str] | None = None) \
        -> tuple[dict[str, dict[str, BoardView]], dict[str, list[str]]]:
    """:func:`read_folder`, strict: (camera -> view name -> view, camera -> names without the board).

    :raises CaptureError: as :func:`read_folder`, and for an unreadable image (the first, named).
    """
    found = read_folder(board, root, cameras)
    for unread in found.unread.values():
        if unread:
            raise CaptureError(next(iter(unread.values())))
    return found.views, found.missed


def _why_unreadable(path: Path) -> str:
    """Why an image that did not decode does not, where the file says (:func:`unread_because`): a TIFF of a
    compression OpenCV does not decode, say (most such were read as black images, the board "not found")."""
    cause = unread_because(path, READ_GREY)
    return "" if cause is None else f": {cause}"


#: A camera that found the board in none of its images: this many of them (spread over the capture) are tried
#: with the other ArUco dictionaries (three detections each).
MISMATCH_TRIES = 3


def _name_board_mismatch(board: BoardSpec, paths: list[Path]) -> None:
    """Raise naming the mistake if the images show the board with another dictionary's markers (the board
    file's), or mirrored (the camera's).

    :raises CaptureError: the image and the key to set (:func:`~calibration.detect.board_mismatch`), or the
        mirroring to turn off (:func:`~calibration.detect.mirrored_corners`).
    """
    step = max(1, len(paths) // MISMATCH_TRIES)
    for path in paths[::step][:MISMATCH_TRIES]:
        image = read_image_or_none(path, READ_GREY)
        if image is None:
            continue
        error = board_mismatch(board, image)
        if error is not None:
            raise CaptureError(f"{path}: {error}") from error
        corners = mirrored_corners(board, image)
        if corners:
            raise CaptureError(f"{path}: {mirrored_words(corners)}")
