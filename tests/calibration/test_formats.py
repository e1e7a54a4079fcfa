"""Foreign calibration formats: round trips, real-world layouts checked with OpenCV, errors name file + field."""
from __future__ import annotations

import dataclasses
import gzip
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration.formats import (
    default_working_volume,
    dumps_anipose_toml,
    read_anipose_toml,
    read_opencv_camera,
    read_opencv_rig,
    write_anipose_toml,
    write_opencv_camera,
    write_opencv_rig,
)
from ghnerf_runtime.errors import GeometryError, RigFileError
from ghnerf_runtime.geometry.camera import Camera, look_at
from ghnerf_runtime.geometry.rig import Rig, WorkingVolume
from ghnerf_runtime.rig_file import load_rig

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "rig.json"


@pytest.fixture
def rig() -> Rig:
    """The committed example plus a third camera with 8 coefficients and a big rotation."""
    base = load_rig(EXAMPLE)
    R, t = look_at((1.7, -0.4, 1.2), (0.0, -1.0, 3.0))
    K = np.array([[1402.5, 0.0, 961.25], [0.0, 1400.75, 538.5], [0.0, 0.0, 1.0]])
    side = Camera("side cam", 1920, 1080, K, [0.12, -0.03, 1e-4, -2e-4, 0.01, 0.2, -0.01, 0.004], R, t)
    return Rig(base.cameras + (side,), base.volume, rig_id=base.rig_id)


def assert_cameras_close(a: Rig, b: Rig, atol=1e-9):
    assert a.names == b.names
    for ca, cb in zip(a.cameras, b.cameras):
        assert (ca.width, ca.height) == (cb.width, cb.height)
        np.testing.assert_allclose(cb.K, ca.K, atol=atol)
        np.testing.assert_allclose(cb.R, ca.R, atol=atol)
        np.testing.assert_allclose(cb.t, ca.t, atol=atol)
        n = max(ca.dist.size, cb.dist.size)
        np.testing.assert_allclose(np.pad(cb.dist, (0, n - cb.dist.size)), np.pad(ca.dist, (0, n - ca.dist.size)), atol=atol)


# ----------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("units", [1.0, 0.001])
def test_yaml_round_trip(rig, tmp_path, units):
    path = tmp_path / "rig.yaml"
    write_opencv_rig(rig, path, units_to_metres=units)
    assert path.read_text().startswith("%YAML")
    back = read_opencv_rig(path, volume=rig.volume, units_to_metres=units)
    assert_cameras_close(rig, back)
    assert back.rig_id == rig.rig_id
    assert back.metadata["source"] == {"format": "opencv-yaml", "path": str(path), "units_to_metres": units}
    np.testing.assert_array_equal(back.volume.min_corner, rig.volume.min_corner)


@pytest.mark.parametrize("units", [1.0, 0.001])
def test_our_yaml_carries_its_units_and_working_volume(rig, tmp_path, units):
    """Read back without arguments: the file says its units and keeps the volume (it was replaced by the
    default one, which cut off people the original volume held)."""
    path = tmp_path / "rig.yaml"
    write_opencv_rig(rig, path, units_to_metres=units)
    back = read_opencv_rig(path)
    assert_cameras_close(rig, back)
    np.testing.assert_allclose(back.volume.min_corner, rig.volume.min_corner, atol=1e-12)
    np.testing.assert_allclose(back.volume.max_corner, rig.volume.max_corner, atol=1e-12)
    write_opencv_camera(rig.cameras[1], tmp_path / "one.yml", units_to_metres=units)
    np.testing.assert_allclose(read_opencv_camera(tmp_path / "one.yml").t, rig.cameras[1].t, atol=1e-12)


@pytest.mark.parametrize("name, starts", [("rig.yml.gz", b"%YAML"), ("rig.xml.gz", b"<?xml"), ("rig.json.gz", b"{")])
def test_a_gz_name_is_written_gzipped_in_the_format_before_it_and_reads_back(rig, tmp_path, name, starts):
    """OpenCV's FileStorage gzips a file whose name ends in .gz; ours wrote plain text under that name (and YAML
    for rig.xml.gz), which gunzip and a tool's gzip reader refused."""
    path = tmp_path / name
    write_opencv_rig(rig, path)
    data = path.read_bytes()
    assert data[:2] == b"\x1f\x8b" and gzip.decompress(data).startswith(starts)
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)  # OpenCV's own reading of it
    try:
        assert fs.getNode("rig_id").string() == rig.rig_id and fs.getNode("cameras").size() == len(rig.cameras)
    finally:
        fs.release()
    back = read_opencv_rig(path)
    assert_cameras_close(rig, back)
    np.testing.assert_allclose(back.volume.max_corner, rig.volume.max_corner, atol=1e-12)
    write_opencv_rig(rig, path)
    assert path.read_bytes() == data  # no time stamp in the gzip header: the same rig, the same bytes
    write_opencv_camera(rig.cameras[2], tmp_path / "one.xml.gz")
    assert gzip.decompress((tmp_path / "one.xml.gz").read_bytes()).startswith(b"<?xml")
    assert_cameras_close(Rig(rig.cameras[1:], rig.volume), Rig((rig.cameras[1], read_opencv_camera(
        tmp_path / "one.xml.gz", name="side cam")), rig.volume))


def test_a_gz_and_digit_name_is_read_from_itself_and_not_written(rig, tmp_path):
    """cv2.FileStorage takes rig.yml.gz9 for gzip at level 9 and opens rig.yml.gz: read_opencv_rig refused the
    gzip as a binary file, and write_opencv_rig wrote plain text under the name."""
    write_opencv_rig(rig, tmp_path / "rig.yml.gz")
    named = tmp_path / "rig.yml.gz9"
    named.write_bytes((tmp_path / "rig.yml.gz").read_bytes())
    write_opencv_rig(Rig(rig.cameras[:2], rig.volume), tmp_path / "rig.yml.gz")  # the file OpenCV would open
    assert_cameras_close(rig, read_opencv_rig(named))
    for write in (lambda path: write_opencv_rig(rig, path), lambda path: write_opencv_camera(rig.cameras[0], path)):
        with pytest.raises(RigFileError, match="opens out.xml.gz for this name"):
            write(tmp_path / "out.xml.gz0")
    assert not (tmp_path / "out.xml.gz0").exists()


@pytest.mark.parametrize("name, meant", [("rig.yml.GZ", "rig.yml.gz"), ("one.xml.Gz", "one.xml.gz"),
                                         ("rig.json.GZ9", "rig.json.gz")])
def test_a_gz_name_in_another_case_is_read_by_its_bytes_and_not_written(rig, tmp_path, name, meant):
    """cv2.FileStorage gzips only a lower-case .gz name: it wrote plain text for rig.yml.GZ and could not read the
    gzip write_opencv_rig put there; read_opencv_rig had OpenCV read that gzip as text ("Invalid character")."""
    probe = tmp_path / f"probe{Path(name).suffix}"
    fs = cv2.FileStorage(str(probe), cv2.FILE_STORAGE_WRITE)  # the premise: OpenCV's own writing of such a name
    fs.write("x", 1)
    fs.release()
    assert probe.read_bytes()[:2] != b"\x1f\x8b"
    path = tmp_path / name
    for write in (lambda: write_opencv_rig(rig, path), lambda: write_opencv_camera(rig.cameras[0], path)):
        with pytest.raises(RigFileError, match=f"OpenCV gzips only a lower-case .gz name .* name it {meant} "):
            write()
    assert not path.exists()
    write_opencv_rig(rig, tmp_path / meant)
    path.write_bytes((tmp_path / meant).read_bytes())  # renamed, gzip under the name: read as gzip
    assert_cameras_close(rig, read_opencv_rig(path))
    path.write_bytes(gzip.decompress((tmp_path / meant).read_bytes()))  # as OpenCV writes the name: plain text
    assert_cameras_close(rig, read_opencv_rig(path))


