"""Two people in the working volume (docs/runtime.md, "Two people in the working volume"): a pair whose joint
maps show a second strong peak in both views is flagged ``several_people`` and reports only the tracked subject's
joints, none without a track; one person is never flagged and loses nothing.

The oracle of ``benchmarks/measure_two_people.py`` gives each map both people's Gaussians (their maximum)."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.measure_two_people import NEAR_M, TwoPeopleOracle
from benchmarks.bench_runtime_common import edge128_contract
from ghnerf_runtime.config import ConfigError, EstimatorConfig, Joints3DConfig, config_from_dict
from ghnerf_runtime.estimator import Estimator

sim = pytest.importorskip("drivers.sim")

#: No check: the estimator as before session 53.
UNCHECKED = EstimatorConfig(joints3d=Joints3DConfig(second_person_min_joints=0))


def _scene(seed: int, alone: int, pairs: int, config: EstimatorConfig = EstimatorConfig(), second: bool = True):
    """Results and both people's joints of the pairs after ``alone`` pairs of the first person alone."""
    rig = sim.RigPlacement().build()
    first = sim.SimScene(sim.SceneConfig(seed=seed, motion="wave", position_xz=(-0.5, 3.0)))
    other = sim.SimScene(sim.SceneConfig(seed=seed + 1000, motion="wave", position_xz=(0.5, 3.4)))
    oracle = TwoPeopleOracle(edge128_contract())
    out = []
    with Estimator(oracle, rig, config) as est:
        for i in range(alone + pairs):
            t = i / 30.0
            a, b = first.joints_3d(t), other.joints_3d(t)
            oracle.set_people(a, b) if second and i >= alone else oracle.set_people(a)
            images = tuple(first.render(c, t, with_truth=False)[0] for c in rig.pair)
            r = est.estimate(images, timestamp_s=t)
            if i >= alone:
                out.append((r, a, b))
    return out


def _split(results) -> tuple[int, int, int]:
    """Joints reported, and of them those more than NEAR_M from the first person's."""
    reported = off_first = 0
    for r, a, _ in results:
        found = ~r.missing
        reported += int(found.sum())
        off_first += int((found & (np.linalg.norm(r.joints_3d - a, axis=-1) >= NEAR_M)).sum())
    return reported, off_first


def test_two_people_from_the_first_pair_are_flagged_and_no_mixed_skeleton_is_reported():
    """Before, 19.6 joints per pair of which 46 % at neither person (the benchmark): now every pair says
    several_people and, with no track to tell whose joints are whose, reports none (3D or 2D)."""
    for seed in (1, 2):
        results = _scene(seed, alone=0, pairs=4)
        assert all(r.several_people for r, *_ in results)
        assert _split(results) == (0, 0)
        for r, *_ in results:
            assert all(m.all() for m in r.missing_2d.values())
            obj = json.loads(json.dumps(r.to_json(), allow_nan=False))
            assert obj["several_people"] is True
            # each view's peak may be either person's: their disagreement says nothing of the rig (the daemon's
            # calibration check must not count it)
            assert r.reprojection_px_median is None and obj["reprojection_px_median"] is None
            assert r.single_view is None and obj["single_view"] is None
    # the old estimator on the same pairs: a mixed skeleton, most of it off the first person
    reported, off_first = _split(_scene(1, alone=0, pairs=4, config=UNCHECKED))
    assert reported >= 40 and off_first > reported / 2


def test_a_second_person_joining_leaves_the_tracked_subject_s_joints_only():
    """The first person tracked alone, then the second joins: flagged, and what is reported is the first
    person's (within 5 cm), at least 6 joints on every pair, 8 or more on average."""
    for seed in (1, 2):
        results = _scene(seed, alone=3, pairs=6)
        assert all(r.several_people for r, *_ in results)
        reported, off_first = _split(results)
        assert off_first == 0
        assert min(r.num_found for r, *_ in results) >= 6  # (the presence gate's minimum)
        assert reported >= 8 * len(results)
        for r, a, _ in results:  # the 2D joints go with the 3D ones
            for name, missing in r.missing_2d.items():
                assert np.all(missing[r.missing]), name
    # the old estimator on the same pairs: more than a third of what it reports is not the first person's
    reported, off_first = _split(_scene(1, alone=3, pairs=6, config=UNCHECKED))
    assert off_first > reported / 3


def test_a_second_person_joining_gives_back_the_subject_s_joints_the_other_outshone():
    """Where the other person's peak is the stronger in a view, the subject's is that map's runner-up: of the four
    pairings of the two views' peaks the one nearest the track is reported (since session 53's second change;
    before, 11.6 of 25 joints per pair on the benchmark). Every pair keeps at least 20 joints, all the first
    person's, and each camera's 2D joints are the first person's peaks (within 1 px of the projections of their
    joints, measured 0.01 px), with those peaks' values."""
    rig = sim.RigPlacement().build()
    for seed in (1, 2):
        results = _scene(seed, alone=3, pairs=6)
        assert all(r.several_people for r, *_ in results)
        reported, off_first = _split(results)
        assert off_first == 0
        assert min(r.num_found for r, *_ in results) >= 20, [r.num_found for r, *_ in results]
        for r, a, b in results:
            assert r.to_json()["several_people"] is True
            for cam in rig.pair:
                shown = ~r.missing_2d[cam.name]
                assert np.array_equal(shown, ~r.missing)  # (the oracle shows every joint in both views)
                to_first = np.linalg.norm(r.joints_2d[cam.name] - cam.project(a)[0], axis=-1)
                to_second = np.linalg.norm(r.joints_2d[cam.name] - cam.project(b)[0], axis=-1)
                assert to_first[shown].max() < 1.0 and to_second[shown].min() > 20.0, cam.name
                assert np.all(r.confidence_2d[cam.name][shown] > 0.5)  # the oracle's peaks: 0.65 or more


def test_one_person_is_never_flagged_and_keeps_every_joint():
    """Nothing changes for one person: the same joints as without the check, every one found, none flagged."""
    checked = _scene(3, alone=0, pairs=5, second=False)
    unchecked = _scene(3, alone=0, pairs=5, config=UNCHECKED, second=False)
    for (r, a, _), (u, *_) in zip(checked, unchecked):
        assert not r.several_people and r.to_json()["several_people"] is False
        assert r.num_found == 25
        np.testing.assert_array_equal(r.joints_3d, u.joints_3d)
        assert np.linalg.norm(r.joints_3d - a, axis=-1).max() < NEAR_M


def test_the_check_can_be_turned_off_and_its_settings_are_checked():
    results = _scene(1, alone=0, pairs=2, config=UNCHECKED)
    assert not any(r.several_people for r, *_ in results) and _split(results)[0] > 0
    for key, value in (("second_person_ratio", 0.0), ("second_person_ratio", 1.5), ("second_person_min_joints", -1),
                       ("second_person_min_joints", 2.5), ("max_track_step_m", 0.0)):
        with pytest.raises(ConfigError, match=key) as e:
            config_from_dict({"joints3d": {key: value}})
        assert str(value) in str(e.value)
    assert replace(Joints3DConfig(), second_person_min_joints=0).second_person_min_joints == 0
