"""``ghcal`` from a user's side: outputs it cannot write, sessions mixed in one folder, a camera lost or
stalled mid-capture, a corrupt frame in a take, Ctrl-C while a view is written, views of another rig, and the units of what it prints."""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration import cli
from calibration.board import BoardSpec
from calibration.render import calibration_views, example_rig
from ghnerf_runtime.geometry.camera import Camera
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.rig_file import save_rig
from tests.calibration.test_ghcal import _write_recording
from tests.framing_note import but_the_framing_notes
from tests.stops import stop_around

BOARD = BoardSpec(squares_x=7, squares_y=5, square_m=0.12, marker_m=0.09)


def _refusing_folder() -> Path:
    """A folder that refuses a new file even to root (sysfs), where os.access still says yes."""
    try:
        fd, name = tempfile.mkstemp(dir="/sys")
    except OSError:
        return Path("/sys")
    os.close(fd)
    os.unlink(name)
    pytest.skip("no folder here refuses a new file")


@pytest.fixture(scope="module")
def truth() -> Rig:
    rig = example_rig()
    return Rig(tuple(c.resized(800, 500) for c in rig.cameras), rig.volume, rig_id="truth")


@pytest.fixture(scope="module")
def one_view(truth):
    return calibration_views(truth, BOARD, count=1, edge_count=0, seed=5, floor_view=False)


def _take(root: Path, truth: Rig, one_view, frames: int = 3) -> Path:
    root.mkdir()
    _write_recording(root, truth, {cam: {str(k): v["000"] for k in range(frames)} for cam, v in one_view.items()},
                     period_s=1.0)
    return root


def _board_file(tmp_path: Path) -> Path:
    board = tmp_path / "board.json"
    board.write_text(json.dumps(BOARD.to_dict()))
    return board


def _no_detection(*args, **kwargs):
    raise AssertionError("the images were read before the output was checked")


def test_solve_refuses_an_output_it_cannot_write_before_the_detection(tmp_path, capsys, monkeypatch):
    # found out only after the detection and the solve (seconds; minutes on a real capture), and named
    # as "No such file or directory" for a folder that was there
    refusing = _refusing_folder()
    images = tmp_path / "capture"
    for cam in ("left", "right"):
        (images / cam).mkdir(parents=True)
    _board_file(images)
    monkeypatch.setattr(cli, "read_folder", _no_detection)
    base = ["solve", "--images", str(images), "--floor-view", "floor"]
    assert cli.main(base + ["--out", str(refusing / "rig.json")]) == 2
    err = capsys.readouterr().err
    assert f"--out {refusing / 'rig.json'}: cannot write the rig file in {refusing} (" in err and err.count("\n") == 1
    assert cli.main(base + ["--out", str(tmp_path / "rig.json"), "--report", str(refusing / "r.json")]) == 2
    assert f"--report {refusing / 'r.json'}: cannot write the report file in {refusing}" in capsys.readouterr().err
    # a rig file linked to one in such a folder is written through the link: its folder is the one checked
    (tmp_path / "linked.json").symlink_to(refusing / "rig.json")
    assert cli.main(base + ["--out", str(tmp_path / "linked.json")]) == 2
    assert f"cannot write the rig file in {refusing}" in capsys.readouterr().err
    assert not list(tmp_path.glob(".*tmp"))  # the test file made and removed


def test_export_refuses_an_output_it_cannot_write(tmp_path, capsys):
    refusing = _refusing_folder()
    save_rig(example_rig(), tmp_path / "rig.json")
    assert cli.main(["export", "--rig", str(tmp_path / "rig.json"), "--out", str(refusing / "rig.yml")]) == 2
    assert f"--out {refusing / 'rig.yml'}: cannot write the export in {refusing}" in capsys.readouterr().err


def test_capture_refuses_a_folder_it_cannot_write_before_opening_the_cameras(tmp_path, capsys, monkeypatch):
    import drivers

    refusing = _refusing_folder()

    def no_open(url, **kwargs):
        raise AssertionError("the cameras were opened before the folder was checked")

    monkeypatch.setattr(drivers, "create_rig_source", no_open)
    assert cli.main(["capture", "--url", "sim://", "--out", str(refusing / "capture" / "today")]) == 2
    assert f"cannot write the views in {refusing} (" in capsys.readouterr().err