def test_a_principal_point_outside_the_image_is_refused(rig, tmp_path):
    # a stereo_calib file has no image size: the caller's, if of another size, went through
    write_opencv_rig(rig, tmp_path / "rig.yaml")
    text = (tmp_path / "rig.yaml").read_text()
    cam = rig.cameras[0]
    half = text.replace(f"image_width: {cam.width}\n      image_height: {cam.height}",
                        f"image_width: {cam.width // 2}\n      image_height: {cam.height // 2}", 1)
    assert half != text
    (tmp_path / "half.yaml").write_text(half)
    with pytest.raises(RigFileError, match=r"cameras\[0\]\.camera_matrix.*camera 'left'.*principal point "
                                           r"\(641.3, 402.85\) lies 50% of the width .* 640x400 image"):
        read_opencv_rig(tmp_path / "half.yaml")


def test_a_calibration_of_a_smaller_image_size_is_refused(tmp_path):
    # 640x480 calibrated, read as 960x720: its principal point is inside the larger image, a sixth of it
    # off centre, and the old "inside the image" test let it through
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    files = {"extrinsics_path": tmp_path / "extrinsics.yml", "units_to_metres": 0.001}
    with pytest.raises(RigFileError) as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", image_size=(960, 720), **files)
    assert info.value.field == "M1" and str(tmp_path / "intrinsics.yml") in str(info.value)
    assert "camera 'left'" in str(info.value) and "(322, 241)" in str(info.value)
    assert "Camera.resized" in str(info.value)
    assert read_opencv_rig(tmp_path / "intrinsics.yml", image_size=(640, 480), **files).pair[0].size == (640, 480)


@pytest.mark.parametrize("suffix", [".yml", ".json", ".xml"])
def test_a_name_that_leaves_opencv_s_text_unreadable_is_refused_naming_it(rig, tmp_path, suffix):
    # a camera or rig called '"': OpenCV could not read back the text it wrote, and ghcal export died of a
    # SystemError traceback
    renamed = Rig((rig.cameras[0], dataclasses.replace(rig.cameras[1], name='"')) + rig.cameras[2:], rig.volume,
                  rig_id=rig.rig_id)
    with pytest.raises(RigFileError, match="would not read back from OpenCV FileStorage") as info:
        write_opencv_rig(renamed, tmp_path / f"rig{suffix}")
    assert info.value.field == "cameras[1].name" and not (tmp_path / f"rig{suffix}").exists()
    with pytest.raises(RigFileError, match="would not read back") as info:
        write_opencv_rig(Rig(rig.cameras, rig.volume, rig_id='"'), tmp_path / f"rig{suffix}")
    assert info.value.field == "rig_id"
    with pytest.raises(RigFileError, match="would not read back") as info:
        write_opencv_camera(renamed.cameras[1], tmp_path / f"one{suffix}")
    assert info.value.field == "name"


@pytest.mark.parametrize("name", ["true", "null", "a b "])
def test_a_name_opencv_would_not_read_back_is_refused_before_writing(rig, tmp_path, name):
    # OpenCV writes strings unquoted: a camera called "true" came back as 1.0, a rig id "null" as nothing
    renamed = Rig((dataclasses.replace(rig.cameras[0], name=name),) + rig.cameras[1:], rig.volume, rig_id=rig.rig_id)
    with pytest.raises(RigFileError, match=r"cameras\[0\]\.name.*would not read back"):
        write_opencv_rig(renamed, tmp_path / "rig.yaml")
    assert not (tmp_path / "rig.yaml").exists()
    with pytest.raises(RigFileError, match=r"rig_id.*would not read back"):
        write_opencv_rig(Rig(rig.cameras, rig.volume, rig_id=name), tmp_path / "rig.yaml")
    with pytest.raises(RigFileError, match=r"'name'.*would not read back"):
        write_opencv_camera(renamed.cameras[0], tmp_path / "one.yml")


@pytest.mark.parametrize("suffix, fmt, name, back", [(".yml", "YAML", "true", "the number 1"),
                                                     (".json", "JSON", "a\x00b", "'a'"),
                                                     (".xml", "XML", "a\x00b", "'a'")])
