"""A user's mistakes in the board file and the image folders, said as what to fix: a board file with its squares
swapped or another marker dictionary, a camera that never found the board, two folders whose images do not pair
by name, the hidden files macOS leaves beside copied images.

Images come from :func:`calibration.render.render_board` (one pose, a few hundred milliseconds each).
"""
from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration import cli
from calibration.board import BoardSpec
from calibration.capture import detect_folder
from calibration.detect import BoardDetector, board_mismatch, mirrored_corners
from calibration.errors import BoardError, CaptureError
from calibration.render import board_pose_facing, example_rig, render_board

BOARD = BoardSpec(squares_x=7, squares_y=6, square_m=0.12, marker_m=0.09)  # DICT_5X5_100, an even number of rows


@pytest.fixture(scope="module")
def camera():
    return example_rig().pair[0].resized(640, 400)


def _render(board: BoardSpec, camera, yaw_deg: float = 20.0) -> np.ndarray:
    R, t = board_pose_facing(board, camera.center + 1.6 * camera.R[2], camera.center, yaw_deg=yaw_deg,
                             pitch_deg=-15, spin_deg=10)
    return render_board(camera, board, R, t)


@pytest.fixture(scope="module")
def image(camera) -> np.ndarray:
    return _render(BOARD, camera)


def _folders(root: Path, images: dict[str, dict[str, np.ndarray]]) -> Path:
    for cam, named in images.items():
        (root / cam).mkdir(parents=True)
        for name, img in named.items():
            assert cv2.imwrite(str(root / cam / f"{name}.png"), img)
    return root


@pytest.mark.parametrize("printed_legacy", [False, True])
def test_a_board_file_with_its_squares_swapped_is_named(camera, tmp_path, printed_legacy):
    # 7x6 printed, 6x7 in the file: every marker is found (the same 21), OpenCV's marker check places them
    # nowhere, and each image was "no board": a capture ran out of time, a solve blamed the floor view
    printed = dataclasses.replace(BOARD, legacy_pattern=printed_legacy)
    written = dataclasses.replace(BOARD, squares_x=6, squares_y=7)
    image = _render(printed, camera)
    with pytest.raises(BoardError, match=r'7x6 squares \(\d+ corners found so\), the board file says 6x7: '
                                         r'set "squares_x": 7, "squares_y": 6') as e:
        BoardDetector(written).detect(image)
    assert e.value.key == "squares_x"
    assert ('"legacy_pattern": true' in str(e.value)) is printed_legacy  # said only where it differs too
    _folders(tmp_path, {"left": {"003": image}, "right": {"003": image}})
    with pytest.raises(CaptureError, match=r"left[/\\]003\.png: squares_x: the board in view is 7x6"):
        detect_folder(written, tmp_path)


def test_a_board_file_with_another_dictionary_is_named(image, tmp_path):
    # Read with DICT_4X4 no marker of a DICT_5X5 print is found at all: nothing said why
    written = dataclasses.replace(BOARD, dictionary="DICT_4X4_50")
    assert BoardDetector(written).detect(image) is None  # per image: no marker, no error (no cost per frame)
    blank = np.full_like(image, 90)
    _folders(tmp_path, {"left": {"000": blank, "001": image}, "right": {"000": blank, "001": image}})
    with pytest.raises(CaptureError, match=r'left[/\\]001\.png: dictionary: the board in view has the markers of another '
                                           r'ArUco dictionary, DICT_5X5_50 \(\d+ corners found with it\), not '
                                           r'DICT_4X4_50\'s: set "dictionary": "DICT_5X5_50"'):
        detect_folder(written, tmp_path)
    # the family's smallest dictionary that holds the board's markers: it reads a DICT_5X5_100 print
    assert len(BoardDetector(dataclasses.replace(BOARD, dictionary="DICT_5X5_50")).detect(image)) == BOARD.corner_count


def test_another_dictionary_and_swapped_squares_are_both_named(image):
    written = dataclasses.replace(BOARD, squares_x=6, squares_y=7, dictionary="DICT_6X6_250")
    error = board_mismatch(written, image)
    assert error is not None and error.key == "dictionary"
    assert '"dictionary": "DICT_5X5_50"' in str(error) and 'set "squares_x": 7, "squares_y": 6' in str(error)


