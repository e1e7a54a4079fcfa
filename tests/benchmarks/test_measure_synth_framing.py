"""``benchmarks/measure_synth_framing.py``: its pitched rigs are ``ghcal synth``'s cameras turned about their own
centres, its floor and framing columns say what docs/rig-file.md says of them, and its command line runs (the tiny
test export, random weights: the scores mean nothing)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.measure_synth_framing import floor_in_view_from_m, pitch_deg, pitched
from calibration.render import example_rig
from ghnerf_runtime.rig_file import person_in_view_share
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


@pytest.mark.parametrize("pitch", [10.0, 17.0, 24.0])
def test_a_pitched_rig_keeps_the_centres_lenses_and_volume_and_looks_that_far_down(pitch):
    synth = example_rig()
    rig = pitched(synth, pitch)
    for cam, old in zip(rig.pair, synth.pair):
        np.testing.assert_allclose(cam.center, old.center, atol=1e-12)
        np.testing.assert_array_equal(cam.K, old.K)
        assert pitch_deg(cam) == pytest.approx(pitch, abs=0.3)  # the convergence turns each axis a little aside
    assert rig.volume is synth.volume


def test_synth_s_rig_sees_the_floor_near_and_cuts_the_head_and_pitched_up_the_reverse():
    """As it is (24 degrees down) the floor comes into view 1.2 m ahead and a 1.8 m person at the volume's centre
    shows 84 % of their height; pitched 17 degrees, the whole height, the floor from 1.5 m (docs/rig-file.md)."""
    synth = example_rig()
    seventeen = pitched(synth, 17.0)
    assert [round(floor_in_view_from_m(cam), 1) for cam in synth.pair] == [1.2, 1.2]
    assert [round(person_in_view_share(cam, synth.volume), 2) for cam in synth.pair] == [0.84, 0.84]
    assert [round(floor_in_view_from_m(cam), 1) for cam in seventeen.pair] == [1.5, 1.5]
    assert [person_in_view_share(cam, seventeen.volume) for cam in seventeen.pair] == [1.0, 1.0]


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch, tmp_path):  # noqa: F811
    out = run_script("measure_synth_framing", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames",
                     "1", "--pitches", "17", "--per-sequence", "--save", str(tmp_path), capsys=capsys,
                     monkeypatch=monkeypatch)
    assert "| ghcal-example | 23.6 | 1.19 | 0.84 | 424 | " in out, out
    assert "| ghcal-example-pitch-17 | 16.9 | 1.51 | 1.00 | " in out, out
    assert "| ghcal-example | 0 | -0.69 | 4.35 | jumping_jacks | " in out, out
    assert (tmp_path / "synth_pitch_17.json").is_file()
