"""The rig-source contract on ``opencv://``, and what is particular to it.

Always: the real backend on two video files OpenCV wrote (MJPG in AVI) from a simulated take, with
its rig file: ``cv2.VideoCapture`` decoding them on the backend's grabbing threads, paced at the
files' frame rate. A live camera that stops delivering is shown with a stand-in capture (the one
thing a file cannot do). With ``GHNERF_TEST_UVC=1``: on two attached webcams (``GHNERF_UVC_FIRST``,
``GHNERF_UVC_SECOND``: default 0 and 1, at their own size: no rig file).
"""
from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers import (
    EndOfStream,
    ManualClock,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    create_rig_source,
    open_rig,
)
from ghnerf_runtime.rig_file import save_rig
from tests.drivers.contract import RigSourceContract

SIZE = (160, 120)


def _write_take(folder: Path, sim_cache, frames: int, fps: float) -> tuple[Path, Path, Path, list]:
    """Two videos and a rig file from ``frames`` simulated pairs; returns (first, second, rig, pairs' images)."""
    folder.mkdir(parents=True)
    url = f"sim://?width={SIZE[0]}&height={SIZE[1]}&seed=4&motion=wave&policy=all&cache={sim_cache}"
    with open_rig(url, clock=ManualClock()) as source:
        pairs = [source.read(timeout_s=5.0) for _ in range(frames)]
        rig = source.rig
    paths = [folder / f"{cam.name}.avi" for cam in rig.pair]
    for k, path in enumerate(paths):
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, SIZE)
        assert writer.isOpened(), "this OpenCV cannot write MJPG"
        for pair in pairs:
            writer.write(pair.images[k])
        writer.release()
    save_rig(rig, folder / "rig.json")
    return paths[0], paths[1], folder / "rig.json", [p.images for p in pairs]


@pytest.fixture(scope="module")
def takes(tmp_path_factory, sim_cache):
    root = tmp_path_factory.mktemp("opencv-contract")
    return _write_take(root / "take", sim_cache, 40, 30.0), _write_take(root / "slow", sim_cache, 3, 1.0)


def _url(take, extra: str = "") -> str:
    first, second, rig, _ = take
    return f"opencv://?first={first}&second={second}&rig={rig}{extra}"


class TestOpenCVVideoContract(RigSourceContract):
    """Two videos played as a live rig, on the real clock."""

    realtime = True
    n_pairs = 25

    @pytest.fixture(autouse=True, scope="class")
    @classmethod
    def _takes(cls, takes):
        cls.take, cls.slow_take = takes

    @classmethod
    def make_source(cls):
        return create_rig_source(_url(cls.take, "&policy=all"))

    @classmethod
    def make_stalling_source(cls):
        return create_rig_source(_url(cls.slow_take))


def test_the_videos_play_as_recorded_then_end(takes):
    take, _ = takes
    with open_rig(_url(take, "&policy=all")) as source:
        pairs = [source.read(timeout_s=5.0) for _ in range(40)]
        with pytest.raises(EndOfStream, match="ended after 40 frames"):
            source.read(timeout_s=5.0)
    images = take[3]
    for pair, (first, second) in zip(pairs, images):
        assert pair.skew_ns == 0  # both stamped by their frame number from one start
        for got, want in ((pair.images[0], first), (pair.images[1], second)):
            assert np.abs(got.astype(int) - want.astype(int)).mean() < 6  # MJPG: lossy, not another frame
    assert [p.frames[0].index for p in pairs] == list(range(40))
    period_ns = np.diff([p.timestamps_ns[0] for p in pairs])
    assert np.allclose(period_ns, 1e9 / 30, atol=1e3)


def test_loop_plays_on_with_increasing_indices(takes):
    first, second, rig, _ = takes[0]
    with open_rig(f"opencv://?first={first}&second={second}&rig={rig}&loop=1&policy=all") as source:
        pairs = [source.read(timeout_s=5.0) for _ in range(50)]  # past the 40 frames of the take
    indices = [p.frames[0].index for p in pairs]
    assert indices == list(range(50))
    assert np.all(np.diff([p.timestamps_ns[0] for p in pairs]) > 0)


def test_without_a_rig_file_a_nominal_rig_names_the_cameras(takes):
    first, second, _, _ = takes[0]
    with open_rig(f"opencv://?first={first}&second={second}&names=cam_a,cam_b&hfov=60") as source:
        pair = source.read(timeout_s=5.0)
        rig = source.rig
    assert rig.rig_id == "opencv-uncalibrated" and rig.names[:2] == ("cam_a", "cam_b")
    assert (rig.pair[0].width, rig.pair[0].height) == SIZE
    assert pair.images[0].shape == (SIZE[1], SIZE[0], 3)


