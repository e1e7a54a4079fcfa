"""Video files (ghnerf_runtime.video_files): read as stored, what each kind of capture backend answers; a still
image told from a video."""
from __future__ import annotations

import logging

import cv2
import numpy as np
import pytest

from ghnerf_runtime.video_files import is_still_image, read_as_stored


class _Capture:
    """A stand-in capture whose backend ``takes`` the property or not, reading ``auto`` for it until it does."""

    def __init__(self, takes: bool, auto: float, rotation: float = 0.0) -> None:
        self.takes, self.props = takes, {cv2.CAP_PROP_ORIENTATION_AUTO: auto, cv2.CAP_PROP_ORIENTATION_META: rotation}

    def set(self, prop, value) -> bool:
        if self.takes:
            self.props[prop] = value
        return self.takes

    def get(self, prop) -> float:
        return self.props.get(prop, 0.0)


def test_a_backend_that_takes_the_property_reads_as_stored(caplog):
    capture = _Capture(takes=True, auto=1.0, rotation=90.0)
    assert read_as_stored(capture, "a.mp4") and capture.props[cv2.CAP_PROP_ORIENTATION_AUTO] == 0
    assert not caplog.records


def test_a_backend_without_the_property_does_not_turn_frames_by_it(caplog):
    # GStreamer or the image-sequence reader: set refused, and it reads 0 (it never turns by it): no warning
    assert read_as_stored(_Capture(takes=False, auto=0.0), "seq/%04d.png")
    assert not caplog.records


def test_a_backend_that_refuses_and_keeps_turning_is_warned_of(caplog):
    with caplog.at_level(logging.WARNING, logger="ghnerf_runtime.video_files"):
        assert not read_as_stored(_Capture(takes=False, auto=1.0, rotation=270.0), "take/left.mov")
        assert not read_as_stored(_Capture(takes=False, auto=1.0, rotation=float("nan")), "take/right.mov")
    first, second = (r.getMessage() for r in caplog.records)
    assert first.startswith("video take/left.mov: ") and "(its container says 270 degrees)" in first
    assert second.startswith("video take/right.mov: ") and "container says" not in second


@pytest.mark.parametrize("name, kind", [("a.png", ".png"), ("a.jpg", ".jpg"), ("a.mp4", ".png")])
def test_a_still_image_is_told_by_its_content_whatever_its_name(tmp_path, name, kind):
    """FFmpeg opens a PNG or JPEG as a one-frame video: ghnerf-run --videos and opencv:// refuse it by this."""
    (tmp_path / name).write_bytes(cv2.imencode(kind, np.zeros((8, 8, 3), np.uint8))[1].tobytes())
    assert is_still_image(tmp_path / name) and is_still_image(str(tmp_path / name))


def test_an_image_sequence_or_a_video_still_plays_as_a_video(tmp_path):
    cv2.imwrite(str(tmp_path / "left_0001.png"), np.zeros((8, 8, 3), np.uint8))
    writer = cv2.VideoWriter(str(tmp_path / "take.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30, (8, 8))
    writer.write(np.zeros((8, 8, 3), np.uint8))
    writer.release()
    assert not is_still_image(tmp_path / "left_%04d.png")
    assert not is_still_image(tmp_path / "take.avi")
    assert not is_still_image(tmp_path / "missing.png")
    assert is_still_image(tmp_path / "left_0001.png")


# no skip for an OpenCV without cv2.Animation (4.10): pyproject.toml asks for 5.0 or later since session 65
def test_an_animated_image_still_plays_as_a_video(tmp_path):
    animation = cv2.Animation()
    animation.frames = [np.full((8, 8, 3), 60 * i, np.uint8) for i in range(3)]
    animation.durations = [40] * 3
    assert cv2.imwriteanimation(str(tmp_path / "moving.png"), animation)
    assert not is_still_image(tmp_path / "moving.png")
