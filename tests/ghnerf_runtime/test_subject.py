"""ghnerf_runtime.subject: the two-people subject selection, moved out of the estimator in session 60 (the
behaviour is the two-people tests', tests/ghnerf_runtime/test_two_people.py; these check the seam)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks.bench_runtime_common import edge128_contract
from benchmarks.measure_two_people import TwoPeopleOracle
from ghnerf_runtime.body25 import JOINT_NAMES, NUM_JOINTS
from ghnerf_runtime.config import EstimatorConfig, Joints3DConfig
from ghnerf_runtime.estimator import Estimator
from ghnerf_runtime.joints3d import Joints3D
from ghnerf_runtime.subject import SubjectSelector, guessed_joints, picks_subject
from tests.ghnerf_runtime.sim_takes import pair_images, two_people

sim = pytest.importorskip("drivers.sim")


def test_the_estimator_holds_one_selector_on_its_resolved_config_and_model_geometry():
    """The estimator resolves its configuration against the model (the prior, the padding, the encoder heatmaps):
    the selector reads that one, not the configuration passed in, and the model's heatmap grid and input size."""
    rig = sim.RigPlacement().build()
    with Estimator(TwoPeopleOracle(edge128_contract()), rig, EstimatorConfig()) as est:
        selector = est.subject_selector
        assert isinstance(selector, SubjectSelector)
        assert selector.config is est.config and selector.rig is rig
        assert (selector.grid, selector.size) == (est.grid, est.size)


class _CountedGates(Estimator):
    """Counts the box gates and floor checks asked of a flagged pair's four pairings (4 * J joints) and of all."""

    def __init__(self, *args, **kwargs):
        self.pairings_gated, self.floor_checks = 0, 0
        super().__init__(*args, **kwargs)

    def _gate_to_boxes(self, j3, regions):
        self.pairings_gated += len(j3.valid) == 4 * NUM_JOINTS
        return super()._gate_to_boxes(j3, regions)

    def _lowest_foot_m(self, tri, kp, regions):
        self.floor_checks += 1
        return super()._lowest_foot_m(tri, kp, regions)


def test_a_flagged_pair_s_pairings_pass_the_estimator_s_own_gates_and_floor_check():
    """The selector is handed the estimator's box gates and floor check (bound at construction, so a subclass's
    override holds, as benchmarks/measure_foot_spread.py's does): two people side by side flag every pair, and the
    subject's pairings go through them."""
    rig = sim.RigPlacement().build()
    first, other = two_people(4, ((-0.5, 3.0), (0.5, 3.4)))
    oracle = TwoPeopleOracle(edge128_contract())
    with _CountedGates(oracle, rig, EstimatorConfig()) as est:
        for i in range(2):
            t = i / 30.0
            oracle.set_people(first.joints_3d(t), other.joints_3d(t))
            images = pair_images(first, rig, t)
            assert est.estimate(images, timestamp_s=t).several_people
        assert est.pairings_gated >= 2 and est.floor_checks >= 2, (est.pairings_gated, est.floor_checks)


@pytest.mark.parametrize("method, rule, picks", [("triangulate", "centre_line", True), ("triangulate", "none", False),
                                                 ("depth_centroid", "centre_line", False)])
def test_a_subject_is_picked_only_by_the_triangulation_with_a_rule(method, rule, picks):
    assert picks_subject(Joints3DConfig(method=method, pick_subject=rule)) is picks


def test_guessed_joints_are_those_a_view_shows_a_peak_of_or_that_hang_from_nothing_found():
    """Of the joints the subject's pairings did not find: one a view shows a peak of is a guess beside the other
    person; one no view shows that hangs from a found joint (a heel from its ankle) is not; one hanging from
    nothing found is."""
    name = JOINT_NAMES.index
    found = np.zeros(NUM_JOINTS, bool)
    found[[name("RAnkle"), name("Neck")]] = True
    subject = Joints3D(np.zeros((NUM_JOINTS, 3)), found.astype(np.float32), found, np.zeros((NUM_JOINTS, 2)))
    peaks = np.zeros((2, NUM_JOINTS), bool)
    peaks[1, name("LWrist")] = True  # a peak in view 1 only, of a joint not found
    peaks[0, name("Neck")] = True  # a found joint's peak
    guessed = guessed_joints(subject, SimpleNamespace(valid=peaks))
    assert guessed[name("LWrist")] and not guessed[name("Neck")] and not guessed[name("RAnkle")]
    assert not guessed[name("RHeel")] and not guessed[name("MidHip")]  # hidden, hanging from the ankle, the neck
    assert guessed[name("LHeel")]  # hidden, hanging from nothing found
