"""``ghcal import`` / ``ghcal export``: a rig through anipose and OpenCV files and back, levelled on import;
what the user must say (units, the format of an unknown suffix) is asked for by name."""
from __future__ import annotations

import gzip
import json
import logging
import math
import re
from pathlib import Path

import numpy as np
import pytest

from calibration import cli
from calibration.render import example_rig
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.rig_file import load_rig, save_rig
from tests.framing_note import but_the_framing_notes, edge_notes, framing_notes

#: example_rig's first camera: 1.4 m up at x = -0.3 m, looking at a point 2.5 m ahead and 0.3 m up (x = 0), no roll
PITCH_DEG = math.degrees(math.atan2(1.4 - 0.3, math.hypot(2.5, 0.3)))


@pytest.fixture()
def rig_file(tmp_path):
    path = tmp_path / "rig.json"
    save_rig(example_rig(), path)
    return path


def _same_cameras(a, b, atol=1e-7):
    for ca, cb in zip(a.cameras, b.cameras):
        assert ca.name == cb.name and (ca.width, ca.height) == (cb.width, cb.height)
        np.testing.assert_allclose(ca.K, cb.K, atol=1e-9)
        np.testing.assert_allclose(ca.dist, cb.dist, atol=1e-12)
        np.testing.assert_allclose(ca.R, cb.R, atol=atol)
        np.testing.assert_allclose(ca.t, cb.t, atol=atol)


@pytest.mark.parametrize("suffix, units", [(".toml", "0.001"), (".yml", None), (".xml", "0.01"), (".json", None)])
def test_export_then_import_levelled_gives_the_rig_back(rig_file, tmp_path, capsys, suffix, units):
    foreign = tmp_path / f"calibration{suffix}"
    unit_args = ["--units-to-metres", units] if units else []
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)] + unit_args) == 0
    assert (foreign.read_text().startswith("<?xml")) == (suffix == ".xml")  # the suffix's own format
    if suffix == ".json":
        json.loads(foreign.read_text())  # strict JSON: no // comment
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back), "--camera-height", "1.4",
                     "--pitch", repr(PITCH_DEG)] + unit_args) == 0
    out = capsys.readouterr().out
    assert "baseline 600.0 mm" in out and "levelled: left 1.4 m above the floor" in out
    _same_cameras(load_rig(rig_file), load_rig(back))


@pytest.mark.parametrize("name, args, starts", [("rig.yml.gz", [], b"%YAML"), ("rig.xml.gz", [], b"<?xml"),
                                                 ("rig.json.gz", [], b"{"),
                                                 ("calibration.gz", ["--format", "opencv"], b"%YAML")])
def test_an_export_to_a_gz_name_is_gzipped_and_imports_back(rig_file, tmp_path, capsys, name, args, starts):
    """cv2.FileStorage gzips a file named so, and reads it so: rig.yml.gz was refused (suffix '.gz'), and with
    --format opencv written as plain text under the name."""
    import cv2

    foreign = tmp_path / name
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), *args]) == 0
    assert f"wrote {foreign} (opencv, gzipped, cameras 'left', 'right')" in capsys.readouterr().out
    data = foreign.read_bytes()
    assert data[:2] == b"\x1f\x8b" and gzip.decompress(data).startswith(starts)
    fs = cv2.FileStorage(str(foreign), cv2.FILE_STORAGE_READ)  # OpenCV's own reading of it
    try:
        assert fs.getNode("cameras").at(1).getNode("name").string() == "right"
    finally:
        fs.release()
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back), *args]) == 0
    assert "levelled already" in capsys.readouterr().out
    _same_cameras(load_rig(rig_file), load_rig(back))


@pytest.mark.parametrize("name", ["rig.yml.gz9", "rig.xml.gz1", "rig.json.gz5"])
def test_a_gz_and_digit_name_is_imported_as_gzip_from_the_file_named(rig_file, tmp_path, capsys, name):
    """OpenCV's FileStorage reads rig.yml.gz9 as gzip (the 9 its compression level); import refused the suffix
    '.gz9', and with --format opencv had OpenCV open rig.yml.gz, another file, beside it."""
    foreign = tmp_path / name
    foreign.write_bytes(gzip.compress(_exported_text(rig_file, tmp_path, name.split(".")[1]), compresslevel=9))
    other = Rig(tuple(reversed(load_rig(rig_file).cameras)), load_rig(rig_file).volume)  # what OpenCV would open
    save_rig(other, tmp_path / "other.json")
    assert cli.main(["export", "--rig", str(tmp_path / "other.json"), "--out", str(foreign.with_suffix(".gz"))]) == 0
    capsys.readouterr()
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back)]) == 0, capsys.readouterr().err
    _same_cameras(load_rig(rig_file), load_rig(back))


def _exported_text(rig_file: Path, tmp_path: Path, suffix: str) -> bytes:
    plain = tmp_path / f"plain.{suffix}"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(plain)]) == 0
    return plain.read_bytes()