def test_capture_refuses_a_file_where_a_camera_s_folder_goes(tmp_path, capsys):
    # mkdir stopped it with a bare "[Errno 17] File exists: 'c/right'", cameras.json written before it
    out = tmp_path / "c"
    out.mkdir()
    (out / "right").write_text("not a folder")
    url = "sim://?width=64&height=48&fps=5&cache=off&workers=1"
    assert cli.main(["capture", "--url", url, "--out", str(out), "--max-seconds", "5"]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: {out / 'right'} is a file, where camera 'right'\'s images go" in err, err
    assert "Errno" not in err and sorted(p.name for p in out.iterdir()) == ["right"]


def test_capture_refuses_a_link_to_nowhere_where_a_camera_s_folder_goes(tmp_path, capsys):
    # the file check passed it (it exists() not), and mkdir stopped it with "[Errno 17] File exists", after
    # cameras.json
    out = tmp_path / "c"
    out.mkdir()
    (out / "right").symlink_to(tmp_path / "gone")
    url = "sim://?width=64&height=48&fps=5&cache=off&workers=1"
    assert cli.main(["capture", "--url", url, "--out", str(out), "--max-seconds", "5"]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: {out / 'right'} is a symbolic link to {tmp_path / 'gone'}, which does not exist" in err, err
    assert "Errno" not in err and sorted(p.name for p in out.iterdir()) == ["right"]


def _no_rendering(*args, **kwargs):
    raise AssertionError("the views were rendered before the output was checked")


def test_board_and_synth_refuse_an_output_they_cannot_write_before_the_work(tmp_path, capsys, monkeypatch):
    # a file given for the folder stopped synth after its half minute of rendering, and both said only
    # OSError's "[Errno 17] File exists: ..." without the flag
    monkeypatch.setattr(cli, "calibration_views", _no_rendering)
    taken = tmp_path / "rig.json"
    taken.write_text("{}")
    for command, what in (("board", "the board"), ("synth", "the views")):
        assert cli.main([command, "--out", str(taken)]) == 2
        assert capsys.readouterr().err == f"ghcal: error: --out {taken}: {taken} is a file; give a folder for {what}\n"
    assert taken.read_text() == "{}"
    # a file where a camera's folder goes
    (tmp_path / "synth").mkdir()
    (tmp_path / "synth" / "left").write_text("notes")
    assert cli.main(["synth", "--out", str(tmp_path / "synth")]) == 2
    assert (f"{tmp_path / 'synth' / 'left'} is a file, where the views of camera 'left' go"
            in capsys.readouterr().err)
    # last: skipped where no folder refuses a new file
    refusing = _refusing_folder()
    for command, what in (("board", "the board"), ("synth", "the views")):
        assert cli.main([command, "--out", str(refusing / "new")]) == 2
        assert f"ghcal: error: --out {refusing / 'new'}: cannot write {what} in {refusing} (" in capsys.readouterr().err


def test_capture_into_an_earlier_sessions_folder_needs_append(truth, one_view, tmp_path, capsys):
    take = _take(tmp_path / "take", truth, one_view)
    board = _board_file(tmp_path)
    out = tmp_path / "capture"
    argv = ["capture", "--url", f"replay://{take}?speed=free", "--board", str(board), "--out", str(out),
            "--count", "1", "--interval-s", "0", "--still-s", "0"]
    assert cli.main(argv) == 0
    capsys.readouterr()
    before = {p: p.read_bytes() for p in out.glob("*/*.png")}
    assert cli.main(argv) == 2  # mixed in silently, after the cameras were perhaps moved
    assert f"{out} already holds 1 views from an earlier capture (000-000)" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in out.glob("*/*.png")} == before  # nothing overwritten or added
    assert cli.main(argv + ["--append"]) == 0
    assert sorted(p.name for p in (out / "left").iterdir()) == ["000.png", "001.png"]
    # the floor view joins the session it belongs to without --append
    assert cli.main(argv[:-6] + ["--floor", "--steady-s", "0"]) == 0
    assert (out / "left" / "floor.png").exists()


def test_views_added_at_another_size_are_refused_before_any_is_kept(truth, one_view, tmp_path, capsys):
    # another rig's cameras, or these opened at another resolution: --append and --floor kept them without a word,
    # and the solve then refused the camera's images at two sizes, the session lost
    board = _board_file(tmp_path)
    out = tmp_path / "capture"
    base = ["--board", str(board), "--out", str(out), "--count", "1", "--interval-s", "0", "--still-s", "0"]
    take = _take(tmp_path / "take", truth, one_view)
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free"] + base) == 0
    small = Rig(tuple(c.resized(640, 400) for c in truth.cameras), truth.volume, rig_id="small")
    other = _take(tmp_path / "other", small, calibration_views(small, BOARD, count=1, edge_count=0, seed=5,
                                                               floor_view=False))
    capsys.readouterr()
    before = {p: p.read_bytes() for p in out.glob("*/*")}
    for extra in (["--append"], ["--floor", "--steady-s", "0"]):
        assert cli.main(["capture", "--url", f"replay://{other}?speed=free"] + base + extra) == 2
        assert (f"ghcal: error: {out / 'left' / '000.png'} is 800x500, but camera 'left' of replay://{other}?speed=free "
                "delivers 640x400: the views in" in capsys.readouterr().err)
        assert {p: p.read_bytes() for p in out.glob("*/*")} == before  # nothing added
    # a floor view replaced (--force) is no reference: the views it joins are
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free"] + base + ["--floor", "--steady-s", "0"]) == 0
    (out / "left" / "000.png").unlink()
    (out / "right" / "000.png").unlink()
    assert cli.main(["capture", "--url", f"replay://{other}?speed=free"] + base
                    + ["--floor", "--steady-s", "0", "--force"]) == 0
    assert cv2.imread(str(out / "left" / "floor.png")).shape[:2] == (400, 640)


def _failing_after(real, reads: int, error: Exception):
    def create(url, **kwargs):
        source = real(url, **kwargs)
        read, calls = source.read, []

        def read_then_fail(*args, **kw):
            calls.append(1)
            if len(calls) > reads:
                raise error
            return read(*args, **kw)
        source.read = read_then_fail
        return source
    return create


def test_a_camera_unplugged_mid_capture_says_what_was_kept(truth, one_view, tmp_path, capsys, monkeypatch):
    import drivers

    take = _take(tmp_path / "take", truth, one_view)
    board = _board_file(tmp_path)
    out = tmp_path / "capture"
    monkeypatch.setattr(drivers, "create_rig_source", _failing_after(
        drivers.create_rig_source, 2, drivers.RigDisconnectedError("camera 'right' vanished (USB reset)")))
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(board), "--out", str(out),
                     "--count", "5", "--interval-s", "0", "--still-s", "0"]) == 2
    err = but_the_framing_notes(capsys.readouterr().err)
    assert "camera 'right' vanished (USB reset); the 1 view(s) kept before it are whole pairs in" in err, err
    assert "--append" in err and err.count("\n") == 1
    for cam in truth.pair:  # and they are
        assert np.array_equal(cv2.imread(str(out / cam.name / "000.png"), cv2.IMREAD_GRAYSCALE),
                              one_view[cam.name]["000"])


