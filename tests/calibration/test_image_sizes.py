"""``calibration.image_sizes``: which size is a camera's usual one where two sizes are as common: the first image's
by name, for the files (``ghcal solve`` and ``check``) as for the views (``calibrate_intrinsics``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.detect import BoardView
from calibration.image_sizes import mixed_sizes_problem, mixed_views_problem

#: as names "a" comes first, as files "a-b.png" ("-" sorts before ".")
SIZES = {"a": (640, 480), "a-b": (800, 600)}


def test_a_tie_between_files_goes_to_the_first_image_by_name():
    # session 70 gave it to the first file by path: ghcal called 800x600 usual where the views' check calls it odd
    sizes = {"left": {name: (Path("capture/left") / f"{name}.png", size) for name, size in SIZES.items()},
             "right": {}}
    assert mixed_sizes_problem(sizes) == ("capture/left/a-b.png is 800x600, the other 1 image(s) of camera 'left' "
                                          "640x480: remove or retake it")


def test_a_tie_between_views_goes_to_the_first_view_by_name():
    views = {name: BoardView(np.zeros(0, int), np.zeros((0, 2)), size) for name, size in SIZES.items()}
    assert mixed_views_problem("left", views) == ("view 'a-b' is 800x600, the other 1 view(s) of camera 'left' "
                                                  "640x480: remove or retake it")
