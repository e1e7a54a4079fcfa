"""``ghcal``'s inputs checked before any work (session 73): ``solve --volume`` by the rig file's rules before an image
is read, a ``board.json`` that does not load named with why, and ``--out`` refused where it is one of the inputs."""
from __future__ import annotations

import os

import pytest

from calibration import cli


def _no_detection(*args, **kwargs):
    raise AssertionError("the images were read before --volume was checked")


@pytest.mark.parametrize("volume, words", [
    ("-1,-2,0.5,1,0.1,2e4", "MAX_DEPTH_M"),  # the rig file refuses it (volume_reach_problem)
    ("0,0,2,1,1,1", "min < max"),
])
def test_solve_refuses_a_volume_the_rig_file_refuses_before_reading_images(tmp_path, capsys, monkeypatch, volume,
                                                                           words):
    monkeypatch.setattr(cli, "read_folder", _no_detection)
    monkeypatch.setattr(cli, "read_camera_order", _no_detection)
    images = tmp_path / "cap"
    for cam in ("left", "right"):
        (images / cam).mkdir(parents=True)
    argv = ["solve", "--images", str(images), "--out", str(tmp_path / "r.json"), "--camera-height", "1.4",
            f"--volume={volume}"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"--volume {volume}" in err or f"got {volume!r}" in err, err
    assert words in err and "--out" not in err, err


def test_import_refuses_an_out_that_is_the_extrinsics_file(tmp_path, capsys, monkeypatch):
    from calibration.render import example_rig
    from tests.calibration.test_ghcal_import_export import _write_stereo_calib_of

    intrinsics, extrinsics = _write_stereo_calib_of(example_rig(), tmp_path, square_m=1.0)
    before = extrinsics.read_bytes()
    monkeypatch.chdir(tmp_path)  # ./extrinsics.yml and extrinsics.yml: one file
    argv = ["import", str(intrinsics), "--extrinsics", "./extrinsics.yml", "--out", "extrinsics.yml",
            "--image-size", "960x600"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "--out extrinsics.yml is the extrinsics read (--extrinsics)" in err, err
    assert extrinsics.read_bytes() == before and not (tmp_path / "extrinsics.prev.yml").exists()


@pytest.mark.parametrize("flag", ["--out", "--report"])
@pytest.mark.parametrize("board_given", [True, False])
def test_solve_refuses_an_output_that_is_the_board_file(tmp_path, capsys, monkeypatch, flag, board_given):
    monkeypatch.setattr(cli, "read_folder", _no_detection)
    images = tmp_path / "cap"
    for cam in ("left", "right"):
        (images / cam).mkdir(parents=True)
    board = images / "board.json"
    board.write_text('{"squares_x": 9}\n')  # never read: the refusal comes first
    monkeypatch.chdir(tmp_path)
    argv = ["solve", "--images", "cap", "--out", "r.json", "--camera-height", "1.4", flag, "./cap/board.json"]
    if board_given:
        argv += ["--board", "cap/board.json"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"{flag} cap/board.json is the board file read (--board)" in err, err
    assert board.read_text() == '{"squares_x": 9}\n'


@pytest.mark.parametrize("text, words", [
    ('{"squares_x": 9,}', "not a JSON file: Expecting property name"),
    ('{"squares_x": "nine"}', "squares_y: missing"),
])
def test_board_names_why_an_existing_board_file_does_not_load(tmp_path, capsys, text, words):
    spec = tmp_path / "board.json"
    spec.write_text(text)
    assert cli.main(["board", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{spec}: {words}" in err and "--force" in err and "defines another board" not in err, err
    assert spec.read_text() == text and not (tmp_path / "board.png").exists()


def test_board_names_an_unreadable_board_file(tmp_path, capsys):
    (tmp_path / "board.json").mkdir()  # a folder of that name: read by no one, whoever runs the test
    assert cli.main(["board", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path / 'board.json'}: cannot read the board file" in err, err


def _cap_with_board(tmp_path):
    images = tmp_path / "cap"
    for cam in ("left", "right"):
        (images / cam).mkdir(parents=True)
    (images / "board.json").write_text('{"squares_x": 9}\n')  # never read: the refusal comes first
    return images


@pytest.mark.parametrize("case", ["import-out", "import-kept", "export-out", "solve-out", "solve-report"])
def test_an_output_that_is_a_hard_link_to_an_input_is_refused(tmp_path, capsys, monkeypatch, case):
    # session 74: outputs were compared with inputs by resolved path, and a hard link has a path of its own
    from calibration.render import example_rig
    from ghnerf_runtime.rig_file import save_rig

    monkeypatch.setattr(cli, "read_folder", _no_detection)
    rig = tmp_path / "rig.json"
    save_rig(example_rig(), rig)
    toml = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig), "--out", str(toml), "--units-to-metres", "0.001"]) == 0
    board = _cap_with_board(tmp_path) / "board.json"
    hard = tmp_path / "hard.json"
    target, argv, words = {
        "import-out": (toml, ["import", str(toml), "--out", str(hard)], f"--out {hard} is the file being imported"),
        "import-kept": (toml, ["import", str(toml), "--out", str(tmp_path / "hard.json")],
                        f"FILE {toml} is where the previous {hard} is kept"),
        "export-out": (rig, ["export", "--rig", str(rig), "--out", str(hard)], f"--out {hard} is the rig file (--rig)"),
        "solve-out": (board, ["solve", "--images", str(tmp_path / "cap"), "--out",
                      str(hard), "--camera-height", "1.4"], f"--out {hard} is the board file read (--board)"),
        "solve-report": (rig, ["solve", "--images", str(tmp_path / "cap"), "--out", str(rig), "--report", str(hard),
                               "--camera-height", "1.4"], f"--report {hard} is the rig file (--out {rig})"),
    }[case]
    os.link(target, tmp_path / "hard.prev.json" if case == "import-kept" else hard)
    before = target.read_bytes()
    capsys.readouterr()
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert words in err, err
    assert target.read_bytes() == before
    assert not (tmp_path / "hard.prev.json").exists() or case == "import-kept"  # (there, the link itself)


def _tiny_views(rig, board, **kwargs):
    """``calibration_views`` stood in for: one dark view and the floor view per camera, no rendering."""
    import numpy as np

    return {cam.name: {"000": np.zeros((8, 8), np.uint8), "floor": np.zeros((8, 8), np.uint8)} for cam in rig.pair}


def _not_rendered(*args, **kwargs):
    raise AssertionError("rendered before the clash was found")


@pytest.mark.parametrize("flag", ["--rig", "--board"])
def test_synth_refuses_to_rewrite_an_input_in_other_words(tmp_path, capsys, monkeypatch, flag):
    # session 74: synth --rig OUT/truth_rig.json --out OUT --force replaced the file it read with its own layout
    import json

    from calibration.render import SYNTH_BOARD, synth_rig
    from ghnerf_runtime.rig_file import save_rig

    monkeypatch.setattr(cli, "calibration_views", _not_rendered)
    out = tmp_path / "synth"
    out.mkdir()
    save_rig(synth_rig(), out / "truth_rig.json")
    (out / "board.json").write_text(json.dumps(SYNTH_BOARD.to_dict()))  # one line: not synth's layout
    if flag == "--rig":  # the same rig, as a hand or an older version wrote it
        (out / "truth_rig.json").write_text(json.dumps(json.loads((out / "truth_rig.json").read_text())))
    given = out / ("truth_rig.json" if flag == "--rig" else "board.json")
    before = given.read_bytes()
    assert cli.main(["synth", "--out", str(out), "--force", flag, str(given)]) == 2
    err = capsys.readouterr().err
    assert f"{flag} {given} is {given}, which synth writes, and written back its text would change" in err, err
    assert given.read_bytes() == before


def test_synth_rerenders_in_place_leaving_an_input_it_would_write_alike(tmp_path, capsys, monkeypatch):
    # the rig and board synth wrote, given back to it: their text is what it writes, and the files are left alone
    from calibration.render import SYNTH_BOARD

    monkeypatch.setattr(cli, "calibration_views", _tiny_views)
    out = tmp_path / "synth"
    assert cli.main(["synth", "--out", str(out)]) == 0
    rig, board = out / "truth_rig.json", out / "board.json"
    before = {path: (path.read_bytes(), path.stat().st_ino) for path in (rig, board)}
    assert cli.main(["synth", "--out", str(out), "--force", "--rig", str(rig), "--board", str(board),
                     "--seed", "1"]) == 0
    assert {path: (path.read_bytes(), path.stat().st_ino) for path in (rig, board)} == before  # not even replaced
    assert cli.load_board(board) == SYNTH_BOARD


@pytest.mark.parametrize("given", [True, False])
def test_board_leaves_a_board_file_of_the_same_board_as_it_is(tmp_path, capsys, given):
    # session 74: board --board OUT/board.json --out OUT (what its refusal tells the user to run) wrote the file it
    # read back in its own layout: the measured size typed in on one line, a byte-order mark, all rewritten
    import json

    from calibration.board import BoardSpec, load_board

    spec = tmp_path / "board.json"
    measured = {**BoardSpec().to_dict(), "square_m": 0.0787, "marker_m": 0.059}
    spec.write_bytes(b"\xef\xbb\xbf" + json.dumps(measured).encode())  # as a Windows editor saves it
    before = (spec.read_bytes(), spec.stat().st_ino)
    argv = ["board", "--out", str(tmp_path), "--dpi", "72", "--board", str(spec if given else _copy(spec, tmp_path))]
    assert cli.main(argv) == 0
    assert (spec.read_bytes(), spec.stat().st_ino) == before
    assert (tmp_path / "board.png").is_file() and load_board(spec).square_m == 0.0787
    assert f"and left {spec} as it is (it defines this board)" in capsys.readouterr().out
    assert cli.main(["board", "--out", str(tmp_path), "--dpi", "72", "--force"]) == 0  # another board: replaced
    assert load_board(spec) == BoardSpec()


def _copy(path, tmp_path):
    copy = tmp_path / "elsewhere" / path.name
    copy.parent.mkdir()
    copy.write_bytes(path.read_bytes())
    return copy


def _views_of_count(rig, board, *, count, edge_count, seed, **kwargs):
    """``calibration_views`` stood in for: ``count`` views and the floor view per camera, each image its seed's and
    its name's (no rendering)."""
    import numpy as np

    names = [f"{k:03d}" for k in range(count)] + ["floor"]
    return {cam.name: {name: np.full((8, 8), (seed * 31 + k) % 256, np.uint8) for k, name in enumerate(names)}
            for cam in rig.pair}


def test_synth_force_takes_back_the_earlier_runs_views_and_nothing_else(tmp_path, capsys, monkeypatch):
    # before: synth --force with a smaller --count left the earlier run's 003 and 004 beside the new views, and
    # ghcal solve on the folder used views of two runs without a word
    monkeypatch.setattr(cli, "calibration_views", _views_of_count)
    out = tmp_path / "synth"
    assert cli.main(["synth", "--out", str(out), "--count", "5", "--seed", "1"]) == 0
    (out / "left" / "004.png").write_bytes(b"a real view copied in under synth's name")  # not synth's bytes now
    (out / "left" / "100.png").write_bytes(b"a real view")  # never synth's
    (out / "left" / "notes.txt").write_text("not an image")
    capsys.readouterr()
    assert cli.main(["synth", "--out", str(out), "--count", "2", "--seed", "2", "--force"]) == 0
    captured = capsys.readouterr()
    assert sorted(p.name for p in (out / "right").iterdir()) == ["000.png", "001.png", "floor.png"]
    assert sorted(p.name for p in (out / "left").iterdir()) == ["000.png", "001.png", "004.png", "100.png",
                                                                "floor.png", "notes.txt"]
    assert "removed 5 images of the earlier ghcal synth run" in captured.out, captured.out
    assert (f"warning: 2 images there are not this run's and were left ({out / 'left' / '004.png'}, "
            f"{out / 'left' / '100.png'}): ghcal solve on {out} reads them") in captured.err, captured.err
    assert cli.main(["synth", "--out", str(out), "--count", "2", "--seed", "2", "--force"]) == 0  # the same again
    assert "removed" not in capsys.readouterr().out


def test_synth_force_takes_back_the_folders_of_cameras_the_rig_no_longer_has(tmp_path, capsys, monkeypatch):
    import dataclasses

    from calibration.render import synth_rig

    monkeypatch.setattr(cli, "calibration_views", _views_of_count)
    out = tmp_path / "synth"
    assert cli.main(["synth", "--out", str(out), "--count", "2"]) == 0
    rig = synth_rig()
    renamed = dataclasses.replace(rig, cameras=tuple(dataclasses.replace(c, name=f"cam{k}")
                                                     for k, c in enumerate(rig.cameras)))
    monkeypatch.setattr(cli, "synth_rig", lambda: renamed)
    assert cli.main(["synth", "--out", str(out), "--count", "2", "--force"]) == 0
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["cam0", "cam1"]  # left/ and right/ emptied: gone


@pytest.mark.parametrize("text, words", [
    ("{not json", "cannot read the record of ghcal synth's images"),
    ('{"cameras": {"left": {"../../elsewhere.png": "00"}}}', "camera 'left': not a map of image file names"),
    ('{"cameras": {"../x": {}}}', "cannot be a folder name"),
    ('{"views": {}}', "not a record of ghcal synth's images"),
])
def test_synth_force_refuses_a_record_of_its_views_that_does_not_read_before_rendering(tmp_path, capsys, monkeypatch,
                                                                                        text, words):
    monkeypatch.setattr(cli, "calibration_views", _views_of_count)
    out = tmp_path / "synth"
    assert cli.main(["synth", "--out", str(out), "--count", "2"]) == 0
    (out / "synth_views.json").write_text(text)
    monkeypatch.setattr(cli, "calibration_views", _not_rendered)
    capsys.readouterr()
    assert cli.main(["synth", "--out", str(out), "--count", "1", "--force"]) == 2
    err = capsys.readouterr().err
    assert f"{out / 'synth_views.json'}" in err and words in err and "remove it" in err, err
