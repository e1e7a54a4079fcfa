"""The calibration board: a ChArUco board (a chessboard with ArUco markers in its white squares).

ChArUco rather than a plain chessboard because each corner is identified by the markers around
it: a board seen partly, at the image edge or half hidden, still gives labelled corners, which is
what fills the corners of the image where the lens distorts most. The board is one small JSON file
(:meth:`BoardSpec.to_dict`), the same one ``ghcal board`` prints from and ``ghcal solve`` reads,
so the printed board and the solver never disagree about the square size.

Measure the printed squares with a ruler and put the measured size in ``square_m``: a printer that
scales by 2 % scales the whole rig by 2 %.
"""
from __future__ import annotations

import dataclasses
import os
import struct
import zlib
from dataclasses import dataclass
from typing import Any, Mapping

import cv2
import numpy as np

from calibration.errors import BoardError
from ghnerf_runtime.json_keys import JsonTextError, loads_remembering
from ghnerf_runtime.plain_values import is_finite_number, is_true_false, whole_number_or_none

__all__ = ["BoardSpec", "load_board", "png_with_dpi", "DICTIONARIES", "MIN_CORNERS", "REQUIRED_KEYS"]

#: Fewest corners a view needs to constrain a pose (and not all on one line); a board with fewer inner
#: corners could never be found.
MIN_CORNERS = 6

#: The keys a board file must give: every one but ``legacy_pattern`` (false unless set, for old prints).
REQUIRED_KEYS = ("squares_x", "squares_y", "square_m", "marker_m", "dictionary")

#: ArUco dictionaries a board may use (OpenCV's predefined ones, by name).
DICTIONARIES = tuple(sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and "APRILTAG" not in n
                            and "ARUCO_ORIGINAL" not in n and "MIP" not in n))


@dataclass(frozen=True)
class BoardSpec:
    """A ChArUco board.

    Attributes:
        squares_x, squares_y: squares along the board's width and height.
        square_m: side of one chessboard square, metres (measured on the print).
        marker_m: side of one ArUco marker, metres (smaller than ``square_m``).
        dictionary: the ArUco dictionary (``DICT_5X5_100``...); it must hold a marker per white square.
        legacy_pattern: boards made by OpenCV before 4.6 with an even number of rows (``squares_y``)
            have their markers in the other squares; set true to read such a print (the detector names
            this setting when an image shows the other pattern).
    """

    squares_x: int = 9
    squares_y: int = 6
    square_m: float = 0.08
    marker_m: float = 0.06
    dictionary: str = "DICT_5X5_100"
    legacy_pattern: bool = False

    def __post_init__(self) -> None:
        for key in ("squares_x", "squares_y"):
            value = getattr(self, key)
            # a NumPy integer counts (np.int64(9) was refused as no whole number); stored as a Python int for
            # to_dict's JSON
            squares = whole_number_or_none(value)
            if squares is None or not 3 <= squares <= 64:
                raise BoardError(f"must be a whole number of squares in [3, 64], got {value!r}", key=key)
            object.__setattr__(self, key, squares)
        if self.corner_count < MIN_CORNERS:
            raise BoardError(f"a {self.squares_x}x{self.squares_y} board has {self.corner_count} inner corners; a view "
                             f"needs at least {MIN_CORNERS}, so it could never be found: add squares",
                             key="squares_x")
        for key in ("square_m", "marker_m"):
            value = getattr(self, key)
            # a NumPy scalar is a length like any number (np.float32(0.03) was refused as out of range); an
            # integer past float64 is refused by name, not with an OverflowError
            if not is_finite_number(value) or not 0.001 <= value <= 2.0:
                # a size typed in millimetres (80 for 0.08) is said as such, not only as out of range; as a float,
                # since every real number is taken now and a Fraction has no :g format before Python 3.12
                mm = (f" (millimetres? {float(value):g} mm is {float(value) / 1000:g} m)"
                      if is_finite_number(value) and 2.0 < value <= 2000.0 else "")
                raise BoardError(f"must be a length in metres in [0.001, 2], got {value!r}{mm}", key=key)
            object.__setattr__(self, key, float(value))
        if not self.marker_m < self.square_m:
            raise BoardError(f"must be smaller than square_m ({self.square_m:g}), got {self.marker_m:g}",
                             key="marker_m")
        if self.dictionary not in DICTIONARIES:
            raise BoardError(f"must be one of OpenCV's ArUco dictionaries ({', '.join(DICTIONARIES[:4])}, ...), "
                             f"got {self.dictionary!r}", key="dictionary")
        if not is_true_false(self.legacy_pattern):  # np.True_ counts (a comparison's result); 1 does not
            raise BoardError(f"must be true or false, got {self.legacy_pattern!r}", key="legacy_pattern")
        object.__setattr__(self, "legacy_pattern", bool(self.legacy_pattern))  # to_dict's JSON
        markers = (self.squares_x * self.squares_y) // 2
        available = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
        if markers > available:
            raise BoardError(f"{self.dictionary} holds {available} markers; a {self.squares_x}x{self.squares_y} "
                             f"board needs {markers}", key="dictionary")

    # ------------------------------------------------------------------ geometry
    @property
    def corner_count(self) -> int:
        """Inner chessboard corners, the points the calibration uses."""
        return (self.squares_x - 1) * (self.squares_y - 1)

    @property
    def size_m(self) -> tuple[float, float]:
        return self.squares_x * self.square_m, self.squares_y * self.square_m

    def corners_m(self) -> np.ndarray:
        """``(corner_count, 3)`` inner corners in the board frame (metres, z = 0), in corner-id order."""
        return np.asarray(self.cv_board().getChessboardCorners(), np.float64).reshape(-1, 3)

    def cv_board(self) -> "cv2.aruco.CharucoBoard":
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m, dictionary)
        board.setLegacyPattern(self.legacy_pattern)
        return board

    def image(self, px_per_square: int = 120, margin_px: int = 0) -> np.ndarray:
        """The board as a greyscale image (white margin of ``margin_px``), ``px_per_square`` per square."""
        for key, value, least in (("px_per_square", px_per_square, 20), ("margin_px", margin_px, 0)):
            # a float or a negative margin reached OpenCV, whose assertion named neither
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise BoardError(f"must be a whole number of pixels, at least {least}, got {value!r}", key=key)
        # a marker is its dictionary's cells plus a one-cell border, each a pixel at least: smaller, OpenCV's
        # assertion (sidePixels >= markerSize + 2*borderBits) stopped `ghcal board` with a traceback
        cells = self.cv_board().getDictionary().markerSize + 2
        marker_px = int(px_per_square * self.marker_m / self.square_m)
        if marker_px < cells:
            raise BoardError(f"markers of {1000 * self.marker_m:g} mm in squares of {1000 * self.square_m:g} mm are "
                             f"{marker_px} px at {px_per_square} px per square, and a marker's {cells} cells (its "
                             f"border included) need {cells}: larger markers (about 0.75 of the square) or more "
                             "pixels per square (--dpi)", key="marker_m")
        size = (self.squares_x * px_per_square + 2 * margin_px, self.squares_y * px_per_square + 2 * margin_px)
        try:
            return self.cv_board().generateImage(size, marginSize=margin_px, borderBits=1)
        except cv2.error as e:  # a few ratios round a marker's cell outside its square (OpenCV's roi assertion)
            raise BoardError(f"OpenCV cannot draw markers of {1000 * self.marker_m:g} mm in squares of "
                             f"{1000 * self.square_m:g} mm at {px_per_square} px per square "
                             "(OpenCV places a marker cell outside its square): try another --dpi",
                             key="px_per_square") from e

    # ------------------------------------------------------------------ I/O
    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Any, *, path: str | None = None) -> "BoardSpec":
        if not isinstance(data, Mapping):
            raise BoardError(f"must be a JSON object, got {type(data).__name__}", path=path)
        names = {f.name for f in dataclasses.fields(cls)}
        for key in data:
            if key not in names:
                raise BoardError(f"unknown key; a board has {sorted(names)}", key=str(key), path=path)
        for key in REQUIRED_KEYS:
            if key not in data:
                # filled in from the defaults, a square_m deleted while typing in the measured size gave the
                # default board's 80 mm squares, and the rig was scaled by them without a word
                raise BoardError(f"missing; a board file gives {', '.join(REQUIRED_KEYS)} ('ghcal board' writes "
                                 "them all; square_m and marker_m as measured on the print)", key=key, path=path)
        try:
            return cls(**data)
        except BoardError as e:
            raise BoardError(e.detail, key=e.key, path=path) from None


