"""Finding the board in an image: pixel types, the board's two chessboard patterns, views that fix no pose.

Images come from :func:`calibration.render.render_board` (the board through a real lens model), so each
corner's true pixel is known.
"""
from __future__ import annotations

import re

import cv2
import numpy as np
import pytest

from calibration import capture
from calibration.board import BoardSpec
from calibration.capture import FolderViews, detect_folder, earlier_size, read_folder
from calibration.detect import BoardDetector, fixes_a_pose, grey8, white_level16
from calibration.errors import BoardError, CaptureError
from calibration.render import board_pose_facing, example_rig, render_board
from drivers.backends import recording_format
from ghnerf_runtime.image_files import read_image_or_none
from tests.exif_images import jpeg_turned
from tests.odd_images import bmp_beyond_opencv_s_limits, tiff_laid_out, tiff_tiled

BOARD = BoardSpec(squares_x=7, squares_y=6, square_m=0.12, marker_m=0.09)  # an even number of rows


@pytest.fixture(scope="module")
def camera():
    return example_rig().pair[0].resized(640, 400)


def _pose(board: BoardSpec, camera, distance: float = 1.6):
    return board_pose_facing(board, camera.center + distance * camera.R[2], camera.center, yaw_deg=20,
                             pitch_deg=-15, spin_deg=10)


def _render(board: BoardSpec, camera, **kwargs) -> tuple[np.ndarray, np.ndarray]:
    """The image and each corner's true pixel."""
    R, t = _pose(board, camera)
    uv, _ = camera.project(board.corners_m() @ R.T + t)
    return render_board(camera, board, R, t, **kwargs), uv


def _rms(view, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((view.corners - truth[view.ids]) ** 2, axis=1))))


def test_a_12_bit_frame_saved_in_a_16_bit_png_is_found_as_precisely(camera, tmp_path):
    # A machine-vision camera's 12-bit frame in a 16-bit PNG (values 0-4095): read as 8 bits by its top
    # byte it was 0-15 grey, and the board was "not found" in every image
    image, truth = _render(BOARD, camera)
    reference = BoardDetector(BOARD).detect(image)
    assert reference is not None and len(reference) == BOARD.corner_count
    rng = np.random.default_rng(1)
    frame12 = np.clip(np.rint(image * 16.0 + rng.uniform(-8, 8, image.shape)), 0, 4095).astype(np.uint16)
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        assert cv2.imwrite(str(tmp_path / cam / "000.png"), frame12)
    views, missed = detect_folder(BOARD, tmp_path)
    assert missed == {"left": [], "right": []}
    view = views["left"]["000"]
    assert len(view) == BOARD.corner_count and view.image_size == (camera.width, camera.height)
    assert _rms(view, truth) < _rms(reference, truth) + 0.02


def test_a_still_tagged_to_be_turned_is_calibrated_as_stored(camera, tmp_path):
    # OpenCV turned it for IMREAD_ANYDEPTH: the views were 400x640 where earlier_size and replay:// read 640x400
    image, truth = _render(BOARD, camera)
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 98])
    assert ok
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        (tmp_path / cam / "000.jpg").write_bytes(jpeg_turned(jpeg.tobytes(), 6))
    assert cv2.imread(str(tmp_path / "left" / "000.jpg"), cv2.IMREAD_ANYDEPTH).shape == (camera.width, camera.height)
    views, missed = detect_folder(BOARD, tmp_path)
    assert missed == {"left": [], "right": []}
    view = views["left"]["000"]
    assert view.image_size == (camera.width, camera.height)
    assert _rms(view, truth) < 0.5


def test_a_16_bit_tiff_tagged_half_a_turn_is_calibrated_as_stored(camera, tmp_path):
    # OpenCV's TIFF decoder turns by the tag whatever the flags: the board was found upside down (same size, each
    # corner at another's pixel, no error) until image_files set the tag to 1 before decoding
    image, truth = _render(BOARD, camera)
    tiff = cv2.imencode(".tiff", image.astype(np.uint16) * 257)[1].tobytes()
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        (tmp_path / cam / "000.tiff").write_bytes(tiff_laid_out(tiff, changed={274: (3, (3,))}))
    views, missed = detect_folder(BOARD, tmp_path)
    assert missed == {"left": [], "right": []}
    assert views["left"]["000"].image_size == (camera.width, camera.height)
    assert _rms(views["left"]["000"], truth) < 0.5


def test_a_view_whose_header_is_beyond_opencv_s_size_limits_is_named_as_unreadable(tmp_path):
    # cv2.imread raises for it rather than failing: the solve stopped with a cv2.error naming no file
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        (tmp_path / cam / "000.bmp").write_bytes(bmp_beyond_opencv_s_limits())
    with pytest.raises(CaptureError, match="000.bmp: not a readable image"):
        detect_folder(BOARD, tmp_path)
    assert earlier_size(tmp_path / "left") is None  # ghcal capture --append: an unreadable one is the solve's to name


