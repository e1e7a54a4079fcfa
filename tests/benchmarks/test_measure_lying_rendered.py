"""``benchmarks/measure_lying_rendered.py``: the poses it renders are the ones it names (a lying body on the floor
with its height axis horizontal, an upside-down one head down), so that it cannot silently measure upright
people; and its command line gets through to its table."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from benchmarks.measure_lying_rendered import POSES, posed_as, render_pair, rotation
from ghnerf_runtime.body25 import JOINT_INDEX
from ghnerf_runtime.cli.simdata import bench_rig_and_scene
from tests.benchmarks.test_bench_smoke import (  # noqa: F401  (scratch_cache: a module fixture)
    run_script, run_script_failing, scratch_cache)
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

NECK, MID_HIP = JOINT_INDEX["Neck"], JOINT_INDEX["MidHip"]


@pytest.fixture(scope="module")
def scenes():
    """Three bench scenes at their first instant: (rig, scene, upright posed body)."""
    out = []
    for k in range(3):
        rig, scene, t0, _ = bench_rig_and_scene(k)
        out.append((rig, scene, scene.posed(t0)))
    return out


def _spine(posed) -> np.ndarray:
    """The unit vector from the mid hip to the neck (the body's height axis, pointing to the head)."""
    v = posed.joints[NECK] - posed.joints[MID_HIP]
    return v / np.linalg.norm(v)


def test_rotation_is_a_proper_rotation_about_its_axis():
    for axis in (0, 1, 2):
        R = rotation(axis, 90.0)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R[:, axis], np.eye(3)[axis], atol=1e-12)  # the axis stays put


def test_turned_bodies_rest_on_the_floor_with_the_height_axis_the_pose_names(scenes):
    up = np.array([0.0, -1.0, 0.0])  # the rig frame's y points down: up is -y
    for rig, _, upright in scenes:
        assert _spine(upright) @ up > 0.9  # the bench's people stand
        for pose in POSES:
            body = posed_as(upright, pose, rig.volume)
            lo, hi = body.bounding_box()
            spine = _spine(body)
            if pose == "upright":
                assert body is upright
                continue
            assert hi[1] == pytest.approx(0.0, abs=1e-9), pose  # its lowest surface point on the floor (y = 0)
            assert lo[1] < -0.1, pose  # and the rest above it
            # a rigid turn: the joints keep their distances
            d0 = np.linalg.norm(upright.joints[:, None] - upright.joints[None], axis=-1)
            d1 = np.linalg.norm(body.joints[:, None] - body.joints[None], axis=-1)
            np.testing.assert_allclose(d1, d0, atol=1e-9)
            if pose == "upside_down":
                assert spine @ up < -0.9, pose  # head down
            else:
                assert abs(spine @ up) < 0.45, (pose, spine)  # lying: the height axis near horizontal
                along = 2 if pose == "lying_x" else 0  # along the line of sight, or across the view
                assert abs(spine[along]) > 0.85, (pose, spine)


def test_a_lying_body_is_moved_into_the_working_volume_where_it_fits(scenes):
    for rig, _, upright in scenes:
        for pose in ("lying_x", "lying_z"):
            lo, hi = posed_as(upright, pose, rig.volume).bounding_box()
            vlo, vhi = rig.volume.min_corner, rig.volume.max_corner
            for a in (0, 2):
                if hi[a] - lo[a] <= vhi[a] - vlo[a]:
                    assert vlo[a] - 1e-9 <= lo[a] and hi[a] <= vhi[a] + 1e-9, (pose, a)
                else:  # longer than the volume: centred on it
                    assert 0.5 * (lo[a] + hi[a]) == pytest.approx(0.5 * (vlo[a] + vhi[a])), (pose, a)


def test_the_pictures_show_the_turned_body(scenes):
    """The rendered truth is the turned body's: its 2D joints are the projections of the turned joints."""
    rig, scene, upright = scenes[1]
    body = posed_as(upright, "upside_down", rig.volume)
    images, j2, vis = render_pair(scene, rig, body, 0.0)
    assert len(images) == 2 and images[0].shape == (rig.pair[0].height, rig.pair[0].width, 3)
    for c, cam in enumerate(rig.pair):
        np.testing.assert_allclose(j2[c], cam.project(body.joints)[0], atol=1e-6)
    head_row, hip_row = j2[0, JOINT_INDEX["Nose"], 1], j2[0, MID_HIP, 1]
    assert head_row > hip_row  # the head below the hips in the picture