def test_a_gz_and_digit_file_of_plain_text_is_read_and_one_of_broken_gzip_is_named(rig_file, tmp_path, capsys):
    foreign = tmp_path / "rig.yml.gz3"
    foreign.write_bytes(_exported_text(rig_file, tmp_path, "yml"))  # zlib's reader takes plain text in a .gz file
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "back.json")]) == 0
    _same_cameras(load_rig(rig_file), load_rig(tmp_path / "back.json"))
    foreign.write_bytes(gzip.compress(_exported_text(rig_file, tmp_path, "yml"))[:-9])  # cut short
    capsys.readouterr()
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "cut.json")]) != 0
    err = capsys.readouterr().err
    assert str(foreign) in err and "cannot unpack it as gzip" in err, err
    assert not (tmp_path / "cut.json").exists()
    foreign.write_bytes(gzip.compress(b"\n"))
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "cut.json")]) != 0
    assert "the file is empty, gzipped" in capsys.readouterr().err


@pytest.mark.parametrize("args", [[], ["--format", "opencv"]])
def test_an_export_to_a_gz_and_digit_name_is_refused_naming_the_name_opencv_opens(rig_file, tmp_path, capsys, args):
    """cv2.FileStorage writes rig.yml.gz for the name rig.yml.gz9, and opens rig.yml.gz to read it: a file named
    rig.yml.gz9 no OpenCV program reads. It was refused as of an unknown suffix, and with --format opencv written
    as plain text."""
    out = tmp_path / "rig.yml.gz9"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(out), *args]) == 2
    err = but_the_framing_notes(capsys.readouterr().err)
    assert f"--out {out}: OpenCV reads the digit after .gz as a compression level, so it opens rig.yml.gz" in err
    assert "name it rig.yml.gz (written gzipped)" in err and err.count("\n") == 1, err
    assert not out.exists()


@pytest.mark.parametrize("name, meant", [("rig.yml.GZ", "rig.yml.gz"), ("rig.xml.Gz", "rig.xml.gz"),
                                         ("rig.json.gZ", "rig.json.gz"), ("rig.yml.GZ9", "rig.yml.gz")])
@pytest.mark.parametrize("args", [[], ["--format", "opencv"]])
def test_an_export_to_a_gz_name_in_another_case_is_refused_naming_the_lower_case_name(rig_file, tmp_path, capsys,
                                                                                      name, meant, args):
    """cv2.FileStorage gzips only a lower-case .gz name (cv2 5.0 writes plain text for rig.yml.GZ): export wrote
    gzip under rig.yml.GZ, which OpenCV then read as text and could not parse."""
    out = tmp_path / name
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(out), *args]) == 2
    err = but_the_framing_notes(capsys.readouterr().err)
    assert f"--out {out}: OpenCV gzips only a lower-case .gz name and reads {name} as plain text" in err
    assert f"name it {meant} (written gzipped)" in err and err.count("\n") == 1, err
    assert not out.exists()


def test_a_gz_name_in_another_case_is_imported_gzip_or_plain_text(rig_file, tmp_path, capsys):
    """Import reads the bytes of rig.yml.GZ: gzip (a rig.yml.gz renamed, or an old export) was refused as OpenCV's
    "Invalid character"; plain text (as OpenCV writes the name) was and is read."""
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(tmp_path / "rig.yml.gz")]) == 0
    foreign = tmp_path / "rig.yml.GZ"
    for data in ((tmp_path / "rig.yml.gz").read_bytes(), _exported_text(rig_file, tmp_path, "yml")):
        foreign.write_bytes(data)
        capsys.readouterr()
        assert cli.main(["import", str(foreign), "--out", str(tmp_path / "back.json")]) == 0, capsys.readouterr().err
        _same_cameras(load_rig(rig_file), load_rig(tmp_path / "back.json"))
        (tmp_path / "back.json").unlink()


def test_an_export_over_a_gz_file_keeps_it_under_a_name_import_tells_the_format_of(rig_file, tmp_path, capsys):
    # kept as rig.yml.prev.gz (<stem>.prev<suffix>), whose format import could not tell from its name ('.prev')
    foreign = tmp_path / "rig.yml.gz"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    first = foreign.read_bytes()
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    kept = tmp_path / "rig.prev.yml.gz"
    assert f"kept the previous {foreign} as {kept}" in capsys.readouterr().out
    assert kept.read_bytes() == first
    assert cli.main(["import", str(kept), "--out", str(tmp_path / "back.json")]) == 0
    _same_cameras(load_rig(rig_file), load_rig(tmp_path / "back.json"))


def test_an_image_size_is_for_the_camera_that_states_none_beside_one_that_states_its_own(rig_file, tmp_path, capsys):
    """A hand-written file: 'left' states 960x600, 'right' states no size and --image-size gives its 1024x600. It
    was refused for disagreeing with left's size, which it was not meant for."""
    foreign = tmp_path / "rig.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    text = foreign.read_text()
    right = text.index("name: right")
    foreign.write_text(text[:right] + re.sub(r"\n *image_(width|height): \d+", "", text[right:], count=2))
    assert "image_width: 960" in foreign.read_text()  # left's, kept
    capsys.readouterr()
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--image-size", "1024x600", "--out", str(back)]) == 0, \
        capsys.readouterr().err
    assert [(c.name, c.width, c.height) for c in load_rig(back).cameras] == [("left", 960, 600), ("right", 1024, 600)]
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "none.json")]) == 2  # right's size still needed
    assert "cameras[1].image_width': missing image size" in capsys.readouterr().err