def test_no_board_in_view_is_no_mismatch(image):
    assert board_mismatch(dataclasses.replace(BOARD, dictionary="DICT_4X4_50"), np.full_like(image, 90)) is None
    # a board file of another layout altogether: its markers' ids are in view, but placed elsewhere, so no
    # dictionary is named as the fix (checkMarkers)
    other = BoardSpec(squares_x=5, squares_y=4, square_m=0.1, marker_m=0.07, dictionary="DICT_6X6_50")
    assert board_mismatch(other, image) is None


def _board_file(tmp_path: Path) -> str:
    path = tmp_path / "board.json"
    path.write_text(json.dumps(BOARD.to_dict()))
    return str(path)


def test_a_camera_that_never_found_the_board_is_said_so(image, tmp_path, capsys):
    # the right camera's lens cap on: the solve blamed the floor view ("seen small and edge-on") or asked
    # for more views ("15-30 is usual")
    blank = np.full_like(image, 40)
    images = _folders(tmp_path / "views", {"left": {f"{k:03d}": image for k in range(4)} | {"floor": image},
                                           "right": {f"{k:03d}": blank for k in range(4)} | {"floor": blank}})
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(images), "--cameras", "left,right",
                   "--floor-view", "floor", "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "camera 'right' found the board in none of its 5 images" in err
    assert "7x6 squares of 120 mm" in err and "floor" not in err.split("error:")[1].split("(")[0]
    assert not (tmp_path / "rig.json").exists()


def test_a_blind_camera_s_count_says_its_unreadable_images_apart(image, tmp_path, capsys):
    # session 75: with two of its images cut off, the right camera "found the board in none of its 5 images" of 7
    blank = np.full_like(image, 40)
    images = _folders(tmp_path / "views", {"left": {f"{k:03d}": image for k in range(6)} | {"floor": image},
                                           "right": {f"{k:03d}": blank for k in range(6)} | {"floor": blank}})
    for name in ("004", "005"):
        (images / "right" / f"{name}.png").write_bytes(b"cut")
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(images), "--cameras", "left,right",
                   "--floor-view", "floor", "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "camera 'right' found the board in none of its 5 readable images (2 more unreadable)" in err


def test_folders_whose_images_do_not_pair_by_name_are_named(image, tmp_path, capsys):
    # another tool's naming, left/000.png beside right/right_000.png: no pair at all, and the solve said
    # "hold it where both cameras see it"
    images = _folders(tmp_path / "views", {"left": {f"{k:03d}": image for k in range(5)},
                                           "right": {f"right_{k:03d}": image for k in range(5)}})
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(images), "--cameras", "left,right",
                   "--camera-height", "1.4", "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2
    assert ("5 of 'left' (000, 001, 002, 003, ...) and 5 of 'right' (right_000, right_001, right_002, right_003, ...) "
            "have no namesake in the other folder, and only 0 name(s) are in both") in err
    assert "name each pair's two images alike" in err


def test_a_few_unpaired_images_are_noted_not_refused(capsys):
    views = {"left": {f"{k:03d}": None for k in range(6)}, "right": {f"{k:03d}": None for k in range(1, 5)}}
    missed = {"left": ["floor"], "right": ["floor", "099"]}
    cli._check_pairing("views", ("left", "right"), views, missed, "floor")
    out = capsys.readouterr().out
    assert ("note: images pair by file name (left/000.png with right/000.png): 2 of 'left' (000, 005) and 1 of "
            "'right' (099) have no namesake in the other folder: they count for that camera's lens only") in out
    cli._check_pairing("views", ("left", "right"), {"left": {"000": None}, "right": {"000": None}},
                       {"left": [], "right": []}, None)
    assert capsys.readouterr().out == ""  # every image paired: nothing said


def test_hidden_files_beside_the_images_are_not_views(image, tmp_path):
    # macOS writes ._NAME beside each file copied to a USB stick: each stopped the solve, one at a time
    root = _folders(tmp_path, {"left": {"000": image}, "right": {"000": image}})
    for cam in ("left", "right"):
        (root / cam / "._000.png").write_bytes(b"\x00\x05\x16\x07\x00\x02\x00\x00Mac OS X")
    views, missed = detect_folder(BOARD, root)
    assert sorted(views["left"]) == ["000"] and missed == {"left": [], "right": []}


