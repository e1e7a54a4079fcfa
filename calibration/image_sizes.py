"""The calibration images' sizes checked against each other, needing no rig file.

``ghcal solve`` compares the image sizes with the rig file it replaces at ``--out`` (folders exchanged whole,
:func:`~calibration.check.sized_as_exchanged`); with none there it had nothing to compare them with, and each
camera's images were compared only among those the board was found in (``calibration.solve.calibrate_intrinsics``,
which keeps that guard for library callers): an image of another size in which the board was not found went
unnoticed, and a pair exchanged between the folders was told only as "its images differ in size". Every image of a
camera is one size here, the board found in it or not: the size of its board detections where it has them, read
from the file's header where it has none. An image of another size is named with both sizes; one whose namesake in
the other camera's folder has this camera's size is said to be exchanged with it. ``ghcal check`` compares them the
same way, before it says the folders exchanged or compares them with its rig file's sizes (since session 69: it
compared only the images the board was found in).
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path

from calibration.capture import camera_folders, list_images, stored_size
from calibration.detect import BoardView

__all__ = ["camera_image_sizes", "mixed_sizes_problem", "mixed_views_problem"]

Size = tuple[int, int]


def camera_image_sizes(root: str | Path, cameras: Sequence[str], views: Mapping[str, Mapping[str, BoardView]]) \
        -> dict[str, dict[str, tuple[Path, Size]]]:
    """Camera -> image name -> (its file, its ``(width, height)``): a board view's size where the board was found
    (what the solve uses), else the file's stored size. An image that does not decode is left out (the detection
    names it)."""
    sizes: dict[str, dict[str, tuple[Path, Size]]] = {}
    for camera, folder in camera_folders(root, cameras).items():
        sizes[camera] = {}
        for name, path in list_images(folder).items():
            view = views.get(camera, {}).get(name)
            size = view.image_size if view is not None else stored_size(path)
            if size is not None:
                sizes[camera][name] = (path, (int(size[0]), int(size[1])))
    return sizes


def _usual_and_odd(named: Mapping[str, Size]) -> tuple[Size | None, list[str]]:
    """The size most of ``named`` (image or view name -> size) have, the first image's by name of equals (None
    without any), and the names of those of another size, sorted: what both the files' and the views' checks name,
    so that ``ghcal`` and a library caller's views of the same folder call the same size usual."""
    names = sorted(named)
    counts = Counter(named[name] for name in names)
    usual = counts.most_common(1)[0][0] if counts else None
    return usual, [name for name in names if named[name] != usual]


def _odd_size_words(what: str, size: Size, camera: str, usual: Size, count: int, kind: str) -> str:
    """One odd image's words, ``what`` its file (``ghcal``) or its view's name (:func:`mixed_views_problem`):
    "capture/left/stray.png is 32x16, the other 10 image(s) of camera 'left' 960x600"."""
    return f"{what} is {size[0]}x{size[1]}, the other {count} {kind}(s) of camera {camera!r} {usual[0]}x{usual[1]}"


def _odd_image_words(camera: str, name: str, sizes: Mapping[str, Mapping[str, tuple[Path, Size]]],
                     usual: Mapping[str, Size | None]) -> str:
    """What is wrong with ``camera``'s image ``name``, whose size is not its camera's usual one."""
    path, (w, h) = sizes[camera][name]
    count = sum(1 for _, size in sizes[camera].values() if size == usual[camera])
    own = usual[camera]
    assert own is not None
    words = _odd_size_words(str(path), (w, h), camera, own, count, "image")
    for other, images in sizes.items():
        namesake = images.get(name)
        if other != camera and namesake is not None and namesake[1] == own and usual[other] == (w, h):
            return (f"{words}, and its namesake {namesake[0]} has camera {camera!r}'s size, camera {other!r}'s "
                    f"images {w}x{h}: the two look exchanged; exchange them (or remove both)")
    return f"{words}: remove or retake it"  # why is the caller's to say: solve's lens, check's rig


def mixed_sizes_problem(sizes: Mapping[str, Mapping[str, tuple[Path, Size]]]) -> str | None:
    """The first camera whose images are not all one size, said per odd image (up to three), or None."""
    # ties by name as for views: by path ("a-b.png" before "a.png", until session 70's review) ghcal called usual
    # the size that calibrate_intrinsics, given the same folder's views, calls odd
    found = {camera: _usual_and_odd({name: size for name, (_, size) in images.items()})
             for camera, images in sizes.items()}
    usual = {camera: size for camera, (size, _) in found.items()}
    for camera, (_, odd) in found.items():
        if odd:
            return "; ".join(_odd_image_words(camera, name, sizes, usual) for name in odd[:3]) + _more(odd)
    return None


def mixed_views_problem(camera: str, views: Mapping[str, BoardView]) -> str | None:
    """One camera's board views not all one size, said per odd view (up to three) as :func:`mixed_sizes_problem`
    says files, or None: the guard of a caller that hands views without their files (``calibrate_intrinsics``)."""
    usual, odd = _usual_and_odd({name: view.image_size for name, view in views.items()})
    if not odd:
        return None
    assert usual is not None
    count = len(views) - len(odd)
    return "; ".join(_odd_size_words(f"view {name!r}", views[name].image_size, camera, usual, count, "view")
                     + ": remove or retake it" for name in odd[:3]) + _more(odd)


def _more(odd: Sequence[str]) -> str:
    """How many odd images were not said (beyond the first three)."""
    return f"; {len(odd) - 3} more" if len(odd) > 3 else ""
