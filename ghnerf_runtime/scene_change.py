"""Whether a camera's scene changed: the wake-up of resting cold tiles (``tracking.cold_tiles_wake_levels``).

A resting search (docs/runtime.md, "Cold tiles") skips the tile pass on most cold pairs, so a person who walks into an
empty room may wait for many pairs. Each camera's frame is kept as a small grey copy (:func:`scene_copy`, a grid
of :data:`THUMB_CELLS` cells, each the mean of :data:`CELL_SAMPLES` x :data:`CELL_SAMPLES` pixels sampled on a
lattice: no pass over the whole frame) when a tile pass finds nobody; a resting pair whose copy differs from the kept
one in :data:`WAKE_MIN_CELLS` cells or more by over the threshold wakes the search (:func:`scene_changed`).

Sensor noise averages out over a cell's samples; a change of exposure or light over the whole frame is taken out by
scaling each copy to its own mean before comparing (a gain, as the simulator's exposure jitter is, moves every cell
alike); a person moves the few cells they cover.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

#: the grey copy's cells, (rows, columns): a person the tiles are for (about a third of the frame tall) covers several
THUMB_CELLS = (18, 24)
#: pixels sampled per cell along each side (64 in all: sensor noise of several levels falls to under one)
CELL_SAMPLES = 8
#: cells that must change: one cell alone may be a flicker or a noise extreme, a person covers more
WAKE_MIN_CELLS = 2
#: a cell that woke this many resting searches whose whole round of tiles then found nobody (no joint: a person in one
#: view alone may be a screen's picture) wakes no more (until it stays still over CALM_AFTER_PASSES tile passes in a
#: row, or the estimator is reset): a screen, a curtain in a draught; one vain wake may be a person the tiles missed
RESTLESS_AFTER_WAKES = 2
#: a restless cell unchanged over this many tile passes in a row that found nobody wakes again (about 32 resting
#: pairs at a tile pass every 4th): a screen's next picture can match its last in a cell by chance, so one still
#: pass is not enough (with one, a screen woke the rest 10 times per 100 pairs, against 4 with none:
#: benchmarks/measure_cold_tiles.py --moving-room)
CALM_AFTER_PASSES = 8
#: a person seen by the same camera alone on this many pairs in a row clears the wake awake as a joint does (not in
#: vain): someone who stays, whose cells grew restless against a walk-in from there; a screen's pictures read as a
#: person on one pair at a time (session 71, benchmarks/measure_cold_tiles.py --moving-room: at most 1 in a row); each
#: pair within tracking.max_gap_s of the last (session 72: pairs apart in time are no stay)
ONE_VIEW_NOT_VAIN_PAIRS = 4


def _lattice(image: np.ndarray) -> np.ndarray:
    """``CELL_SAMPLES`` pixels per cell side of ``image``, evenly over the frame: a nearest-pixel resize (cv2's, a
    fifth of the time of NumPy's strided copy of a colour frame)."""
    size = (THUMB_CELLS[1] * CELL_SAMPLES, THUMB_CELLS[0] * CELL_SAMPLES)
    return cv2.resize(np.ascontiguousarray(image), size, interpolation=cv2.INTER_NEAREST)


@dataclass(frozen=True)
class SceneCopy:
    """One camera's frame as a small grey copy.

    Attributes:
        cells: ``THUMB_CELLS`` float32, each cell's mean grey over the frame's mean (a gain on the frame leaves them).
        mean_levels: the frame's mean grey, 8-bit levels (turns a difference of ``cells`` back into levels).
    """

    cells: np.ndarray
    mean_levels: float


def scene_copy(image: np.ndarray) -> SceneCopy:
    """``image`` (``(H, W)`` or ``(H, W, C)`` 8-bit) as a :class:`SceneCopy`: each cell the mean of its lattice
    samples over the channels."""
    samples = _lattice(image)
    if samples.ndim == 3 and samples.shape[2] == 3:
        samples = cv2.cvtColor(samples, cv2.COLOR_BGR2GRAY)  # the frames are BGR (drivers)
    elif samples.ndim == 3:
        samples = samples.mean(axis=2)
    # a box mean of each cell's samples (cv2: a tenth of NumPy's time on this small copy)
    cells = cv2.resize(samples.astype(np.float32), THUMB_CELLS[::-1], interpolation=cv2.INTER_AREA)
    mean = float(cells.mean())
    return SceneCopy(cells / mean if mean > 0 else cells, mean)


def pair_copies(images: Sequence[np.ndarray]) -> tuple[SceneCopy, ...]:
    """The pair's two frames (the first two of ``images``) as :class:`SceneCopy` s, the cameras' order kept: what
    :func:`scene_changed` compares."""
    return tuple(scene_copy(im) for im in images[:2])


def cell_differences(now: SceneCopy, kept: SceneCopy) -> np.ndarray:
    """Each cell's difference of ``now`` from ``kept``, 8-bit levels (at ``kept``'s brightness; at ``now``'s where
    ``kept`` is black, whose cells are 0 with no mean to scale by: scaled by its 0, nothing woke)."""
    scale = kept.mean_levels if kept.mean_levels > 0 else now.mean_levels
    return np.abs(now.cells - kept.cells) * scale


def changed_mask(now: SceneCopy, kept: SceneCopy, levels: float) -> np.ndarray:
    """The cells of ``now`` that differ from ``kept`` by over ``levels`` 8-bit levels (``THUMB_CELLS`` bool)."""
    return cell_differences(now, kept) > levels


def wake_statistic(now: tuple[SceneCopy, ...], kept: tuple[SceneCopy, ...]) -> float:
    """The difference the wake-up thresholds, 8-bit levels: each camera's :data:`WAKE_MIN_CELLS`-th largest cell
    difference, the largest over the cameras. :func:`scene_changed` is true exactly where this is over ``levels``
    (nothing ignored): what ``benchmarks/measure_cold_tiles.py --wake-margin`` reports."""
    return max(float(np.sort(cell_differences(n, k), axis=None)[-WAKE_MIN_CELLS]) for n, k in zip(now, kept))


def changed_masks(now: tuple[SceneCopy, ...], kept: tuple[SceneCopy, ...], levels: float) -> tuple[np.ndarray, ...]:
    """Each camera's :func:`changed_mask` of ``now`` against ``kept``, the cameras' order."""
    return tuple(changed_mask(n, k, levels) for n, k in zip(now, kept))


def masks_wake(masks: Sequence[np.ndarray], ignored: tuple[np.ndarray, ...] | None = None) -> bool:
    """Whether any camera's changed cells (:func:`changed_masks`) number :data:`WAKE_MIN_CELLS` or more, leaving out
    each camera's ``ignored`` cells (``THUMB_CELLS`` bool masks, the cameras' order) where given."""
    if ignored is not None:
        masks = [m & ~i for m, i in zip(masks, ignored)]
    return any(np.count_nonzero(m) >= WAKE_MIN_CELLS for m in masks)


def scene_changed(now: tuple[SceneCopy, ...], kept: tuple[SceneCopy, ...], levels: float,
                  ignored: tuple[np.ndarray, ...] | None = None) -> bool:
    """Whether any camera's copy ``now`` differs from the one ``kept`` in :data:`WAKE_MIN_CELLS` cells or more,
    leaving out each camera's ``ignored`` cells where given (:func:`masks_wake`)."""
    return masks_wake(changed_masks(now, kept, levels), ignored)


def restless_with_neighbours(restless: np.ndarray) -> np.ndarray:
    """``restless`` (``THUMB_CELLS`` bool) grown by one cell each way, diagonals too: a moving thing's edge cells,
    which it covers in part, change by less and not every time, so they wake on their own long after its core."""
    return cv2.dilate(restless.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
