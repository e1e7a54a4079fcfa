"""Finding the board's corners in an image: ChArUco detection, labelled corners with sub-pixel positions."""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calibration.board import MIN_CORNERS, BoardSpec

__all__ = ["BoardView", "BoardDetector", "MIN_CORNERS"]


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


class BoardDetector:
    """Detects one board in images; reuse it across images (it holds OpenCV's detector)."""

    def __init__(self, board: BoardSpec, *, min_corners: int = MIN_CORNERS) -> None:
        self.board = board
        self.min_corners = max(int(min_corners), 4)
        self._cv_board = board.cv_board()
        self._detector = cv2.aruco.CharucoDetector(self._cv_board)

    def detect(self, image: np.ndarray) -> BoardView | None:
        """The board's corners in ``image`` (grey or BGR, uint8), or None when too few are found or
        they all lie on one line (such a view does not fix a pose)."""
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        corners, ids, _, _ = self._detector.detectBoard(image)
        if ids is None or len(ids) < self.min_corners:
            return None
        if self._cv_board.checkCharucoCornersCollinear(ids):
            return None
        ids = ids.reshape(-1).astype(np.int64)
        corners = corners.reshape(-1, 2).astype(np.float64)
        order = np.argsort(ids)
        return BoardView(ids[order], corners[order], (int(image.shape[1]), int(image.shape[0])))