@pytest.mark.parametrize("size", ["640x400", "960x400"])
def test_an_image_size_the_file_s_own_contradicts_is_refused_naming_both_and_the_file(rig_file, tmp_path, capsys,
                                                                                     size):
    # --image-size was dropped without a word where the file gives a size: a user who gave 640x400 got 960x600
    foreign = tmp_path / "rig.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    capsys.readouterr()
    out = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--image-size", size, "--out", str(out)]) == 2
    err = but_the_framing_notes(capsys.readouterr().err)
    assert err.count("\n") == 1 and str(foreign) in err, err
    assert f"image size 960x600, but the image_size argument (--image-size) is {size}" in err, err
    assert not out.exists()
    assert cli.main(["import", str(foreign), "--image-size", "960x600", "--out", str(out)]) == 0  # agreeing: fine
    assert "warning" not in but_the_framing_notes(capsys.readouterr().err) and load_rig(out).pair[0].size == (960, 600)


def _without_levelling(path):
    """The file as another tool writes it: without our ``levelled_*`` keys (OpenCV: their XML elements)."""
    path.write_text("".join(line for line in path.read_text().splitlines(keepends=True)
                            if "levelled_" not in line))


def test_import_without_levelling_keeps_the_tools_frame_and_says_so(rig_file, tmp_path, capsys):
    foreign = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    _without_levelling(foreign)
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back), "--units-to-metres", "1", "--rig-id", "lab"]) == 0
    assert "warning: not levelled" in capsys.readouterr().out
    rig = load_rig(back)
    assert rig.rig_id == "lab" and "levelled" not in rig.metadata
    _same_cameras(load_rig(rig_file), rig)  # anipose keeps the world frame it was given: ours
    # exported again, the rig in a tool's frame is not claimed to be levelled
    again = tmp_path / "again.yml"
    assert cli.main(["export", "--rig", str(back), "--out", str(again)]) == 0
    assert "levelled_" not in again.read_text()
    assert cli.main(["import", str(again), "--out", str(tmp_path / "again.json")]) == 0
    assert "warning: not levelled" in capsys.readouterr().out


@pytest.mark.parametrize("suffix, units", [(".toml", "0.001"), (".yml", None), (".yaml", "0.001"), (".xml", "0.01"),
                                           (".json", None)])
def test_our_export_of_a_levelled_rig_imports_levelled(rig_file, tmp_path, capsys, caplog, suffix, units):
    # The formats have no word for the rig frame: re-importing our own export of a levelled rig warned
    # "not levelled" (and the runtime did too, for anipose), asking for a height it already had.
    foreign = tmp_path / f"calibration{suffix}"
    unit_args = ["--units-to-metres", units] if units else []
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)] + unit_args) == 0
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back)]) == 0  # anipose: the unit the file records
    out = capsys.readouterr().out
    assert "warning" not in out and "levelled already" in out and "left 1.400 m above the floor" in out, out
    original, rig = load_rig(rig_file), load_rig(back)
    _same_cameras(original, rig)
    np.testing.assert_allclose(rig.volume.min_corner, original.volume.min_corner, atol=1e-12)
    np.testing.assert_allclose(rig.volume.max_corner, original.volume.max_corner, atol=1e-12)
    levelled = rig.metadata["levelled"]
    assert levelled["reference"] == "left" and abs(levelled["camera_height_m"] - 1.4) < 1e-9
    assert abs(levelled["pitch_deg"] - PITCH_DEG) < 1e-9 and abs(levelled["roll_deg"]) < 1e-9
    from ghnerf_runtime.estimator import _warn_if_not_levelled  # nor does the runtime warn about it

    with caplog.at_level(logging.WARNING):
        _warn_if_not_levelled(rig)
        _warn_if_not_levelled(Rig(rig.cameras, rig.volume, metadata={"source": rig.metadata["source"]}))
    assert len(caplog.records) == (suffix == ".toml")  # (the runtime warns about anipose files only)


@pytest.mark.parametrize("suffix, key, value, words", [
    (".toml", "levelled_camera_height_m", "1.2", ["is 1.4000 m above the floor", "1.2000 m in the levelling"]),
    (".yml", "levelled_pitch_deg", "10.0", ["tilted 13.599 degrees away from the pitch 10.00"]),
    (".toml", "levelled_reference", '"right"', ["names camera 'right' as the first, but the first is 'left'"]),
])
def test_a_levelling_the_poses_do_not_show_is_not_taken(rig_file, tmp_path, capsys, suffix, key, value, words):
    # another tool re-solved the poses in a frame of its own and kept our keys: its frame is not levelled
    foreign = tmp_path / f"calibration{suffix}"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    sep = " = " if suffix == ".toml" else ": "
    foreign.write_text("".join(f"{key}{sep}{value}\n" if line.startswith(key + sep) else line
                               for line in foreign.read_text().splitlines(keepends=True)))
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back), "--units-to-metres", "1"]) == 0
    out = capsys.readouterr().out
    assert "warning: not levelled" in out and "the file records a levelled frame, but" in out, out
    assert all(w in out for w in words), out
    assert "levelled" not in load_rig(back).metadata


