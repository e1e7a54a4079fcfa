"""``benchmarks/measure_baseline.py``: its rigs are what the table says (the baseline asked for, the frame lifted with
its geometry kept), and its command line runs (the tiny test export, random weights: the figures mean nothing)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.measure_baseline import (baseline_for_angle, find_outcomes, framing_cells, in_cold_crop_px, lifted,
                                         rig_with_baseline, standing_person_px, tile_find_rows, tile_find_summary)
from ghnerf_runtime.preprocess import roi_from_volume
from ghnerf_runtime.rig_file import STANDING_PERSON_M, load_rig, pair_angle_deg
from tests.benchmarks.test_bench_smoke import run_script, run_script_failing, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


@pytest.mark.parametrize("baseline_m", [0.02, 0.6])
def test_the_rig_has_the_baseline_asked_for_below_the_simulator_s_own_floor(baseline_m):
    rig = rig_with_baseline(baseline_m, 3.0)
    assert rig.baseline == pytest.approx(baseline_m, abs=1e-12)
    assert [-c.center[1] for c in rig.pair] == pytest.approx([1.3, 1.3])


@pytest.mark.parametrize("angle_deg, distance_m, hfov_deg", [(0.5, 1.5, 50.0), (1.0, 3.0, 80.0), (4.0, 5.0, 110.0)])
def test_the_baseline_for_an_angle_gives_that_angle_at_the_volume_s_centre(angle_deg, distance_m, hfov_deg):
    """The lens and distance rows of the table (session 66) compare pairs at the same angle: the baseline is chosen
    for it, whatever the lens and distance."""
    rig = rig_with_baseline(baseline_for_angle(angle_deg, distance_m, hfov_deg), distance_m, hfov_deg)
    assert pair_angle_deg(rig, rig.volume.center) == pytest.approx(angle_deg, rel=1e-9)
    assert rig.pair[0].K[0, 0] == pytest.approx(320.0 / np.tan(np.radians(hfov_deg) / 2), rel=1e-3)


def test_a_lifted_rig_keeps_every_pixel_of_a_point_lifted_with_it():
    rig = rig_with_baseline(1.2, 3.0)
    up = lifted(rig, 50.0)
    point = np.array([[0.1, -1.0, 3.0]])
    for a, b in zip(rig.pair, up.pair):
        assert b.project(point - [0.0, 50.0, 0.0])[0] == pytest.approx(a.project(point)[0], abs=1e-6)
    assert up.volume.max_corner[1] == pytest.approx(rig.volume.max_corner[1] - 50.0)


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_baseline", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1",
                     "--baselines", "0.02,0.6", "--lifts", "0,50", capsys=capsys, monkeypatch=monkeypatch)
    assert "| 3 | 80 | 381 | 0.02 | 0.38 | 1.180 |" in out and "| 3 | 80 | 381 | 0.6 | 11.37 | 0.039 |" in out, out
    assert "| 50 | 51.30 |" in out, out


def test_the_command_line_takes_angles_distances_and_lenses(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                            monkeypatch):
    out = run_script("measure_baseline", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1",
                     "--distances", "3,5", "--hfovs", "110", "--angles", "1", "--lifts", "", capsys=capsys,
                     monkeypatch=monkeypatch)
    assert "| 3 | 110 | 224 | 0.0526 | 1.00 | 0.764 |" in out, out
    assert "| 5 | 110 | 224 | 0.0874 | 1.00 | 1.277 |" in out, out
    assert "frame moved up" not in out, out


def test_the_command_line_prints_the_framing_and_takes_rig_files(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                                 monkeypatch):
    """The framing columns (docs/rig-file.md, "A person who does not fit the view"): through a 50-degree lens at
    1.5 m a standing person shows 62 % of their height, 783 pixels tall; ``--rigs`` adds the example rig's row."""
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "rig.json"
    out = run_script("measure_baseline", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1",
                     "--distances", "1.5", "--hfovs", "50", "--angles", "4", "--rigs", str(example), "--lifts", "",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "| 1.5 | 50 | 686 | 0.107 | 4.00 | 0.031 | 0.62 | 783 | " in out, out
    assert f"| {example} | 1.00 | 517 | " in out, out


def test_the_standing_person_s_image_height_is_the_pinhole_s_and_the_framing_cell_s():
    """``standing_person_px`` (rig_file's, shared by the cold tiles and the framing benchmarks): 1.8 m at the
    volume's centre over its depth, times the focal length, for a camera looking straight at it; the framing cell is
    the pair's smaller."""
    rig = rig_with_baseline(0.02, 3.0)
    cam = rig.pair[0]
    depth = float((cam.R @ rig.volume.center + cam.t)[2])
    assert standing_person_px(cam, rig.volume) == pytest.approx(STANDING_PERSON_M * cam.K[1, 1] / depth, rel=0.02)
    example = load_rig("docs/examples/rig.json", warn=False)
    shorter_shown = min(standing_person_px(c, example.volume) for c in example.pair)
    assert framing_cells(example, 128).split(" | ")[1] == f"{shorter_shown:.0f}"


def test_the_tile_find_rows_say_where_the_person_stood_and_the_error_then_and_after():
    """``--tile-finds`` (session 70): per pair whose cold tile search found someone, kept or refused, the person's
    true joints' mean and nearest depth, that pair's lower foot, MPJPE and joints found, and the MPJPE from that pair
    on."""
    truth = np.zeros((3, 25, 3))
    truth[..., 2] = 2.0
    truth[:, 0, 2] = 1.2
    pred = truth + np.array([0.0, 0.0, 0.1])
    pred[2] += [0.0, 0.0, 0.2]
    found = np.ones((3, 25), bool)
    found[0] = False
    rows = tile_find_rows("rig.json", 4, (pred, found, truth), [(1, True, 0.73), (0, False, None)])
    assert rows == ["| rig.json | 4 | 1 | kept | 0.00, 0.00, 1.97 | 1.20 | 0.73 | 100 | 1.000 | 200 |",
                    "| rig.json | 4 | 0 | refused | 0.00, 0.00, 1.97 | 1.20 | - | - | 0.000 | 200 |"]


def test_a_find_s_outcome_is_its_pair_s_error_and_none_where_no_joint_was_found():
    """``--tile-finds``' closing lines (session 72) judge a find by its own pair's MPJPE, the rows' cell."""
    truth = np.zeros((2, 25, 3))
    pred = truth + np.array([0.0, 0.3, 0.0])
    found = np.ones((2, 25), bool)
    found[1] = False
    outcomes = find_outcomes((pred, found, truth), [(0, True, 0.2), (1, False, 0.6)])
    assert outcomes == [(True, 0.2, pytest.approx(300.0)), (False, 0.6, None)]


def test_the_tile_find_summary_counts_the_feet_of_good_and_bad_finds_and_what_each_bound_refuses():
    """Session 72: the judged feet of the kept finds, good (pair MPJPE under the bound) and bad, those with no foot
    figure (which no bound judges) and no joint found apart, the refused ones apart (their error unseen), and per foot
    bound the kept good and bad finds it would refuse."""
    outcomes = [(True, -0.16, 40.0), (True, 0.35, 149.0), (True, 0.45, 150.0), (True, 0.69, 394.0),
                (False, 0.8, None), (True, None, 60.0), (True, None, 1111.0), (True, None, 344.0), (True, 0.1, None)]
    assert tile_find_summary(outcomes, 150.0) == [
        "tile finds kept and judged: good (pair MPJPE < 150 mm) 2, feet -0.16 to 0.35 m; bad 2, feet 0.45 to 0.69 m; "
        "with no foot figure good 1, bad 2; kept with no joint found 1; refused 1, feet 0.80 to 0.80 m (error unseen)",
        "a 0.3 m bound would refuse of those kept: good 1, bad 2",
        "a 0.4 m bound would refuse of those kept: good 0, bad 2",
        "a 0.5 m bound would refuse of those kept: good 0, bad 1"]
    assert tile_find_summary([], 150.0)[0] == ("tile finds kept and judged: good (pair MPJPE < 150 mm) 0; bad 0; "
                                               "with no foot figure good 0, bad 0; kept with no joint found 0; "
                                               "refused 0 (error unseen)")


def test_the_rig_files_estimators_refuse_feet_over_the_bound_asked_for(tiny_model_dir, scratch_cache,  # noqa: F811
                                                                        monkeypatch):
    """``--tile-find-max-foot`` (session 72): the ``--rigs`` estimators run with that bound in their config,
    ``tracking.cold_tiles_max_foot_m`` (``inf``: None, every find kept, each showing its own error); without it, the
    runtime's default."""
    import benchmarks.measure_baseline as mb
    from ghnerf_runtime.config import TrackingConfig

    seen = []

    class Recording(mb.Estimator):
        def __init__(self, session, rig, config):
            super().__init__(session, rig, config)
            seen.append((config.tracking.cold_tiles_max_foot_m, self._feet_float(5.0)))

    monkeypatch.setattr(mb, "Estimator", Recording)
    common = ["--model-dir", str(tiny_model_dir), "--sequences", "2", "--frames", "1", "--baselines", "",
              "--rigs", "docs/examples/rig.json", "--lifts", ""]
    assert mb.main(common + ["--tile-find-max-foot", "inf"]) == 0
    assert seen == [(None, False)] * 2
    seen.clear()
    assert mb.main(common + ["--tile-find-max-foot", "0.25"]) == 0
    assert seen == [(0.25, True)] * 2
    seen.clear()
    assert mb.main(common) == 0
    assert seen == [(TrackingConfig().cold_tiles_max_foot_m, True)] * 2


@pytest.mark.parametrize("option", ["--tile-find-max-foot", "--good-find-mm"])
def test_the_bounds_are_numbers(option, capsys, monkeypatch):
    err = run_script_failing("measure_baseline", option, "nan", capsys=capsys, monkeypatch=monkeypatch)
    assert option in err, err


@pytest.mark.parametrize("value", ["-0.1", "12", "-inf"])
def test_a_foot_bound_the_config_refuses_is_a_usage_error(value, capsys, monkeypatch):
    """Past tracking.cold_tiles_max_foot_m's 0-10 m (inf: none), a usage error naming the option and the value, not
    the config's traceback from inside the run."""
    err = run_script_failing("measure_baseline", f"--tile-find-max-foot={value}", capsys=capsys,
                             monkeypatch=monkeypatch)  # (=: argparse reads a lone -0.1 as an option)
    assert "--tile-find-max-foot" in err and value in err, err


def test_the_command_line_prints_the_tile_finds(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "docs" / "examples" / "rig.json"
    out = run_script("measure_baseline", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1",
                     "--baselines", "", "--rigs", str(example), "--lifts", "", "--tile-finds", capsys=capsys,
                     monkeypatch=monkeypatch)
    assert "| rig file | sequence | pair | tile find | person's joints' mean x, y, z, m |" in out, out
    assert "tile finds kept and judged: good (pair MPJPE < 150 mm) " in out, out


def test_the_rig_files_estimators_get_the_rig_lifted(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    """``--rig-lift`` (session 71): each ``--rigs`` file's estimator gets that rig with its frame moved up (the same
    images, the floor no longer at y = 0: docs/runtime.md, "The first tile"), and its rows say so; the framing cells
    stay the file's."""
    import benchmarks.measure_baseline as mb

    given = []

    class Recording(mb.Estimator):
        def __init__(self, session, rig, config):
            given.append(rig)
            super().__init__(session, rig, config)

    monkeypatch.setattr(mb, "Estimator", Recording)
    assert mb.main(["--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "1", "--baselines", "",
                    "--rigs", "docs/examples/rig.json", "--lifts", "", "--tile-finds", "--rig-lift", "1.2"]) == 0
    out = capsys.readouterr().out
    assert "| docs/examples/rig.json, frame 1.2 m up | 1.00 | 517 | " in out, out
    assert [r.volume.max_corner[1] for r in given] == pytest.approx([0.05 - 1.2])


@pytest.mark.parametrize("lift", ["nan", "inf", "up"])
def test_the_rig_lift_is_a_finite_number(lift, capsys, monkeypatch):
    err = run_script_failing("measure_baseline", "--rig-lift", lift, capsys=capsys, monkeypatch=monkeypatch)
    assert "--rig-lift" in err, err


def test_the_cold_crop_height_wants_one_height_per_camera():
    """``in_cold_crop_px`` (``framing_cells``' and ``measure_synth_framing.cold_crop_px``'s): one image height per
    camera of the pair, else a ValueError naming the count (``zip`` would drop the second camera silently)."""
    rig = rig_with_baseline(0.6, 3.0)
    crops = [roi_from_volume(cam, rig.volume).size for cam in rig.pair]
    assert in_cold_crop_px(rig, [200.0, 100.0], 128) == min(200.0 * 128 / crops[0], 100.0 * 128 / crops[1])
    with pytest.raises(ValueError, match=r"image_px: one height per camera of the pair \(2\), got 1"):
        in_cold_crop_px(rig, [200.0], 128)