@pytest.fixture(scope="module")
def three_views(truth):
    return calibration_views(truth, BOARD, count=3, edge_count=0, seed=5, floor_view=False)


def _three_pose_take(root: Path, truth: Rig, three_views) -> Path:
    """Each of three board poses in three pairs in a row (frames 0-2, 3-5, 6-8): a pose stays kept after its
    first pair is lost (the next holds it still, the third is kept)."""
    root.mkdir()
    _write_recording(root, truth, {cam: {f"{name}{k}": image for name, image in views.items() for k in range(3)}
                                   for cam, views in three_views.items()}, period_s=1.0)
    return root


def test_a_corrupt_image_mid_take_is_skipped_and_the_views_after_it_kept(truth, three_views, tmp_path, capsys):
    """One image of a replay:// take that does not decode is a frame the rig could not deliver, raised once by the
    read, the next going on (docs/recording-format.md, "Image sizes"). The capture stopped there (exit 2) and lost
    the take's views after it; it goes past it as ghnerf-demo does, naming it once, and counts it at the end."""
    take = _three_pose_take(tmp_path / "take", truth, three_views)
    corrupt = take / "images" / "left" / "00000003.png"  # the second pose's first pair (not one checked at open)
    corrupt.write_bytes(b"not a png")
    out = tmp_path / "capture"
    rc = cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(_board_file(tmp_path)),
                   "--out", str(out), "--count", "3", "--interval-s", "0", "--still-s", "0"])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert but_the_framing_notes(captured.err) == (f"ghcal: skipped a frame the rig could not deliver: recording image "
                                                 f"{corrupt} is corrupt (OpenCV cannot decode it)\n")
    assert captured.out.splitlines()[-1] == f"kept 3 view(s) in {out}; skipped 1 frame(s) the rig could not deliver"
    for cam in truth.pair:  # the poses before and after it, each a whole pair
        for k, name in enumerate(sorted(three_views[cam.name])):
            assert np.array_equal(cv2.imread(str(out / cam.name / f"{k:03d}.png"), cv2.IMREAD_GRAYSCALE),
                                  three_views[cam.name][name])