@pytest.mark.parametrize("suffix, edit, words", [
    (".toml", lambda line: not line.startswith("levelled_roll_deg"), ["metadata.levelled_roll_deg", "missing"]),
    (".yml", lambda line: not line.startswith("levelled_roll_deg"), ["levelled_roll_deg", "missing"]),
])
def test_a_levelling_recorded_in_part_is_named(rig_file, tmp_path, capsys, suffix, edit, words):
    foreign = tmp_path / f"calibration{suffix}"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    foreign.write_text("".join(line for line in foreign.read_text().splitlines(keepends=True) if edit(line)))
    capsys.readouterr()
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "back.json"), "--units-to-metres", "1"]) == 2
    err = capsys.readouterr().err
    assert all(w in err for w in words), err


@pytest.mark.parametrize("args, words", [
    (["import", "{foreign}", "--out", "{out}"], ["do not record the unit", "--units-to-metres"]),
    (["export", "--rig", "{rig}", "--out", "{dir}/c.toml"], ["--units-to-metres"]),
    (["export", "--rig", "{rig}", "--out", "{dir}/c.cal"], ["suffix '.cal'", "--format"]),
    (["import", "{toml}", "--out", "{out}", "--units-to-metres", "1", "--pitch", "10"], ["--camera-height"]),
    (["import", "{toml}", "--out", "{dir}", "--units-to-metres", "1"], ["is a folder"]),
    (["import", "{toml}", "--out", "{toml}", "--units-to-metres", "1"], ["is the file being imported"]),
    (["import", "{toml}", "--out", "{out}", "--units-to-metres", "1", "--image-size", "640x480"], ["go with OpenCV"]),
    (["import", "{dir}/none.yml", "--out", "{out}"], ["none.yml", "no such file"]),
    # gzip is OpenCV's: an anipose export to c.toml.gz was refused as of an unknown suffix '.gz'
    (["export", "--rig", "{rig}", "--out", "{dir}/c.toml.gz", "--units-to-metres", "1"], ["plain TOML", ".toml name"]),
    (["import", "{toml}.gz", "--out", "{out}", "--units-to-metres", "1"], ["plain TOML", "calibration.toml.gz"]),
])
def test_what_the_user_must_give_is_named(rig_file, tmp_path, capsys, args, words):
    toml = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(toml), "--units-to-metres", "0.001"]) == 0
    capsys.readouterr()
    foreign = tmp_path / "foreign.toml"  # as anipose writes it: no unit in [metadata]
    foreign.write_text("".join(line for line in toml.read_text().splitlines(keepends=True)
                               if not line.startswith("units_to_metres")))
    argv = [a.format(toml=toml, foreign=foreign, out=tmp_path / "out.json", rig=rig_file, dir=tmp_path)
            for a in args]
    assert cli.main(argv) == 2
    # one line, bar the note of the rig file an export reads (example_rig's: 84 % of a standing person in view)
    err = but_the_framing_notes(capsys.readouterr().err)
    assert err.count("\n") == 1 and all(w in err for w in words), err
    assert not (tmp_path / "out.json").exists()


@pytest.mark.parametrize("value", ["0", "nan", '"mm"', "true"])
def test_a_unit_our_anipose_file_records_wrongly_is_named(rig_file, tmp_path, capsys, value):
    # 0 and nan were taken as the argument and refused naming neither file nor key; "mm" was read as no
    # unit recorded, and the user told that anipose files do not record one
    toml = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(toml), "--units-to-metres", "0.001"]) == 0
    toml.write_text(toml.read_text().replace("units_to_metres = 0.001", f"units_to_metres = {value}"))
    capsys.readouterr()
    assert cli.main(["import", str(toml), "--out", str(tmp_path / "back.json")]) == 2
    err = capsys.readouterr().err
    assert str(toml) in err and "'metadata.units_to_metres'" in err and "positive number" in err, err
    assert not (tmp_path / "back.json").exists()


@pytest.mark.parametrize("make, said", [("missing", "cannot read: No such file"),
                                        ("folder", "cannot read: Is a directory"), ("empty", "the file is empty"),
                                        ("cut", "invalid TOML: "), ("utf16", "UTF-16 text"),
                                        ("latin1", "not UTF-8 text (byte 19)"), ("deep", "nested too deeply")])
def test_an_anipose_file_that_cannot_be_read_is_named_before_any_unit_is_asked_for(tmp_path, capsys, make, said):
    # a mistyped name, a folder, an empty file or one cut off mid-edit was told "anipose files do not record the
    # unit ...: pass --units-to-metres", and named only once a unit was given; a file not UTF-8 (an editor's
    # Latin-1) or nested too deeply still was until session 75's second look
    toml = tmp_path / "calibration.toml"
    if make == "folder":
        toml.mkdir()
    elif make != "missing":
        text = {"empty": "\n", "cut": '[cam_0]\nname = "left\n', "utf16": '[cam_0]\nname = "left"\n',
                "latin1": '[cam_0]\nname = "caf\xe9"\n', "deep": "a = " + "[" * 5000 + "]" * 5000 + "\n"}[make]
        codec = {"utf16": "utf-16", "latin1": "latin-1"}.get(make, "utf-8")
        toml.write_bytes(text.encode(codec))
    assert cli.main(["import", str(toml), "--out", str(tmp_path / "back.json")]) == 2
    err = capsys.readouterr().err
    assert str(toml) in err and said in err and "--units-to-metres" not in err, err


