"""The ChArUco board definition: validation by key, files, the printed image, corner geometry."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from calibration.board import BoardSpec, load_board
from calibration.detect import BoardDetector
from calibration.errors import BoardError


@pytest.mark.parametrize("kwargs, key", [
    ({"squares_x": 2}, "squares_x"),
    ({"squares_y": 3.5}, "squares_y"),
    ({"squares_x": True}, "squares_x"),
    ({"square_m": 0}, "square_m"),
    ({"square_m": float("nan")}, "square_m"),
    ({"marker_m": 0.09}, "marker_m"),  # not smaller than the 0.08 square
    ({"dictionary": "DICT_9X9_1"}, "dictionary"),
    ({"dictionary": "DICT_4X4_50", "squares_x": 12, "squares_y": 10}, "dictionary"),  # 60 markers needed
    ({"legacy_pattern": 1}, "legacy_pattern"),
])
def test_invalid_boards_name_the_key(kwargs, key):
    with pytest.raises(BoardError) as e:
        BoardSpec(**kwargs)
    assert e.value.key == key and str(e.value).startswith(f"{key}: ")


def test_file_round_trip_and_errors(tmp_path):
    board = BoardSpec(squares_x=7, squares_y=5, square_m=0.05, marker_m=0.037)
    path = tmp_path / "board.json"
    path.write_text(json.dumps(board.to_dict()))
    assert load_board(path) == board
    path.write_text(json.dumps({**board.to_dict(), "square_mm": 50}))
    with pytest.raises(BoardError, match=f"^{path}: square_mm: unknown key"):
        load_board(path)
    path.write_text(json.dumps({**board.to_dict(), "marker_m": 0.06}))
    with pytest.raises(BoardError, match=f"^{path}: marker_m: must be smaller"):
        load_board(path)
    path.write_text("{not json")
    with pytest.raises(BoardError, match=f"^{path}: not a JSON file"):
        load_board(path)
    with pytest.raises(BoardError, match="cannot read"):
        load_board(tmp_path / "missing.json")


def test_corners_are_a_grid_of_squares():
    board = BoardSpec(squares_x=5, squares_y=4, square_m=0.1, marker_m=0.07)
    corners = board.corners_m()
    assert corners.shape == (board.corner_count, 3) == (12, 3)
    np.testing.assert_allclose(corners[0], [0.1, 0.1, 0.0], atol=1e-6)
    np.testing.assert_allclose(corners[1] - corners[0], [0.1, 0.0, 0.0], atol=1e-6)  # ids run along x
    np.testing.assert_allclose(corners[4] - corners[0], [0.0, 0.1, 0.0], atol=1e-6)  # then down a row


def test_the_printed_image_detects_with_every_corner():
    board = BoardSpec()
    image = board.image(px_per_square=60, margin_px=30)
    assert image.shape == (6 * 60 + 60, 9 * 60 + 60)
    view = BoardDetector(board).detect(image)
    assert view is not None and len(view) == board.corner_count
    # the corner with id k sits at its board position scaled to pixels (pixel centres at integers)
    expected = board.corners_m()[view.ids, :2] / board.square_m * 60 + 30 - 0.5
    assert np.max(np.abs(view.corners - expected)) < 0.5


def test_no_board_no_view():
    assert BoardDetector(BoardSpec()).detect(np.full((200, 300), 128, np.uint8)) is None
    assert BoardDetector(BoardSpec()).detect(cv2.cvtColor(np.zeros((50, 50), np.uint8), cv2.COLOR_GRAY2BGR)) is None
