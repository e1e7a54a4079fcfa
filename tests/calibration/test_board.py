"""The ChArUco board definition: validation by key, files, the printed image, corner geometry."""
from __future__ import annotations

import json
import re
from fractions import Fraction

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
    ({"squares_y": np.True_}, "squares_y"),
    ({"squares_x": np.float64(9)}, "squares_x"),
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


def test_a_board_file_saved_by_a_windows_editor_reads(tmp_path):
    # the measured square size typed in with Notepad: a byte-order mark and CRLF line ends, refused as "not JSON"
    board = BoardSpec(square_m=0.0787, marker_m=0.059)
    path = tmp_path / "board.json"
    path.write_bytes(b"\xef\xbb\xbf" + json.dumps(board.to_dict(), indent=2).replace("\n", "\r\n").encode())
    assert load_board(path) == board


def test_a_key_given_twice_is_refused_naming_it(tmp_path):
    # the measured size typed in above the old line: json kept the last, the old 80 mm, and scaled the rig by it
    path = tmp_path / "board.json"
    path.write_text('{"squares_x": 9, "squares_y": 6, "square_m": 0.0787, "marker_m": 0.059, "square_m": 0.08}')
    with pytest.raises(BoardError, match=r"square_m: given twice \(0\.0787 and 0\.08\)") as e:
        load_board(path)
    assert e.value.key == "square_m" and e.value.path == str(path)


@pytest.mark.parametrize("content, words", [(b"", "the file is empty"), (b" \r\n\t\n", "the file is empty"),
                                            (b"\x89PNG\r\n\x1a\n\x00\x00", "not UTF-8 text (byte 0)")])
def test_an_empty_or_binary_board_file_says_so(tmp_path, content, words):
    path = tmp_path / "board.json"
    path.write_bytes(content)
    with pytest.raises(BoardError, match=f"^{re.escape(str(path))}: .*{re.escape(words)}"):  # was "Expecting value"
        load_board(path)


def test_a_size_typed_in_millimetres_is_said_as_such():
    with pytest.raises(BoardError, match=r"square_m: .*got 80 \(millimetres\? 80 mm is 0\.08 m\)"):
        BoardSpec(square_m=80, marker_m=60)
    with pytest.raises(BoardError) as e:  # far out of range, and not a number: no guess
        BoardSpec(square_m=5000.0)
    assert "millimetres" not in str(e.value)


@pytest.mark.parametrize("kwargs, key", [
    ({"px_per_square": 30.5}, "px_per_square"),
    ({"px_per_square": 19}, "px_per_square"),
    ({"px_per_square": "60"}, "px_per_square"),
    ({"px_per_square": 60, "margin_px": -1}, "margin_px"),
])
def test_image_parameters_are_named(kwargs, key):
    # a float or a negative margin reached OpenCV: a bare cv2.error naming neither
    with pytest.raises(BoardError) as e:
        BoardSpec().image(**kwargs)
    assert e.value.key == key


def test_markers_too_small_to_draw_are_named_not_an_opencv_traceback(tmp_path, capsys):
    from calibration import cli

    board = BoardSpec(square_m=0.1, marker_m=0.002)  # 2 mm markers: valid, but 5 px at 72 dpi for 7 cells
    with pytest.raises(BoardError, match="marker_m: markers of 2 mm in squares of 100 mm are 5 px") as e:
        board.image(px_per_square=283)
    assert e.value.key == "marker_m"
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(board.to_dict()))
    assert cli.main(["board", "--board", str(path), "--out", str(tmp_path / "out"), "--dpi", "72"]) == 2
    assert "marker_m: markers of 2 mm" in capsys.readouterr().err
    assert board.image(px_per_square=400).shape == (6 * 400, 9 * 400)  # 8 px: drawn


def test_the_file_is_named_before_the_key_and_the_whole_message(tmp_path):
    # the file's name is put before the message as raised (BoardError.detail), colons in it kept
    path = tmp_path / "board.json"
    path.write_text(json.dumps({**BoardSpec().to_dict(), "squares_x": 3, "squares_y": 3}))
    with pytest.raises(BoardError) as e:
        load_board(path)
    assert str(e.value) == (f"{path}: squares_x: a 3x3 board has 4 inner corners; a view needs at least 6, so it "
                            "could never be found: add squares")