def test_our_own_anipose_export_needs_no_units_and_a_rig_file_needs_no_import(rig_file, tmp_path, capsys):
    """The unit our anipose writer records is used when none is given; a rig file given to import is named."""
    toml = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(toml), "--units-to-metres", "0.001"]) == 0
    back = tmp_path / "back.json"
    assert cli.main(["import", str(toml), "--out", str(back)]) == 0
    _same_cameras(load_rig(rig_file), load_rig(back))
    capsys.readouterr()
    assert cli.main(["import", str(rig_file), "--out", str(tmp_path / "again.json")]) == 2
    assert "is a rig file already" in capsys.readouterr().err


def test_our_anipose_export_saved_with_a_byte_order_mark_imports_with_its_recorded_unit(rig_file, tmp_path, capsys):
    """Opened and saved in a Windows editor: the recorded unit was not found (an invalid TOML line 1), so the
    unit was asked for, and the reader refused the file anyway."""
    foreign = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "0.001"]) == 0
    foreign.write_bytes(b"\xef\xbb\xbf" + foreign.read_bytes())
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back)]) == 0
    assert "baseline 600.0 mm (file units x 0.001 m)" in capsys.readouterr().out
    _same_cameras(load_rig(rig_file), load_rig(back))


def test_a_typed_pitch_read_from_the_vertical_is_warned_about_on_import_as_in_solve(rig_file, tmp_path, capsys):
    """Review 51: ``solve --pitch 80`` warned (USUAL_PITCH_DEG) while ``import --pitch 80`` levelled the rig
    looking at the floor without a word; both now say the same, from one function."""
    from calibration.solve import typed_pitch_warning

    foreign = tmp_path / "calibration.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    capsys.readouterr()
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "steep.json"), "--camera-height", "1.4",
                     "--pitch", "80"]) == 0
    out = capsys.readouterr().out
    assert f"warning: {typed_pitch_warning(80.0, 'left')}" in out, out
    assert "--pitch 80 degrees for camera 'left' is unusual" in out and "not from the vertical" in out, out
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "usual.json"), "--camera-height", "1.4",
                     "--pitch", "24"]) == 0
    assert "warning" not in capsys.readouterr().out


def test_importing_over_a_rig_keeps_the_previous_one_each_time(rig_file, tmp_path, capsys):
    # import replaced the rig file without --force and without a copy: the previous calibration was lost
    foreign = tmp_path / "calibration.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    first = rig_file.read_bytes()
    prev = tmp_path / "rig.prev.json"
    assert cli.main(["import", str(foreign), "--out", str(rig_file), "--rig-id", "second"]) == 0
    assert f"kept the previous {rig_file} as {prev}" in capsys.readouterr().out
    assert prev.read_bytes() == first and load_rig(rig_file).rig_id == "second"
    second = rig_file.read_bytes()
    assert cli.main(["import", str(foreign), "--out", str(rig_file), "--rig-id", "third"]) == 0
    assert prev.read_bytes() == second and load_rig(rig_file).rig_id == "third"  # replaced each time
    capsys.readouterr()
    # a new file keeps nothing and says nothing of it
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "new.json")]) == 0
    assert "kept the previous" not in capsys.readouterr().out and not (tmp_path / "new.prev.json").exists()


def test_import_refuses_to_keep_the_previous_rig_over_the_file_it_imports(rig_file, tmp_path, capsys):
    source = tmp_path / "lab.prev.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(source)]) == 0
    text = source.read_text()
    out = tmp_path / "lab.yml"
    out.write_text("an earlier rig\n")
    assert cli.main(["import", str(source), "--out", str(out)]) == 2
    assert f"FILE {source} is where the previous {out} is kept" in capsys.readouterr().err
    assert source.read_text() == text and out.read_text() == "an earlier rig\n"


def test_exporting_over_a_file_keeps_the_previous_one(rig_file, tmp_path, capsys):
    # an export over the anipose file a rig was imported from replaced the other tool's calibration, without a copy
    theirs = tmp_path / "calibration.toml"
    theirs.write_text("# anipose's own calibration\n")
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(theirs), "--units-to-metres", "0.001"]) == 0
    prev = tmp_path / "calibration.prev.toml"
    assert f"kept the previous {theirs} as {prev}" in capsys.readouterr().out
    assert prev.read_text() == "# anipose's own calibration\n" and "[metadata]" in theirs.read_text()
    # nor is a rig file given as --rig kept over: where the copy would go, refused before anything is written
    (tmp_path / "lab.json").write_text("an export of another rig\n")
    kept = tmp_path / "lab.prev.json"
    save_rig(example_rig(), kept)
    before = kept.read_bytes()
    assert cli.main(["export", "--rig", str(kept), "--out", str(tmp_path / "lab.json")]) == 2
    assert f"--rig {kept} is where the previous {tmp_path / 'lab.json'} is kept" in capsys.readouterr().err
    assert kept.read_bytes() == before and (tmp_path / "lab.json").read_text() == "an export of another rig\n"


