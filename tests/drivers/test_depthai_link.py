"""``open_device``: how the production link connects, on a stand-in for ``dai.Device`` (no hardware here).

The stand-in answers the calls ``open_device`` makes with depthai's own value types (``dai.UsbSpeed``)."""
import logging

import depthai as dai
import pytest

from drivers.backends.depthai.link import StereoRequest, open_device


class FakeDevice:
    speed = dai.UsbSpeed.SUPER
    fail_on: str | None = None

    def __init__(self, *args) -> None:
        self.args = args
        self.calls: list[tuple] = []
        self.closed = False

    def setMaxReconnectionAttempts(self, attempts, callback=None) -> None:  # noqa: N802 - depthai's name
        self.calls.append(("setMaxReconnectionAttempts", attempts))

    def getUsbSpeed(self):  # noqa: N802
        if self.fail_on == "getUsbSpeed":
            raise ValueError("Device already closed or disconnected")
        return self.speed

    def getDeviceId(self) -> str:  # noqa: N802
        return "14442C10D13EABCE00"

    def close(self) -> None:
        self.closed = True


def request(device_id=None, width=640, height=400, fps=30.0) -> StereoRequest:
    return StereoRequest(device_id, "CAM_B", "CAM_C", fps, width, height, 11.0, 4)


def test_depthai_reconnection_is_switched_off_so_an_unplug_closes_the_queue():
    device = open_device(request("14442C10D13EABCE00"), FakeDevice)
    assert device.args == ("14442C10D13EABCE00",)
    assert ("setMaxReconnectionAttempts", 0) in device.calls
    assert open_device(request(), FakeDevice).args == ()  # no id: the first device found


def test_a_usb2_link_is_a_warning_naming_the_speed_and_the_bandwidth(caplog):
    class Usb2(FakeDevice):
        speed = dai.UsbSpeed.HIGH

    with caplog.at_level(logging.INFO, logger="drivers.backends.depthai.link"):
        open_device(request(width=1280, height=800), Usb2)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "HIGH" in warnings[0] and "1280x800" in warnings[0] and "92 MB/s" in warnings[0]  # 2*1280*800*1.5*30
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="drivers.backends.depthai.link"):
        open_device(request(), FakeDevice)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert any("SUPER" in r.getMessage() for r in caplog.records)


def test_a_device_that_fails_while_being_prepared_is_closed():
    class Lost(FakeDevice):
        fail_on = "getUsbSpeed"
        made: list = []

        def __init__(self, *args) -> None:
            super().__init__(*args)
            Lost.made.append(self)

    with pytest.raises(ValueError, match="already closed"):
        open_device(request(), Lost)
    assert Lost.made[0].closed


def test_the_declared_depthai_floor_is_the_version_the_backend_is_tested_on():
    """pyproject.toml once allowed depthai 3.0, whose API the backend was never checked against (it calls
    getCameraExtrinsics(unit=), absent from depthai 2 and documented from 3.4): the floor is the pin."""
    import re
    import tomllib
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    deps = tomllib.loads((root / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in deps if re.match(r"depthai\b", d)]
    floor = re.search(r">=\s*([\d.]+)", spec).group(1)
    pinned = re.search(r"^depthai==([\d.]+)$", (root / "constraints.txt").read_text(), re.M).group(1)
    assert floor.split(".")[:2] == pinned.split(".")[:2], (spec, pinned)
    assert dai.__version__.split(".")[:2] == pinned.split(".")[:2]
