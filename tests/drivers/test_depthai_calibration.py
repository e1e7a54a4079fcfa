"""A real ``dai.CalibrationHandler`` (loaded from an OAK-D-like EEPROM JSON, no device) converted into our Rig."""
import json

import depthai as dai
import numpy as np
import pytest

from drivers import RigInitializationError
from drivers.backends.depthai.calibration import crop_resize_intrinsics, rig_from_calibration
from tests.drivers.depthai_host import CALIBRATION

S = dai.CameraBoardSocket


@pytest.fixture(scope="module")
def calib():
    return dai.CalibrationHandler(CALIBRATION)


@pytest.fixture(scope="module")
def rig(calib):
    return rig_from_calibration(calib, S.CAM_B, S.CAM_C, (640, 400), mount_height_m=1.25)


def by_socket(eeprom_json: dict) -> dict:
    """``cameraData`` as {socket: data}: depthai writes the cameras in no fixed order."""
    return {socket: data for socket, data in eeprom_json["cameraData"]}


def test_fixture_round_trips_through_depthai_json(calib):
    data = calib.eepromToJson()
    again = dai.CalibrationHandler.fromJson(data)
    assert by_socket(again.eepromToJson()) == by_socket(data)
    assert by_socket(json.loads(CALIBRATION.read_text())) == by_socket(json.loads(json.dumps(data)))
    a = rig_from_calibration(calib, S.CAM_B, S.CAM_C, (640, 400), 1.0)
    b = rig_from_calibration(again, S.CAM_B, S.CAM_C, (640, 400), 1.0)
    for ca, cb in zip(a.cameras, b.cameras):
        assert np.array_equal(ca.K, cb.K) and np.array_equal(ca.R, cb.R) and np.array_equal(ca.t, cb.t)


def test_depthai_extrinsics_are_centimetres_unless_asked(calib):
    cm = np.array(calib.getCameraExtrinsics(S.CAM_B, S.CAM_C))
    m = np.array(calib.getCameraExtrinsics(S.CAM_B, S.CAM_C, unit=dai.LengthUnit.METER))
    assert np.allclose(cm[:3, 3] / 100.0, m[:3, 3], atol=1e-7)
    assert np.linalg.norm(cm[:3, 3]) == pytest.approx(7.5, abs=0.01)  # the 7.5 cm OAK-D baseline


def test_baseline_in_metres(rig, calib):
    measured_cm = np.linalg.norm(np.array(calib.getCameraExtrinsics(S.CAM_B, S.CAM_C))[:3, 3])
    assert rig.baseline == pytest.approx(measured_cm / 100.0, abs=1e-7)
    assert rig.baseline == pytest.approx(0.075, abs=1e-3)


def test_rig_frame_origin_on_the_floor_below_the_midpoint(rig):
    left, right = rig.pair
    assert (left.name, right.name) == ("left", "right")
    mid = 0.5 * (left.center + right.center)
    assert mid == pytest.approx(np.array([0.0, -1.25, 0.0]), abs=1e-9)  # y down: 1.25 m up
    assert right.center[0] > left.center[0]  # the right camera is on +x
    assert np.array_equal(left.R, np.eye(3))  # level mount: the left camera's axes are the rig's


def test_relative_pose_is_the_eeprom_extrinsics(rig, calib):
    T = np.array(calib.getCameraExtrinsics(S.CAM_B, S.CAM_C, unit=dai.LengthUnit.METER))
    points = np.random.default_rng(0).uniform([-1, -2, 1], [1, 0, 4], (50, 3))
    in_left = rig.pair[0].to_camera(points)
    in_right = rig.pair[1].to_camera(points)
    assert np.allclose(in_right, in_left @ T[:3, :3].T + T[:3, 3], atol=1e-6)


def test_intrinsics_scaled_to_the_output_size(rig, calib):
    K0, w0, h0 = calib.getDefaultIntrinsics(S.CAM_B)
    assert (w0, h0) == (1280, 800)
    left = rig.pair[0]
    assert (left.width, left.height) == (640, 400)
    assert left.K[0, 0] == pytest.approx(K0[0][0] / 2) and left.K[0, 2] == pytest.approx(K0[0][2] / 2)
    # same aspect ratio: exactly what depthai itself computes for that size
    assert np.allclose(left.K, calib.getCameraIntrinsics(S.CAM_B, 640, 400), atol=1e-4)


