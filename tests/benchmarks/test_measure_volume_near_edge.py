"""``benchmarks/measure_volume_near_edge.py``: its near edges are where docs/rig-file.md says a standing person fits
``ghcal synth``'s and the example rig's lenses, the cold crop it reports does not move with that near edge (the 3 m
wide volume fills the image's width either way: why the lens-aware default did not pay, session 67), and its command
line runs (the tiny test export, random weights: the scores mean nothing)."""
from __future__ import annotations

import pytest

from benchmarks.measure_baseline import bench_scene_in
from benchmarks.measure_volume_near_edge import lens_fit_m, rig_named, variants, whole_fit_m, with_depth
from calibration.render import example_rig, synth_rig
from ghnerf_runtime.preprocess import roi_from_volume
from ghnerf_runtime.rig_file import load_rig
from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

EXAMPLE_RIG = "docs/examples/rig.json"


def test_the_lens_fit_is_the_person_over_the_vertical_view():
    """1.8 m over 600 px at fy 625.5 (synth's 75-degree 960x600), over 800 px at fy 798.6 (the example rig's)."""
    assert lens_fit_m(example_rig()) == pytest.approx(1.877, abs=1e-3)
    assert lens_fit_m(load_rig(EXAMPLE_RIG)) == pytest.approx(1.797, abs=1e-3)


def test_synth_s_old_rig_never_shows_the_whole_person_within_its_volume_and_the_example_rig_from_1_9_m():
    """Aimed 24 degrees down from 1.4 m, synth's rig until session 68 cut the head of a person anywhere within 5 m: the
    aim-aware near edge does not exist there, so the rows fall back on the lens's. Its rig since (1.8 m up, 23
    degrees down) shows the person whole from 1.55 m."""
    assert whole_fit_m(example_rig()) is None
    assert whole_fit_m(synth_rig()) == pytest.approx(1.55, abs=1e-6)
    assert whole_fit_m(load_rig(EXAMPLE_RIG)) == pytest.approx(1.9, abs=1e-6)
    labels = [rig.rig_id.split(" ", 1)[1] for rig in variants(example_rig(), 4.0)]
    assert labels == ["as written", "near edge at the lens's fit", "lens near edge, far edge 4 m"]


def test_synth_67_names_the_session_67_rig():
    assert rig_named("synth-67").rig_id == example_rig().rig_id
    assert rig_named("synth").rig_id == synth_rig().rig_id


@pytest.mark.parametrize("rig", [example_rig(), load_rig(EXAMPLE_RIG)], ids=["synth-67", "example"])
def test_the_cold_crop_is_the_same_from_the_written_near_edge_to_the_lens_fit(rig):
    """The measured reason the lens-aware default was not shipped: the crop is bound by the volume's 3 m width."""
    near = with_depth(rig.volume, lens_fit_m(rig), float(rig.volume.max_corner[2]))
    for cam in rig.pair:
        assert roi_from_volume(cam, near).size == roi_from_volume(cam, rig.volume).size


def test_the_people_drawn_in_another_volume_keep_the_bench_sequence_s_seed_and_first_instant():
    """The rows film the same people wherever the rig's volume is told: ``measure_baseline.bench_scene_in`` draws the
    sequence's person in the volume given, its motion and first instant the bench sequence's as in the rig's own."""
    rig = load_rig(EXAMPLE_RIG)
    people = with_depth(rig.volume, 2.5, 3.0)
    own, own_t0 = bench_scene_in(rig, 1)
    drawn, t0 = bench_scene_in(rig, 1, people)
    assert t0 == own_t0 and drawn.config.motion == own.config.motion
    hip = drawn.joints_3d(t0)[8]
    assert 2.5 - 0.3 <= hip[2] <= 3.0 + 0.3, hip  # the person's place is drawn in ``people``, not the rig's 1-4.5 m


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    """The tiny export's input is not 128 pixels: the model-pixel cell is not pinned here."""
    out = run_script("measure_volume_near_edge", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames",
                     "1", "--rigs", f"synth-67,{EXAMPLE_RIG}", capsys=capsys, monkeypatch=monkeypatch)
    assert "| synth-67: as written | 0.50-5.00 | 1058 | " in out, out
    assert "| synth-67: near edge at the lens's fit | 1.88-5.00 | 1058 | " in out, out
    assert f"| {EXAMPLE_RIG}: near edge where the person is whole | 1.90-4.50 | " in out, out
