"""The OpenCV versions the project says it takes: pyproject.toml's floor, constraints.txt's pin, the OpenCV installed
and the README's "OpenCV versions" agree.

The floor was 4.10 until session 65, which ran the OpenCV tests on 4.10.0 to 4.14.0 and 5.1.0: below 5.0 ghcal's
ChArUco corners came half a pixel off (4.10-4.13; ``tests/calibration/test_board.py``) and a camera named ``true``
was written to OpenCV YAML that 5.0 reads back as a number (4.x; ``tests/calibration/test_formats.py``). Those
tests check the behaviour on the OpenCV installed; this one keeps the stated range from drifting below it.
"""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

import cv2

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "opencv-contrib-python-headless"
#: The lowest OpenCV on which every test passes (measured in session 65; README, "OpenCV versions").
MEASURED_FLOOR = (5, 0)


def version_tuple(text: str) -> tuple[int, ...]:
    """``"5.0.0.93"`` as ``(5, 0, 0, 93)``; a suffix after the numbers (``"4.10.0-dev"``) is dropped."""
    return tuple(int(part) for part in re.match(r"[\d.]*\d", text).group().split("."))


def pyproject_floor() -> str:
    """The version after ``>=`` in pyproject.toml's one requirement of OpenCV, e.g. "5.0"."""
    requirements = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]["dependencies"]
    (requirement,) = [r for r in requirements if re.match(rf"{PACKAGE}\b", r)]
    floor = re.fullmatch(rf"{PACKAGE}\s*>=\s*([\d.]+)(,.*)?", requirement)
    assert floor, f"pyproject.toml: {requirement!r} gives no '>=' floor"
    return floor.group(1)


def constraints_pin() -> str:
    """The version constraints.txt pins OpenCV to, e.g. "5.0.0.93"."""
    pins = re.findall(rf"^{PACKAGE}==(\S+)$", (REPO / "constraints.txt").read_text(encoding="utf-8"), re.MULTILINE)
    assert len(pins) == 1, f"constraints.txt: {len(pins)} pins of {PACKAGE}"
    return pins[0]


def test_pyproject_asks_for_the_measured_floor_not_a_version_that_fails():
    # was >=4.10, on which calibrations solved by ghcal carried the half-pixel corner offset
    assert version_tuple(pyproject_floor()) == MEASURED_FLOOR


def test_the_pinned_and_the_installed_opencv_are_at_or_above_the_floor():
    floor = version_tuple(pyproject_floor())
    assert version_tuple(constraints_pin()) >= floor
    assert version_tuple(cv2.__version__) >= floor, f"OpenCV {cv2.__version__} installed, below {pyproject_floor()}"


def test_the_readme_states_the_floor_and_the_pin():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("### OpenCV versions"):]
    section = section[:section.index("\n## ")]
    assert f"`{PACKAGE}>={pyproject_floor()}`" in section
    assert f"pins {constraints_pin()}" in section