def test_fourteen_coefficient_distortion_is_kept(rig, calib):
    expected = np.array(calib.getDistortionCoefficients(S.CAM_B))
    assert expected.size == 14
    assert np.array_equal(rig.pair[0].dist, expected)


def test_crop_resize_matches_cropping_then_scaling_the_image():
    """A point's pixel after crop+scale, via the converted K, equals converting the full-size pixel."""
    K = np.array([[798.0, 0, 652.0], [0, 798.0, 398.0], [0, 0, 1.0]])
    K2 = crop_resize_intrinsics(K, (1280, 800), (640, 480))  # 16:10 -> 4:3: the sides are cropped
    scale = 0.6
    x0 = (1280 * scale - 640) / 2
    pts = np.random.default_rng(1).uniform(-0.5, 0.5, (20, 2))
    full = pts @ K[:2, :2].T + K[:2, 2]
    out = pts @ K2[:2, :2].T + K2[:2, 2]
    assert np.allclose(out, full * scale - [x0, 0.0])


def test_unsupported_calibrations_are_initialization_errors(calib):
    with pytest.raises(RigInitializationError, match="CAM_D"):
        rig_from_calibration(calib, S.CAM_B, S.CAM_D, (640, 400), 1.0)
    fisheye = dai.CalibrationHandler.fromJson(calib.eepromToJson())
    fisheye.setCameraType(S.CAM_C, dai.CameraModel.Fisheye)
    with pytest.raises(RigInitializationError, match="Fisheye"):
        rig_from_calibration(fisheye, S.CAM_B, S.CAM_C, (640, 400), 1.0)
    tilted = dai.CalibrationHandler.fromJson(calib.eepromToJson())
    tilted.setDistortionCoefficients(S.CAM_B, [0.0] * 12 + [0.01, 0.0])
    with pytest.raises(RigInitializationError, match="tilted"):
        rig_from_calibration(tilted, S.CAM_B, S.CAM_C, (640, 400), 1.0)


@pytest.mark.parametrize("roll", [180.0, 90.0, -30.0])
def test_a_rolled_mount_keeps_the_rig_level_and_the_cameras_carry_the_roll(calib, rig, roll):
    from ghnerf_runtime.preprocess import upright_roll_deg

    rolled = rig_from_calibration(calib, S.CAM_B, S.CAM_C, (640, 400), mount_height_m=1.25, mount_roll_deg=roll)
    left, right = rolled.pair
    assert 0.5 * (left.center + right.center) == pytest.approx(np.array([0.0, -1.25, 0.0]), abs=1e-9)
    a = np.radians(roll)  # turned counterclockwise seen from behind: the image's right turns towards up
    assert left.R[0] == pytest.approx([np.cos(a), -np.sin(a), 0.0], abs=1e-12)
    if roll == 180.0:
        assert right.center[0] < left.center[0]  # upside down, the right-hand camera hangs on the rig's left
    # the relative pose is still the EEPROM's, and the crops are rotated back upright
    points = np.random.default_rng(0).uniform([-1, -2, 1], [1, 0, 4], (50, 3))
    T = np.array(calib.getCameraExtrinsics(S.CAM_B, S.CAM_C, unit=dai.LengthUnit.METER))
    assert np.allclose(right.to_camera(points), left.to_camera(points) @ T[:3, :3].T + T[:3, 3], atol=1e-6)
    assert (upright_roll_deg(left) - roll + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
    assert rolled.metadata["mount_roll_deg"] == roll


def test_a_principal_point_far_off_centre_is_refused_naming_device_socket_and_values(calib):
    """A rig the recorder could write but replay (rig_from_dict) would refuse is refused where it is made."""
    off = dai.CalibrationHandler.fromJson(calib.eepromToJson())
    K0, w0, h0 = off.getDefaultIntrinsics(S.CAM_C)
    K0 = np.array(K0)
    K0[0, 2] = 0.9 * w0  # 40% of the width off centre
    off.setCameraIntrinsics(S.CAM_C, K0.tolist(), w0, h0)
    with pytest.raises(RigInitializationError) as info:
        rig_from_calibration(off, S.CAM_B, S.CAM_C, (640, 400), 1.0, rig_id="oak-1844301")
    message = str(info.value)
    assert "oak-1844301" in message and "CAM_C" in message and "principal point" in message
    assert f"({0.9 * w0 / 2:g}," in message and "640x400" in message
