"""Anyone besides the tracked subject in the working volume (``presence.scan_every_s``, ``PairResult.someone_else``;
docs/two-people.md, "Anyone else near?"): the scan's rule on synthetic heatmaps, its clock, its settings, and the
estimator on the two-people oracle of ``benchmarks/measure_two_people.py``."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from benchmarks.bench_runtime_common import edge128_contract
from benchmarks.measure_two_people import TwoPeopleOracle
from ghnerf_runtime.config import ConfigError, EstimatorConfig, HeatmapsConfig, PresenceConfig, config_from_dict
from ghnerf_runtime.errors import ModelError
from ghnerf_runtime.estimator import Estimator
from ghnerf_runtime.others_scan import ScanClock, box_cells, someone_else, strong_joints_outside, subject_box

sim = pytest.importorskip("drivers.sim")

#: The scan on every tracked pair (the benchmark's 0.001 s at 30 fps).
EVERY_PAIR = EstimatorConfig(presence=PresenceConfig(scan_every_s=0.001))
#: The benchmark's places: the subject, and a second person a metre beside and 0.4 m behind.
SIDE_BY_SIDE = ((-0.5, 3.0), (0.5, 3.4))


def _maps(peaks_per_view: list[list[tuple[int, int, int]]], J: int = 25, size: int = 32) -> np.ndarray:
    """``(2, J, size, size)`` zero maps with a peak of 1 at each view's ``(joint, row, column)``."""
    heat = np.zeros((2, J, size, size), np.float32)
    for v, peaks in enumerate(peaks_per_view):
        for j, row, col in peaks:
            heat[v, j, row, col] = 1.0
    return heat


def test_someone_else_needs_min_joints_strong_outside_the_subject_s_cells_in_both_views():
    subject = (4, 4, 12, 20)  # (u0, v0, u1, v1): columns 4-12, rows 4-20
    inside = [(j, 10, 8) for j in range(8)]
    outside = [(j, 10, 25) for j in range(8)]
    assert someone_else(_maps([outside, outside]), [subject] * 2, 0.35, 6)
    assert not someone_else(_maps([inside, inside]), [subject] * 2, 0.35, 6)  # the subject's own peaks
    assert not someone_else(_maps([outside, inside]), [subject] * 2, 0.35, 6)  # one view alone
    assert not someone_else(_maps([outside[:5], outside[:5]]), [subject] * 2, 0.35, 6)  # too few joints
    weak = _maps([outside, outside]) * 0.3
    assert not someone_else(weak, [subject] * 2, 0.35, 6)
    # cells past the map's edge blank what lies on the map; a box wholly off the map blanks nothing
    assert strong_joints_outside(_maps([outside, []])[0], (-5, -5, 40, 40), 0.35) == 0
    assert strong_joints_outside(_maps([outside, []])[0], (40, 40, 50, 50), 0.35) == 8
    assert strong_joints_outside(_maps([outside, []])[0], (-9, -9, -2, -2), 0.35) == 8


def test_subject_box_and_its_cells():
    points = np.array([[0.0, -1.0, 3.0], [0.2, 0.5, 3.2], [9.0, 9.0, 9.0]])
    box = subject_box(points, np.array([True, True, False]), margin_m=0.3)
    np.testing.assert_allclose(box, [[-0.3, -1.3, 2.7], [0.5, 0.8, 3.5]])
    assert subject_box(points, np.zeros(3, bool)) is None
    P = np.array([[100.0, 0, 64, 0], [0, 100.0, 64, 0], [0, 0, 1, 0]])  # a camera at the origin looking down +z
    u0, v0, u1, v1 = box_cells(P, box, 4)
    assert (u0, v0) == (int(np.floor((64 - 30 / 2.7) / 4)), int(np.floor((64 - 130 / 2.7) / 4)))
    assert (u1, v1) == (int(np.ceil((64 + 50 / 2.7) / 4)), int(np.ceil((64 + 80 / 2.7) / 4)))