def test_unknown_pose_is_refused():
    with pytest.raises(ValueError, match="unknown pose 'sitting'"):
        posed_as(None, "sitting")


def test_command_line_prints_a_row_per_pose_and_prior(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                       monkeypatch):
    out = run_script("measure_lying_rendered", "--model-dir", str(tiny_model_dir), "--scenes", "1", "--frames",
                     "1", "--turned-crops", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^\| (\w+) \| (on|off|on, crops turned with the body \(oracle\)) \| 1 \(\d\) \|", out, re.M)
    assert rows == [("upright", "on"), ("upright", "off"), ("lying_x", "on"), ("lying_x", "off"),
                    ("lying_z", "on"), ("lying_z", "off"), ("lying_z", "on, crops turned with the body (oracle)"),
                    ("upside_down", "on"), ("upside_down", "off"),
                    ("upside_down", "on, crops turned with the body (oracle)")], out


def test_turn_search_adds_a_row_per_pose_with_its_searches(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                          monkeypatch):
    out = run_script("measure_lying_rendered", "--model-dir", str(tiny_model_dir), "--scenes", "1", "--frames",
                     "1", "--poses", "upright,lying_z", "--turn-search", capsys=capsys, monkeypatch=monkeypatch)
    searches, refused, checks = r"(- |\d+ \(\d+, \d+\) )", r"(- |\d+ )", r"(- |\d+ \(\d+\) )"
    rows = re.findall(rf"^\| (\w+) \| ([^|]+) \| 1 \(\d\) \|.*\| {searches}\| {refused}\| {checks}\| [\d.]+ \|$",
                      out, re.M)
    assert [(pose, prior) for pose, prior, _, _, _ in rows] == [
        ("upright", "on"), ("upright", "off"), ("upright", "on, `roi.turn_search` on"),
        ("lying_z", "on"), ("lying_z", "off"), ("lying_z", "on, `roi.turn_search` on")], out
    assert [searches != "- " for _, _, searches, _, _ in rows] == [False, False, True] * 2
    # the turned passes refused (lies_as_turned), a count on the search's rows only
    assert [refused != "- " for _, _, _, refused, _ in rows] == [False, False, True] * 2
    assert [checks != "- " for _, _, _, _, checks in rows] == [False, False, True] * 2


MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.mark.skipif(not (MODELS / "model_card.json").is_file(), reason="no trained model in models/")
def test_only_the_turn_search_rows_search(scratch_cache):  # noqa: F811
    """roi.turn_search is on by default since session 57: the rows without it (the prior on and off, the oracle's
    turned crops) set it off, so that they still say what upright crops give a person lying across the view."""
    from benchmarks.measure_lying_rendered import measure

    out = measure(str(MODELS), scenes=1, frames=1, poses=["lying_z"], turned_crops=True, turn_search=True,
                  log=lambda _: None)
    assert {name: s["turn_searches"] for (_, name), s in out.items()} == {
        "prior": 0, "no prior": 0, "turned crops": 0, "turn search": 1}


def test_then_changes_every_body_at_change_at(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_lying_rendered", "--model-dir", str(tiny_model_dir), "--scenes", "1", "--frames",
                     "2", "--poses", "upside_down", "--then", "upright", "--turn-search", capsys=capsys,
                     monkeypatch=monkeypatch)
    rows = re.findall(r"^\| ([\w, ]+) \| ([^|]+) \| 2 \(\d\) \|", out, re.M)
    assert rows == [("upside_down, then upright", "on"), ("upside_down, then upright", "off"),
                    ("upside_down, then upright", "on, `roi.turn_search` on")], out
    err = run_script_failing("measure_lying_rendered", "--model-dir", str(tiny_model_dir), "--then", "sitting",
                             capsys=capsys, monkeypatch=monkeypatch)
    assert "--then: unknown 'sitting'" in err


def test_roll_angles_move_evenly_from_the_first_angle_to_the_last():
    from benchmarks.measure_lying_rendered import ROLLS, roll_angles, roll_band

    np.testing.assert_allclose(roll_angles("roll_down", 4), [0.0, 30.0, 60.0, 90.0])
    np.testing.assert_allclose(roll_angles("cartwheel_back", 3), [180.0, 90.0, 0.0])
    assert set(ROLLS) == {"roll_down", "roll_up", "cartwheel", "cartwheel_back"}
    # 30-degree bands of the roll's range, the last one closed: lying flat counts in 60-90, not a band of its own
    assert [roll_band(d, "roll_down") for d in (0.0, 29.9, 30.0, 89.0, 90.0)] == [
        (0.0, 30.0), (0.0, 30.0), (30.0, 60.0), (60.0, 90.0), (60.0, 90.0)]
    assert roll_band(90.0, "cartwheel") == (90.0, 120.0) and roll_band(180.0, "cartwheel") == (150.0, 180.0)
    with pytest.raises(ValueError, match="unknown roll 'somersault'"):
        roll_angles("somersault", 10)
    with pytest.raises(ValueError, match="at least 2 frames"):
        roll_angles("roll_down", 1)


def test_a_rolled_body_rests_on_the_floor_turned_across_the_view(scenes):
    """``--rolls`` turns the body about the rig's z axis (across the view) by the roll's angle: halfway down a roll
    its height axis leans sideways by that angle, and it rests on the floor."""
    from benchmarks.measure_lying_rendered import turned

    def tilt(posed) -> float:  # the height axis's angle from straight up (the rig frame's -y), degrees
        return float(np.degrees(np.arccos(np.clip(-_spine(posed)[1], -1.0, 1.0))))

    for rig, _, upright in scenes:
        for deg in (45.0, 135.0):
            body = turned(upright, 2, deg, rig.volume)
            assert body.bounding_box()[1][1] == pytest.approx(0.0, abs=1e-9)
            # turned by deg, give or take how far the bench's standing person leans
            assert abs(tilt(body) - deg) <= tilt(upright) + 1.0, (deg, tilt(body), tilt(upright))
            assert abs(_spine(body)[2]) < 0.45  # across the view, not along the line of sight


def test_rolls_print_a_row_per_band_with_the_search_off_and_on(tiny_model_dir, scratch_cache, capsys,  # noqa: F811
                                                              monkeypatch):
    out = run_script("measure_lying_rendered", "--model-dir", str(tiny_model_dir), "--scenes", "1", "--frames",
                     "4", "--rolls", "roll_up,cartwheel", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^\| (\w+) \| (\d+-\d+) \| (off|on) \| (\d+) \(\d+\) \|.*\| ([^|]+) \| ([^|]+) \|$", out, re.M)
    # roll_up 90, 60, 30, 0 degrees: its bands in the roll's order; the cartwheel 0, 60, 120, 180
    assert [(roll, band, search, int(pairs)) for roll, band, search, pairs, _, _ in rows] == [
        ("roll_up", "60-90", "off", 2), ("roll_up", "60-90", "on", 2),
        ("roll_up", "30-60", "off", 1), ("roll_up", "30-60", "on", 1),
        ("roll_up", "0-30", "off", 1), ("roll_up", "0-30", "on", 1),
        ("cartwheel", "0-30", "off", 1), ("cartwheel", "0-30", "on", 1),
        ("cartwheel", "60-90", "off", 1), ("cartwheel", "60-90", "on", 1),
        ("cartwheel", "120-150", "off", 1), ("cartwheel", "120-150", "on", 1),
        ("cartwheel", "150-180", "off", 1), ("cartwheel", "150-180", "on", 1)], out
    # the turn counts (pairs read turned, turn changes) on the search's rows only
    assert all((turned == "-") == (search == "off") for _, _, search, _, turned, _ in rows), out
    for bad, said in ((["--rolls", "somersault"], "--rolls: unknown ['somersault']"),
                      (["--rolls", "roll_up", "--frames", "1"], "--frames of at least 2"),
                      (["--rolls", "roll_up", "--turn-search"], "without --then, --turned-crops, --turn-search"),
                      (["--rolls", "roll_up", "--far-m", "0"], "--far-m must be a positive distance"),
                      (["--far-m", "0.5"], "--far-m needs --rolls")):
        err = run_script_failing("measure_lying_rendered", "--model-dir", str(tiny_model_dir), *bad, capsys=capsys,
                                 monkeypatch=monkeypatch)
        assert said in err, err