def test_two_frames_the_rig_could_not_deliver_in_a_row_end_the_capture(truth, three_views, tmp_path, capsys):
    """Both cameras' images of one instant corrupt: a second failed read before a pair is a failed rig, as for
    ghnerf-demo and the daemon. It ends the capture as a lost camera does, saying what was kept."""
    take = _three_pose_take(tmp_path / "take", truth, three_views)
    for cam in truth.pair:
        (take / "images" / cam.name / "00000003.png").write_bytes(b"not a png")
    out = tmp_path / "capture"
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(_board_file(tmp_path)),
                     "--out", str(out), "--count", "3", "--interval-s", "0", "--still-s", "0"]) == 2
    lines = but_the_framing_notes(capsys.readouterr().err).splitlines()
    assert len(lines) == 2 and lines[0].startswith("ghcal: skipped a frame the rig could not deliver: "), lines
    assert f"{take / 'images' / 'right' / '00000003.png'} is corrupt (OpenCV cannot decode it) (the second frame " \
        "in a row the rig could not deliver); the 1 view(s) kept before it are whole pairs in" in lines[1], lines
    assert lines[1].endswith("; skipped 1 frame(s) the rig could not deliver"), lines
    assert sorted(p.name for p in (out / "left").iterdir()) == ["000.png"]


@pytest.mark.parametrize("kind", ["size", "recording"])
def test_a_rig_of_another_size_or_a_take_not_written_ends_the_capture_at_once(truth, one_view, tmp_path, capsys,
                                                                              monkeypatch, kind):
    """Not frames to go past: cameras delivering another size than the rig's (FrameSizeError), a record+ take that
    can no longer be written (RecordingError), as for ghnerf-demo; nor a camera gone (the test above)."""
    import drivers

    take = _take(tmp_path / "take", truth, one_view)
    error = (drivers.FrameSizeError("camera 'left' delivers 640x480, its rig camera is 800x500", "left",
                                    (800, 500), (640, 480)) if kind == "size"
             else drivers.RecordingError("recording to /data/take failed: [Errno 28] No space left on device"))
    monkeypatch.setattr(drivers, "create_rig_source", _failing_after(drivers.create_rig_source, 2, error))
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(_board_file(tmp_path)),
                     "--out", str(tmp_path / "c"), "--count", "5", "--interval-s", "0", "--still-s", "0"]) == 2
    err = but_the_framing_notes(capsys.readouterr().err)
    assert f"{error}; the 1 view(s) kept before it are whole pairs in" in err and err.count("\n") == 1, err
    assert "skipped" not in err


def test_a_sim_camera_unplugged_before_any_view_is_kept(tmp_path, capsys):
    url = "sim://?width=64&height=48&fps=5&cache=off&workers=1&unplug_after_s=0.5"
    assert cli.main(["capture", "--url", url, "--out", str(tmp_path / "c"), "--max-seconds", "20"]) == 2
    err = capsys.readouterr().err
    assert "unplugged" in err and "no view was kept" in err and "Traceback" not in err


def test_a_stalled_camera_is_said_not_waited_on_silently(truth, one_view, tmp_path, capsys, monkeypatch):
    import drivers

    take = _take(tmp_path / "take", truth, one_view)
    monkeypatch.setattr(drivers, "create_rig_source", _failing_after(
        drivers.create_rig_source, 0, drivers.RigTimeoutError("no pair within 2 s")))
    monkeypatch.setattr(cli, "STALL_NOTE_S", 0.05, raising=False)
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free", "--out", str(tmp_path / "c"),
                     "--max-seconds", "0.3"]) == 2
    err = capsys.readouterr().err
    assert err.count(f"no image pair from replay://{take}?speed=free for") == 1, err  # once, not every 2 s
    assert "kept 0 of 20 views: --max-seconds ran out" in err


@pytest.mark.parametrize("stalled", [True, False])
def test_capture_prints_the_camera_url_without_its_password(truth, one_view, tmp_path, capsys, monkeypatch, stalled):
    import drivers

    take = _take(tmp_path / "take", truth, one_view)
    error = (drivers.RigTimeoutError("no pair within 2 s") if stalled
             else drivers.RigDisconnectedError("camera 'right' vanished (USB reset)"))
    real = _failing_after(drivers.create_rig_source, 0, error)
    # replay:// takes no token: the URL given stands for a network camera's, read from the take
    monkeypatch.setattr(drivers, "create_rig_source", lambda url, **kw: real(url.replace("&token=s3cret", ""), **kw))
    monkeypatch.setattr(cli, "STALL_NOTE_S", 0.05, raising=False)
    assert cli.main(["capture", "--url", f"replay://{take}?speed=free&token=s3cret", "--out", str(tmp_path / "c"),
                     "--max-seconds", "0.3"]) == 2
    captured = capsys.readouterr()
    shown = f"replay://{take}?speed=free&token=***"
    assert f"capturing from {shown} (cameras" in captured.out
    assert (f"no image pair from {shown} for" if stalled
            else f"{shown}: camera 'right' vanished (USB reset); no view was kept") in captured.err
    assert "s3cret" not in captured.out + captured.err