def test_a_view_that_is_a_jpeg_cut_short_is_named_not_read_grey(tmp_path):
    # OpenCV's file reader filled the missing part with grey, and the board was looked for in it
    image = np.random.default_rng(0).integers(0, 256, (30, 40), dtype=np.uint8)
    data = cv2.imencode(".jpg", image)[1].tobytes()
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        (tmp_path / cam / "000.jpg").write_bytes(data[:len(data) // 3])
    with pytest.raises(CaptureError, match=r"000.jpg: not a readable image: it is a JPEG cut short"):
        detect_folder(BOARD, tmp_path)


def test_a_view_of_a_compression_opencv_does_not_decode_is_named_not_a_black_image(tmp_path):
    # a JPEG 2000 TIFF (Compression 34712) was read as an image of zeros: the board "not found" in it
    data = cv2.imencode(".tiff", np.full((30, 40), 200, np.uint8), [cv2.IMWRITE_TIFF_COMPRESSION, 1])[1].tobytes()
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        (tmp_path / cam / "000.tiff").write_bytes(tiff_laid_out(data, changed={259: (3, (34712,))}))
    with pytest.raises(CaptureError, match=r"000.tiff: not a readable image: it is a TIFF of Compression 34712 "
                                           r"\(JPEG 2000\), which OpenCV"):
        detect_folder(BOARD, tmp_path)
    assert earlier_size(tmp_path / "left") is None  # ghcal capture --append: the solve names it


def test_read_folder_passes_over_an_unreadable_image_and_says_why(camera, tmp_path):
    # session 74: solve and check go on past an image that does not read; detect_folder stays strict
    image, _ = _render(BOARD, camera)
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        for name in ("000", "002"):
            assert cv2.imwrite(str(tmp_path / cam / f"{name}.png"), image)
    assert cv2.imwrite(str(tmp_path / "right" / "001.png"), np.full((400, 640), 128, np.uint8))  # no board
    cut = tmp_path / "left" / "001.png"
    cut.write_bytes(cv2.imencode(".png", image)[1].tobytes()[:60])  # a cut-off copy
    found = read_folder(BOARD, tmp_path)
    assert isinstance(found, FolderViews)
    assert {cam: sorted(named) for cam, named in found.views.items()} == {"left": ["000", "002"],
                                                                         "right": ["000", "002"]}
    assert found.missed == {"left": [], "right": ["001"]}
    assert found.unread == {"left": {"001": f"{cut}: not a readable image"}, "right": {}}
    assert found.views["left"]["002"].ids.tolist() == found.views["right"]["002"].ids.tolist()
    with pytest.raises(CaptureError, match=f"^{re.escape(str(cut))}: not a readable image$"):
        detect_folder(BOARD, tmp_path)
    for name in ("000", "002"):  # none of a camera's images reads: stopped, the first named
        (tmp_path / "left" / f"{name}.png").write_bytes(b"cut")
    with pytest.raises(CaptureError, match=r"camera 'left': none of its 3 image\(s\) reads: .*000.png: not a"):
        read_folder(BOARD, tmp_path)


def test_a_hot_pixel_does_not_darken_a_dim_16_bit_frame(camera, tmp_path):
    # session 74: a 16-bit frame was scaled by its brightest pixel, so one hot pixel at a 12-bit camera's top
    # (4095) left a dim frame (white at 3 % of the range) 8 grey levels, and the board was not found in it
    image, truth = _render(BOARD, camera)
    rng = np.random.default_rng(1)
    dim = np.clip(np.rint(image * (0.03 * 4095 / 255) + rng.normal(0, 1, image.shape)), 0, 4095).astype(np.uint16)
    dim[5, 7] = 4095
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        assert cv2.imwrite(str(tmp_path / cam / "000.png"), dim)
    views, missed = detect_folder(BOARD, tmp_path)
    assert missed == {"left": [], "right": []}
    assert len(views["left"]["000"]) == BOARD.corner_count and _rms(views["left"]["000"], truth) < 0.2


def test_a_16_bit_frame_s_white_is_a_high_percentile_of_it():
    frame = np.full((100, 100), 1000, np.uint16)
    frame[:50] = 100
    frame[0, :9] = 65535  # 0.09 % of the pixels: clipped
    assert white_level16(frame) == 1000
    frame[0, :11] = 65535  # 0.11 %: the top 0.1 % is theirs
    assert white_level16(frame) == 65535
    sparse = np.zeros((100, 100), np.uint16)
    sparse[3, 4] = 700  # black but for a pixel: its maximum, not 0
    assert white_level16(sparse) == 700 and grey8(sparse)[3, 4] == 255
    assert white_level16(np.zeros((4, 5), np.uint16)) == 0


@pytest.mark.parametrize("convert", [
    lambda im: im.astype(np.uint16) * 257,                      # 16-bit grey
    lambda im: im[..., None],                                   # (H, W, 1)
    lambda im: cv2.cvtColor(im, cv2.COLOR_GRAY2BGRA),           # BGRA
    lambda im: cv2.cvtColor(im, cv2.COLOR_GRAY2BGR).astype(np.uint16) * 16,  # 16-bit colour
], ids=["uint16", "hw1", "bgra", "uint16-bgr"])
def test_frames_of_other_layouts_give_the_same_corners(camera, convert):
    image, _ = _render(BOARD, camera)
    detector = BoardDetector(BOARD)
    reference = detector.detect(image)
    view = detector.detect(convert(image))
    assert view is not None and np.array_equal(view.ids, reference.ids)
    assert np.max(np.abs(view.corners - reference.corners)) < 0.05


def test_frames_the_detector_cannot_take_are_named(camera):
    image, _ = _render(BOARD, camera)
    detector = BoardDetector(BOARD)
    with pytest.raises(CaptureError, match="float32 pixels"):
        detector.detect(image.astype(np.float32) / 255)
    with pytest.raises(CaptureError, match=r"shape \(400, 640, 2\)"):
        detector.detect(np.stack([image, image], axis=-1))
    assert grey8(np.zeros((4, 5), np.uint16)).dtype == np.uint8  # all black: no division by 0


@pytest.mark.parametrize("printed_legacy", [True, False])
def test_a_print_with_the_other_chessboard_pattern_is_named(camera, tmp_path, printed_legacy):
    # A board of even rows printed by OpenCV before 4.6 has its markers in the other squares: read with
    # the wrong legacy_pattern it was no board in any image, and a capture just ran out of time
    printed = BoardSpec(**{**BOARD.to_dict(), "legacy_pattern": printed_legacy})
    expected = BoardSpec(**{**BOARD.to_dict(), "legacy_pattern": not printed_legacy})
    image, _ = _render(printed, camera)
    with pytest.raises(BoardError, match=f'"legacy_pattern": {str(printed_legacy).lower()} in the board file') as e:
        BoardDetector(expected).detect(image)
    assert e.value.key == "legacy_pattern"
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        assert cv2.imwrite(str(tmp_path / cam / "007.png"), image)
    with pytest.raises(CaptureError, match=r"left[/\\]007\.png: legacy_pattern: the board in view is printed"):
        detect_folder(expected, tmp_path)
    assert len(BoardDetector(printed).detect(image)) >= BOARD.corner_count - 2  # read with its own pattern


def test_boards_of_odd_rows_have_one_pattern(camera):
    # Odd rows: both settings print the same board, so either reads it and neither is an error
    odd = BoardSpec(squares_x=8, squares_y=5, square_m=0.1, marker_m=0.075)
    image, _ = _render(odd, camera)
    modern, legacy = (BoardDetector(BoardSpec(**{**odd.to_dict(), "legacy_pattern": flag})).detect(image)
                      for flag in (False, True))
    assert len(modern) >= odd.corner_count - 2 and np.array_equal(modern.ids, legacy.ids)


def test_no_board_and_a_few_markers_are_no_view_not_an_error(camera):
    image, _ = _render(BOARD, camera)
    detector = BoardDetector(BOARD)
    assert detector.detect(np.full_like(image, 90)) is None
    # keep a single square's neighbourhood: a marker or two, no corner
    R, t = _pose(BOARD, camera)
    mask = _board_region_mask(camera, R, t, [(2, 2, 3, 3)])
    assert detector.detect(np.where(mask, image, 90).astype(np.uint8)) is None


def _board_region_mask(camera, R, t, rects) -> np.ndarray:
    """Pixels showing the board's squares in ``rects`` (col0, row0, col1, row1: square indices, end
    exclusive)."""
    mask = np.zeros((camera.height, camera.width), np.uint8)
    s = BOARD.square_m
    for c0, r0, c1, r1 in rects:
        xs, ys = np.linspace(c0 * s, c1 * s, 20), np.linspace(r0 * s, r1 * s, 20)
        edge = np.concatenate([np.stack([xs, np.full_like(xs, ys[0])], 1), np.stack([np.full_like(ys, xs[-1]), ys], 1),
                               np.stack([xs[::-1], np.full_like(xs, ys[-1])], 1),
                               np.stack([np.full_like(ys, xs[0]), ys[::-1]], 1)])
        uv, _ = camera.project(np.concatenate([edge, np.zeros((len(edge), 1))], 1) @ R.T + t)
        cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], 1)
    return mask.astype(bool)


