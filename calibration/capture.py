"""Calibration images on disk: one folder per camera, a pair shares its file name.

Layout (what ``ghcal capture`` writes and ``ghcal solve`` reads)::

    DIR/left/000.png  DIR/right/000.png     # one pair: both cameras at the same instant
    DIR/left/001.png  DIR/right/001.png
    DIR/left/floor.png DIR/right/floor.png  # optional: the board lying on the floor

Images may be PNG, JPEG, BMP or TIFF; a name present in one folder only is still used for that
camera's intrinsics.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Iterable

import cv2

from calibration.board import BoardSpec
from calibration.detect import BoardDetector, BoardView
from calibration.errors import CaptureError

__all__ = ["IMAGE_SUFFIXES", "camera_folders", "list_images", "detect_folder", "check_camera_name",
           "next_view_number"]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")
_NUMBERED = re.compile(r"^(\d+)$")


def check_camera_name(name: str) -> str:
    """A camera name used as a folder name: letters, digits, ``_ - .``, not starting with a dot.

    :raises CaptureError: another name (``..`` or one with ``/`` would write outside the folder).
    """
    if not _SAFE_NAME.match(name):
        raise CaptureError(f"camera name {name!r} cannot be a folder name (letters, digits, '_', '-', '.'; "
                           "not starting with '.'): rename the camera in the rig file")
    return name


def next_view_number(folders: Iterable[Path]) -> int:
    """One past the highest numbered view in any of ``folders`` (so a new session never overwrites)."""
    numbers = [int(m[1]) for folder in folders if folder.is_dir() for p in folder.iterdir()
               if p.suffix.lower() in IMAGE_SUFFIXES and (m := _NUMBERED.match(p.stem))]
    return max(numbers, default=-1) + 1


def camera_folders(root: str | os.PathLike, cameras: Iterable[str] | None = None) -> dict[str, Path]:
    """Camera name -> its folder under ``root`` (``cameras`` in rig order; default: the two subfolders, sorted).

    :raises CaptureError: a missing folder, or not exactly two subfolders when ``cameras`` is not given.
    """
    root = Path(root)
    if not root.is_dir():
        raise CaptureError(f"{root}: no such folder of calibration images")
    if cameras is None:
        found = sorted(p.name for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
        if len(found) != 2:
            raise CaptureError(f"{root}: expected one subfolder per camera (two), found {found}; "
                               "name the pair with --cameras FIRST,SECOND")
        cameras = found
    out = {}
    for name in cameras:
        folder = root / check_camera_name(name)
        if not folder.is_dir():
            raise CaptureError(f"{folder}: no such folder (camera {name!r})")
        out[name] = folder
    return out


def list_images(folder: Path) -> dict[str, Path]:
    """View name (file stem) -> image path."""
    images = {}
    for path in sorted(folder.iterdir()):
        if path.suffix.lower() in IMAGE_SUFFIXES and path.is_file():
            if path.stem in images:
                raise CaptureError(f"{folder}: two images named {path.stem!r} ({images[path.stem].name}, {path.name})")
            images[path.stem] = path
    return images


def detect_folder(board: BoardSpec, root: str | os.PathLike, cameras: Iterable[str] | None = None) \
        -> tuple[dict[str, dict[str, BoardView]], dict[str, list[str]]]:
    """Detect the board in every image: (camera -> view name -> view, camera -> names without the board).

    :raises CaptureError: an unreadable image (named), a camera folder without images.
    """
    detector = BoardDetector(board)
    views: dict[str, dict[str, BoardView]] = {}
    missed: dict[str, list[str]] = {}
    for camera, folder in camera_folders(root, cameras).items():
        images = list_images(folder)
        if not images:
            raise CaptureError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
        views[camera], missed[camera] = {}, []
        for name, path in images.items():
            image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise CaptureError(f"{path}: not a readable image")
            view = detector.detect(image)
            if view is None:
                missed[camera].append(name)
            else:
                views[camera][name] = view
    return views, missed