def test_a_name_that_would_not_read_back_is_said_in_the_format_written(rig, tmp_path, suffix, fmt, name, back):
    # a .json or .xml export was said to be "OpenCV YAML", which it is not
    renamed = Rig((dataclasses.replace(rig.cameras[0], name=name),) + rig.cameras[1:], rig.volume, rig_id=rig.rig_id)
    said = f"would not read back from OpenCV {fmt} as written \\(it comes back as {back}"
    with pytest.raises(RigFileError, match=said):
        write_opencv_rig(renamed, tmp_path / f"rig{suffix}")
    skewed = Camera("s", 640, 480, [[600.0, 5.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    with pytest.raises(GeometryError, match=f"; an OpenCV {fmt} file cannot hold it"):
        write_opencv_camera(skewed, tmp_path / f"one{suffix}")
    with pytest.raises(GeometryError, match=f"; an OpenCV {fmt} file cannot hold it"):
        write_opencv_rig(Rig((skewed, rig.cameras[1]), rig.volume), tmp_path / f"rig{suffix}")


def test_an_argument_that_contradicts_the_files_units_is_refused(rig, tmp_path):
    # the argument won silently: a rig written in millimetres and read "in metres" had a 75 m baseline
    write_opencv_rig(rig, tmp_path / "rig.yaml", units_to_metres=0.001)
    with pytest.raises(RigFileError, match=r"units_to_metres.*the file says 0.001 m per unit, the argument 1.0"):
        read_opencv_rig(tmp_path / "rig.yaml", units_to_metres=1.0)
    assert_cameras_close(rig, read_opencv_rig(tmp_path / "rig.yaml", units_to_metres=0.001))
    write_anipose_toml(rig, tmp_path / "calibration.toml", units_to_metres=0.001)
    with pytest.raises(RigFileError, match=r"metadata\.units_to_metres.*the file says 0.001"):
        read_anipose_toml(tmp_path / "calibration.toml", units_to_metres=1.0)


def test_a_single_camera_file_with_a_translation_needs_its_units(tmp_path):
    (tmp_path / "cam.yml").write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                                      "camera_matrix: [[600, 0, 320], [0, 600, 240], [0, 0, 1]]\n"
                                      "distortion_coefficients: [0, 0, 0, 0]\nR: [0, 0, 0]\nT: [60, 0, 0]\n")
    with pytest.raises(RigFileError, match="pass units_to_metres") as info:
        read_opencv_camera(tmp_path / "cam.yml")
    assert info.value.field == "T"
    np.testing.assert_allclose(read_opencv_camera(tmp_path / "cam.yml", units_to_metres=0.001).t, [0.06, 0, 0])


def test_toml_volume_round_trips_and_cameras_come_in_anipose_order(rig, tmp_path):
    path = tmp_path / "calibration.toml"
    write_anipose_toml(rig, path, units_to_metres=0.001)
    back = read_anipose_toml(path, units_to_metres=0.001)
    np.testing.assert_allclose(back.volume.min_corner, rig.volume.min_corner, atol=1e-12)
    text = path.read_text()
    head, cam0, rest = text.partition("[cam_0]")
    cam0_body, cam1, tail = rest.partition("[cam_1]")
    swapped = head + cam1 + tail.split("[metadata]")[0] + cam0 + cam0_body + "[metadata]" + tail.split("[metadata]")[1]
    path.write_text(swapped)  # a hand-merged file with [cam_1] first: aniposelib still sorts the keys
    assert read_anipose_toml(path, units_to_metres=0.001).names == back.names


def test_a_dozen_cameras_keep_their_order_through_toml(rig, tmp_path):
    cams = tuple(Camera(f"c{i}", rig.cameras[0].width, rig.cameras[0].height, rig.cameras[0].K, rig.cameras[0].dist, rig.cameras[0].R,
                        rig.cameras[0].t + [0.1 * i, 0.0, 0.0]) for i in range(12))
    path = tmp_path / "many.toml"
    write_anipose_toml(Rig(cams, rig.volume), path, units_to_metres=1.0)
    assert "[cam_00]" in path.read_text() and "[cam_11]" in path.read_text()
    assert read_anipose_toml(path, units_to_metres=1.0).names == tuple(f"c{i}" for i in range(12))


def test_skew_is_refused_by_the_foreign_formats(rig, tmp_path):
    skewed = Camera("s", 640, 480, [[600.0, 5.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    for write in (lambda: write_opencv_camera(skewed, tmp_path / "s.yml"),
                  lambda: write_anipose_toml(Rig((skewed, rig.cameras[1]), rig.volume), tmp_path / "s.toml",
                                             units_to_metres=1.0)):
        with pytest.raises(GeometryError, match=r"skew K\[0\]\[1\] = 5\.0;"):  # not np.float64(5.0) (NumPy 2)
            write()
    (tmp_path / "k.yml").write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n"
                                    "camera_matrix: [[600, 5, 320], [0, 600, 240], [0, 0, 1]]\n"
                                    "distortion_coefficients: [0, 0, 0, 0]\n")
    with pytest.raises(RigFileError, match=r"skew K\[0\]\[1\] = 5\.0,"):
        read_opencv_camera(tmp_path / "k.yml")


@pytest.mark.parametrize("units", [1.0, 0.001])
def test_toml_round_trip(rig, tmp_path, units):
    path = tmp_path / "calibration.toml"
    write_anipose_toml(rig, path, units_to_metres=units)
    back = read_anipose_toml(path, units_to_metres=units, volume=rig.volume)
    assert_cameras_close(rig, back)
    assert back.rig_id == rig.rig_id


def test_single_camera_round_trip(rig, tmp_path):
    cam = rig.cameras[2]
    write_opencv_camera(cam, tmp_path / "side.yml", units_to_metres=0.01)
    back = read_opencv_camera(tmp_path / "side.yml", units_to_metres=0.01)
    assert back.name == "side cam"
    for attr in ("K", "dist", "R", "t"):
        np.testing.assert_allclose(getattr(back, attr), getattr(cam, attr), atol=1e-9)
    assert read_opencv_camera(tmp_path / "side.yml", name="other").name == "other"


def test_zero_distortion_round_trips(tmp_path):
    base = load_rig(EXAMPLE)
    rig = Rig(tuple(c.without_distortion() for c in base.cameras), base.volume)
    write_opencv_rig(rig, tmp_path / "r.yaml")
    assert_cameras_close(rig, read_opencv_rig(tmp_path / "r.yaml"))
    write_anipose_toml(rig, tmp_path / "c.toml", units_to_metres=1.0)
    assert_cameras_close(rig, read_anipose_toml(tmp_path / "c.toml", units_to_metres=1.0))


# ----------------------------------------------------------------------------- real-world layouts
ANIPOSE_TOML = """\
[cam_0]
name = "A"
size = [ 1920, 1080,]
matrix = [ [ 1423.5, 0.0, 959.5,], [ 0.0, 1421.25, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.12, 0.08, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 0.0, 0.0, 0.0,]

[cam_1]
name = "B"
size = [ 1920, 1080,]
matrix = [ [ 1418.0, 0.0, 962.0,], [ 0.0, 1417.5, 541.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.11, 0.07, 0.001, -0.0005, 0.0,]
rotation = [ 0.012, -0.523, 0.004,]
translation = [ 1480.3, -4.1, 410.7,]

[metadata]
adjusted = false
error = 0.4213
"""


def test_anipose_file_matches_opencv_projection(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML)
    rig = read_anipose_toml(path, units_to_metres=0.001)
    assert rig.names == ("A", "B") and rig.rig_id == "calibration"
    assert rig.cameras[0].size == (1920, 1080)
    # A point in anipose units (mm), projected by OpenCV with the file's rvec/tvec, must
    # land where our camera projects the same point in metres.
    X_mm = np.array([[150.0, -300.0, 2800.0], [-400.0, 200.0, 3500.0]])
    expected, _ = cv2.projectPoints(X_mm, np.array([0.012, -0.523, 0.004]), np.array([1480.3, -4.1, 410.7]),
                                    rig.cameras[1].K, rig.cameras[1].dist)
    uv, _ = rig.cameras[1].project(X_mm * 0.001)
    np.testing.assert_allclose(uv, expected.reshape(-1, 2), atol=1e-9)
    assert rig.baseline == pytest.approx(np.linalg.norm(rig.cameras[1].center), rel=1e-12)


def test_anipose_units_are_required(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML)
    with pytest.raises(TypeError):
        read_anipose_toml(path)  # type: ignore[call-arg]
    with pytest.raises(GeometryError, match="units_to_metres"):
        read_anipose_toml(path, units_to_metres=0.0)
    with pytest.raises(GeometryError, match="units_to_metres"):
        write_opencv_rig(read_anipose_toml(path, units_to_metres=0.001), tmp_path / "x.yaml", units_to_metres=-1)


def test_toml_writer_escapes_and_is_anipose_shaped(rig):
    tricky = Rig((Camera('a "quoted"\\ \t name', 640, 480, rig.cameras[0].K), rig.cameras[1]), rig.volume,
                 rig_id="id\n2")
    text = dumps_anipose_toml(tricky, units_to_metres=0.001)
    import tomllib

    doc = tomllib.loads(text)
    assert doc["cam_0"]["name"] == 'a "quoted"\\ \t name' and doc["metadata"]["rig_id"] == "id\n2"
    assert set(doc["cam_1"]) == {"name", "size", "matrix", "distortions", "rotation", "translation"}
    assert doc["cam_1"]["translation"][0] == pytest.approx(rig.cameras[1].t[0] * 1000)


OPENCV_SAMPLE = """\
%YAML:1.0
---
calibration_time: "Thu Nov 21 10:12:45 2024"
nr_of_frames: 25
image_width: 640
image_height: 480
board_width: 9
board_height: 6
square_size: 25.
fix_aspect_ratio: 1.
flags: 2
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 6.5746697944293521e+02, 0., 3.1950000000000000e+02, 0.,
       6.5746697944293521e+02, 2.3950000000000000e+02, 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 5
   cols: 1
   dt: d
   data: [ -4.1802327176423804e-01, 5.0715244063187526e-01, 0., 0.,
       -5.7843597214487474e-01 ]
avg_reprojection_error: 3.9223999999999997e-01
"""


def test_opencv_calibration_sample_file(tmp_path):
    path = tmp_path / "out_camera_data.yml"
    path.write_text(OPENCV_SAMPLE)
    cam = read_opencv_camera(path)
    assert cam.name == "out_camera_data" and cam.size == (640, 480)
    assert cam.K[0, 0] == 6.5746697944293521e02 and cam.dist.tolist()[-1] == -5.7843597214487474e-01
    np.testing.assert_array_equal(cam.R, np.eye(3))
    with pytest.raises(RigFileError, match="no known layout") as info:
        read_opencv_rig(path)
    assert info.value.path == str(path)


def test_opencv_aliases_and_plain_sequences(tmp_path):
    path = tmp_path / "cam.yaml"
    path.write_text("%YAML:1.0\n---\nname: front\nimage_size: [800, 600]\nK: [[500, 0, 400], [0, 500, 300], [0, 0, 1]]\n"
                    "D: [0.1, -0.01, 0, 0]\nR: [0.0, 0.1, 0.0]\nT: [100, 0, 0]\n")
    cam = read_opencv_camera(path, units_to_metres=0.001)
    assert cam.name == "front" and cam.size == (800, 600) and cam.dist.size == 4
    np.testing.assert_allclose(cam.R, cv2.Rodrigues(np.array([0.0, 0.1, 0.0]))[0])
    np.testing.assert_allclose(cam.t, [0.1, 0.0, 0.0])


def test_an_image_size_that_disagrees_with_image_width_and_height_is_refused_naming_both(tmp_path):
    # image_width won without a word: a camera calibrated at 1280x720 was read as 640x480
    path = tmp_path / "cam.yml"
    head = "%YAML:1.0\n---\nK: [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]]\nD: [0, 0, 0, 0]\n"
    path.write_text(head + "image_width: 640\nimage_height: 480\nimage_size: [1280, 720]\n")
    said = r"is \[1280, 720\], but image_width and image_height are 640 and 480"
    with pytest.raises(RigFileError, match=said) as info:
        read_opencv_camera(path)
    assert info.value.path == str(path) and info.value.field == "image_size"
    path.write_text(head + "image_width: 640\nimage_height: 480\nimage_size: [640, 480]\n")  # agreeing: fine
    assert read_opencv_camera(path).size == (640, 480)
    multi = tmp_path / "rig.yml"
    multi.write_text(_multi_yaml(_cams(image_size="[480, 640]")))
    with pytest.raises(RigFileError, match="480, 640") as info:
        read_opencv_rig(multi)
    assert info.value.field == "cameras[1].image_size"


@pytest.mark.parametrize("size, field", [("image_width: 640\nimage_height: 480\n", "image_height"),
                                         ("image_size: [640, 480]\n", "image_size")])
def test_an_image_size_argument_the_file_s_own_size_contradicts_is_refused_naming_both(tmp_path, size, field):
    # the file's size was taken and the argument dropped without a word: a 640x360 calibration told so was read
    # as the file's 640x480
    path = tmp_path / "cam.yml"
    path.write_text("%YAML:1.0\n---\nK: [[600, 0, 319.5], [0, 600, 239.5], [0, 0, 1]]\nD: [0, 0, 0, 0]\n" + size)
    with pytest.raises(RigFileError, match=r"gives the image size 640x480, but the image_size argument "
                                           r"\(--image-size\) is 640x360") as info:
        read_opencv_camera(path, image_size=(640, 360))
    assert info.value.path == str(path) and info.value.field == field
    assert read_opencv_camera(path, image_size=(640, 480)).size == (640, 480)  # agreeing: taken without a word
    with pytest.raises(RigFileError, match="must be \\(width, height\\)"):  # not a pair: named, not ignored
        read_opencv_camera(path, image_size=640)
    multi = tmp_path / "rig.yml"
    wide = "[[900, 0, 640], [0, 900, 360], [0, 0, 1]]"
    multi.write_text(_multi_yaml(_cams(image_width=1280, image_height=720, camera_matrix=wide)))
    with pytest.raises(RigFileError, match="1280x720, but .* is 640x480") as info:  # the first camera agrees
        read_opencv_rig(multi, image_size=(640, 480))
    assert info.value.path == str(multi) and info.value.field == "cameras[1].image_width"
    assert read_opencv_rig(multi).pair[1].size == (1280, 720)


def _write_stereo_calib(tmp_path, T_mm):
    """intrinsics.yml + extrinsics.yml exactly as OpenCV's stereo_calib sample writes them."""
    K1 = np.array([[700.0, 0, 322.0], [0, 701.0, 241.0], [0, 0, 1]])
    K2 = np.array([[705.0, 0, 318.0], [0, 704.0, 243.0], [0, 0, 1]])
    D1, D2 = np.array([[-0.2, 0.05, 0.001, 0.0, 0.0]]), np.array([[-0.21, 0.06, 0.0, 0.001, 0.0]])
    R, _ = cv2.Rodrigues(np.array([0.01, -0.05, 0.002]))
    fs = cv2.FileStorage(str(tmp_path / "intrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for key, value in (("M1", K1), ("D1", D1), ("M2", K2), ("D2", D2)):
        fs.write(key, value)
    fs.release()
    fs = cv2.FileStorage(str(tmp_path / "extrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for key, value in (("R", R), ("T", np.asarray(T_mm, float).reshape(3, 1)), ("R1", np.eye(3)), ("R2", np.eye(3)),
                       ("P1", np.eye(3, 4)), ("P2", np.eye(3, 4)), ("Q", np.eye(4))):
        fs.write(key, value)
    fs.release()
    return K2, D2, R


def test_opencv_stereo_calib_layout(tmp_path):
    K2, D2, R = _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    rig = read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml",
                          image_size=(640, 480), units_to_metres=0.001)
    left, right = rig.pair
    assert rig.names == ("left", "right") and right.size == (640, 480)
    np.testing.assert_array_equal(left.R, np.eye(3))
    np.testing.assert_allclose(right.t, [-0.06, 0.0005, 0.001], atol=1e-15)
    X = np.array([[0.1, -0.05, 2.0], [-0.3, 0.2, 3.0]])  # camera-1 frame, metres
    expected, _ = cv2.projectPoints(X * 1000, cv2.Rodrigues(R)[0], np.array([-60.0, 0.5, 1.0]), K2, D2)
    np.testing.assert_allclose(right.project(X)[0], expected.reshape(-1, 2), atol=1e-9)
    assert rig.metadata["source"]["format"] == "opencv-stereo-calib"


def test_an_extrinsics_file_given_with_the_multi_camera_layout_is_refused(rig, tmp_path):
    # the cameras' poses are in the file: the extrinsics file was ignored, a missing one included, and the rig written
    write_opencv_rig(rig, tmp_path / "rig.yml")
    with pytest.raises(RigFileError, match="extrinsics_path .*nope.yml.* goes with stereo_calib") as info:
        read_opencv_rig(tmp_path / "rig.yml", extrinsics_path=tmp_path / "nope.yml")
    assert info.value.path == str(tmp_path / "rig.yml") and info.value.field == "cameras"


def test_stereo_calib_errors_name_the_right_file(tmp_path):
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    mm = {"units_to_metres": 0.001}
    with pytest.raises(RigFileError, match="pass units_to_metres") as info:  # stereo_calib's T is in board units
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml", image_size=(640, 480))
    assert info.value.field == "T"
    with pytest.raises(RigFileError, match="missing image size") as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml", **mm)
    assert info.value.field == "image_width"
    with pytest.raises(RigFileError) as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", image_size=(640, 480), **mm)  # R, T live in the other file
    assert info.value.path == str(tmp_path / "intrinsics.yml") and info.value.field == "R"
    (tmp_path / "bad_ext.yml").write_text("%YAML:1.0\n---\nR: [1, 2, 3, 4]\nT: [0, 0, 0]\n")
    with pytest.raises(RigFileError) as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "bad_ext.yml", image_size=(640, 480),
                        **mm)
    assert info.value.path == str(tmp_path / "bad_ext.yml") and info.value.field == "R"
    # a Rodrigues vector so long its matrix is NaN: said as the extrinsics file's R, with the value (it was the
    # intrinsics file's R, shown as a matrix of NaN)
    (tmp_path / "bad_ext.yml").write_text("%YAML:1.0\n---\nR: [0, 1e300, 0]\nT: [-60, 0.5, 1]\n")
    with pytest.raises(RigFileError, match=r"a Rodrigues vector this long gives no rotation.*1\.e\+300") as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "bad_ext.yml", image_size=(640, 480),
                        **mm)
    assert info.value.path == str(tmp_path / "bad_ext.yml") and info.value.field == "R"


def test_a_missing_extrinsics_file_is_named_before_the_unit_is_asked_for(tmp_path):
    # named only once units_to_metres was given: the first error asked for a unit
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    with pytest.raises(RigFileError, match="no such file") as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsic.yml", image_size=(640, 480))
    assert info.value.path == str(tmp_path / "extrinsic.yml")


def _add_pose_to_intrinsics(tmp_path, R, T):
    """stereo_calib's intrinsics.yml with an ``R`` and a ``T`` of its own (a file merged or edited by hand)."""
    fs = cv2.FileStorage(str(tmp_path / "intrinsics.yml"), cv2.FILE_STORAGE_READ)
    values = {key: fs.getNode(key).mat() for key in ("M1", "D1", "M2", "D2")}
    fs.release()
    fs = cv2.FileStorage(str(tmp_path / "intrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for key, value in (*values.items(), ("R", np.asarray(R)), ("T", np.asarray(T).reshape(3, 1))):
        fs.write(key, value)
    fs.release()


def test_a_pose_in_the_intrinsics_file_that_is_not_the_extrinsics_file_s_is_refused_naming_both(tmp_path):
    # the extrinsics file's won without a word: one of the two is another calibration's pose
    _, _, R = _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    intrinsics, extrinsics, mm = tmp_path / "intrinsics.yml", tmp_path / "extrinsics.yml", {"units_to_metres": 0.001}
    _add_pose_to_intrinsics(tmp_path, R.astype(np.float32), np.float32([-60.0, 0.5, 1.0]))  # the same, float32
    assert read_opencv_rig(intrinsics, extrinsics_path=extrinsics, image_size=(640, 480), **mm).baseline > 0
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    _add_pose_to_intrinsics(tmp_path, R, [-65.0, 0.5, 1.0])
    said = r"T.*-65.*the T of .*extrinsics\.yml.*-60.*leave out extrinsics_path"
    with pytest.raises(RigFileError, match=said) as info:
        read_opencv_rig(intrinsics, extrinsics_path=extrinsics, image_size=(640, 480), **mm)
    assert info.value.path == str(intrinsics) and info.value.field == "T"
    assert read_opencv_rig(intrinsics, image_size=(640, 480), **mm).pair[1].t[0] == pytest.approx(-0.065)  # its own
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    _add_pose_to_intrinsics(tmp_path, cv2.Rodrigues(np.array([0.01, -0.04, 0.002]))[0], [-60.0, 0.5, 1.0])
    with pytest.raises(RigFileError, match=r"is 0\.573 deg from the R of .*extrinsics\.yml") as info:
        read_opencv_rig(intrinsics, extrinsics_path=extrinsics, image_size=(640, 480), **mm)
    assert info.value.path == str(intrinsics) and info.value.field == "R"



def test_a_pose_copied_into_the_intrinsics_file_with_6_decimals_in_metres_is_read(tmp_path):
    # 1e-5 of the largest component refused a 30 mm baseline's T written with "%.6f" (0.5 um steps), and the message
    # showed the two T equal; a T 10 um off (3e-4 of that baseline) is still another calibration's
    _, _, R = _write_stereo_calib(tmp_path, [-0.0301234567, 0.000234567, 0.00134567])
    intrinsics, extrinsics = tmp_path / "intrinsics.yml", tmp_path / "extrinsics.yml"
    printed = np.array([float(f"{v:.6f}") for v in (-0.0301234567, 0.000234567, 0.00134567)])
    _add_pose_to_intrinsics(tmp_path, R, printed)
    rig = read_opencv_rig(intrinsics, extrinsics_path=extrinsics, image_size=(640, 480), units_to_metres=1.0)
    assert rig.pair[1].t[0] == -0.0301234567  # the extrinsics file's
    _add_pose_to_intrinsics(tmp_path, R, printed + [1e-5, 0.0, 0.0])
    with pytest.raises(RigFileError, match=r"T.* 1e-05 from the T of .*extrinsics\.yml") as info:
        read_opencv_rig(intrinsics, extrinsics_path=extrinsics, image_size=(640, 480), units_to_metres=1.0)
    assert info.value.field == "T"


# ----------------------------------------------------------------------------- errors
def _multi_yaml(cameras: list[dict]) -> str:
    lines = ["%YAML:1.0", "---", "cameras:"]
    for cam in cameras:
        lines.append("   -")
        lines += [f"      {k}: {v}" for k, v in cam.items()]
    return "\n".join(lines) + "\n"


GOOD_CAM = {
    "name": "a",
    "image_width": 640,
    "image_height": 480,
    "camera_matrix": "[[600, 0, 320], [0, 600, 240], [0, 0, 1]]",
    "distortion_coefficients": "[0, 0, 0, 0, 0]",
    "R": "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]",
    "T": "[0.1, 0, 0]",
}


def _cams(**overrides):
    second = dict(GOOD_CAM, name="b", T="[-0.1, 0, 0]")
    for key, value in overrides.items():
        if value is None:
            del second[key]
        else:
            second[key] = value
    return [dict(GOOD_CAM), second]


YAML_ERRORS = {
    "missing camera_matrix": (_cams(camera_matrix=None), "cameras[1].camera_matrix", "missing required key"),
    "K 2x2": (_cams(camera_matrix="[[1, 0], [0, 1]]"), "cameras[1].camera_matrix", "shape (2, 2)"),
    "K not pinhole": (_cams(camera_matrix="[[600, 0, 320], [0, 600, 240], [0, 0, 3]]"), "cameras[1].camera_matrix", "3."),
    "K string": (_cams(camera_matrix='"abc"'), "cameras[1].camera_matrix", "'abc'"),
    "K bad element": (_cams(camera_matrix="[[600, 0, x], [0, 600, 240], [0, 0, 1]]"), "cameras[1].camera_matrix[0][2]", "'x'"),
    "both aliases": (_cams(K="[[600, 0, 320], [0, 600, 240], [0, 0, 1]]"), "cameras[1].K", "both"),
    "dist count": (_cams(distortion_coefficients="[0.1, 0.2, 0.3]"), "cameras[1].distortion_coefficients", "got 3"),
    "R not rotation": (_cams(R="[[1, 0, 0], [0, 1, 0], [0, 0, -1]]"), "cameras[1].R", "det = -1"),
    "R missing": (_cams(R=None), "cameras[1].R", "missing"),
    "T shape": (_cams(T="[1, 2]"), "cameras[1].T", "3-vector"),
    "T nan": (_cams(T="[.nan, 0, 0]"), "cameras[1].T", "finite"),
    "no image size": (_cams(image_width=None, image_height=None), "cameras[1].image_width", "missing image size"),
    "width only": (_cams(image_height=None), "cameras[1].image_height", "missing"),
    "width fractional": (_cams(image_width=640.5), "cameras[1].image_width", "640.5"),
    "width beyond float": (_cams(image_width="1e400"), "cameras[1].image_width", "inf"),
    "duplicate name": (_cams(name="a"), "cameras[1].name", "duplicate camera name 'a'"),
    "name number": (_cams(name=5), "cameras[1].name", "string"),
    "one camera": ([dict(GOOD_CAM)], "cameras", "at least two"),
}


@pytest.mark.parametrize("case", list(YAML_ERRORS))
def test_yaml_errors_name_file_and_field(case, tmp_path):
    cams, field, text = YAML_ERRORS[case]
    path = tmp_path / "rig.yaml"
    path.write_text(_multi_yaml(cams))
    with pytest.raises(RigFileError) as info:
        read_opencv_rig(path)
    assert info.value.path == str(path) and info.value.field == field
    assert str(path) in str(info.value) and text in str(info.value), str(info.value)


def test_yaml_good_file_reads(tmp_path):
    path = tmp_path / "rig.yaml"
    path.write_text(_multi_yaml(_cams()))
    rig = read_opencv_rig(path)
    assert rig.names == ("a", "b") and rig.rig_id == "rig"


def test_yaml_unparseable_and_missing_files(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("%YAML:1.0\n---\ncameras:\n  - name: a\n   bad: [1, 2\n")
    with pytest.raises(RigFileError, match="cannot parse OpenCV YAML") as info:
        read_opencv_rig(path)
    assert info.value.path == str(path) and "broken.yaml(" in str(info.value)  # OpenCV's file(line) marker
    with pytest.raises(RigFileError, match="no such file"):
        read_opencv_rig(tmp_path / "nope.yaml")
    (tmp_path / "empty.yaml").write_text("")
    with pytest.raises(RigFileError, match="the file is empty"):  # was OpenCV's "(-215:Assertion failed) buf"
        read_opencv_camera(tmp_path / "empty.yaml")
    matrix = tmp_path / "matrix.yaml"
    matrix.write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n  rows: 3\n  cols: 3\n  dt: d\n  data: [1, 2]\n"
                      "distortion_coefficients: [0, 0, 0, 0]\nimage_size: [4, 4]\n")
    with pytest.raises(RigFileError, match="malformed !!opencv-matrix") as info:
        read_opencv_camera(matrix)
    assert info.value.field == "camera_matrix"


def _toml_with(section: str, key: str, value: str | None) -> str:
    out, current = [], None
    for line in ANIPOSE_TOML.splitlines():
        if line.startswith("["):
            current = line.strip("[]")
        if current == section and line.split(" = ")[0] == key:
            if value is None:
                continue
            line = f"{key} = {value}"
        out.append(line)
    return "\n".join(out) + "\n"


TOML_ERRORS = {
    "missing matrix": (_toml_with("cam_1", "matrix", None), "cam_1.matrix", "missing required key 'matrix'"),
    "bool in matrix": (_toml_with("cam_1", "matrix", "[[true, 0, 1], [0, 1, 1], [0, 0, 1]]"), "cam_1.matrix", "True"),
    "string in distortions": (_toml_with("cam_0", "distortions", '["a", 0, 0, 0]'), "cam_0.distortions", "'a'"),
    "matrix shape": (_toml_with("cam_1", "matrix", "[1.0, 2.0]"), "cam_1.matrix", "3x3"),
    "rotation length": (_toml_with("cam_1", "rotation", "[0.1, 0.2]"), "cam_1.rotation", "Rodrigues"),
    "translation nan": (_toml_with("cam_1", "translation", "[nan, 0.0, 0.0]"), "cam_1.translation", "finite"),
    "size beyond float": (_toml_with("cam_0", "size", "[1e400, 1080]"), "cam_0.size", "inf"),
    "rotation beyond float": (_toml_with("cam_1", "rotation", "[1e400, 0.0, 0.0]"), "cam_1.rotation", "finite"),
    "size": (_toml_with("cam_0", "size", "[1920]"), "cam_0.size", "[1920]"),
    "size string": (_toml_with("cam_0", "size", '["1920", 1080]'), "cam_0.size", "'1920'"),
    "fisheye": (ANIPOSE_TOML.replace('name = "B"', 'name = "B"\nfisheye = true'), "cam_1.fisheye", "fisheye"),
    # read by truth, an empty string passed as pinhole (and "false" was refused as a fisheye)
    "fisheye empty": (ANIPOSE_TOML.replace('name = "B"', 'name = "B"\nfisheye = ""'), "cam_1.fisheye",
                      "must be true or false (as aniposelib writes it), got ''"),
    "fisheye zero": (ANIPOSE_TOML.replace('name = "B"', 'name = "B"\nfisheye = 0'), "cam_1.fisheye",
                     "must be true or false"),
    "name bool": (_toml_with("cam_0", "name", "false"), "cam_0.name", "False"),
    # taken as the camera "5": aniposelib writes its names as strings
    "metadata not a table": ("metadata = 5\n" + ANIPOSE_TOML.split("[metadata]")[0], "metadata", "must be a table ([metadata]), got 5"),
    "duplicate name": (_toml_with("cam_1", "name", '"A"'), "cam_1.name", "duplicate camera name 'A'"),
    "stray value": ("scale = 2\n" + ANIPOSE_TOML, "scale", "camera table"),
    "K not pinhole": (_toml_with("cam_0", "matrix", "[[1.0, 0, 1], [0, 1, 1], [0, 0, 0]]"), "cam_0.matrix", "pinhole"),
}


@pytest.mark.parametrize("case", list(TOML_ERRORS))
def test_toml_errors_name_file_and_field(case, tmp_path):
    text, field, snippet = TOML_ERRORS[case]
    path = tmp_path / "calibration.toml"
    path.write_text(text)
    with pytest.raises(RigFileError) as info:
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.path == str(path) and info.value.field == field
    assert str(path) in str(info.value) and snippet in str(info.value), str(info.value)


def test_toml_syntax_error_has_line(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML.replace("size = [ 1920, 1080,]", "size = [ 1920, 1080", 1))
    with pytest.raises(RigFileError, match=r"invalid TOML: .*line \d+") as info:
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.path == str(path)
    with pytest.raises(RigFileError, match="cannot read"):
        read_anipose_toml(tmp_path / "missing.toml", units_to_metres=0.001)


# ----------------------------------------------------------------------------- working volume
def test_default_volume_parallel_rig():
    rig = load_rig(EXAMPLE)  # nearly parallel stereo pair
    vol = default_working_volume(rig.cameras)
    axis = rig.cameras[0].R[2]
    expected = np.mean([c.center for c in rig.cameras], axis=0) + 2.5 * np.mean([c.R[2] for c in rig.cameras], axis=0) / np.linalg.norm(np.mean([c.R[2] for c in rig.cameras], axis=0))
    np.testing.assert_allclose(vol.center, expected, atol=1e-12)
    np.testing.assert_allclose(vol.size, [2.5, 2.5, 2.5])
    assert axis @ (vol.center - rig.cameras[0].center) > 2.0


def test_default_volume_converging_and_facing_rigs():
    target = np.array([0.3, -1.0, 3.0])
    cams = [Camera(f"c{i}", 640, 480, np.diag([500.0, 500, 1]) + np.array([[0, 0, 320], [0, 0, 240], [0, 0, 0]]),
                   np.zeros(5), *look_at(eye, target)) for i, eye in enumerate([(-1.5, -1.5, 0), (1.5, -1.4, 0.2)])]
    vol = default_working_volume(cams, side_m=2.0)
    np.testing.assert_allclose(vol.center, target, atol=1e-9)
    np.testing.assert_allclose(vol.size, 2.0)
    facing = [Camera("a", 640, 480, cams[0].K, np.zeros(5), *look_at((0, -1, 0), (0, -1, 4))),
              Camera("b", 640, 480, cams[0].K, np.zeros(5), *look_at((0, -1, 4), (0, -1, 0)))]
    np.testing.assert_allclose(default_working_volume(facing).center, [0, -1, 2], atol=1e-9)
    with pytest.raises(GeometryError):
        default_working_volume([])


def test_imported_rig_gets_default_volume(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML)
    rig = read_anipose_toml(path, units_to_metres=0.001)
    vol = default_working_volume(rig.cameras)
    np.testing.assert_array_equal(rig.volume.min_corner, vol.min_corner)
    with pytest.raises(GeometryError, match="WorkingVolume"):
        read_anipose_toml(path, units_to_metres=0.001, volume=([0, 0, 0], [1, 1, 1]))  # type: ignore[arg-type]
    custom = WorkingVolume([-1, -2, 1], [1, 0, 4])
    assert read_anipose_toml(path, units_to_metres=0.001, volume=custom).volume is custom


@pytest.mark.parametrize("ext", ["yml", "xml"])
def test_a_fisheye_calibration_is_refused_not_read_as_pinhole(tmp_path, ext):
    # OpenCV's calibration sample marks a cv::fisheye calibration with fisheye_model: 1; its k1..k4 read as the
    # pinhole model's k1 k2 p1 p2 gave a camera that projects elsewhere, silently
    path = tmp_path / f"out_camera_data.{ext}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 640)
    fs.write("image_height", 480)
    fs.write("fisheye_model", 1)
    fs.write("camera_matrix", np.array([[300.0, 0, 319.5], [0, 300.0, 239.5], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[0.05], [-0.01], [0.002], [-0.0003]]))
    fs.release()
    with pytest.raises(RigFileError, match="is 1: the fisheye model") as info:
        read_opencv_camera(path)
    assert info.value.path == str(path) and info.value.field == "fisheye_model"
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])  # the same flag beside stereo_calib's intrinsics
    intrinsics = tmp_path / "intrinsics.yml"
    intrinsics.write_text(intrinsics.read_text() + "fisheye_model: 1\n")
    with pytest.raises(RigFileError, match="fisheye") as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml",
                        image_size=(640, 480), units_to_metres=0.001)
    assert info.value.field == "fisheye_model"
    path.write_text(path.read_text().replace("<fisheye_model>1<", "<fisheye_model>0<").replace("fisheye_model: 1",
                                                                                             "fisheye_model: 0"))
    assert read_opencv_camera(path).dist.size == 4  # the pinhole model, said so


def test_a_pair_without_a_baseline_is_refused_naming_the_translation(tmp_path):
    # an intrinsics-only calibration leaves every pose at zero: read, it could not be saved (save_rig and
    # load_rig refuse a pair under 10 mm apart) and every joint would be missing
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML.replace("rotation = [ 0.012, -0.523, 0.004,]", "rotation = [ 0.0, 0.0, 0.0,]")
                    .replace("translation = [ 1480.3, -4.1, 410.7,]", "translation = [ 0.0, 0.0, 0.0,]"))
    with pytest.raises(RigFileError, match="apart") as info:
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.path == str(path) and info.value.field == "cam_1.translation"
    _write_stereo_calib(tmp_path, [-0.004, 0.0, 0.0])  # 4 um: a mm calibration read with a um unit
    with pytest.raises(RigFileError, match="apart") as info:
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml",
                        image_size=(640, 480), units_to_metres=0.001)
    assert info.value.path == str(tmp_path / "extrinsics.yml") and info.value.field == "T"
    cams = _cams()
    cams[1]["T"] = "[0.095, 0, 0]"  # 5 mm from the first camera (T = [0.1, 0, 0])
    (tmp_path / "rig.yaml").write_text(_multi_yaml(cams))
    with pytest.raises(RigFileError, match="apart") as info:
        read_opencv_rig(tmp_path / "rig.yaml")
    assert info.value.field == "cameras[1].T"
    path.write_text(ANIPOSE_TOML.replace("translation = [ 1480.3, -4.1, 410.7,]", "translation = [ 1e20, 0.0, 0.0,]"))
    with pytest.raises(RigFileError, match="working volume") as info:  # no default volume fits: was a GeometryError
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.path == str(path)


@pytest.mark.parametrize("size", [(480, 640, 3), (640,), "640x480", 640])
def test_an_image_size_argument_that_is_not_a_pair_names_it(tmp_path, size):
    _write_stereo_calib(tmp_path, [-60.0, 0.5, 1.0])
    with pytest.raises(RigFileError, match="must be \\(width, height\\)") as info:  # was a bare ValueError/TypeError
        read_opencv_rig(tmp_path / "intrinsics.yml", extrinsics_path=tmp_path / "extrinsics.yml", image_size=size,
                        units_to_metres=0.001)
    assert info.value.field == "image_size argument" and info.value.path == str(tmp_path / "intrinsics.yml")


def test_a_zero_translation_needs_no_units_whichever_way_it_is_written(tmp_path):
    # a zero T as a plain sequence demanded units_to_metres, the same T as an !!opencv-matrix did not
    path = tmp_path / "cam.yaml"
    path.write_text("%YAML:1.0\n---\nimage_size: [800, 600]\nK: [[500, 0, 399.5], [0, 500, 299.5], [0, 0, 1]]\n"
                    "D: [0.1, -0.01, 0, 0]\nR: [0.0, 0.1, 0.0]\nT: [0, 0, 0.0]\n")
    np.testing.assert_array_equal(read_opencv_camera(path).t, np.zeros(3))
    path.write_text(path.read_text().replace("T: [0, 0, 0.0]", "T: [0, 0, 5.0]"))
    with pytest.raises(RigFileError, match="pass units_to_metres") as info:
        read_opencv_camera(path)
    assert info.value.field == "T"


def test_an_image_side_the_rig_file_cannot_hold_is_refused_on_import(rig, tmp_path):
    """Imported, a 40000-pixel camera was saved by ghcal import to a rig file load_rig refused."""
    K = [[20000.0, 0.0, 19999.5], [0.0, 20000.0, 14999.5], [0.0, 0.0, 1.0]]
    big = Rig(tuple(Camera(c.name, 40000, 30000, K, c.dist, c.R, c.t) for c in rig.cameras), rig.volume)
    write_opencv_rig(big, tmp_path / "big.yml")
    with pytest.raises(RigFileError, match="must be at most 32767, got 40000") as info:
        read_opencv_rig(tmp_path / "big.yml")
    assert info.value.field == "cameras[0].image_width"
    write_anipose_toml(big, tmp_path / "big.toml", units_to_metres=1.0)
    with pytest.raises(RigFileError, match="must be at most 32767, got 40000") as info:
        read_anipose_toml(tmp_path / "big.toml", units_to_metres=1.0)
    assert info.value.field == "cam_0.size"


def test_millimetres_read_as_metres_are_refused_naming_the_translation(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(ANIPOSE_TOML)  # millimetres: read as metres it was a rig 1.5 km wide
    with pytest.raises(RigFileError, match="1536 m apart.*millimetres") as info:
        read_anipose_toml(path, units_to_metres=1.0)
    assert info.value.field == "cam_1.translation" and info.value.path == str(path)
    assert read_anipose_toml(path, units_to_metres=0.001).baseline == pytest.approx(1.536, abs=1e-3)


@pytest.mark.parametrize("suffix", [".yml", ".xml", ".json", ".toml"])
def test_a_byte_order_mark_is_skipped(rig, tmp_path, suffix):
    """Saved by a Windows editor: OpenCV and tomllib refused line 1 ("unsupported syntax", "invalid statement")."""
    plain, marked = tmp_path / f"plain{suffix}", tmp_path / f"marked{suffix}"
    if suffix == ".toml":
        write_anipose_toml(rig, plain, units_to_metres=0.001)
        read = lambda p: read_anipose_toml(p, units_to_metres=0.001)  # noqa: E731
    else:
        write_opencv_rig(rig, plain)
        read = read_opencv_rig
    marked.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert_cameras_close(read(plain), read(marked), atol=0)
    crlf = tmp_path / f"crlf{suffix}"  # and Windows line ends, with the mark or without
    crlf.write_bytes(plain.read_bytes().replace(b"\n", b"\r\n"))
    marked.write_bytes(b"\xef\xbb\xbf" + crlf.read_bytes())
    assert_cameras_close(read(plain), read(crlf), atol=0)
    assert_cameras_close(read(plain), read(marked), atol=0)


@pytest.mark.parametrize("suffix", [".yml", ".json", ".xml"])
@pytest.mark.parametrize("key, field", [("units_to_metres", "units_to_metres"),
                                        ("image_width", "cameras[0].image_width")])
def test_a_key_given_twice_in_an_opencv_file_is_refused_naming_it(rig, tmp_path, suffix, key, field):
    """OpenCV reads a key's first value and other readers its last: a value typed in below the old line was
    dropped without a word (a unit corrected to millimetres read as metres)."""
    path = tmp_path / f"rig{suffix}"
    write_opencv_rig(rig, path)
    lines = path.read_text().splitlines(keepends=True)
    k = next(i for i, line in enumerate(lines) if key in line)
    lines.insert(k + 1, lines[k])  # the same line twice: the value matters not, the repetition does
    path.write_text("".join(lines))
    with pytest.raises(RigFileError, match="is given 2 times in one map: OpenCV reads the first") as info:
        read_opencv_rig(path)
    assert info.value.field == field and info.value.path == str(path)


def test_an_empty_foreign_file_says_so(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text("\n")
    with pytest.raises(RigFileError, match="the file is empty") as info:  # was "a rig needs at least two cameras"
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.path == str(path) and info.value.field is None
    yaml = tmp_path / "rig.yml"
    yaml.write_text("\n\n\n%YAML:1.0\n---\nrig_id: r\n")  # blank lines first: not empty
    with pytest.raises(RigFileError, match="no known layout"):
        read_opencv_rig(yaml)


def test_a_focal_length_no_lens_has_is_refused_on_import(rig, tmp_path):
    # 1e300 px was imported and written to a rig.json; every point then projected onto the principal point
    import dataclasses

    K = rig.cameras[1].K.copy()
    K[0, 0] = 1e300
    cams = (rig.cameras[0], dataclasses.replace(rig.cameras[1], K=K))
    write_opencv_rig(dataclasses.replace(rig, cameras=cams), tmp_path / "rig.yaml")
    with pytest.raises(RigFileError, match=r"cameras\[1\]\.camera_matrix.*camera 'right'.*focal length fx = 1e\+300"):
        read_opencv_rig(tmp_path / "rig.yaml")


def test_a_distortion_or_a_third_camera_the_rig_file_refuses_is_refused_on_import(rig, tmp_path):
    # imported, each was written to a rig.json that load_rig refuses (|k| > 1e3; a third camera 10 m off the first)
    side = rig.cameras[2]
    far = Rig(rig.cameras[:2] + (dataclasses.replace(side, t=side.t + side.R @ np.array([-40.0, 0.0, 0.0])),),
              rig.volume, rig_id=rig.rig_id)
    write_opencv_rig(far, tmp_path / "far.yaml")
    with pytest.raises(RigFileError, match=r"camera 'side cam' is 4\d\.\d+ m from camera 'left' \(at most 10 m") as info:
        read_opencv_rig(tmp_path / "far.yaml")
    assert info.value.field == "cameras[2].T"
    write_anipose_toml(far, tmp_path / "far.toml", units_to_metres=1.0)
    with pytest.raises(RigFileError, match="camera 'side cam' is") as info:
        read_anipose_toml(tmp_path / "far.toml", units_to_metres=1.0)
    assert info.value.field.endswith(".translation")
    dist = side.dist.copy()
    dist[0] = 1e308
    wild = Rig(rig.cameras[:2] + (dataclasses.replace(side, dist=dist),), rig.volume, rig_id=rig.rig_id)
    write_opencv_rig(wild, tmp_path / "wild.yaml")
    with pytest.raises(RigFileError, match=r"camera 'side cam': its distortion coefficient k1 = 1e\+308") as info:
        read_opencv_rig(tmp_path / "wild.yaml")
    assert info.value.field == "cameras[2].distortion_coefficients"


@pytest.mark.parametrize("suffix", [".yml", ".xml", ".json", ".toml"])
def test_a_binary_or_utf16_file_is_named_as_such(rig, tmp_path, suffix):
    # OpenCV said "(-215:Assertion failed) buf" for NULs and "Invalid or unsupported syntax" for UTF-16 text
    good = tmp_path / f"good{suffix}"
    if suffix == ".toml":
        write_anipose_toml(rig, good, units_to_metres=0.001)
        read = lambda p: read_anipose_toml(p, units_to_metres=0.001)  # noqa: E731
    else:
        write_opencv_rig(rig, good)
        read = read_opencv_rig
    cases = {"nul": (bytes(16), "a binary file (a NUL byte at 0)"),
             "png": (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "a binary file (a NUL byte at 8)"),
             "utf16": (good.read_text().encode("utf-16"), "UTF-16 text")}
    for name, (content, words) in cases.items():
        path = tmp_path / f"{name}{suffix}"
        path.write_bytes(content)
        with pytest.raises(RigFileError) as info:
            read(path)
        assert info.value.path == str(path) and info.value.field is None
        assert words in str(info.value), (name, str(info.value))


OPENCV_TYPED_K = """%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: {dt}
   data: [ {fx}, 0., {cx}, 0., 600., 240., 0., 0., 1. ]
distortion_coefficients: [0, 0, 0, 0, 0]
"""


@pytest.mark.parametrize("dt, fx, cx, words", [
    ("i", "600", "320.5", "dt: i cannot hold data[2] = 320.5: OpenCV reads it as 320.0"),
    ("u", "600", "320", "dt: u cannot hold data[0] = 600.0: OpenCV reads it as 255.0 (3 of 9 values change)"),
])
def test_a_matrix_type_that_changes_its_values_is_refused(tmp_path, dt, fx, cx, words):
    # OpenCV converts data to dt silently: a principal point 0.5 px off, or a focal length of 255 px
    path = tmp_path / "cam.yml"
    path.write_text(OPENCV_TYPED_K.format(dt=dt, fx=fx, cx=cx))
    with pytest.raises(RigFileError) as info:
        read_opencv_camera(path)
    assert info.value.field == "camera_matrix" and words in str(info.value), str(info.value)


def test_a_float32_matrix_reads_the_digits_printed(tmp_path):
    path = tmp_path / "cam.yml"
    path.write_text(OPENCV_TYPED_K.format(dt="f", fx="600.1", cx="320.3"))
    cam = read_opencv_camera(path)  # not float32's 600.0999755859375
    assert cam.K[0, 0] == 600.1 and cam.K[0, 2] == 320.3
    path.write_text(OPENCV_TYPED_K.format(dt="i", fx="600", cx="320"))  # whole numbers: nothing changes
    assert read_opencv_camera(path).K[0, 2] == 320.0


@pytest.mark.parametrize("units", ["0.001", "mm", True, None])
def test_a_units_argument_that_is_not_a_number_is_named(rig, tmp_path, units):
    # float() took "0.001" and True (1 m per unit), and "mm" raised a bare ValueError
    write_anipose_toml(rig, tmp_path / "rig.toml", units_to_metres=1.0)
    with pytest.raises(GeometryError, match="units_to_metres must be a positive finite number"):
        read_anipose_toml(tmp_path / "rig.toml", units_to_metres=units)
    with pytest.raises(GeometryError, match="units_to_metres"):
        write_opencv_rig(rig, tmp_path / "rig.yml", units_to_metres=units)


@pytest.mark.parametrize("tail, words", [
    ("camera_matrix: !!opencv-matrix\n   rows: 3\n", "an !!opencv-matrix without its data (it has rows; the file cut short?)"),
    ("camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n", "without its data (it has rows, cols, dt;"),
    ("camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 600., 0., 320., 0. ]\n",
     "malformed !!opencv-matrix: rows 3 x cols 3 is 9 values, but data has 4"),
    ("camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: \"3d\"\n   data: [ 600., 0., 320. ]\n",
     "rows 3 x cols 1 x 3 channels is 9 values, but data has 3"),
    ("camera_matrix:\n", "has no value (the file cut short?)"),
])
def test_a_file_cut_short_in_a_matrix_says_what_is_missing(tmp_path, tail, words):
    # OpenCV's readings: "a map with keys ['rows']", "(-215:Assertion failed) nelems == m.total()*m.channels()",
    # and a key left without a value read as "the string '...'"
    path = tmp_path / "cam.yml"
    path.write_text("%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\ndistortion_coefficients: [0, 0, 0, 0, 0]\n"
                    + tail)
    with pytest.raises(RigFileError) as info:
        read_opencv_camera(path)
    assert info.value.field == "camera_matrix" and words in str(info.value), str(info.value)


def test_a_rotation_printed_with_few_digits_is_snapped_and_one_that_is_not_a_rotation_refused(tmp_path):
    # docs/rig-file.md: within 1e-4 of a rotation, snapped to the nearest (SVD); else refused naming R
    true = cv2.Rodrigues(np.array([0.01, -0.05, 0.002]))[0]
    printed = np.round(true, 5)
    path = tmp_path / "rig.yaml"

    def read_with(R):
        rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in R)
        path.write_text(_multi_yaml(_cams(R=f"[{rows}]")))
        return read_opencv_rig(path).cameras[1].R

    R = read_with(printed)
    assert np.abs(R @ R.T - np.eye(3)).max() < 1e-12 and np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    assert np.abs(R - true).max() < 1e-5
    for bad, words in ((true @ np.diag([1.0, 1.0, -1.0]), "det = -1"),  # a reflection: orthonormal, det -1
                       (1.01 * true, "det = 1.03"),  # scaled: det far from 1
                       (true + np.array([[0.0, 0.05, 0.0], [0, 0, 0], [0, 0, 0]]), "max |R R^T - I| = 0.05")):
        with pytest.raises(RigFileError, match=r"must be a rotation \(orthonormal, det \+1\)") as info:
            read_with(bad)
        assert info.value.field == "cameras[1].R" and words in str(info.value), str(info.value)


@pytest.mark.parametrize("declared", ["inf", "nan", "-0.001", '"mm"'])
def test_a_units_key_in_a_toml_file_that_is_not_a_unit_is_named(rig, tmp_path, declared):
    # inf passed the check and was then called a unit that contradicts the argument
    text = dumps_anipose_toml(rig, units_to_metres=0.001).replace("units_to_metres = 0.001",
                                                                  f"units_to_metres = {declared}")
    path = tmp_path / "calibration.toml"
    path.write_text(text)
    with pytest.raises(RigFileError, match="must be a positive finite number") as info:
        read_anipose_toml(path, units_to_metres=0.001)
    assert info.value.field == "metadata.units_to_metres"


@pytest.mark.parametrize("noise_m", [0.0, 1e-12, -1e-12, 5e-4])
def test_a_rig_in_its_first_camera_s_frame_records_no_levelling(noise_m):
    """A rig in a calibration tool's own frame (the first camera at the origin, up to float noise) is not levelled:
    the writers record no levelling for it, so ``ghcal import`` says "not levelled", not "levelled already ... 0.000 m
    above the floor" (a height of 1e-12 m passed the old ``height > 0``)."""
    from calibration.formats._frame import levelling_of
    from calibration.render import example_rig

    rig = example_rig()
    first = rig.cameras[0]

    def in_first_frame(cam: Camera) -> Camera:
        R = cam.R @ first.R.T
        return dataclasses.replace(cam, R=R, t=cam.t - R @ first.t)

    cameras = [in_first_frame(c) for c in rig.cameras]
    cameras[0] = dataclasses.replace(cameras[0], t=cameras[0].t + np.array([0.0, noise_m, 0.0]))
    assert levelling_of(dataclasses.replace(rig, cameras=tuple(cameras))) is None
    assert levelling_of(rig) is not None  # the levelled rig itself records its levelling
