"""``ghnerf_runtime.scene_change``: the small grey copies a resting cold-tile search wakes on
(``tracking.cold_tiles_wake_levels``, docs/runtime.md, "Cold tiles")."""
from __future__ import annotations

import numpy as np

from ghnerf_runtime.scene_change import (THUMB_CELLS, WAKE_MIN_CELLS, changed_masks, masks_wake, pair_copies,
                                         restless_with_neighbours, scene_changed, scene_copy, wake_statistic)


def textured_frame(seed: int = 0) -> np.ndarray:
    """An 800 x 1280 BGR frame of smooth texture, levels 60-190."""
    rng = np.random.default_rng(seed)
    coarse = rng.uniform(60, 190, (10, 16, 3)).astype(np.float32)
    return np.repeat(np.repeat(coarse, 80, axis=0), 80, axis=1).astype(np.uint8)


def _cells_changed(now: np.ndarray, kept: np.ndarray, levels: float) -> int:
    """How many cells of frame ``now``'s copy differ from frame ``kept``'s by over ``levels``, through
    ``changed_masks``, which the estimator's wake check counts (``masks_wake``)."""
    (mask,) = changed_masks((scene_copy(now),), (scene_copy(kept),), levels)
    return int(np.count_nonzero(mask))


def test_a_copy_is_the_cells_over_the_frame_mean():
    copy = scene_copy(textured_frame())
    assert copy.cells.shape == THUMB_CELLS
    assert abs(float(copy.cells.mean()) - 1.0) < 1e-5 and 60 < copy.mean_levels < 190


def test_a_gain_over_the_whole_frame_changes_no_cell():
    frame = textured_frame()
    brighter = np.clip(frame * 1.15, 0, 255).astype(np.uint8)
    assert _cells_changed(brighter, frame, 3.0) == 0


def test_a_person_sized_patch_changes_cells_and_the_scene():
    frame = textured_frame()
    walked_in = frame.copy()
    walked_in[300:620, 500:580] = 20  # dark clothes, about 320 x 80 pixels (a person the tiles are for)
    kept = (scene_copy(frame), scene_copy(frame))
    assert _cells_changed(walked_in, frame, 6.0) >= 4
    assert scene_changed((scene_copy(frame), scene_copy(walked_in)), kept, 6.0)
    assert not scene_changed((scene_copy(frame), scene_copy(frame)), kept, 6.0)


def test_grey_and_small_frames_are_copied_too():
    grey = textured_frame()[:, :, 1]
    assert scene_copy(grey).cells.shape == THUMB_CELLS
    assert scene_copy(grey[:50, :60]).cells.shape == THUMB_CELLS  # smaller than the lattice: resized up


def test_a_person_lit_in_front_of_a_camera_kept_black_changes_its_cells():
    """A copy kept from a black frame (lights off, a covered lens) has no mean to scale by: the difference was scaled
    by its 0 and no change, however large, woke the search through that camera. The frame now seen gives the scale."""
    black = np.zeros((480, 640, 3), np.uint8)
    lit = black.copy()
    lit[100:400, 200:300] = 200  # a person-sized patch
    assert _cells_changed(lit, black, 6.0) >= 2
    assert scene_changed((scene_copy(lit),), (scene_copy(black),), 6.0)
    assert _cells_changed(black, black, 6.0) == 0


def test_pair_copies_are_the_first_two_frames_copies_in_the_cameras_order():
    """What the estimator keeps and compares (a third frame, a novel view's or a spare camera's, is not the pair's)."""
    frames = [textured_frame(seed) for seed in range(3)]
    copies = pair_copies(frames)
    assert len(copies) == 2
    for copy, frame in zip(copies, frames):
        expected = scene_copy(frame)
        np.testing.assert_array_equal(copy.cells, expected.cells)
        assert copy.mean_levels == expected.mean_levels


def test_the_wake_statistic_is_over_the_levels_exactly_where_the_scene_changed():
    """The 2nd largest cell difference of either camera: what ``measure_cold_tiles.py --wake-margin`` reports."""
    frame = textured_frame()
    kept = (scene_copy(frame), scene_copy(frame))
    for patch_levels in (3, 8, 20, 60):
        walked_in = frame.copy()
        walked_in[300:620, 500:580] = np.clip(walked_in[300:620, 500:580].astype(int) - patch_levels, 0, 255)
        now = (scene_copy(frame), scene_copy(walked_in))
        stat = wake_statistic(now, kept)
        for levels in (2.0, 6.0, 15.0, 40.0):
            assert (stat > levels) == scene_changed(now, kept, levels), (patch_levels, levels, stat)
    assert wake_statistic(kept, kept) == 0.0


def test_ignored_cells_do_not_change_the_scene():
    frame = textured_frame()
    walked_in = frame.copy()
    walked_in[300:620, 500:580] = 20
    kept, now = (scene_copy(frame),), (scene_copy(walked_in),)
    changed = np.abs(now[0].cells - kept[0].cells) * kept[0].mean_levels > 6.0
    assert np.count_nonzero(changed) >= WAKE_MIN_CELLS
    assert not scene_changed(now, kept, 6.0, (changed,))
    all_but_two = changed.copy()
    for row, col in np.argwhere(changed)[:WAKE_MIN_CELLS]:
        all_but_two[row, col] = False  # two changed cells not ignored: a change again
    assert scene_changed(now, kept, 6.0, (all_but_two,))


def test_restless_cells_grow_by_their_neighbours():
    restless = np.zeros(THUMB_CELLS, bool)
    restless[5, 10] = True
    grown = restless_with_neighbours(restless)
    assert grown.sum() == 9 and grown[4:7, 9:12].all()
    corner = np.zeros(THUMB_CELLS, bool)
    corner[0, 0] = True
    assert restless_with_neighbours(corner).sum() == 4


def test_the_wake_counts_each_camera_s_changed_cells_apart():
    """``masks_wake`` (the estimator's check): ``WAKE_MIN_CELLS`` changed cells in one camera wake, one fewer in each
    camera do not (a cell of a flicker in each view is no person), and a camera's ignored cells are left out."""
    one_short, enough, none = (np.zeros(THUMB_CELLS, bool) for _ in range(3))
    one_short.flat[:WAKE_MIN_CELLS - 1] = True
    enough.flat[:WAKE_MIN_CELLS] = True
    assert not masks_wake((one_short, one_short))
    assert masks_wake((one_short, enough)) and masks_wake((enough, one_short))
    assert not masks_wake((enough, one_short), (enough, none)) and masks_wake((enough, one_short), (none, enough))