def load_board(path: str | os.PathLike) -> BoardSpec:
    """Read a board JSON file; errors name the file and the key."""
    try:
        # utf-8-sig: a board.json saved by a Windows editor (the measured square size typed in) starts with a
        # byte-order mark, which json refused as "not a JSON file"
        with open(path, encoding="utf-8-sig") as fh:
            text = fh.read()
    except OSError as e:
        raise BoardError(f"cannot read the board file ({e.strerror or e})", path=str(path)) from e
    except UnicodeDecodeError as e:
        raise BoardError(f"not a JSON file: not UTF-8 text (byte {e.start}): {e.reason}", path=str(path)) from e
    if not text.strip():
        raise BoardError("the file is empty", path=str(path))
    try:  # a key given twice raises the hook's BoardError, which goes through
        data = loads_remembering(text, object_pairs_hook=_refuse_repeats(str(path)))
    except JsonTextError as e:  # invalid, nested past MAX_JSON_DEPTH (129 levels read as a field error before), or
        # an integer past 4300 digits
        raise BoardError(f"not a JSON file: {_json_words(e)}", path=str(path)) from e
    return BoardSpec.from_dict(data, path=str(path))


def _json_words(e: JsonTextError) -> str:
    """Why the text is not JSON, with its place where it has one: ``Expecting value at line 1, column 1``."""
    return e.reason if e.line is None else f"{e.reason} at line {e.line}, column {e.column}"


def _refuse_repeats(path: str):
    """A JSON object hook refusing a key given twice: json kept the last silently, so a ``square_m`` measured on
    the print and typed in above the old line was overridden by the old value, and the rig scaled by it."""
    def hook(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        seen: dict[str, Any] = {}
        for key, value in pairs:
            if key in seen:
                raise BoardError(f"given twice ({seen[key]!r} and {value!r}): keep the one measured on the print",
                                 key=key, path=path)
            seen[key] = value
        return seen
    return hook


def png_with_dpi(png: bytes, dpi: float) -> bytes:
    """``png`` (a PNG file's bytes) recording its resolution, ``dpi``, in a ``pHYs`` chunk.

    OpenCV writes none, and a viewer prints such an image at its own default (72 or 96 dpi): a board
    drawn for 300 dpi came out 3-4 times too large, or "fitted" to the page at an arbitrary scale.
    """
    if png[:8] != b"\x89PNG\r\n\x1a\n" or png[12:16] != b"IHDR":
        raise BoardError("not a PNG image")
    per_metre = int(round(dpi / 0.0254))
    body = b"pHYs" + struct.pack(">IIB", per_metre, per_metre, 1)  # unit 1: the metre
    chunk = struct.pack(">I", len(body) - 4) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    end_of_ihdr = 8 + 8 + struct.unpack(">I", png[8:12])[0] + 4  # length, type, data, CRC
    return png[:end_of_ihdr] + chunk + png[end_of_ihdr:]

