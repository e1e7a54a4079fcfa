"""The runtime's black padding of a crop that reaches past its camera's frame, for training crops.

The runtime keeps a crop square where it leaves the frame and shows zeros there under
``roi.pad_fill="black"`` (``ghnerf_runtime/preprocess.py``, "Clamp / pad policy"; the runtime's default
since session 56 is ``"fade"``, which this does not imitate: a model trained with it is exported with
``frame_padding: "black"`` in its contract, and an unset ``roi.pad_fill`` then gives it "black").
The synthetic training crops are rendered directly at the crop camera (``training/data/views.py``), so the
simulator fills those pixels with the room: the model never saw the black band it meets at run time
(``docs/runtime.md``, "Known gaps").

:func:`frame_coverage` is the runtime's own crop (its remap tables and ``apply_crop_maps``) of a frame of
ones: each model pixel's share of frame, 1 inside, 0 past the edge, and in between on the one-pixel fade
of the bilinear taps and box means there. The runtime's crop of any frame is that frame's crop times this
share along the edge (the taps past it read 0), so a training crop multiplied by it shows the padding
the runtime would give the same box: the same side, the same value, the same resize.

The training crop's own pixels are the simulator's box-reduced render, not the runtime's resampling of a
frame, so on the fade band (the pixels strictly between 0 and 1) the two differ by what the reduction of a
product differs from the product of the reductions: a few levels; the zeros and the pixels all inside the
frame are the same.

Used at training time on the model's inputs only (``training.data.targets.model_inputs``,
``TargetConfig.frame_padding``): the stored crops and the render targets keep the whole picture (a
source view is also a rendering target, whose colour behind the band is known). Exact for the synthetic
data, whose rigs have no lens distortion (``drivers.sim.RigPlacement.random``): the stored ``full_K`` and
``full_size`` are then the whole camera. Torch-free.
"""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.config import RoiConfig
from ghnerf_runtime.geometry import Camera
from ghnerf_runtime.preprocess import Roi, apply_crop_maps, build_undistort_crop_maps

#: The runtime's default ``roi.supersample``: the padding's fade band is that of the runtime's default crops.
RUNTIME_SUPERSAMPLE = RoiConfig().supersample


def frame_coverage(full_K: np.ndarray, full_size: tuple[int, int], roi: Roi, resolution: int, *,
                   supersample: int = RUNTIME_SUPERSAMPLE) -> np.ndarray | None:
    """``(S, S)`` float32: the share of each model pixel of ``roi``'s crop that the ``full_size`` frame of a
    pinhole camera ``full_K`` shows, as the runtime's crop maps sample it (module docstring); ``None`` where
    the crop lies inside the frame (every pixel 1).

    Raises:
        GeometryError: ``full_K`` or ``full_size`` do not make a camera (the message names the value).
    """
    width, height = (int(v) for v in full_size)
    # A crop whose window, grown by two model pixels for the bilinear taps and box steps, stays inside the
    # frame reads frame only: skip the remap tables (about 1 ms a view) for the ~99 % of crops that do.
    grow = 2 * roi.size / resolution + 1
    if roi.x0 - grow >= 0 and roi.y0 - grow >= 0 and roi.x0 + roi.size - 1 + grow <= width - 1 \
            and roi.y0 + roi.size - 1 + grow <= height - 1:
        return None
    camera = Camera("frame", width, height, np.asarray(full_K, dtype=np.float64))
    maps = build_undistort_crop_maps(camera, roi, resolution, supersample=supersample)
    if maps.inside is None:
        return None
    return apply_crop_maps(np.ones((height, width), np.float32), maps)


def cut_frame(full_K: np.ndarray, full_size: tuple[int, int], roi: Roi, side: str,
              band: float) -> tuple[np.ndarray, tuple[int, int], Roi]:
    """The camera of a frame cut on its ``side`` (``"left"`` or ``"right"``) so that ``band`` of ``roi``'s side
    lies past the cut: ``(K, (width, height), roi)`` of the cut camera (``Camera.cropped``'s), for
    :func:`frame_coverage`. A cut that would not enter the frame leaves it as it is.

    The runtime meets it where a person stands at the frame's edge: its crop then holds a band of black a third
    or more of its side wide (``docs/runtime.md``, "Known gaps"), where the working volume keeps the training
    subjects inside the frame (their crops cross it by a few pixels at most).
    """
    width, height = (int(v) for v in full_size)
    K = np.array(full_K, dtype=np.float64)
    cut = int(round(band * roi.size))
    if side == "left":
        c = roi.x0 + cut  # the first column kept
        if c <= 0 or c >= width:
            return K, (width, height), roi
        K[0, 2] -= c
        return K, (width - c, height), Roi(roi.x0 - c, roi.y0, roi.size)
    if side == "right":
        c = roi.x0 + roi.size - cut  # the first column cut off
        if c >= width or c <= 0:
            return K, (width, height), roi
        return K, (c, height), roi
    raise ValueError(f"side must be 'left' or 'right', got {side!r}")


__all__ = ["RUNTIME_SUPERSAMPLE", "frame_coverage", "cut_frame"]