def test_a_failed_import_leaves_the_kept_copy_and_the_rig_file_as_they_were(rig_file, tmp_path, capsys):
    # a --volume the rig file's reader refuses (past MAX_DEPTH_M): save_rig refused it after the rig file was kept,
    # over the older kept copy
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(tmp_path / "lab.yml")]) == 0
    out, prev = tmp_path / "rig.json", tmp_path / "rig.prev.json"
    out.write_text("the rig in use\n")
    prev.write_text("the one before it\n")
    assert cli.main(["import", str(tmp_path / "lab.yml"), "--out", str(out), "--volume=-1,-1,20000,1,1,20001"]) == 2
    assert "MAX_DEPTH_M" in capsys.readouterr().err
    assert prev.read_text() == "the one before it\n" and out.read_text() == "the rig in use\n"


@pytest.mark.parametrize("suffix, units", [(".toml", ["--units-to-metres", "0.001"]), (".yml", [])])
def test_a_failed_export_leaves_the_kept_copy_and_the_file_as_they_were(tmp_path, capsys, suffix, units):
    # a rig the format cannot hold (a skew): the file it would replace was kept first, over the older kept copy
    # (the other tool's own calibration, kept by the export before), and the export then refused
    from ghnerf_runtime.geometry.camera import Camera

    first, second = example_rig().pair
    K = first.K.copy()
    K[0, 1] = 0.5
    skewed = Camera(first.name, first.width, first.height, K, first.dist, first.R, first.t)
    save_rig(Rig((skewed, second), example_rig().volume, rig_id="skewed"), tmp_path / "skewed.json")
    out, prev = tmp_path / f"calibration{suffix}", tmp_path / f"calibration.prev{suffix}"
    out.write_text("# our earlier export\n")
    prev.write_text("# the other tool's own calibration\n")
    assert cli.main(["export", "--rig", str(tmp_path / "skewed.json"), "--out", str(out), *units]) == 2
    assert "has a skew K[0][1]" in capsys.readouterr().err
    assert prev.read_text() == "# the other tool's own calibration\n" and out.read_text() == "# our earlier export\n"


@pytest.mark.parametrize("units", [[], ["--units-to-metres", "1"]])
def test_import_of_an_anipose_file_whose_metadata_is_not_a_table_names_file_and_key(rig_file, tmp_path, capsys,
                                                                                     units):
    """``metadata = 5`` was passed over as a file that records no unit (asked for --units-to-metres), and with
    one given, called 'a camera table' that was not one."""
    foreign = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    foreign.write_text("metadata = 5\n" + foreign.read_text().split("[metadata]")[0])
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "back.json"), *units]) == 2
    err = capsys.readouterr().err
    assert str(foreign) in err and "'metadata'" in err and "must be a table ([metadata]), got 5" in err, err


def test_import_of_an_anipose_camera_named_by_a_number_takes_the_number_as_its_name(rig_file, tmp_path):
    # aniposelib writes the names it was given: CameraGroup.from_names([1, 2]) dumps name = 1 (a TOML integer)
    foreign = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    foreign.write_text(foreign.read_text().replace('name = "left"', "name = 5"))
    assert cli.main(["import", str(foreign), "--out", str(tmp_path / "back.json"), "--units-to-metres", "1"]) == 0
    names = [camera["name"] for camera in json.loads((tmp_path / "back.json").read_text())["cameras"]]
    assert "5" in names and "left" not in names


