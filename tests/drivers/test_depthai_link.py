"""``open_device``: how the production link connects, on a stand-in for ``dai.Device`` (no hardware here).

The stand-in answers the calls ``open_device`` makes with depthai's own value types (``dai.UsbSpeed``)."""
import logging

import depthai as dai
import pytest

from drivers import RigInitializationError
from drivers.backends.depthai.link import StereoRequest, check_cameras, open_device
from tests.drivers.depthai_host import OAK_D
from tests.drivers.depthai_host import camera_features as camera

ID_A, ID_B, ID_C = "14442C10D13EABCE00", "18443010D116631200", "1844301011F4C51200"
FREE, IN_USE = dai.XLinkDeviceState.X_LINK_UNBOOTED, dai.XLinkDeviceState.X_LINK_BOOTED


def info(device_id: str, name: str, state=FREE) -> dai.DeviceInfo:
    """A connected device as ``getAllConnectedDevices()`` lists it (depthai's own DeviceInfo)."""
    return dai.DeviceInfo(name, device_id, state, dai.XLinkProtocol.X_LINK_USB_VSC,
                          dai.XLinkPlatform.X_LINK_MYRIAD_X, dai.XLinkError_t.X_LINK_SUCCESS)


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


def connect(req: StereoRequest, device_class=FakeDevice, devices=()):
    """``open_device`` with these devices connected (none: depthai's own search is left to ``device_class``)."""
    return open_device(req, device_class, lambda: list(devices))


def test_depthai_reconnection_is_switched_off_so_an_unplug_closes_the_queue():
    device = connect(request("14442C10D13EABCE00"))
    assert device.args == ("14442C10D13EABCE00",)  # not listed (yet): depthai searches for it
    assert ("setMaxReconnectionAttempts", 0) in device.calls
    assert connect(request()).args == ()  # no id, nothing listed: the first device depthai finds


def test_a_usb2_link_is_a_warning_naming_the_speed_and_the_bandwidth(caplog):
    class Usb2(FakeDevice):
        speed = dai.UsbSpeed.HIGH

    with caplog.at_level(logging.INFO, logger="drivers.backends.depthai.link"):
        connect(request(width=1280, height=800), Usb2)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert "HIGH" in warnings[0] and "1280x800" in warnings[0] and "92 MB/s" in warnings[0]  # 2*1280*800*1.5*30
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="drivers.backends.depthai.link"):
        connect(request())
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
        connect(request(), Lost)
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


# ----------------------------------------------------------------- which device: looked up before connecting
class Refusing(FakeDevice):
    """depthai's answer for a device it cannot find within its search time."""

    def __init__(self, *args) -> None:
        raise RuntimeError("No available devices")


def test_a_listed_device_is_opened_by_its_device_info_whether_named_by_id_or_by_usb_port():
    devices = [info(ID_A, "1.3"), info(ID_B, "1.4")]
    for target in (ID_B, "1.4"):
        (opened,) = connect(request(target), devices=devices).args
        assert isinstance(opened, dai.DeviceInfo) and opened.getDeviceId() == ID_B


def test_a_device_in_use_by_another_process_is_refused_naming_it_and_its_state():
    made: list = []

    class Recording(FakeDevice):
        def __init__(self, *args) -> None:
            super().__init__(*args)
            made.append(self)

    for target in (ID_A, None):  # named, or the only device there is
        with pytest.raises(RigInitializationError, match=rf"{ID_A} \(1\.3\) is in use by another process "
                                                         r"\(XLink state BOOTED\)"):
            connect(request(target), Recording, devices=[info(ID_A, "1.3", IN_USE)])
    assert not made  # refused before depthai was asked to connect
    with pytest.raises(RigInitializationError, match=f"every connected depthai device is in use.*{ID_A}.*{ID_B}"):
        connect(request(), Recording, devices=[info(ID_A, "1.3", IN_USE), info(ID_B, "1.4", IN_USE)])


def test_a_device_that_is_not_connected_lists_the_connected_ones():
    devices = [info(ID_A, "1.3"), info(ID_B, "1.4", IN_USE)]
    with pytest.raises(RigInitializationError) as caught:
        connect(request(ID_C), Refusing, devices=devices)
    message = str(caught.value)
    assert f"cannot connect to depthai device '{ID_C}': No available devices" in message
    assert f"connected devices: {ID_A} (1.3, UNBOOTED), {ID_B} (1.4, BOOTED)" in message
    assert isinstance(caught.value.__cause__, RuntimeError)
    with pytest.raises(RigInitializationError, match="cannot connect to a depthai device: .*connected devices: none"):
        connect(request(), Refusing)


def test_a_name_that_two_devices_share_is_ambiguous():
    devices = [info(ID_A, "oak"), info(ID_B, "oak")]
    with pytest.raises(RigInitializationError, match=f"'oak' is ambiguous: it names 2 connected devices "
                                                     rf"\({ID_A} \(oak, UNBOOTED\), {ID_B}.*give the device id"):
        connect(request("oak"), devices=devices)