@pytest.mark.parametrize("query, error, message", [
    ("", RigConfigError, "option first="),
    ("first=0", RigConfigError, "option second="),
    ("first=0&second=1&fsp=30", RigConfigError, r"unknown option\(s\) \['fsp'\]"),
    ("first=0&second=1&fourcc=MJPEG", RigConfigError, "four characters"),
    ("first=0&second=1&names=a,a", RigConfigError, "two different names"),
    ("first=0&second=1&width=640", RigConfigError, "width= and height= together"),
    ("first=0&second=1&api=qt", RigConfigError, "option api='qt'"),
])
def test_bad_urls_name_the_option(query, error, message):
    with pytest.raises(error, match=message):
        create_rig_source(f"opencv://?{query}")


def test_a_missing_video_or_a_size_the_rig_does_not_have_is_refused_at_open(takes, tmp_path):
    first, second, rig, _ = takes[0]
    with pytest.raises(RigInitializationError, match=r"camera 'right': OpenCV cannot open .*nope\.avi"):
        open_rig(f"opencv://?first={first}&second={tmp_path / 'nope.avi'}&rig={rig}")
    other = tmp_path / "rig.json"
    from ghnerf_runtime.geometry.rig import Rig
    from ghnerf_runtime.rig_file import load_rig
    loaded = load_rig(rig)
    save_rig(Rig(tuple(c.resized(320, 240) for c in loaded.cameras), loaded.volume, rig_id="big"), other)
    with pytest.raises(RigInitializationError, match=r"delivers 160x120 but the rig's camera is 320x240"):
        open_rig(f"opencv://?first={first}&second={second}&rig={other}")
    with pytest.raises(RigConfigError, match=r"width=320&height=240 but the rig file's cameras are 160x120"):
        create_rig_source(f"opencv://?first=0&second=1&rig={rig}&width=320&height=240")


class _Webcam:
    """A stand-in ``cv2.VideoCapture`` of a live camera that delivers ``frames`` frames, then nothing."""

    made: list["_Webcam"] = []

    def __init__(self, target, api, frames: int = 6) -> None:
        self.target, self.api, self.left, self.props = target, api, frames, {}
        self.props[cv2.CAP_PROP_FRAME_WIDTH], self.props[cv2.CAP_PROP_FRAME_HEIGHT] = SIZE
        _Webcam.made.append(self)

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return True

    def set(self, prop, value) -> bool:
        self.props[prop] = value
        return True

    def get(self, prop) -> float:
        return float(self.props.get(prop, 0.0))

    def grab(self) -> bool:
        import time
        time.sleep(1 / 30)  # a camera's frame period
        self.left -= 1
        return self.left >= 0

    def retrieve(self):
        return True, np.full((SIZE[1], SIZE[0], 3), 100, np.uint8)

    def release(self) -> None:
        pass


def test_a_live_camera_that_stops_delivering_is_a_disconnect_after_its_frames(takes):
    _, _, rig, _ = takes[0]
    _Webcam.made.clear()
    url = f"opencv://?first=0&second=/dev/video4&rig={rig}&fourcc=MJPG&fps=30&policy=all&tolerance_ms=40"
    with open_rig(url, capture_factory=_Webcam) as source:
        pairs = []
        with pytest.raises(RigDisconnectedError, match=r"camera '(left|right)' \((0|/dev/video4)\) stopped delivering"):
            while True:
                pairs.append(source.read(timeout_s=5.0))
    assert 1 <= len(pairs) <= 6
    assert [cam.target for cam in _Webcam.made] == [0, "/dev/video4"]  # an index as an int, a path as it is
    props = _Webcam.made[0].props
    assert props[cv2.CAP_PROP_FOURCC] == cv2.VideoWriter_fourcc(*"MJPG") and props[cv2.CAP_PROP_FPS] == 30
    assert props[cv2.CAP_PROP_BUFFERSIZE] == 1  # the newest frame, not one queued in the driver


@pytest.mark.hardware
@pytest.mark.skipif(os.environ.get("GHNERF_TEST_UVC") != "1",
                    reason="needs two webcams; set GHNERF_TEST_UVC=1 (GHNERF_UVC_FIRST/SECOND pick them) to run")
class TestWebcamContract(RigSourceContract):
    realtime = True
    first_timeout_s = 10.0
    slack_s = 0.5

    @classmethod
    def make_source(cls):
        first, second = os.environ.get("GHNERF_UVC_FIRST", "0"), os.environ.get("GHNERF_UVC_SECOND", "1")
        return create_rig_source(f"opencv://?first={first}&second={second}&fourcc=MJPG")

    @classmethod
    def make_stalling_source(cls):  # pragma: no cover - a webcam cannot be told to stall
        pytest.skip("a webcam cannot be made to stall")
