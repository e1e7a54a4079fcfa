"""``ghcal``'s inputs checked before any work (session 73): ``solve --volume`` by the rig file's rules before an image
is read, a ``board.json`` that does not load named with why, and ``--out`` refused where it is one of the inputs."""
from __future__ import annotations

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
    monkeypatch.setattr(cli, "detect_folder", _no_detection)
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