def _capture_a_7x5_print(tmp_path: Path, mirrored: tuple[str, ...] = (), **board_file) -> tuple[int, Path, Path]:
    """``ghcal capture`` of a replay take that shows one view of a 7x5 DICT_5X5_100 print, with a board file that
    differs from the print by ``board_file`` (BoardSpec fields), the cameras named in ``mirrored`` delivering it
    flipped left to right: its exit status, the board file, the capture folder."""
    from calibration.render import calibration_views
    from ghnerf_runtime.geometry.rig import Rig
    from tests.calibration.test_ghcal_user_flows import _take

    rig = example_rig()
    truth = Rig(tuple(c.resized(800, 500) for c in rig.cameras), rig.volume, rig_id="truth")
    printed = BoardSpec(squares_x=7, squares_y=5, square_m=0.12, marker_m=0.09)
    one_view = calibration_views(truth, printed, count=1, edge_count=0, seed=5, floor_view=False)
    for cam in mirrored:
        one_view[cam] = {name: image[:, ::-1].copy() for name, image in one_view[cam].items()}
    take = _take(tmp_path / "take", truth, one_view)
    board = tmp_path / "board.json"
    board.write_text(json.dumps(dataclasses.replace(printed, **board_file).to_dict()))
    out = tmp_path / "capture"
    rc = cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(board), "--out", str(out),
                   "--count", "1", "--interval-s", "0", "--still-s", "0"])
    return rc, board, out


def test_a_capture_with_another_dictionary_says_so_at_once(tmp_path, capsys):
    # the board file of a DICT_4X4 board, a DICT_5X5 print in view: no marker in any frame, and the capture
    # ran its --max-seconds (10 minutes) without a word
    rc, board, out = _capture_a_7x5_print(tmp_path, dictionary="DICT_4X4_50")
    err = capsys.readouterr().err
    assert rc == 2 and f"camera 'left': {board}: dictionary: the board in view has the markers of another" in err
    assert 'set "dictionary": "DICT_5X5_50"' in err and not list(out.glob("*/*.png"))


def test_a_capture_with_another_number_of_squares_says_so_and_why_nothing_was_kept(tmp_path, capsys):
    # the board file of an 8x5 board, a 7x5 print in view: its markers are found, OpenCV places none of them
    # on the board described, and the capture ran its --max-seconds (10 minutes) without a word
    rc, board, out = _capture_a_7x5_print(tmp_path, squares_x=8)
    err = capsys.readouterr().err
    assert rc == 2 and not list(out.glob("*/*.png"))
    said = [line for line in err.splitlines() if "markers but not the board" in line]
    assert len(said) == 1  # once, not every few seconds
    assert re.match(rf"ghcal: camera 'left' sees 1[0-7] DICT_5X5_100 markers but not the board {re.escape(str(board))} "
                    r"describes \(8x5 squares of 120 mm", said[0])  # 17 on the print, a few may be missed
    assert "kept 0 of 1 views: the stream ended, and the board was in no image" in err


def test_a_capture_from_a_mirroring_camera_says_so_at_once(tmp_path, capsys):
    # both webcams set to mirror: no marker is found reversed, and the capture ran its --max-seconds without a word
    # (one camera mirrored, the other's views are kept, and the solve names the mirrored camera's images)
    rc, _, out = _capture_a_7x5_print(tmp_path, mirrored=("left", "right"))
    err = capsys.readouterr().err
    assert rc == 2 and "camera 'left': the board in view is mirrored (" in err
    assert "turn the mirroring off and capture again" in err and not list(out.glob("*/*.png"))


def test_a_camera_whose_images_are_mirrored_is_said_so(camera, image, tmp_path, capsys):
    # the solve asked whether the board file described the print, and whether the board was in view and sharp
    mirrored = np.ascontiguousarray(image[:, ::-1])
    assert BoardDetector(BOARD).detect(mirrored) is None and mirrored_corners(BOARD, image) == 0
    assert mirrored_corners(BOARD, mirrored) == BOARD.corner_count
    assert mirrored_corners(BOARD, np.ascontiguousarray(image[::-1])) == BOARD.corner_count  # top to bottom too
    images = _folders(tmp_path / "views", {"left": {f"{k:03d}": image for k in range(4)},
                                           "right": {f"{k:03d}": mirrored for k in range(4)}})
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(images), "--cameras", "left,right",
                   "--camera-height", "1.4", "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2 and re.search(r"right[/\\]000\.png: the board in view is mirrored \(\d+ corners found in the image "
                                 r"flipped left to right, none as it is\)", err)
    assert "turn the mirroring off and capture again" in err and "describe the print" not in err
    assert not (tmp_path / "rig.json").exists()


