"""The production DaiDeviceLink against depthai 3.12's real API, without a device.

What depthai runs without hardware runs for real (a host-only pipeline: the Sync stage, its queue,
start/stop, messages, the calibration handler). What it refuses without one (``dai.Device``, the
``Camera`` nodes) is stood in for, and each call on a stand-in is checked against the ``.pyi`` stubs
inside the installed wheel (tests/drivers/depthai_stubs.py): a misspelt method or keyword, or an
argument of the wrong type, fails here as it would on an OAK.
"""
import depthai as dai
import pytest

from drivers import RigDisconnectedError, open_rig
from drivers.backends.depthai.link import DaiDeviceLink, StereoRequest, open_device
from tests.drivers.depthai_host import DEVICE_ID, HostBackedPipeline, StandInDevice
from tests.drivers.depthai_stubs import StubMismatch, check_call

URL = "depthai://?width=160&height=100&fps=30&mount_height=1.2"


class Rig:
    """The production link with a stand-in device and a host-backed pipeline; both kept for inspection."""

    def __init__(self) -> None:
        self.device = StandInDevice()
        self.pipeline: HostBackedPipeline | None = None

    def _pipeline_for(self, device: StandInDevice) -> HostBackedPipeline:
        self.pipeline = HostBackedPipeline(device)
        return self.pipeline

    def link(self) -> DaiDeviceLink:
        return DaiDeviceLink(connect=lambda request: self.device, pipeline_for=self._pipeline_for)


# ----------------------------------------------------------------- the checker has teeth
def test_the_stub_checker_refuses_what_depthai_would():
    camera, socket = dai.node.Camera, dai.CameraBoardSocket.CAM_B
    check_call(camera, "build", (socket,), {"sensorFps": 30.0})
    check_call(camera, "requestOutput", ((640, 400),), {"resizeMode": dai.ImgResizeMode.CROP, "fps": 30.0})
    wrong = [
        (camera, "build", ("CAM_B",), {}),  # a socket name, not the enum
        (camera, "build", (socket,), {"fps": 30.0}),  # requestOutput's keyword, not build's (sensorFps)
        (camera, "requestOutput", ((640, 400),), {"resize_mode": dai.ImgResizeMode.CROP}),  # as in a Luxonis example
        (camera, "requestOutput", ((640.0, 400),), {}),  # sizes are ints
        (dai.Device, "setMaxReconnectAttempts", (0,), {}),  # no such method
        (dai.node.Sync, "setSyncThreshold", (0.011,), {}),  # a timedelta, not seconds
    ]
    for cls, method, args, kwargs in wrong:
        with pytest.raises(StubMismatch):
            check_call(cls, method, args, kwargs)


def test_a_stand_in_cannot_answer_with_another_type_than_depthai_does():
    device = StandInDevice(speed="SUPER")  # depthai answers a dai.UsbSpeed
    with pytest.raises(StubMismatch, match="getUsbSpeed"):
        device.getUsbSpeed()
    with pytest.raises(AttributeError, match="no answer for 'getMxId'"):
        device.getMxId()


# ----------------------------------------------------------------- the production link, checked
def test_the_production_link_streams_pairs_through_a_host_backed_pipeline():
    rig = Rig()
    with open_rig(URL, link_factory=rig.link) as source:
        assert source.rig.rig_id == f"oak-{DEVICE_ID}"  # the calibration came through readCalibration()
        pairs = [source.read(timeout_s=3.0) for _ in range(5)]
    assert all(p.skew_ns == 0 and p.frames[0].index == p.frames[1].index for p in pairs)
    assert all(p.images[0].shape == (100, 160, 3) for p in pairs)
    cameras = rig.pipeline.cameras
    assert [c.called("build")[0] for c in cameras] == [
        ((dai.CameraBoardSocket.CAM_B,), {"sensorFps": 30.0}), ((dai.CameraBoardSocket.CAM_C,), {"sensorFps": 30.0})]
    (args, kwargs), = cameras[0].called("requestOutput")
    assert args == ((160, 100),) and kwargs["resizeMode"] == dai.ImgResizeMode.CROP and kwargs["fps"] == 30.0
    assert rig.device.closed and not rig.pipeline.real.isRunning()


def test_open_device_calls_fit_the_stubs():
    info = dai.DeviceInfo("1.3", DEVICE_ID, dai.XLinkDeviceState.X_LINK_UNBOOTED, dai.XLinkProtocol.X_LINK_USB_VSC,
                          dai.XLinkPlatform.X_LINK_MYRIAD_X, dai.XLinkError_t.X_LINK_SUCCESS)
    made: list[StandInDevice] = []

    def device_class(*args):
        check_call(dai.Device, "__init__", args)
        made.append(StandInDevice())
        return made[-1]

    request = StereoRequest(DEVICE_ID, "CAM_B", "CAM_C", 30.0, 640, 400, 11.0, 4)
    assert open_device(request, device_class, lambda: [info]) is made[0]
    assert made[0].called("setMaxReconnectionAttempts") == [((0,), {})]
    open_device(StereoRequest(None, "CAM_B", "CAM_C", 30.0, 640, 400, 11.0, 4), device_class, lambda: [])
    open_device(request, device_class, lambda: [])  # by id, depthai's own search


# ----------------------------------------------------------------- what 3.12 changed or leaves to the device
def test_frames_are_asked_for_as_the_lens_gives_them_not_undistorted_by_the_device():
    """The rig carries the EEPROM's distortion coefficients and the runtime undistorts with them: a frame the
    device had already undistorted would be undistorted twice. requestOutput's enableUndistortion defaults to
    None (the device decides; a wide-FOV OAK has been undistorted automatically), so it is asked as False."""
    rig = Rig()
    with open_rig(URL, link_factory=rig.link) as source:
        source.read(timeout_s=3.0)
    for camera in rig.pipeline.cameras:
        (_, kwargs), = camera.called("requestOutput")
        assert kwargs.get("enableUndistortion") is False


def test_a_device_lost_while_its_pipeline_still_runs_is_a_disconnect_not_a_timeout():
    """depthai 3.12: a lost device's streams go idle and its pipeline may keep running (permissive mode);
    the device's state says DISCONNECTED/RECONNECTING/FAILED. Strict mode is asked for, and a read that
    times out asks the device's state too."""
    rig = Rig()
    with open_rig(URL, link_factory=rig.link) as source:
        source.read(timeout_s=3.0)
        assert rig.pipeline.real.getStopOnDeviceLoss()
        rig.pipeline.silence()
        rig.device.state = dai.DeviceState.DISCONNECTED
        with pytest.raises(RigDisconnectedError, match="both cameras stopped"):
            for _ in range(20):  # the queue may still hold a group or two
                source.read(timeout_s=0.3)