def _write_stereo_calib_of(rig: Rig, folder, square_m: float):
    """``rig``'s pair as OpenCV's stereo_calib writes it (intrinsics.yml + extrinsics.yml, camera 1 -> camera 2)
    after a calibration without ``-s``: the translation in board squares of ``square_m``."""
    import cv2

    a, b = rig.pair
    R = b.R @ a.R.T
    T = (b.t - R @ a.t) / square_m
    fs = cv2.FileStorage(str(folder / "intrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for key, value in (("M1", a.K), ("D1", a.dist.reshape(1, -1)), ("M2", b.K), ("D2", b.dist.reshape(1, -1))):
        fs.write(key, value)
    fs.release()
    fs = cv2.FileStorage(str(folder / "extrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("R", R)
    fs.write("T", T.reshape(3, 1))
    fs.release()
    return folder / "intrinsics.yml", folder / "extrinsics.yml"


@pytest.mark.parametrize("level", [[], ["--camera-height", "1.4", "--pitch", repr(PITCH_DEG)]])
def test_a_stereo_calib_pair_in_board_squares_read_as_metres_is_warned_about(tmp_path, capsys, level):
    """stereo_calib without ``-s`` writes T in squares: the 0.6 m pair on 80 mm squares, read with units 1, came
    out 7.5 m apart (under the 10 m bound) and was taken without a word; it now warns, naming the baseline, the
    volume and the unit. Read in the square's side it imports as before, no warning."""
    intrinsics, extrinsics = _write_stereo_calib_of(example_rig(), tmp_path, square_m=0.08)
    args = ["import", str(intrinsics), "--extrinsics", str(extrinsics), "--image-size", "960x600", *level]
    assert cli.main([*args, "--units-to-metres", "1", "--out", str(tmp_path / "squares.json")]) == 0
    out = capsys.readouterr().out
    assert "baseline 7500.0 mm" in out
    warning = next(line for line in out.splitlines() if line.startswith("warning: cameras 'left' and 'right'"))
    assert "% of the working volume [" in warning and "7.50 m apart, farther than the volume reaches" in warning
    assert "--units-to-metres the square's side in metres" in warning
    assert load_rig(tmp_path / "squares.json").baseline == pytest.approx(7.5)  # written all the same: a warning
    assert cli.main([*args, "--units-to-metres", "0.08", "--out", str(tmp_path / "metres.json")]) == 0
    out = capsys.readouterr().out
    assert "baseline 600.0 mm" in out and "% of the working volume" not in out


@pytest.mark.parametrize("make, said", [("missing", "no such file"), ("folder", "not a regular file"),
                                        ("empty", "the file is empty")])
def test_a_stereo_calib_extrinsics_file_that_cannot_be_read_is_named_before_any_unit_is_asked_for(tmp_path, capsys,
                                                                                                  make, said):
    # a mistyped --extrinsics was told "pass units_to_metres", and named only once a unit was given
    intrinsics, _ = _write_stereo_calib_of(example_rig(), tmp_path, square_m=0.08)
    extrinsics = tmp_path / "extrinsic.yml"
    if make == "folder":
        extrinsics.mkdir()
    elif make == "empty":
        extrinsics.write_text("\n")
    assert cli.main(["import", str(intrinsics), "--extrinsics", str(extrinsics), "--image-size", "960x600",
                     "--out", str(tmp_path / "rig.json")]) == 2
    err = capsys.readouterr().err
    assert str(extrinsics) in err and said in err and "units_to_metres" not in err, err


def test_an_intrinsics_file_with_another_pose_than_its_extrinsics_file_is_refused_naming_both(tmp_path, capsys):
    # the extrinsics file's pose was taken without a word
    from tests.calibration.test_formats import _add_pose_to_intrinsics

    intrinsics, extrinsics = _write_stereo_calib_of(example_rig(), tmp_path, square_m=0.08)
    _add_pose_to_intrinsics(tmp_path, np.eye(3), [-7.0, 0.0, 0.0])
    assert cli.main(["import", str(intrinsics), "--extrinsics", str(extrinsics), "--image-size", "960x600",
                     "--units-to-metres", "0.08", "--out", str(tmp_path / "rig.json")]) == 2
    err = capsys.readouterr().err
    assert str(intrinsics) in err and str(extrinsics) in err and "--extrinsics" in err, err
    assert not (tmp_path / "rig.json").exists()


def test_a_volume_the_pair_does_not_face_is_warned_about_as_such(tmp_path, capsys):
    """A pair in the right unit given a working volume off to its side: the same warning, the cause the volume."""
    intrinsics, extrinsics = _write_stereo_calib_of(example_rig(), tmp_path, square_m=0.08)
    assert cli.main(["import", str(intrinsics), "--extrinsics", str(extrinsics), "--image-size", "960x600",
                     "--units-to-metres", "0.08", "--volume", "6,-1,1,8,1,3", "--out", str(tmp_path / "rig.json")]) == 0
    warning = next(line for line in capsys.readouterr().out.splitlines() if "% of the working volume" in line)
    assert "both see 0.0 % of the working volume [6.0, -1.0, 1.0] to [8.0, 1.0, 3.0] m" in warning
    assert "0.60 m apart" in warning and "not where the pair looks" in warning and "--volume" in warning
    assert "--units-to-metres" not in warning


def test_the_real_rigs_pass_the_common_view_check():
    """The rigs of the repo and the simulator see far more than MIN_COMMON_SHARE of their working volume in both
    views, as they are and imported from stereo_calib in the right unit (the tool's frame, and levelled)."""
    from calibration.common_view import MIN_COMMON_SHARE, common_view_share, common_view_warning
    from calibration.formats import default_working_volume
    from calibration.level import level_rig
    from drivers.sim.placement import RigPlacement
    from tests.calibration.test_level import as_stereo_calib

    repo_rig = load_rig(Path(__file__).parents[2] / "docs" / "examples" / "rig.json")
    rigs = {"docs/examples/rig.json": repo_rig, "ghcal example": example_rig(), "sim": RigPlacement().build()}
    for name, rig in list(rigs.items()):
        tools = as_stereo_calib(rig)
        rigs[f"{name} imported"] = Rig(tools.cameras, default_working_volume(tools.cameras))
        height = -rig.cameras[0].center[1]  # each is levelled already: its own height, its pitch from its axis
        pitch = math.degrees(math.asin(rig.cameras[0].R[2, 1]))
        rigs[f"{name} imported, levelled"] = level_rig(rigs[f"{name} imported"], camera_height_m=height,
                                                      pitch_deg=pitch)
    shares = {name: common_view_share(rig) for name, rig in rigs.items()}
    assert all(common_view_warning(rig) is None for rig in rigs.values())
    assert min(shares.values()) >= 2 * MIN_COMMON_SHARE  # a margin: half the volume, not a quarter


def test_an_anipose_file_nested_thousands_deep_is_refused_naming_it_not_a_traceback(tmp_path, capsys):
    """tomllib parses arrays recursively: ``a = [[[...]]]`` 2000 deep was a bare RecursionError from ``ghcal
    import`` (its units check, then the reader), as JSON nested so deep was from the JSON readers (session 67's
    MAX_JSON_DEPTH)."""
    from calibration.formats import read_anipose_toml
    from ghnerf_runtime.errors import RigFileError

    deep = tmp_path / "calibration.toml"
    deep.write_text("a = " + "[" * 2000 + "1" + "]" * 2000 + "\n")
    with pytest.raises(RigFileError, match=r"calibration\.toml.*invalid TOML: nested too deeply"):
        read_anipose_toml(deep, units_to_metres=1.0)
    assert cli.main(["import", str(deep), "--units-to-metres", "1", "--out", str(tmp_path / "rig.json")]) == 2
    err = capsys.readouterr().err
    assert "invalid TOML: nested too deeply" in err and "Traceback" not in err, err


def test_export_and_import_say_the_rig_s_note_once_on_stderr_naming_the_file(rig_file, tmp_path, capsys):
    """``example_rig`` (``ghcal synth``'s rig until session 68) shows a standing person 84 % of their height: loading
    notes it at INFO (session 67), and ghcal, which sets no logging up, showed WARNING and over only: neither the
    export of it (which reads it) nor the import (which writes it) said it. Since session 68 each says it once on
    stderr, a bare line beside the warnings, naming the rig file read or written; since session 69 the note of its
    volume's near edge (0.5 m ahead) after it, once too."""
    foreign = tmp_path / "calibration.yml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign)]) == 0
    _assert_noted_once(capsys.readouterr().err, rig_file)
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back)]) == 0
    captured = capsys.readouterr()
    _assert_noted_once(captured.err, back)
    assert framing_notes(captured.out) == [] and edge_notes(captured.out) == []


def _assert_noted_once(err: str, path: Path) -> None:
    """``err`` holds example_rig's centre note (84 %) then its near edge's, each once, naming ``path``."""
    notes = framing_notes(err) + edge_notes(err)
    assert [note.split("(")[0] for note in notes] == [
        f"{path}: a 1.8 m person standing at the working volume's centre ",
        f"{path}: a 1.8 m person standing at the working volume's near edge "], err
    assert "84%" in notes[0] and [line for line in err.splitlines() if line in notes] == notes, err


#: the words of the rig file's warning for a camera's height (rig_file.camera_height_warning) of example_rig's first
#: camera moved to the origin, as a calibration tool's own frame puts it
HEIGHT_WORDS = "camera 'left' stands 0.00 m above the floor"
#: the words of the rig file's warning for a person who does not fit the view, in that frame (73 % in view)
FRAMING_WORDS = "does not fit the view: camera 'left' shows"


def _in_the_first_camera_s_frame(rig: Rig) -> Rig:
    """``rig`` in its first camera's frame, as OpenCV's stereo_calib writes a pair: that camera at the origin."""
    first = rig.pair[0]
    cams = tuple(c.with_pose(c.R @ first.R.T, c.t - c.R @ first.R.T @ first.t) for c in rig.cameras)
    return Rig(cams, rig.volume, rig.rig_id)


def test_import_of_a_tool_s_frame_says_not_levelled_and_the_written_rig_s_warnings_once(tmp_path, capsys):
    """A rig file of ours in a tool's frame (its first camera at the origin), exported and imported: the export
    records no levelling for it (until session 68 float noise in that camera's height recorded one, and ``import``
    said "levelled already ... 0.000 m above the floor"), so ``import`` warns "not levelled", and says the rig's
    other warnings of the rig it writes, once, bare on stderr as ghcal shows a loaded rig's."""
    ours = tmp_path / "tool.json"
    save_rig(_in_the_first_camera_s_frame(example_rig()), ours)
    foreign = tmp_path / "tool.yml"
    assert cli.main(["export", "--rig", str(ours), "--out", str(foreign)]) == 0
    assert "levelled_" not in foreign.read_text()
    capsys.readouterr()
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back)]) == 0
    out, err = capsys.readouterr()
    assert "levelled already" not in out and "warning: not levelled" in out
    # the rig file's warning for the first camera's height (0.00 m, "Level the rig (... ghcal import
    # --camera-height)") says what "not levelled" says: left out
    assert HEIGHT_WORDS not in err + out and "m above the floor (y = 0, y down)" not in err, err
    assert err.count(FRAMING_WORDS) == 1 and f"\n{back}: a 1.8 m person standing" in "\n" + err, err
    assert FRAMING_WORDS not in out