@pytest.mark.parametrize("key", ["square_m", "marker_m", "squares_x", "squares_y", "dictionary"])
def test_a_key_left_out_of_the_board_file_is_named_not_taken_from_the_default_board(tmp_path, key):
    # the measured square_m deleted while editing: the default board's 80 mm squares scaled the rig silently
    measured = {**BoardSpec(square_m=0.0787, marker_m=0.059).to_dict()}
    del measured[key]
    path = tmp_path / "board.json"
    path.write_text(json.dumps(measured))
    with pytest.raises(BoardError) as e:
        load_board(path)
    assert e.value.key == key and str(e.value).startswith(f"{path}: {key}: missing")


def test_a_board_file_without_legacy_pattern_reads_as_a_print_of_today(tmp_path):
    board = BoardSpec(square_m=0.0787, marker_m=0.059)
    path = tmp_path / "board.json"
    path.write_text(json.dumps({k: v for k, v in board.to_dict().items() if k != "legacy_pattern"}))
    assert load_board(path) == board


def test_a_numpy_length_is_a_length_and_a_huge_integer_is_refused_by_name():
    # np.float32(0.04) was refused as out of range though inside it; 10**400 raised a bare OverflowError
    assert BoardSpec(square_m=np.float32(0.04), marker_m=np.float64(0.03)).square_m == pytest.approx(0.04)
    with pytest.raises(BoardError, match="square_m"):
        BoardSpec(square_m=10 ** 400, marker_m=0.03)


def test_numpy_square_counts_are_counts_kept_as_python_ints():
    # np.int64(9) was refused as "not a whole number of squares"
    board = BoardSpec(squares_x=np.int64(9), squares_y=np.uint8(6))
    assert (board.squares_x, board.squares_y) == (9, 6)
    assert type(board.squares_x) is int and type(board.squares_y) is int
    assert json.loads(json.dumps(board.to_dict()))["squares_x"] == 9


def test_a_numpy_true_is_a_legacy_pattern_flag_kept_as_a_python_bool():
    # np.True_ (a comparison's result) was refused as "must be true or false"
    board = BoardSpec(legacy_pattern=np.True_)
    assert board.legacy_pattern is True
    assert json.loads(json.dumps(board.to_dict()))["legacy_pattern"] is True


def test_a_fraction_in_millimetres_is_refused_by_name_not_a_format_error():
    # any real number is a length since plain_values.is_finite_number; the millimetres hint formatted the value
    # itself with :g, which a Fraction refuses (Python 3.11): a bare TypeError instead of the BoardError
    with pytest.raises(BoardError, match=r"square_m: .*millimetres\? 80 mm is 0\.08 m"):
        BoardSpec(square_m=Fraction(80), marker_m=0.03)
    assert BoardSpec(square_m=Fraction(1, 25), marker_m=0.03).square_m == pytest.approx(0.04)


@pytest.mark.parametrize("text, says", [
    ("[" * 100_000 + "]" * 100_000, "not a JSON file: nested too deeply"),  # was a RecursionError traceback
    ('{"squares_x": 1' + "0" * 5000 + "}", "not a JSON file: Exceeds the limit (4300 digits)"),  # a ValueError one
    # parsed, and read as a field error ("squares_x: must be a whole number, got [[[...") until session 68
    ('{"squares_x": ' + "[" * 199 + "]" * 199 + "}", "not a JSON file: nested too deeply (objects and arrays more "
                                                     "than 128 levels deep, MAX_JSON_DEPTH)"),
    ("{not json", "not a JSON file: Expecting property name enclosed in double quotes at line 1, column 2"),
])
def test_board_json_past_the_parser_names_the_file(tmp_path, text, says):
    path = tmp_path / "board.json"
    path.write_text(text)
    with pytest.raises(BoardError) as e:
        load_board(path)
    assert str(e.value).startswith(f"{path}: {says}")
