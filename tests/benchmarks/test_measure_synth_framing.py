"""``benchmarks/measure_synth_framing.py``: its pitched rigs are ``ghcal synth``'s cameras turned about their own
centres (or moved to a given height), its row of the rig as it was until session 68 is that rig, its floor and
framing columns say what docs/rig-file.md says of them, and its command line runs (the tiny
test export, random weights: the scores mean nothing)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.measure_baseline import framing_cells
from benchmarks.measure_synth_framing import cold_crop_px, floor_in_view_from_m, pitch_deg, pitched
from calibration.render import example_rig, synth_rig
from ghnerf_runtime.rig_file import person_in_view_share, standing_person
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


@pytest.mark.parametrize("pitch", [10.0, 17.0, 24.0])
def test_a_pitched_rig_keeps_the_centres_lenses_and_volume_and_looks_that_far_down(pitch):
    synth = synth_rig()
    rig = pitched(synth, pitch)
    for cam, old in zip(rig.pair, synth.pair):
        np.testing.assert_allclose(cam.center, old.center, atol=1e-12)
        np.testing.assert_array_equal(cam.K, old.K)
        assert pitch_deg(cam) == pytest.approx(pitch, abs=0.3)  # the convergence turns each axis a little aside
    assert rig.volume is synth.volume


def test_synth_s_old_rig_saw_the_floor_near_and_cut_the_head_and_its_new_one_frames_the_person():
    """Until session 68 (1.4 m up, 24 degrees down) the floor came into view 1.2 m ahead and a 1.8 m person at the
    volume's centre showed 84 % of their height; pitched 17 degrees, the whole height, the floor from 1.5 m. Since, 1.8
    m up and 23 degrees down: the whole height, the floor from 1.6 m (docs/rig-file.md)."""
    old, synth = example_rig(), synth_rig()
    seventeen = pitched(old, 17.0)
    assert [round(floor_in_view_from_m(cam), 1) for cam in old.pair] == [1.2, 1.2]
    assert [round(person_in_view_share(cam, old.volume), 2) for cam in old.pair] == [0.84, 0.84]
    assert [round(floor_in_view_from_m(cam), 1) for cam in seventeen.pair] == [1.5, 1.5]
    assert [person_in_view_share(cam, seventeen.volume) for cam in seventeen.pair] == [1.0, 1.0]
    assert [round(floor_in_view_from_m(cam), 1) for cam in synth.pair] == [1.5, 1.6]
    assert [person_in_view_share(cam, synth.volume) for cam in synth.pair] == [1.0, 1.0]


def test_the_old_rig_raised_to_1_8_m_and_pitched_23_degrees_is_the_new_one():
    old, synth = example_rig(), synth_rig()
    assert [round(-cam.center[1], 6) for cam in old.pair] == [1.4, 1.4]
    assert [round(pitch_deg(cam), 1) for cam in old.pair] == [23.6, 23.6]
    assert float(old.volume.min_corner[2]) == 0.5 and float(synth.volume.min_corner[2]) == 2.0
    raised = pitched(old, 23.0, height=1.8)
    for cam, ref in zip(raised.pair, synth.pair):
        np.testing.assert_allclose(cam.center, ref.center, atol=1e-12)
        np.testing.assert_allclose(cam.R, ref.R, atol=1e-12)  # the new default: the old pair raised, 23 degrees down


def test_cold_crop_px_is_framing_cells_model_px_for_the_person_at_the_volume_s_centre_and_less_farther_back():
    """The per-sequence column ``cold_crop_px``: the standing person at the volume's centre is as tall as
    ``framing_cells``' model pixels say (38 through ``ghcal synth``'s rig); moved 1 m back, shorter."""
    synth = synth_rig()
    person = standing_person(synth.volume)
    assert round(cold_crop_px(synth, person, 128)) == int(framing_cells(synth, 128).split(" | ")[2]) == 38
    assert cold_crop_px(synth, person + [0.0, 0.0, 1.0], 128) < 0.85 * cold_crop_px(synth, person, 128)


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch, tmp_path):  # noqa: F811
    out = run_script("measure_synth_framing", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames",
                     "1", "--pitches", "17", "--per-sequence", "--floor-seeds", "1", "--save", str(tmp_path),
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "| ghcal-synth | 1.80 | 22.9 | 1.58 | 2.0-5.0 | 1.00 | 311 | " in out, out
    assert "| ghcal-example | 1.40 | 23.6 | 1.19 | 0.5-5.0 | 0.84 | 424 | " in out, out
    assert "| ghcal-synth-pitch-17 | 1.80 | 16.9 | 1.94 | 2.0-5.0 | 1.00 | " in out, out
    assert "| ghcal-synth | 0 | -0.69 | 4.50 | jumping_jacks | 1.00 | 1.0 | 1.0 | " in out, out
    row = next(line for line in out.splitlines() if line.startswith("| ghcal-synth | 0 | "))
    one_view, tall = row.split(" | ")[-2:]
    # 4.50 m ahead, arms up: 37 of 128 model px, 18 of the tiny export's 64
    assert one_view in ("0 of 1", "1 of 1") and tall == "18 |", row
    assert "| ghcal-example | 0 | -0.69 | 4.35 | jumping_jacks | 0.64 | 0.0 | 1.0 | " in out, out
    assert "| ghcal-synth | 1.58 | " in out and "| ghcal-example | 1.19 | " in out, out  # the floor-view rows
    assert (tmp_path / "synth_pitch_17.json").is_file()
