"""``ghnerf-sim-demo``'s bad arguments: exit status 2 and one line naming the value, no traceback, nothing written."""
from __future__ import annotations

import pytest

from drivers.sim.demo import main


@pytest.mark.parametrize(("extra", "words"), [
    (["--motion", "dance"], ["SceneConfig.motion: unknown motion 'dance'"]),
    (["--t", "nan"], ["t: scene time must be finite"]),
    (["--motion", "MISSING.bvh"], ["MISSING.bvh: cannot read"]),
])
def test_a_bad_scene_value_is_a_usage_error(tmp_path, capsys, extra, words):
    extra = [str(tmp_path / a) if a.endswith(".bvh") else a for a in extra]
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "pair.png"), *extra])
    assert e.value.code == 2  # was a SimConfigError / BvhError traceback (exit 1)
    err = capsys.readouterr().err
    assert all(w in err for w in words) and "Traceback" not in err, err
    assert not (tmp_path / "pair.png").exists()


@pytest.mark.parametrize("name, words", [("folder", "is a folder"), ("pair.txt", "cannot write an image of this kind")])
def test_an_output_it_cannot_write_is_refused_before_the_render(tmp_path, capsys, name, words):
    (tmp_path / "folder").mkdir()
    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / name)])
    assert e.value.code == 2  # was a cv2.error traceback after the render
    assert f"--out {tmp_path / name}: {words}" in capsys.readouterr().err
