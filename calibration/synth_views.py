"""The record of the images ``ghcal synth`` wrote (``synth_views.json``), so that ``synth --force`` can take back the
earlier run's it does not write again, and only those.

Before it, ``synth --force --count 5`` into a folder an earlier ``--count 20`` had rendered left that run's views
``017``-``031`` beside the new ones, and ``ghcal solve`` on the folder used views of both rigs or seeds without a word.
The names alone cannot tell synth's images from a capture's (``ghcal capture`` numbers its views ``000``... too), so
each image is recorded with its SHA-256: one replaced since (a real view copied in under the same name) is left.
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping
from pathlib import Path

from calibration.capture import IMAGE_SUFFIXES, check_camera_name
from calibration.errors import CaptureError
from ghnerf_runtime.json_keys import first_repeat, loads_remembering
from ghnerf_runtime.rig_file import write_text_atomic

__all__ = ["SYNTH_VIEWS_FILE", "ViewDigests", "image_digest", "read_synth_views", "write_synth_views",
           "remove_earlier_views", "images_not_written"]

SYNTH_VIEWS_FILE = "synth_views.json"

#: camera name -> image file name (``000.png``) -> SHA-256 of its bytes, hex.
ViewDigests = Mapping[str, Mapping[str, str]]


def image_digest(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _plain_image_name(name: object) -> bool:
    """A file name inside a camera folder, of an image: nothing a hand-edited record could aim outside it with."""
    return (isinstance(name, str) and Path(name).name == name and not name.startswith(".")
            and Path(name).suffix.lower() in IMAGE_SUFFIXES)


def read_synth_views(out: Path) -> dict[str, dict[str, str]]:
    """The images an earlier ``synth`` recorded in ``out``; empty without the record.

    :raises CaptureError: a record that does not read as one, naming the file and the fix.
    """
    path = out / SYNTH_VIEWS_FILE
    if not path.is_file():
        return {}
    fix = "remove it (the images it lists are then left as they are)"
    try:
        data = loads_remembering(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise CaptureError(f"{path}: cannot read the record of ghcal synth's images ({e}): {fix}") from e
    cameras = data.get("cameras") if isinstance(data, dict) else None
    if first_repeat(data) is not None or not isinstance(cameras, dict):
        raise CaptureError(f"{path}: not a record of ghcal synth's images "
                           f"({{\"cameras\": {{NAME: {{FILE: SHA256}}}}}}): {fix}")
    views: dict[str, dict[str, str]] = {}
    for camera, files in cameras.items():
        check_camera_name(camera, fix=f"{path} names it: {fix}")
        if not isinstance(files, dict) or not all(_plain_image_name(n) and isinstance(d, str)
                                                  for n, d in files.items()):
            raise CaptureError(f"{path}: camera {camera!r}: not a map of image file names to SHA-256 digests: {fix}")
        views[camera] = dict(files)
    return views


def write_synth_views(out: Path, views: ViewDigests) -> None:
    """Record ``views`` (the images this run wrote) in ``out``, atomically: the earlier run's record is replaced."""
    record = {"cameras": {camera: dict(sorted(files.items())) for camera, files in views.items()}}
    write_text_atomic(out / SYNTH_VIEWS_FILE, json.dumps(record, indent=2) + "\n")


def remove_earlier_views(out: Path, earlier: ViewDigests, written: ViewDigests) -> list[Path]:
    """Remove the images of ``earlier`` (a record read before this run) that this run did not write again and that
    still hold the bytes recorded; a camera folder left empty that this run does not use goes too. Returns the
    images removed."""
    removed = []
    for camera, files in earlier.items():
        folder = out / camera
        for name, digest in files.items():
            path = folder / name
            if name in written.get(camera, {}) or not path.is_file() or path.is_symlink():
                continue
            if image_digest(path.read_bytes()) == digest:
                path.unlink()
                removed.append(path)
        if camera not in written and folder.is_dir() and not any(folder.iterdir()):
            folder.rmdir()
    return removed


def images_not_written(out: Path, cameras: Iterable[str], written: ViewDigests) -> list[Path]:
    """The images in ``cameras``' folders of ``out`` that this run did not write: ``ghcal solve`` reads them with its
    views (a capture's, or an earlier synth's it did not record or whose bytes were changed since)."""
    # listed here, not by list_images: a 000.jpg beside the 000.png written is named, not refused (the solve does)
    return [path for camera in cameras if (out / camera).is_dir() for path in sorted((out / camera).iterdir())
            if _plain_image_name(path.name) and path.is_file() and path.name not in written.get(camera, {})]