def test_without_an_id_the_first_free_device_is_opened_and_the_others_named(caplog):
    devices = [info(ID_A, "1.3", IN_USE), info(ID_B, "1.4"), info(ID_C, "1.5")]
    with caplog.at_level(logging.WARNING, logger="drivers.backends.depthai.link"):
        (opened,) = connect(request(), devices=devices).args
    assert opened.getDeviceId() == ID_B  # the one in use is passed over
    (warning,) = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert f"2 devices are free ({ID_B} (1.4, UNBOOTED), {ID_C} (1.5, UNBOOTED))" in warning
    assert f"opening {ID_B}" in warning and "depthai://ID" in warning


# ----------------------------------------------------------------- what the sensors can give
def test_a_device_or_sensor_name_holding_a_control_character_is_escaped():
    """The names a device and XLink report reached the log raw: an ESC sequence in one rewrote the terminal."""
    with pytest.raises(RigInitializationError) as caught:
        connect(request(), devices=[info(ID_A, "1.3\x1b[2J", IN_USE)])
    assert f"{ID_A} ('1.3\\x1b[2J') is in use by another process" in str(caught.value), str(caught.value)
    with pytest.raises(RigInitializationError) as caught:
        connect(request("oak\x85"), devices=[info(ID_A, "oak\x85"), info(ID_B, "oak\x85")])
    assert f"({ID_A} ('oak\\x85', UNBOOTED), {ID_B} ('oak\\x85', UNBOOTED))" in str(caught.value), str(caught.value)
    odd = [camera("CAM_B", "OV\x1b9282", (1280, 800), 120.0), camera("CAM_C", "OV9282", (1280, 800), 120.0)]
    with pytest.raises(RigInitializationError) as caught:
        check_cameras(request(fps=200.0), ID_A, odd)
    assert "exceeds the CAM_B sensor's ('OV\\x1b9282') fastest mode" in str(caught.value), str(caught.value)
    req = StereoRequest(None, "CAM_B", "CAM_D", 30.0, 640, 400, 11.0, 4)
    with pytest.raises(RigInitializationError) as caught:
        check_cameras(req, ID_A, odd)
    assert "its cameras: CAM_B ('OV\\x1b9282', 1280x800), CAM_C (OV9282, 1280x800)" in str(caught.value)
    # the device's id too, as describe_devices and _in_use_error show it (check_cameras named it raw)
    with pytest.raises(RigInitializationError) as caught:
        check_cameras(request(fps=200.0), "14442C\x1b[2J", odd)
    assert str(caught.value).startswith("depthai device '14442C\\x1b[2J': option fps=200"), str(caught.value)


def test_a_stream_the_sensors_can_give_passes():
    check_cameras(request(width=1280, height=800, fps=120.0), ID_A, OAK_D)
    check_cameras(StereoRequest(None, "CAM_A", "CAM_B", 30.0, 640, 400, 11.0, 4), ID_A, OAK_D)
    unreported = [camera("CAM_B", "OV9282", (-1, -1), 120.0), camera("CAM_C", "OV9282", (-1, -1), 120.0)]
    check_cameras(request(), ID_A, unreported)  # a size the device does not report is not held against it


def test_a_socket_without_a_camera_is_refused_naming_the_option_and_the_cameras_there_are():
    req = StereoRequest(None, "CAM_B", "CAM_D", 30.0, 640, 400, 11.0, 4)
    with pytest.raises(RigInitializationError, match=rf"{ID_A} has no camera on socket CAM_D \(option right=CAM_D\); "
                                                     r"its cameras: CAM_A \(IMX378, 4056x3040\), CAM_B"):
        check_cameras(req, ID_A, OAK_D)


def test_a_size_or_fps_beyond_the_sensor_is_refused_naming_the_option():
    with pytest.raises(RigInitializationError, match=r"width=1920 height=1080 exceed the CAM_B sensor's \(OV9282\) "
                                                     r"1280x800"):
        check_cameras(request(width=1920, height=1080), ID_A, OAK_D)
    with pytest.raises(RigInitializationError, match=r"fps=200 exceeds the CAM_B sensor's \(OV9282\) fastest mode, "
                                                     r"120 fps"):
        check_cameras(request(fps=200.0), ID_A, OAK_D)


def test_the_production_link_checks_the_cameras_before_building_its_pipeline(monkeypatch):
    """DaiDeviceLink.start on a stand-in device (the pipeline itself needs hardware): the check runs on what
    the device reports, and the source closes the device it refuses."""
    from drivers import open_rig
    from drivers.backends.depthai import link as link_module

    made: list[FakeDevice] = []

    class WithCameras(FakeDevice):
        def getConnectedCameraFeatures(self):  # noqa: N802 - depthai's name
            return OAK_D

    def fake_open_device(req):
        made.append(WithCameras())
        return made[-1]

    monkeypatch.setattr(link_module, "open_device", fake_open_device)
    with pytest.raises(RigInitializationError, match="no camera on socket CAM_D"):
        open_rig("depthai://?right=CAM_D")
    assert len(made) == 1 and made[0].closed


def test_a_group_asked_of_a_link_not_started_or_closed_is_a_typed_error():
    # an AssertionError ("start() first") reached a reader whose read raced a close() from another thread
    from drivers import RigOperationError
    from drivers.backends.depthai.link import DaiDeviceLink

    link = DaiDeviceLink()
    for _ in range(2):
        with pytest.raises(RigOperationError, match="depthai link is not started, or was closed"):
            link.next_group(0.0)
        link.close()