def test_a_row_and_one_corner_is_no_view(camera):
    # Square rows 1-2 in full give corner row 1 (ids 6-11); the last square of row 3 adds the one corner
    # (id 17) between its marker and row 2's. All but one on a line: no homography, no pose, yet OpenCV's
    # collinearity check passed it, and the solve dropped it as a blurred frame (or, shared by both
    # cameras, as a pair "not taken at the same instant", which can stop the solve)
    image, truth = _render(BOARD, camera)
    R, t = _pose(BOARD, camera)
    detector = BoardDetector(BOARD)
    region = _board_region_mask(camera, R, t, [(0, 1, 7, 3), (6, 3, 7, 4)])
    masked = np.where(region, image, 90).astype(np.uint8)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(BOARD.cv_board()).detectBoard(masked)
    assert sorted(ids.ravel().tolist()) == [6, 7, 8, 9, 10, 11, 17]  # what OpenCV finds there
    assert detector.detect(masked) is None
    # the first square of row 3 as well: a second corner off the row, and four corners fix the pose
    region = _board_region_mask(camera, R, t, [(0, 1, 7, 3), (6, 3, 7, 4), (0, 3, 1, 4)])
    view = detector.detect(np.where(region, image, 90).astype(np.uint8))
    assert view is not None and view.ids.tolist() == [6, 7, 8, 9, 10, 11, 12, 17]
    assert _rms(view, truth) < 0.3