def test_the_scan_clock_runs_every_so_many_seconds_and_again_after_a_reset_or_a_clock_gone_back():
    clock = ScanClock(1.0)
    assert clock.due(10.0)
    clock.ran(10.0)
    assert not clock.due(10.5) and clock.due(11.0)
    assert clock.due(9.0)  # a replay started again
    clock.reset()
    assert clock.due(10.2)
    assert not ScanClock(0.0).due(0.0)


@pytest.mark.parametrize("value", [-1.0, float("nan"), "1", True, 4000.0])
def test_scan_every_s_is_checked(value):
    with pytest.raises(ConfigError, match="scan_every_s") as e:
        config_from_dict({"presence": {"scan_every_s": value}})
    assert repr(value) in str(e.value) or str(value) in str(e.value)
    assert EstimatorConfig().presence.scan_every_s == 0.0  # off by default
    assert config_from_dict({"presence": {"scan_every_s": 1}}).presence.scan_every_s == 1.0


def test_the_scan_needs_encoder_heatmaps_said_at_load():
    oracle = TwoPeopleOracle(replace(edge128_contract(), encoder_heatmaps=False))
    rendered = EstimatorConfig(heatmaps=HeatmapsConfig("rendered", flip_test=False),
                               roi=replace(EstimatorConfig().roi, turn_search=False))
    Estimator(oracle, sim.RigPlacement().build(), rendered).close()  # loads with the scan off
    with pytest.raises(ModelError, match="presence.scan_every_s"):
        Estimator(oracle, sim.RigPlacement().build(), replace(rendered, presence=EVERY_PAIR.presence))


def _joining(config: EstimatorConfig, alone: int = 3, pairs: int = 4, where: tuple = SIDE_BY_SIDE) -> list:
    """The results of ``alone`` pairs of the first person, then ``pairs`` with the second beside them."""
    rig = sim.RigPlacement().build()
    first = sim.SimScene(sim.SceneConfig(seed=1, motion="wave", position_xz=where[0]))
    other = sim.SimScene(sim.SceneConfig(seed=1001, motion="wave", position_xz=where[1]))
    oracle = TwoPeopleOracle(edge128_contract())
    out = []
    with Estimator(oracle, rig, config) as est:
        for i in range(alone + pairs):
            t = i / 30.0
            a, b = first.joints_3d(t), other.joints_3d(t)
            oracle.set_people(a, b) if i >= alone else oracle.set_people(a)
            images = tuple(first.render(c, t, with_truth=False)[0] for c in rig.pair)
            out.append(est.estimate(images, timestamp_s=t))
    return out


def test_a_second_person_beside_the_tracked_subject_is_told_and_the_joints_do_not_change():
    """The tracked crop mostly leaves the second person out (``several_people`` is not a presence detector): the scan
    of the whole working volume tells them, and one person alone is not told. Off by default: ``None``."""
    scanned, plain = _joining(EVERY_PAIR), _joining(EstimatorConfig())
    assert [r.someone_else for r in scanned] == [False] * 3 + [True] * 4
    assert all(r.tracked for r in scanned)
    assert all(r.someone_else is None and r.to_json()["someone_else"] is None for r in plain)
    assert scanned[-1].to_json()["someone_else"] is True
    for r, u in zip(scanned, plain):
        np.testing.assert_array_equal(r.joints_3d, u.joints_3d)
        np.testing.assert_array_equal(r.missing, u.missing)
        assert r.several_people == u.several_people
    assert all("scan" in r.timing_ms for r in scanned) and not any("scan" in r.timing_ms for r in plain)


def test_the_answer_is_held_between_scans():
    """Every second: the pairs between two scans carry the last answer, and run no scan."""
    results = _joining(EstimatorConfig(presence=PresenceConfig(scan_every_s=1.0)), alone=3, pairs=4)
    assert [r.someone_else for r in results] == [False] * 7  # the one scan, on the first pair, saw one person
    assert ["scan" in r.timing_ms for r in results] == [True] + [False] * 6
