"""Finding the board's corners in an image: ChArUco detection, labelled corners with sub-pixel positions."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from calibration.board import DICTIONARIES, MIN_CORNERS, BoardSpec
from calibration.errors import BoardError, CaptureError

__all__ = ["BoardView", "BoardDetector", "MIN_CORNERS", "WHITE_PERCENTILE", "grey8", "white_level16", "fixes_a_pose",
           "board_mismatch", "markers_in_view", "mirrored_corners", "mirrored_words"]

#: A 16-bit image's white (:func:`white_level16`): this percentile of its pixels, the brighter 0.1 % clipped. A board
#: in view covers far more than 0.1 % of the image with white squares and margin, so its white is below the cut.
WHITE_PERCENTILE = 99.9
#: Markers seen, with no corners found, before the detector tries the board's other chessboard pattern
#: (a print from OpenCV before 4.6, or from it since, read with the other ``legacy_pattern``).
PATTERN_CHECK_MARKERS = 4


@dataclass(frozen=True)
class BoardView:
    """The board's corners found in one image.

    Attributes:
        ids: ``(N,)`` corner ids (indices into ``BoardSpec.corners_m()``), ascending.
        corners: ``(N, 2)`` their pixel positions (OpenCV convention: pixel centres at integers).
        image_size: ``(width, height)`` of the image.
    """

    ids: np.ndarray
    corners: np.ndarray
    image_size: tuple[int, int]

    def __len__(self) -> int:
        return int(self.ids.size)


def grey8(image: np.ndarray) -> np.ndarray:
    """``image`` as the 8-bit greyscale the ArUco detector takes: grey, ``(H, W, 1)``, BGR or BGRA; 8 or 16 bits.

    16-bit images are scaled by their own white (:func:`white_level16`), not by 256: a 10- or 12-bit camera's
    frame stored in a 16-bit PNG or TIFF uses only its low bits, and cut to its top 8 it kept 4-16 grey levels, in
    which the board was not found.

    :raises CaptureError: another number of channels or another pixel type (named).
    """
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.dtype not in (np.uint8, np.uint16):
        raise CaptureError(f"an image of {image.dtype} pixels: the board is found in 8- or 16-bit images only")
    if image.ndim == 3 and image.shape[2] in (3, 4):
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    elif image.ndim != 2:
        raise CaptureError(f"an image of shape {image.shape}: the board is found in grey, BGR or BGRA images only")
    if image.dtype == np.uint16:
        top = white_level16(image)  # the pixels above it clipped to 255 (convertScaleAbs saturates)
        image = cv2.convertScaleAbs(image, alpha=255.0 / top) if top > 0 else np.zeros(image.shape, np.uint8)
    return image


def white_level16(image: np.ndarray) -> int:
    """The level a 16-bit grey ``image`` is scaled to white by: its :data:`WHITE_PERCENTILE` th percentile, else
    (a frame black but for a few pixels) its maximum; 0 for an all-black one.

    Not the maximum: one hot pixel (or a glint) at the sensor's top darkened a dimly lit frame, and the board was
    found in part or not at all (rendered 12-bit frame, white at 3 % of the range: not found). Not the bit depth
    either, which scales such a frame alike: a percentile keeps the dim frame's grey levels whatever its depth.
    """
    # OpenCV's histogram: a third of np.bincount's time on a 12-megapixel frame (30 ms)
    counts = cv2.calcHist([np.ascontiguousarray(image)], [0], None, [65536], [0, 65536]).ravel()
    below = np.cumsum(counts, dtype=np.float64)
    level = int(np.searchsorted(below, below[-1] * WHITE_PERCENTILE / 100.0))
    return level if level > 0 else int(image.max())


def fixes_a_pose(board: BoardSpec, ids: np.ndarray) -> bool:
    """Whether the corners ``ids`` fix the board's pose in an image: four of them with no three on one line.

    That fails only where all but (at most) one lie on one line: a row, a column or a diagonal of the grid.
    OpenCV's ``checkCharucoCornersCollinear`` asks only whether all lie on one row or column, so a row
    and one corner below it passed: no homography, no pose, and the solve blamed the view (or the pair)
    as a blurred frame or two instants.
    """
    ids = np.unique(np.asarray(ids, np.int64).reshape(-1))
    if ids.size < 4:
        return False
    per_row = board.squares_x - 1
    grid = np.stack([ids % per_row, ids // per_row], axis=1)
    # a line holding all but one of the corners holds two of any three of them
    for a, b in ((0, 1), (0, 2), (1, 2)):
        d = grid[b] - grid[a]
        rel = grid - grid[a]
        on_line = int(np.count_nonzero(rel[:, 0] * d[1] - rel[:, 1] * d[0] == 0))
        if on_line >= ids.size - 1:
            return False
    return True


class BoardDetector:
    """Detects one board in images; reuse it across images (it holds OpenCV's detector)."""

    def __init__(self, board: BoardSpec, *, min_corners: int = MIN_CORNERS) -> None:
        self.board = board
        self.min_corners = max(int(min_corners), 4)
        self._cv_board = board.cv_board()
        self._detector = cv2.aruco.CharucoDetector(self._cv_board)
        # The two chessboard patterns differ only for an even number of rows (OpenCV's setLegacyPattern)
        self._other: cv2.aruco.CharucoDetector | None = None
        if board.squares_y % 2 == 0:
            other = board.cv_board()
            other.setLegacyPattern(not board.legacy_pattern)
            self._other = cv2.aruco.CharucoDetector(other)
        # The board with squares_x and squares_y swapped, read from the same markers: the same marker count,
        # so every marker is found, but OpenCV's marker check (CharucoParameters.checkMarkers) places them
        # nowhere and no image of the print ever gave a corner
        self._swapped = [(spec, cv2.aruco.CharucoDetector(spec.cv_board())) for spec in _swapped_boards(board)]

    def detect(self, image: np.ndarray) -> BoardView | None:
        """The board's corners in ``image`` (:func:`grey8`'s inputs), or None when too few are found or
        they do not fix a pose (:func:`fixes_a_pose`).

        :raises BoardError: the image shows this board printed with the other chessboard pattern
            (key ``legacy_pattern``): no image of it would ever give a corner.
        :raises CaptureError: an image of a type :func:`grey8` does not take.
        """
        image = grey8(image)
        corners, ids, marker_corners, marker_ids = self._detector.detectBoard(image)
        if ids is None or len(ids) < self.min_corners:
            self._check_pattern(image, marker_corners, marker_ids)
            return None
        ids = ids.reshape(-1).astype(np.int64)
        if not fixes_a_pose(self.board, ids):
            return None
        corners = corners.reshape(-1, 2).astype(np.float64)
        order = np.argsort(ids)
        return BoardView(ids[order], corners[order], (int(image.shape[1]), int(image.shape[0])))

    def _check_pattern(self, image: np.ndarray, marker_corners, marker_ids) -> None:
        """Markers but no corners: is it the board printed with the other pattern, or with its squares_x and
        squares_y swapped? Its markers sit in other squares, so each image was silently "no board" and a
        capture ran out of time."""
        if marker_ids is None or len(marker_ids) < PATTERN_CHECK_MARKERS:
            return
        for spec, detector in self._swapped:
            _, ids, _, _ = detector.detectBoard(image, markerCorners=marker_corners, markerIds=marker_ids)
            if ids is not None and len(ids) >= self.min_corners and fixes_a_pose(spec, ids):
                raise BoardError(_swapped_message(self.board, spec, len(ids)), key="squares_x")
        if self._other is None:
            return
        _, ids, _, _ = self._other.detectBoard(image, markerCorners=marker_corners, markerIds=marker_ids)
        if ids is not None and len(ids) >= self.min_corners:
            setting = not self.board.legacy_pattern
            raise BoardError(
                f"the board in view is printed with the other chessboard pattern ({len(ids)} corners found with "
                f"legacy_pattern {str(setting).lower()}, none with {str(self.board.legacy_pattern).lower()}): "
                + ("boards of an even number of rows printed by OpenCV before 4.6 need it" if setting else
                   "boards printed by OpenCV 4.6 or later do not use it")
                + f"; set \"legacy_pattern\": {str(setting).lower()} in the board file", key="legacy_pattern")


def _swapped_boards(board: BoardSpec) -> list[BoardSpec]:
    """``board`` with squares_x and squares_y swapped (both chessboard patterns where they differ); none for a
    square board."""
    if board.squares_x == board.squares_y:
        return []
    swapped = dataclasses.replace(board, squares_x=board.squares_y, squares_y=board.squares_x)
    if swapped.squares_y % 2:  # odd rows: both patterns print the same board
        return [swapped]
    return [swapped, dataclasses.replace(swapped, legacy_pattern=not swapped.legacy_pattern)]


def _swapped_message(board: BoardSpec, found: BoardSpec, corners: int) -> str:
    legacy = (f', "legacy_pattern": {str(found.legacy_pattern).lower()}'
              if found.legacy_pattern != board.legacy_pattern else "")
    return (f"the board in view is {found.squares_x}x{found.squares_y} squares ({corners} corners found so), the board "
            f"file says {board.squares_x}x{board.squares_y}: set \"squares_x\": {found.squares_x}, "
            f"\"squares_y\": {found.squares_y}{legacy} in the board file")


def _other_dictionaries(board: BoardSpec) -> list[BoardSpec]:
    """``board`` with the markers of each other ArUco family (4x4, 5x5, 6x6, 7x7 bits), the smallest dictionary
    of the family that holds its markers: a family's dictionaries begin with the same markers
    (DICT_6X6_50 is DICT_6X6_250's first 50), so that one reads a print made with any of them."""
    own = board.dictionary.rsplit("_", 1)[0]
    families: dict[str, list[str]] = {}
    for name in DICTIONARIES:
        families.setdefault(name.rsplit("_", 1)[0], []).append(name)
    out = []
    for family, names in sorted(families.items()):
        if family == own:
            continue
        for name in sorted(names, key=lambda n: int(n.rsplit("_", 1)[1])):
            try:
                out.append(dataclasses.replace(board, dictionary=name))
                break
            except BoardError:  # too few markers for this board: the next size up
                continue
    return out


def board_mismatch(board: BoardSpec, image: np.ndarray, *, min_corners: int = MIN_CORNERS) -> BoardError | None:
    """What the board file gets wrong when ``image`` shows the board with the markers of another ArUco
    dictionary family (:func:`_other_dictionaries`); None when none of them finds it.

    Read with the wrong dictionary no marker is found at all, so every image was "no board", saying nothing
    of why. Meant for an image in which ``board`` was not found, by a camera that found it in none of its
    images: it runs a detection per family (three), so once per folder, not per frame. A board that is also
    swapped or printed with the other pattern is named so too (the detector's own check, with the right
    dictionary).
    """
    image = grey8(image)
    for spec in _other_dictionaries(board):
        try:
            view = BoardDetector(spec, min_corners=min_corners).detect(image)
            also = ""
        except BoardError as e:  # found, read with this dictionary, as swapped or with the other pattern
            view, also = None, f"; and with it: {e}"
        if view is None and not also:
            continue
        found = f"{len(view)} corners found with it" if view is not None else "its markers found with it"
        return BoardError(f"the board in view has the markers of another ArUco dictionary, {spec.dictionary} "
                          f"({found}), not {board.dictionary}'s: set \"dictionary\": \"{spec.dictionary}\" in the "
                          f"board file{also}", key="dictionary")
    return None


def mirrored_corners(board: BoardSpec, image: np.ndarray, *, min_corners: int = MIN_CORNERS) -> int:
    """How many of ``board``'s corners ``image`` shows once turned back left to right; 0 where it shows none.

    A mirrored board (a webcam's "mirror" or "horizontal flip" setting, a selfie camera, a tool that saved the
    preview) has every marker reversed, and no reversed marker is in the dictionary: each image was "no board",
    and the solve asked whether the board file described the print. Mirrored top to bottom is the same reversal
    turned half a turn, so one flip finds both. Meant, as :func:`board_mismatch`, for a camera that found the
    board in none of its images (one detection).
    """
    view = BoardDetector(board, min_corners=min_corners).detect(np.ascontiguousarray(grey8(image)[:, ::-1]))
    return 0 if view is None else len(view)


def mirrored_words(corners: int) -> str:
    """What a mirrored image is and what to do: :func:`mirrored_corners` found ``corners`` in it turned back."""
    return (f"the board in view is mirrored ({corners} corners found in the image flipped left to right, none as "
            "it is): the camera, or the tool that saved its images, mirrors them (a webcam's mirror or horizontal "
            "flip setting, a selfie preview). No lens gives a mirrored image, so it cannot be calibrated: turn the "
            "mirroring off and capture again")


def markers_in_view(board: BoardSpec, image: np.ndarray) -> int:
    """How many markers of ``board``'s dictionary ``image`` shows, whether or not they make up ``board``.

    Markers seen and no board found (and no :func:`board_mismatch`) is a board file with another number of
    squares than the print (8x6 typed for 9x6): OpenCV places no marker on the board described, and a
    capture ran its --max-seconds without a word.
    """
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    _, ids, _ = cv2.aruco.ArucoDetector(dictionary).detectMarkers(grey8(image))
    return 0 if ids is None else int(len(ids))
