"""``ghcal import`` / ``ghcal export``: a rig through anipose and OpenCV files and back, levelled on import;
what the user must say (units, the format of an unknown suffix) is asked for by name."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from calibration import cli
from calibration.render import example_rig
from ghnerf_runtime.rig_file import load_rig, save_rig

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


def test_import_without_levelling_keeps_the_tools_frame_and_says_so(rig_file, tmp_path, capsys):
    foreign = tmp_path / "calibration.toml"
    assert cli.main(["export", "--rig", str(rig_file), "--out", str(foreign), "--units-to-metres", "1"]) == 0
    back = tmp_path / "back.json"
    assert cli.main(["import", str(foreign), "--out", str(back), "--units-to-metres", "1", "--rig-id", "lab"]) == 0
    assert "warning: not levelled" in capsys.readouterr().out
    rig = load_rig(back)
    assert rig.rig_id == "lab"
    _same_cameras(load_rig(rig_file), rig)  # anipose keeps the world frame it was given: ours


@pytest.mark.parametrize("args, words", [
    (["import", "{foreign}", "--out", "{out}"], ["do not record the unit", "--units-to-metres"]),
    (["export", "--rig", "{rig}", "--out", "{dir}/c.toml"], ["--units-to-metres"]),
    (["export", "--rig", "{rig}", "--out", "{dir}/c.cal"], ["suffix '.cal'", "--format"]),
    (["import", "{toml}", "--out", "{out}", "--units-to-metres", "1", "--pitch", "10"], ["--camera-height"]),
    (["import", "{toml}", "--out", "{dir}", "--units-to-metres", "1"], ["is a folder"]),
    (["import", "{toml}", "--out", "{toml}", "--units-to-metres", "1"], ["is the file being imported"]),
    (["import", "{toml}", "--out", "{out}", "--units-to-metres", "1", "--image-size", "640"], ["go with OpenCV"]),
    (["import", "{dir}/none.yml", "--out", "{out}"], ["none.yml", "no such file"]),
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
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and all(w in err for w in words), err
    assert not (tmp_path / "out.json").exists()


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