def test_ctrl_c_while_a_view_is_written_leaves_no_half_pair(truth, one_view, tmp_path, capsys, monkeypatch):
    take = _take(tmp_path / "take", truth, one_view)
    board = _board_file(tmp_path)
    out = tmp_path / "capture"
    images = []

    def counted(real):
        def write(*args, **kwargs):
            images.append(1)
            if len(images) == 2:  # the second camera's image of the first view
                raise KeyboardInterrupt
            return real(*args, **kwargs)
        return write

    monkeypatch.setattr(cv2, "imwrite", counted(cv2.imwrite))
    monkeypatch.setattr(cv2, "imencode", counted(cv2.imencode))
    try:
        rc = cli.main(["capture", "--url", f"replay://{take}?speed=free", "--board", str(board), "--out", str(out),
                       "--count", "5", "--interval-s", "0", "--still-s", "0"])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghcal: the user saw a traceback")
    assert rc == 130 and "stopped before any view was kept" in capsys.readouterr().err
    # not the first camera's image alone as view 000 (kept by no count), nor a half-written file
    assert [p.name for p in out.rglob("*") if p.is_file() and p.name != "cameras.json"] == []


def test_check_names_both_pairs_for_the_views_of_another_rig(tmp_path, capsys):
    rig = tmp_path / "rig.json"
    save_rig(example_rig(), rig)  # cameras left, right
    images = tmp_path / "other"
    for cam in ("cam_a", "cam_b"):
        (images / cam).mkdir(parents=True)
    (images / "cameras.json").write_text(json.dumps({"cameras": ["cam_b", "cam_a"]}))
    _board_file(images)
    assert cli.main(["check", "--rig", str(rig), "--images", str(images)]) == 2
    assert (f"{images} holds views of the cameras ['cam_b', 'cam_a'], but {rig} is the rig of the cameras "
            "['left', 'right'] (no folder 'left'): views of another rig?") in capsys.readouterr().err


def test_a_lens_that_folds_is_said_in_degrees_off_the_axis():
    from calibration.solve import fold_warning  # "(radius 1.29)": of what, in what unit?

    # r (1 - 0.2 r^2) stops growing at r = 1 / sqrt(0.6) = 1.29: 52 degrees off the axis
    cam = Camera("left", 800, 500, np.array([[300.0, 0, 400], [0, 300, 250], [0, 0, 1]]),
                 np.array([-0.2, 0, 0, 0, 0]))
    text = fold_warning(cam)
    assert "folds over inside the image, 52 degrees off the optical axis (normalised radius 1.29)" in text, text


def test_a_lens_folded_by_its_tangential_terms_is_said_so_naming_the_term():
    from calibration.solve import fold_warning  # was: "folds over inside the image, 90 degrees (radius inf)"

    cam = Camera("left", 800, 500, np.array([[300.0, 0, 400], [0, 300, 250], [0, 0, 1]]),
                 np.array([-0.01, 0, 0, -0.3, 0]))
    text = fold_warning(cam)
    assert text.startswith("left: the solved lens model folds over inside the image, 29 degrees off the optical axis "
                           "(normalised radius 0.55), by its tangential or thin-prism terms (p2 = -0.3;"), text