@pytest.mark.parametrize("text, says", [
    ("[" * 100_000 + "]" * 100_000, "(invalid JSON: nested too deeply)"),  # a RecursionError traceback from ghcal solve
    ('{"cameras": 1' + "0" * 5000 + "}", "(invalid JSON: Exceeds the limit (4300 digits)"),  # a ValueError traceback
    # parsed, and said to be of the wrong layout (its 200 levels shown) until session 68
    ('{"cameras": ' + "[" * 199 + "]" * 199 + "}", "(invalid JSON: nested too deeply (objects and arrays more than "
                                                   "128 levels deep, MAX_JSON_DEPTH))"),
])
def test_a_camera_order_file_past_the_parser_is_named(tmp_path, text, says):
    from calibration.capture import read_camera_order

    (tmp_path / "cameras.json").write_text(text)
    with pytest.raises(CaptureError) as e:
        read_camera_order(tmp_path)
    assert str(e.value).startswith(f"{tmp_path / 'cameras.json'}: cannot read the camera order {says}")


@pytest.mark.parametrize("argv, said", [
    # argparse named the parser functions: "invalid _positive_int value: '1.5'", "invalid parse value: 'abc'"; a
    # count is worded as the benchmark scripts' (ghnerf_runtime.cli.counts), no longer "expected a whole number"
    (["board", "--out", "b", "--dpi", "1.5"], "argument --dpi: must be a whole number >= 1, got '1.5'"),
    (["synth", "--out", "s", "--seed", "x"], "argument --seed: must be a whole number >= 0, got 'x'"),
    (["check", "--rig", "r.json", "--images", "i", "--max-px", "abc"],
     "argument --max-px: expected a number, got 'abc'"),
    (["capture", "--url", "sim://", "--out", "c", "--still-s", "soon"],
     "argument --still-s: expected a number, got 'soon'"),
])
def test_a_number_that_is_not_one_is_said_so(argv, said, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2 and said in capsys.readouterr().err


@pytest.mark.parametrize("argv, said", [
    (["synth", "--out", "s", "--seed", "\u0663"], "argument --seed: must be a whole number >= 0, got '\u0663'"),
    (["board", "--out", "b", "--dpi", "\uff13\uff10\uff10"],
     "argument --dpi: must be a whole number >= 1, got '\uff13\uff10\uff10'"),
    (["synth", "--out", "s", "--count", "1\uff15"],
     "argument --count: must be a whole number from 1 to 100, got '1\uff15'"),
    # import's own parser, not counts.image_size, read these: 1_280x720 and \u0663\u0662\u0660x240 imported as 1280x720
    # and 320x240
    (["import", "c.yml", "--out", "r.json", "--image-size", "1_280x720"],
     "argument --image-size: must be WIDTHxHEIGHT in pixels, each >= 1 (as 640x480), got '1_280x720'"),
    (["import", "c.yml", "--out", "r.json", "--image-size", "\u0663\u0662\u0660x240"],
     "argument --image-size: must be WIDTHxHEIGHT in pixels, each >= 1 (as 640x480), got '\u0663\u0662\u0660x240'"),
])
def test_a_count_in_digits_of_another_script_is_refused_as_other_bad_counts(argv, said, capsys):
    """int() takes Arabic-Indic '\u0663' and full-width '\uff13' for 3: ghcal synth --seed \u0663 ran seed 3 and
    --dpi \uff13\uff10\uff10 printed at 300 dpi, a value the command line shows to few readers; import's
    --image-size is parsed as every tool's WIDTHxHEIGHT."""
    with pytest.raises(SystemExit) as e:
        cli.build_parser().parse_args(argv)
    assert e.value.code == 2 and said in capsys.readouterr().err


@pytest.mark.parametrize("argv, said", [
    # no bound: --count 100000000 rendered for hours and filled the disk
    (["synth", "--out", "s", "--count", "100000000"],
     "argument --count: must be a whole number from 1 to 100, got '100000000'"),
    (["synth", "--out", "s", "--edge-count", "101"],
     "argument --edge-count: must be a whole number from 0 to 100, got '101'"),
    (["synth", "--out", "s", "--count", "0"], "argument --count: must be a whole number from 1 to 100, got '0'"),
    (["capture", "--url", "sim://", "--out", "c", "--count", "101"],
     "argument --count: must be a whole number from 1 to 100, got '101'"),
])
def test_a_view_count_past_the_bound_is_refused_before_anything_runs(argv, said, capsys):
    # the parser refuses it: nothing rendered or opened (cli.main on the old code rendered for hours)
    with pytest.raises(SystemExit) as e:
        cli.build_parser().parse_args(argv)
    assert e.value.code == 2 and said in capsys.readouterr().err


def test_the_view_bound_itself_is_taken():
    args = cli.build_parser().parse_args(["synth", "--out", "s", "--count", str(cli.MAX_VIEWS),
                                          "--edge-count", "0"])
    assert (args.count, args.edge_count) == (cli.MAX_VIEWS, 0)


def test_cameras_given_against_the_recorded_order_are_refused(image, tmp_path, capsys):
    # the capture recorded left as the camera opened first (opencv://?first=); --cameras right,left made 'right'
    # the rig file's first camera, which the driver binds to first=: each camera got the other's lens and pose,
    # and the rig file loaded without a word
    images = _folders(tmp_path / "views", {"left": {f"{k:03d}": image for k in range(4)},
                                           "right": {f"{k:03d}": image for k in range(4)}})
    (images / "cameras.json").write_text(json.dumps({"cameras": ["left", "right"]}))
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(images), "--cameras", "right,left",
                   "--camera-height", "1.4", "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "--cameras right,left reverses the order" in err and "(left,right: 'left' is the camera" in err
    assert "swap first= and second= in the rig URL and edit cameras.json" in err
    assert not (tmp_path / "rig.json").exists()


def test_a_camera_order_file_with_a_key_given_twice_is_refused_naming_it(tmp_path, capsys):
    # the docs say to edit cameras.json to match a swapped rig URL: the new order typed in above the old line was
    # undone by it (JSON keeps the last), and the pair solved in the old order without a word
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
    (tmp_path / "cameras.json").write_text('{"cameras": ["right", "left"],\n "cameras": ["left", "right"]}\n')
    rc = cli.main(["solve", "--board", _board_file(tmp_path), "--images", str(tmp_path), "--camera-height", "1.4",
                   "--out", str(tmp_path / "rig.json")])
    err = capsys.readouterr().err
    assert rc == 2 and f"{tmp_path / 'cameras.json'}: the key 'cameras' is given twice" in err
    assert "Traceback" not in err and not (tmp_path / "rig.json").exists()


def test_a_camera_order_file_saved_with_a_byte_order_mark_reads(tmp_path):
    from calibration.capture import read_camera_order

    # Notepad's UTF-8 starts with one: the file edited as the docs say was refused as invalid JSON
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
    (tmp_path / "cameras.json").write_bytes(b'\xef\xbb\xbf{"cameras": ["right", "left"]}\n')
    assert read_camera_order(tmp_path) == ["right", "left"]


def test_a_camera_order_file_naming_no_folder_name_is_named(tmp_path):
    from calibration.capture import read_camera_order

    # said as a camera to rename in the rig file, the file that named it unnamed
    (tmp_path / "cameras.json").write_text('{"cameras": ["../left", "right"]}')
    with pytest.raises(CaptureError) as e:
        read_camera_order(tmp_path)
    assert "camera name '../left' cannot be a folder name" in str(e.value)
    message = str(e.value)
    assert f"{tmp_path / 'cameras.json'} names the pair's two folders" in message and "rig file" not in message


def test_a_camera_folder_whose_name_is_no_camera_name_is_said_as_a_folder_to_rename(tmp_path):
    from calibration.capture import camera_folders

    # a folder copied from a phone as "cam 1": it was "rename the camera in the rig file", which solve has none of
    for name in ("cam 1", "cam2"):
        (tmp_path / name).mkdir()
    with pytest.raises(CaptureError) as e:
        camera_folders(tmp_path)
    assert "camera name 'cam 1' cannot be a folder name" in str(e.value) and "rig file" not in str(e.value)
    assert f"the camera folders of {tmp_path} name the pair (rename the folder)" in str(e.value)