@pytest.mark.parametrize("ids, fixes", [
    ([0, 1, 2, 3, 4, 5], False),         # one row
    ([0, 6, 12, 18, 24], False),         # one column
    ([0, 7, 14, 21, 28, 5], False),      # a diagonal and one corner
    ([6, 7, 8, 9, 10, 11, 17], False),   # a row and one corner
    ([0, 1, 2], False),                  # too few for any pose
    ([6, 7, 8, 9, 10, 11, 12, 17], True),
    ([0, 1, 6, 7], True),                # one square's four corners
    ([0, 2, 4, 12, 13], True),
])
def test_which_corners_fix_a_pose(ids, fixes):
    assert fixes_a_pose(BOARD, np.array(ids)) is fixes


def test_an_earlier_view_s_size_is_read_from_its_header_without_decoding_it(tmp_path, monkeypatch):
    # ghcal capture --append decoded a whole earlier view (400 MB for an 8000x6000 still) for its size alone
    (tmp_path / "left").mkdir()
    assert cv2.imwrite(str(tmp_path / "left" / "000.png"), np.zeros((60, 80), np.uint8))

    def no_decode(*args):
        raise AssertionError(f"decoded: {args[0]!r:.60}")

    for decoder in ("imread", "imdecode"):  # whichever reader stored_size decodes with
        monkeypatch.setattr(cv2, decoder, no_decode)
    assert earlier_size(tmp_path / "left") == (tmp_path / "left" / "000.png", (80, 60))


@pytest.mark.parametrize(("shape", "separate"), [((5, 7, 3), False), ((5, 7), False), ((5, 7, 3), True)])
def test_an_image_decoded_for_its_size_is_the_size_ghcal_decodes(tmp_path, shape, separate):
    # capture's stored_size reads sizes with replay's reader (recording_format.image_size) since session 69; where
    # the header gives none (a tiled TIFF OpenCV refuses from memory, read from the file), its decode gives the
    # size capture's own decode (unchanged) gave
    path = tmp_path / "000.tiff"
    path.write_bytes(tiff_tiled(np.zeros(shape, np.uint8), (16, 16), separate_planes=separate))
    assert recording_format.header_size(path) is None
    image = read_image_or_none(path, cv2.IMREAD_UNCHANGED)
    assert image is not None and capture.stored_size(path) == (image.shape[1], image.shape[0]) == (7, 5)


@pytest.mark.parametrize("dtype", [np.float32, np.int32])
def test_an_earlier_view_of_32_bit_samples_does_not_stand_for_the_folder(tmp_path, dtype):
    # decoded unchanged, such a TIFF gave earlier_size its size, though the detection refuses it (and replay does
    # not decode it): ghcal capture --append compared the new views with an image the solve cannot use
    for cam in ("left", "right"):
        (tmp_path / cam).mkdir()
        assert cv2.imwrite(str(tmp_path / cam / "000.tiff"), np.zeros((16, 32), dtype))
        assert cv2.imwrite(str(tmp_path / cam / "001.png"), np.zeros((60, 80), np.uint8))
    folder = tmp_path / "left"
    assert capture.stored_size(folder / "000.tiff") is None
    assert earlier_size(folder) == (folder / "001.png", (80, 60))
    with pytest.raises(CaptureError, match=rf"000.tiff: an image of {np.dtype(dtype).name} pixels: the board is "
                                           r"found in 8- or 16-bit images only"):
        detect_folder(BOARD, tmp_path)