def test_ctrl_c_while_the_board_is_written_leaves_the_earlier_print(tmp_path, capsys, monkeypatch):
    # board.png was written in place: stopped halfway, the folder held a cut-off print beside its board.json
    assert cli.main(["board", "--out", str(tmp_path), "--dpi", "72"]) == 0
    earlier = (tmp_path / "board.png").read_bytes()

    def half_then_stop(self, data):  # a write in place, stopped halfway
        with open(self, "wb") as fh:
            fh.write(data[: len(data) // 2])
        raise KeyboardInterrupt

    def stop(*args, **kwargs):  # a write aside, stopped before its rename
        raise KeyboardInterrupt

    monkeypatch.setattr(Path, "write_bytes", half_then_stop)
    monkeypatch.setattr(os, "replace", stop)
    assert cli.main(["board", "--out", str(tmp_path), "--dpi", "100"]) == 130
    assert (tmp_path / "board.png").read_bytes() == earlier
    assert not list(tmp_path.glob(".*tmp"))


@pytest.fixture(scope="module")
def synth_views(tmp_path_factory) -> Path:
    """``ghcal synth``'s folder of the example rig: 6 shared views, 1 per camera in its corners, a floor view."""
    out = tmp_path_factory.mktemp("synth") / "views"
    assert cli.main(["synth", "--out", str(out), "--count", "6", "--edge-count", "1", "--seed", "2"]) == 0
    return out


def _solved_tangential_terms(views: Path, out: Path, *extra: str) -> list[list[float]]:
    assert cli.main(["solve", "--images", str(views), "--out", str(out), "--floor-view", "floor", *extra]) == 0
    rig = json.loads(out.read_text())
    return [cam["distortion"]["coefficients"][2:4] for cam in rig["cameras"]]


def test_no_tangential_solves_p1_p2_at_exactly_zero(synth_views, tmp_path, capsys):
    """OpenCV's CALIB_ZERO_TANGENT_DIST, for a lens whose fitted p1/p2 fold its model inside the image: ghcal had
    no way to ask for it."""
    fitted = _solved_tangential_terms(synth_views, tmp_path / "fitted.json")
    held = _solved_tangential_terms(synth_views, tmp_path / "held.json", "--no-tangential")
    assert all(p != 0.0 for terms in fitted for p in terms), fitted  # fitted, they are not zero on these views
    assert held == [[0.0, 0.0], [0.0, 0.0]]
    report = json.loads((tmp_path / "held.report.json").read_text())
    rig = json.loads((tmp_path / "held.json").read_text())
    assert report["tangential"] is False and rig["metadata"]["calibration"]["tangential"] is False
    assert json.loads((tmp_path / "fitted.report.json").read_text())["tangential"] is True


def test_the_tangential_fold_warning_suggests_holding_p1_p2_at_zero():
    from calibration.solve import fold_warning

    cam = Camera("left", 800, 500, np.array([[300.0, 0, 400], [0, 300, 250], [0, 0, 1]]),
                 np.array([-0.01, 0, 0, -0.3, 0]))
    assert fold_warning(cam).endswith("solve again, or solve with --no-tangential to hold p1 and p2 at 0")
    radial = Camera("left", 800, 500, np.array([[300.0, 0, 400], [0, 300, 250], [0, 0, 1]]),
                    np.array([-0.2, 0, 0, 0, 0]))
    assert "--no-tangential" not in fold_warning(radial)  # a radial fold: p1, p2 are not at fault


def _fsync_fails(monkeypatch) -> None:
    """A record+ take's fsyncs fail as on a full disk."""
    import drivers.backends.record as record_module

    def full_disk(path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(record_module, "_fsync", full_disk)


@pytest.mark.parametrize("end", ["count", "ctrl-c", "unplugged"])
def test_a_take_recorded_with_the_capture_that_fails_as_it_closes_is_said_exit_2(truth, one_view, tmp_path, capsys,
                                                                                  monkeypatch, end):
    """A capture recorded as it is taken (record+...) whose take failed as it closed (its last fsync, a frame still
    queued: no read raised it) was a log line at most: exit 0 with the views kept, the take complete: false. Now
    one error line names the take and why, after the views kept are said, and the exit status is 2 however the
    capture ended (all its views, Ctrl-C, a camera gone: both errors said)."""
    import drivers

    _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    if end != "count":
        error = KeyboardInterrupt() if end == "ctrl-c" else drivers.RigDisconnectedError("camera 'right' vanished")
        monkeypatch.setattr(drivers, "create_rig_source", _failing_after(drivers.create_rig_source, 2, error))
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = cli.main(["capture", "--url", f"record+replay://{take}?speed=free&out={recorded}", "--board",
                   str(_board_file(tmp_path)), "--out", str(out), "--count", "1" if end == "count" else "5",
                   "--interval-s", "0", "--still-s", "0"])
    captured = capsys.readouterr()
    assert rc == 2, captured
    err = but_the_framing_notes(captured.err).splitlines()
    said = [line for line in err if "failed as it closed" in line]
    assert said == [f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space left on device; "
                    "its manifest says complete: false"], err
    assert len(err) == (2 if end == "unplugged" else 1), err  # the camera's error, said by main after the take's
    assert ("kept 1 view(s) in" if end != "unplugged" else "") in captured.out
    assert json.loads((recorded / "manifest.json").read_text())["complete"] is False
    assert (out / truth.pair[0].name / "000.png").exists()  # the views are whole: kept


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_a_failed_take_is_said_when_a_stop_lands_in_the_close_of_a_capture_that_read_to_its_end(
        truth, one_view, tmp_path, capsys, monkeypatch, stop):
    """A Ctrl-C or SIGTERM (timeout's, as --count is reached) landing in the close of a capture that had kept all
    its views was raised once the close was done, past the take's check: the failed take went unsaid, exit 143
    (130). Now it is said, exit 2, as for any other end (the stop came after the views were whole)."""
    import signal
    import time

    import drivers

    def create(url, **kwargs):
        source = real(url, **kwargs)
        close = source.close

        def close_under_a_stop():
            os.kill(os.getpid(), signal.Signals[stop])
            time.sleep(0.3)  # the signal's Python handler runs here, in the main thread, before the close's work
            close()
        source.close = close_under_a_stop
        return source

    real = drivers.create_rig_source
    _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    monkeypatch.setattr(drivers, "create_rig_source", create)
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = _captured_through_record(tmp_path, take, recorded, out, count=1)
    captured = capsys.readouterr()
    assert rc == 2, captured
    assert but_the_framing_notes(captured.err).splitlines() == [
        f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space left on device; "
        "its manifest says complete: false"]
    assert "kept 1 view(s) in" in captured.out
    assert (out / truth.pair[0].name / "000.png").exists()  # the views are whole: kept


class _Escaped(Exception):
    """SIGTERM's default action, which would end the test run, reached."""


def _outer_sigterm(signum, frame):
    raise _Escaped


def _captured_through_record(tmp_path, take: Path, recorded: Path, out: Path, *, count: int) -> int:
    """``ghcal capture``'s exit status for ``count`` views of ``take`` through ``record+`` into ``recorded``, with
    SIGTERM's default action stood in for: a stop escaping ghcal fails the test."""
    import signal

    previous = signal.signal(signal.SIGTERM, _outer_sigterm)
    try:
        return cli.main(["capture", "--url", f"record+replay://{take}?speed=free&out={recorded}", "--board",
                         str(_board_file(tmp_path)), "--out", str(out), "--count", str(count), "--interval-s", "0",
                         "--still-s", "0"])
    except (_Escaped, KeyboardInterrupt):
        pytest.fail("the stop escaped ghcal")
    finally:
        signal.signal(signal.SIGTERM, previous)


def _stop_after_the_close(monkeypatch, signum: int) -> None:
    """A stop lands once the cameras' close is done (its stops held), before the take's check."""
    stop_around(monkeypatch, cli, "closed_with_stops_deferred", signum, after=True)


def _stop_in_the_last_line(monkeypatch, signum: int) -> None:
    """A stop lands in the capture's last line (kept..., stopped: kept...), the take closed by then."""
    stop_around(monkeypatch, cli, "_skipped_note", signum)


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("end, where", [("count", "after the close"), ("count", "in the last line"),
                                        ("ctrl-c", "in the last line")])
def test_a_failed_take_is_said_when_a_stop_lands_after_the_capture_s_close(truth, one_view, tmp_path, capsys,
                                                                           monkeypatch, end, where, stop, take_fails):
    """A Ctrl-C or SIGTERM landing after the cameras' close (between it and the take's check, or in the capture's
    last line) was raised to main past the take's check: "the capture did not finish", 130 or 143, of a take whose
    manifest says complete: false. Now a failed take is said (one line, exit 2) wherever the stop lands, whether
    the capture kept all its views or was stopped; a whole one leaves the stop its own exit status. (A second stop
    just after the close of a stopped capture is dropped: the test below.)"""
    import signal

    import drivers

    if take_fails:
        _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    if end == "ctrl-c":  # the capture stopped: the late stop is a second one
        monkeypatch.setattr(drivers, "create_rig_source",
                            _failing_after(drivers.create_rig_source, 2, KeyboardInterrupt()))
    stop_there = _stop_after_the_close if where == "after the close" else _stop_in_the_last_line
    stop_there(monkeypatch, signal.Signals[stop])
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = _captured_through_record(tmp_path, take, recorded, out, count=1 if end == "count" else 5)
    captured = capsys.readouterr()
    err = but_the_framing_notes(captured.err).splitlines()
    if take_fails:
        assert (rc, err) == (2, [f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space "
                                 "left on device; its manifest says complete: false"]), captured
    else:  # not swallowed: the stop is the capture's end
        words = "SIGTERM" if stop == "SIGTERM" else "Ctrl-C"
        assert (rc, err) == (128 + signal.Signals[stop], [f"ghcal: stopped ({words}); the capture did not finish"]), \
            captured
    if (end, where, take_fails) == ("count", "after the close", True):
        # noted with the close (the capture's first stop), as one in the close: the take failed, the last line said
        assert "kept 1 view(s)" in captured.out
    else:
        assert "kept 1 view(s)" not in captured.out  # the last line, cut short by the stop
    assert json.loads((recorded / "manifest.json").read_text())["complete"] is not take_fails
    assert (out / truth.pair[0].name / "000.png").exists()  # the views are whole: kept
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def _stop_before_the_close(monkeypatch, signum: int) -> None:
    """A stop lands just before the cameras' close, outside its deferral."""
    stop_around(monkeypatch, cli, "closed_with_stops_deferred", signum)


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("second", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("where", ["before the close", "after the close"])
def test_a_second_stop_next_to_the_close_of_a_stopped_capture_is_dropped_and_the_first_reported(
        truth, one_view, tmp_path, capsys, monkeypatch, where, second, take_fails):
    """Ctrl-C ends a capture that kept a view; a second Ctrl-C or SIGTERM landing just before the cameras' close
    (outside its deferral) skipped that close, the take left complete: false, and one just after it was raised past
    the capture's last line: "the capture did not finish", 130 or 143, in place of the first stop's 0. Now both are
    dropped: the take closed and checked, the views kept said, 0 (a failed take: said, exit 2)."""
    import signal

    import drivers

    if take_fails:
        _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    monkeypatch.setattr(drivers, "create_rig_source", _failing_after(drivers.create_rig_source, 2, KeyboardInterrupt()))
    stop_there = _stop_before_the_close if where == "before the close" else _stop_after_the_close
    stop_there(monkeypatch, signal.Signals[second])
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = _captured_through_record(tmp_path, take, recorded, out, count=5)
    captured = capsys.readouterr()
    err = but_the_framing_notes(captured.err).splitlines()
    failed = [f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space left on device; its "
              "manifest says complete: false"]
    assert (rc, err) == ((2, failed) if take_fails else (0, [])), captured
    assert "stopped: kept 1 view(s)" in captured.out  # the first stop's last line
    assert json.loads((recorded / "manifest.json").read_text())["complete"] is not take_fails
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def _stop_as_the_noting_begins(monkeypatch, signum: int) -> None:
    """A stop lands as a capture that read to its end starts noting stops, before its handlers are in."""
    stop_around(monkeypatch, cli, "stop_signals_noted", signum)


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("where", ["before the close", "as the noting begins"])
def test_a_first_stop_just_before_the_close_of_a_capture_that_read_to_its_end_still_closes_the_take(
        truth, one_view, tmp_path, capsys, monkeypatch, where, stop, take_fails):
    """A capture kept all its views and no stop had come; a Ctrl-C or SIGTERM (timeout's, as --count is reached)
    landing in the finally just before the cameras' close (outside its deferral) was raised past the close: the take
    left complete: false and unchecked. Now the take is closed whatever instant the stop lands, then the stop is
    the capture's end as one in the close is (130, 143; a failed take said, exit 2)."""
    import signal

    if take_fails:
        _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    stop_there = _stop_before_the_close if where == "before the close" else _stop_as_the_noting_begins
    stop_there(monkeypatch, signal.Signals[stop])
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = _captured_through_record(tmp_path, take, recorded, out, count=1)
    captured = capsys.readouterr()
    err = but_the_framing_notes(captured.err).splitlines()
    assert json.loads((recorded / "manifest.json").read_text())["complete"] is not take_fails  # closed
    if take_fails:
        assert (rc, err) == (2, [f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space "
                                 "left on device; its manifest says complete: false"]), captured
    else:
        words = "SIGTERM" if stop == "SIGTERM" else "Ctrl-C"
        assert (rc, err) == (128 + signal.Signals[stop], [f"ghcal: stopped ({words}); the capture did not finish"]), \
            captured
    assert (out / truth.pair[0].name / "000.png").exists()  # the views are whole: kept
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("where", ["before the close", "after the close", "as the take's failure is said"])
def test_a_stop_while_an_error_leaves_the_capture_does_not_hide_the_error(
        truth, one_view, tmp_path, capsys, monkeypatch, where, stop, take_fails):
    """A camera gone mid-capture ends it with an error; a Ctrl-C or SIGTERM landing as that error left (a second
    Ctrl-C pressed while the cameras closed, or a stop just before their close, which it then skipped) was raised
    in its place: "stopped; the capture did not finish", 130 or 143, the error's words lost. Now the cameras are
    closed and the error is said, exit 2 (a failed take said before it)."""
    import signal

    import drivers

    from ghnerf_runtime.cli import recorded_take

    if take_fails:
        _fsync_fails(monkeypatch)  # a short take: only the close's fsync runs
    gone = drivers.RigDisconnectedError("camera 'right' vanished (USB reset)")
    monkeypatch.setattr(drivers, "create_rig_source", _failing_after(drivers.create_rig_source, 2, gone))
    signum = signal.Signals[stop]
    if where == "before the close":
        _stop_before_the_close(monkeypatch, signum)
    elif where == "after the close":
        _stop_after_the_close(monkeypatch, signum)
    else:  # the take's failure said by the tool, on the error's way out to main
        stop_around(monkeypatch, recorded_take.RecordedTake, "say_failure", signum, after=True)
    take, recorded, out = _take(tmp_path / "take", truth, one_view), tmp_path / "recorded", tmp_path / "capture"
    rc = _captured_through_record(tmp_path, take, recorded, out, count=5)
    captured = capsys.readouterr()
    err = but_the_framing_notes(captured.err).splitlines()
    failed = [f"ghcal: error: recording to {recorded} failed as it closed: [Errno 28] No space left on device; its "
              "manifest says complete: false"] if take_fails else []
    assert rc == 2, captured
    assert err[:-1] == failed, captured
    assert err[-1].startswith("ghcal: error: ") and "camera 'right' vanished (USB reset)" in err[-1], captured
    assert json.loads((recorded / "manifest.json").read_text())["complete"] is not take_fails  # closed
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back
