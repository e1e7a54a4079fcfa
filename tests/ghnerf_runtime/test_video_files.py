"""Video files read as stored (ghnerf_runtime.video_files): what each kind of capture backend answers."""
from __future__ import annotations

import logging

import cv2

from ghnerf_runtime.video_files import read_as_stored


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
