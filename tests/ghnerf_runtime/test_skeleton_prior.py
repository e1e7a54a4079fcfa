"""The skeleton prior: its inputs (canonical frame, invariance, the mirror used in training), the ONNX
file (torch parity, refusal of bad files), extremes, and its place in the estimator."""
from __future__ import annotations

import os
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ghnerf_runtime.body25 import FLIP_INDEX, NUM_JOINTS
from ghnerf_runtime.config import EstimatorConfig, Joints3DConfig
from ghnerf_runtime.errors import ConfigError, ModelContractError, ModelError, ModelLoadError, ModelRunError
from ghnerf_runtime.geometry.camera import Camera, look_at
from ghnerf_runtime.geometry.triangulation import MIN_BLOCK_VOLUME, block_volume
from ghnerf_runtime.skeleton_prior import (
    CONTEXT_FEATURES,
    FILE_NAME,
    JOINT_FEATURES,
    SkeletonPrior,
    mirror_inputs,
    prior_inputs,
)

SIZE = 128
K = np.array([[110.0, 0, 63.5], [0, 110.0, 63.5], [0, 0, 1]])


def _rig(yaw_deg: float = 0.0, shift=(0.0, 0.0)) -> list[np.ndarray]:
    """Two crop cameras 1.2 m apart, 1.4 m up, converging on a subject 3 m ahead (then the whole scene turned
    by ``yaw_deg`` about the vertical and shifted on the floor)."""
    cams = []
    for x in (-0.6, 0.6):
        cam = Camera("c", SIZE, SIZE, K, [], *look_at((x, -1.4, 0.0), (0.0, -1.0, 3.0)))
        cams.append(cam.P @ _scene_motion(yaw_deg, shift, inverse=True))
    return cams


def _scene_motion(yaw_deg: float, shift, inverse: bool = False) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[0, 3], T[2, 3] = shift
    return np.linalg.inv(T) if inverse else T


def _skeleton(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.array([0.0, -1.0, 3.0]) + rng.uniform(-0.4, 0.4, (NUM_JOINTS, 3)) * [1.0, 2.0, 0.5]


def _observe(P: list[np.ndarray], X: np.ndarray):
    Xh = np.c_[X, np.ones(len(X))]
    uv = np.stack([(Xh @ p.T)[:, :2] / (Xh @ p.T)[:, 2:] for p in P])
    return uv, np.full((2, NUM_JOINTS), 0.8), np.ones((2, NUM_JOINTS), bool)


def test_canonical_frame_round_trip_and_exact_triangulation():
    P, X = _rig(), _skeleton()
    uv, conf, valid = _observe(P, X)
    inp = prior_inputs(uv[None], conf[None], valid[None], np.stack(P)[None])
    assert inp.joint_features.shape == (1, NUM_JOINTS, JOINT_FEATURES)
    assert inp.context.shape == (1, CONTEXT_FEATURES)
    assert inp.triangulated.all()
    # the triangulated points are the true ones, in the canonical frame
    np.testing.assert_allclose(inp.joint_features[0, :, :3], inp.frame.to_canonical(X[None])[0], atol=1e-5)
    np.testing.assert_allclose(inp.frame.to_rig(inp.frame.to_canonical(X[None])), X[None], atol=1e-9)
    # height above the floor is kept: y is the rig's y
    np.testing.assert_allclose(inp.joint_features[0, :, 1], X[:, 1], atol=1e-5)
    # baseline 1.2 m, subject about 3 m away
    assert inp.context[0, 6] == pytest.approx(1.2, abs=1e-5) and 2.5 < inp.context[0, 7] < 3.5


@pytest.mark.parametrize("yaw, shift", [(90.0, (0.0, 0.0)), (-37.0, (1.5, -2.0)), (180.0, (-0.3, 0.7))])
def test_inputs_do_not_depend_on_where_the_rig_stands(yaw, shift):
    """Turning the rig and the subject together about the vertical, or moving them on the floor, changes nothing."""
    X = _skeleton(1)
    base = prior_inputs(*(a[None] for a in _observe(_rig(), X)), np.stack(_rig())[None])
    Xm = (np.c_[X, np.ones(len(X))] @ _scene_motion(yaw, shift).T)[:, :3]
    Pm = _rig(yaw, shift)
    moved = prior_inputs(*(a[None] for a in _observe(Pm, Xm)), np.stack(Pm)[None])
    np.testing.assert_allclose(moved.joint_features, base.joint_features, atol=2e-5)
    np.testing.assert_allclose(moved.context, base.context, atol=2e-5)


@pytest.mark.parametrize("yaw, shift", [(90.0, (0.0, 0.0)), (-37.0, (1.5, -2.0))])
def test_with_no_joint_triangulated_the_inputs_still_turn_with_the_rig(yaw, shift):
    """One view decoded nothing, so no joint is triangulated and the body centre is a guess: 2.5 m along the
    cameras' mean heading, which turns with the rig (it was rig +z, beside a rig turned 90 degrees)."""
    X = _skeleton(1)

    def inputs(yaw_deg, where):
        P = _rig(yaw_deg, where)
        Xm = (np.c_[X, np.ones(len(X))] @ _scene_motion(yaw_deg, where).T)[:, :3]
        uv, conf, valid = _observe(P, Xm)
        valid[1] = False  # view 1 undecoded (occluded, or gated)
        return prior_inputs(uv[None], conf[None], valid[None], np.stack(P)[None]), Xm

    (base, Xb), (moved, Xm) = inputs(0.0, (0.0, 0.0)), inputs(yaw, shift)
    assert not base.triangulated.any() and not moved.triangulated.any()
    # the frame itself, in float64: the same body lands on the same canonical points
    np.testing.assert_allclose(moved.frame.to_canonical(Xm[None]), base.frame.to_canonical(Xb[None]), atol=1e-9)
    # the float32 features: equal to their rounding (values up to a few metres: 1e-6 is a few float32 ulps)
    np.testing.assert_allclose(moved.joint_features, base.joint_features, rtol=0, atol=1e-6)
    np.testing.assert_allclose(moved.context, base.context, rtol=0, atol=1e-6)
    assert base.context[0, 7] == pytest.approx(2.5)  # the guess: 2.5 m ahead of the cameras' midpoint


def test_mirror_is_the_inputs_of_the_mirrored_scene():
    """``mirror_inputs`` (training's augmentation) equals the features of the world seen in a mirror, with the
    detector calling the mirrored left joints right."""
    P, X = _rig(), _skeleton(2)
    uv, conf, valid = _observe(P, X)
    conf = conf * np.linspace(0.3, 1.0, NUM_JOINTS)
    base = prior_inputs(uv[None], conf[None], valid[None], np.stack(P)[None])
    S = np.diag([-1.0, 1.0, 1.0, 1.0])  # world x -> -x
    F = np.array([[-1.0, 0, SIZE - 1], [0, 1, 0], [0, 0, 1]])  # image u -> W-1-u: a proper camera again
    Pm = [F @ p @ S for p in P]
    Xm = X * [-1.0, 1.0, 1.0]
    uvm, _, _ = _observe(Pm, Xm)
    flip = list(FLIP_INDEX)
    mirrored = prior_inputs(uvm[:, flip][None], conf[:, flip][None], valid[None], np.stack(Pm)[None])
    f, c, j = mirror_inputs(base.joint_features, base.context, base.frame.to_canonical(X[None]))
    np.testing.assert_allclose(mirrored.joint_features, f, atol=2e-5)
    np.testing.assert_allclose(mirrored.context, c, atol=2e-5)
    np.testing.assert_allclose(mirrored.frame.to_canonical(Xm[flip][None]), j, atol=1e-6)
    f2, c2 = mirror_inputs(f, c)
    np.testing.assert_allclose(f2, base.joint_features) and np.testing.assert_allclose(c2, base.context)


def test_a_dlt_point_far_from_the_body_is_not_a_triangulation():
    """Two peaks whose rays meet 100 m away (nearly parallel rays through wrong peaks) give no DLT feature:
    as one, such a point threw the prior's answer metres off. The joint keeps its rays."""
    P = _rig()
    X = _skeleton(6)
    X[3] = [0.3, -1.2, 100.0]
    inp = prior_inputs(*(a[None] for a in _observe(P, X)), np.stack(P)[None])
    others = np.arange(NUM_JOINTS) != 3
    assert not inp.triangulated[0, 3] and inp.triangulated[0, others].all()
    assert not inp.joint_features[0, 3, :4].any() and not inp.joint_features[0, 3, 6:9].any()
    assert np.abs(inp.joint_features[0, 3, 9:15]).sum() > 1.0  # both rays are still there
    assert np.abs(inp.joint_features[0][inp.triangulated[0]][:, :3]).max() < 2.0


def test_inputs_finite_at_the_extremes():
    P = np.stack(_rig())
    N = 4
    uv = np.zeros((N, 2, NUM_JOINTS, 2))
    conf = np.zeros((N, 2, NUM_JOINTS))
    valid = np.zeros((N, 2, NUM_JOINTS), bool)
    uv[1] = 1e12  # absurd peaks, decoded
    valid[1] = True
    conf[1] = 1.0
    uv[2] = np.nan  # NaN peaks said to be decoded
    valid[2] = True
    conf[2] = np.inf
    valid[3, 0] = True  # one view only
    conf[3, 0] = 0.9
    inp = prior_inputs(uv, conf, valid, np.broadcast_to(P, (N, 2, 3, 4)))
    assert np.isfinite(inp.joint_features).all() and np.isfinite(inp.context).all()
    assert not inp.triangulated[0].any() and not inp.triangulated[2].any() and not inp.triangulated[3].any()
    np.testing.assert_allclose(inp.joint_features[0], 0.0)  # nothing decoded: nothing said



@pytest.mark.parametrize("focal_px", [1e-3, 1.0, 500.0, 1e5, 1e7])
def test_inputs_finite_or_refused_by_name_for_extreme_cameras(focal_px):
    """Property sweep of the crop cameras: focal lengths 1e-3..1e7 px, principal points up to 1e7 px off, baselines
    1e-9..10 m, a body 1e-3..1e4 m away, peaks exact or 2 px off: the inputs are finite (and float32-finite), or
    the two-view solve refuses the matrices by name; exact peaks whose rays meet under 0.1 degrees triangulate
    nothing."""
    from ghnerf_runtime.errors import GeometryError

    rng = np.random.default_rng(int(focal_px * 1000) % 2**32)
    for shift in (0.0, 1e4, 1e7):
        K = np.array([[focal_px, 0.0, 320.0 + shift], [0.0, focal_px, 240.0 - shift], [0.0, 0.0, 1.0]])
        for baseline in (1e-9, 1e-4, 0.1, 10.0):
            for distance in (1e-3, 1.0, 1e4):
                aim = np.array([0.0, 0.0, distance])
                cams = [Camera(n, 640, 480, K, [], *look_at((x, 0.0, 0.0), aim))
                        for n, x in (("a", -baseline / 2), ("b", baseline / 2))]
                X = aim + rng.uniform(-0.3, 0.3, (NUM_JOINTS, 3)) * distance
                uv = np.stack([c.project(X)[0] for c in cams])
                uv = np.stack([uv, uv + rng.normal(0.0, 2.0, uv.shape)])  # (2 pairs, 2 views, J, 2)
                P = np.broadcast_to(np.stack([c.P for c in cams]), (2, 2, 3, 4))
                try:
                    inp = prior_inputs(uv, np.full((2, 2, NUM_JOINTS), 0.9), np.ones((2, 2, NUM_JOINTS), bool), P)
                except GeometryError as e:
                    v = int(np.argmin(block_volume(P[0]) > MIN_BLOCK_VOLUME))  # the first view refused
                    assert str(e).startswith(f"P[{v}] (view {v}) projection matrix has a singular left 3x3 block"), e
                    continue
                case = (focal_px, shift, baseline, distance)
                assert np.isfinite(inp.joint_features).all() and np.isfinite(inp.context).all(), case
                assert np.isfinite(inp.frame.rotation).all() and np.isfinite(inp.frame.origin).all(), case
                if baseline < 1e-3 * distance:  # the exact peaks (noisy ones may cross near the cameras)
                    assert not inp.triangulated[0].any(), case

# ------------------------------------------------------------------------------------------- the ONNX file
@pytest.fixture(scope="module")
def tiny_prior(tmp_path_factory) -> SimpleNamespace:
    """A prior trained a few steps on random scenes of the test rig and exported by the real code."""
    pytest.importorskip("torch")
    pytest.importorskip("onnx")
    from training.skeleton_prior import PriorTrainConfig, export, train

    rng = np.random.default_rng(0)
    P = np.stack(_rig())
    arrays = [_observe(P, _skeleton(s)) for s in range(32)]
    uv = np.stack([a[0] for a in arrays]) + rng.normal(0, 1.0, (32, 2, NUM_JOINTS, 2))
    truth = np.stack([_skeleton(s) for s in range(32)])
    inp = prior_inputs(uv, np.stack([a[1] for a in arrays]), np.stack([a[2] for a in arrays]),
                       np.broadcast_to(P, (32, 2, 3, 4)))
    net = train(inp, inp.frame.to_canonical(truth), np.ones((32, NUM_JOINTS), bool),
                PriorTrainConfig(steps=3, hidden=16, batch=8), progress=False)
    path = export(net, tmp_path_factory.mktemp("prior") / FILE_NAME, {"trained_on": "test"})
    return SimpleNamespace(path=path, net=net, data=(inp, inp.frame.to_canonical(truth)))  # file, torch twin


@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_a_prior_whose_weights_hold_nan_is_refused_at_warm_up(tiny_prior, tmp_path, bad):
    """NaN weights answer NaN to every pair, which the estimator takes as no prior estimate: the prior warmed up
    and then dropped out of every pair without a word (the graphs' warm-up refuses such outputs)."""
    onnx = pytest.importorskip("onnx")
    model = onnx.load(str(tiny_prior.path))
    weights = max(model.graph.initializer, key=lambda t: int(np.prod(t.dims)))
    values = onnx.numpy_helper.to_array(weights).copy()
    values.flat[0] = bad
    weights.CopyFrom(onnx.numpy_helper.from_array(values, weights.name))
    onnx.save(model, str(tmp_path / FILE_NAME))
    with pytest.raises(ModelRunError, match=r"^.*skeleton prior returned NaN or infinite values in '(joints|"
                                            r"log_error)' at its warm-up run \(batch \d+\)") as e:
        SkeletonPrior.load(tmp_path / FILE_NAME).warm_up()
    assert e.value.path == str(tmp_path / FILE_NAME)
    assert SkeletonPrior.load(tiny_prior.path).warm_up() >= 0  # the file it was made from warms up


def test_onnx_matches_torch_and_answers_in_the_rig_frame(tiny_prior):
    import torch

    prior = SkeletonPrior.load(tiny_prior.path)
    assert {"ghnerf_skeleton.feature_version", "ghnerf_skeleton.num_joints"} <= set(prior.metadata)
    P = _rig(30.0, (0.5, 0.5))
    X = (np.c_[_skeleton(3), np.ones(NUM_JOINTS)] @ _scene_motion(30.0, (0.5, 0.5)).T)[:, :3]
    uv, conf, valid = _observe(P, X)
    est = prior.estimate(uv, conf, valid, P, flip_test=False)
    assert est.points.shape == (NUM_JOINTS, 3) and est.expected_error_m.shape == (NUM_JOINTS,)
    assert np.isfinite(est.points).all() and (est.expected_error_m > 0).all()
    # torch vs onnxruntime on the same inputs, back in the rig frame
    inp = prior_inputs(uv[None], conf[None], valid[None], np.stack(P)[None])
    with torch.no_grad():
        joints, log_err = tiny_prior.net(torch.from_numpy(inp.joint_features), torch.from_numpy(inp.context))
    np.testing.assert_allclose(est.points, inp.frame.to_rig(joints.double().numpy())[0], atol=1e-5)
    np.testing.assert_allclose(est.expected_error_m, np.exp(log_err.double().numpy()[0]), rtol=1e-4)
    # batched and single answers agree (N is dynamic)
    batch = prior.estimate(np.stack([uv, uv]), np.stack([conf, conf]), np.stack([valid, valid]),
                           np.stack([np.stack(P)] * 2), flip_test=False)
    np.testing.assert_allclose(batch.points[1], est.points, atol=1e-6)
    # the network starts as the identity on the triangulated points and has had 3 steps: near the truth
    assert np.median(np.linalg.norm(est.points - X, axis=-1)) < 0.1


def test_an_ensemble_file_answers_the_mean_of_its_members(tiny_prior, tmp_path):
    """``members=2`` trains two networks (seeds 0 and 1) and exports one file answering their mean joints and
    the mean of their expected errors; member 0 is the single network of seed 0."""
    import torch
    from training.skeleton_prior import PriorTrainConfig, export, train

    inp, truth = tiny_prior.data
    both = train(inp, truth, np.ones(truth.shape[:2], bool), PriorTrainConfig(steps=3, hidden=16, batch=8,
                                                                              members=2), progress=False)
    assert len(both.members) == 2
    f, c = torch.from_numpy(inp.joint_features), torch.from_numpy(inp.context)
    with torch.no_grad():
        single, member0 = tiny_prior.net(f, c), both.members[0](f, c)
        j1, e1 = both.members[1](f, c)
    for a, b in zip(single, member0):  # training is deterministic, member 0 is the seed-0 network
        torch.testing.assert_close(a, b)
    assert (j1 - member0[0]).abs().max() > 1e-5  # seed 1 is another network
    prior = SkeletonPrior.load(export(both, tmp_path / FILE_NAME, {"trained_on": "test"}))
    joints, log_err = prior._session.run(None, {"joint_features": inp.joint_features, "context": inp.context})
    np.testing.assert_allclose(joints, 0.5 * (member0[0] + j1).numpy(), atol=1e-5)
    np.testing.assert_allclose(np.exp(log_err), 0.5 * (member0[1].exp() + e1.exp()).numpy(), rtol=1e-4)


def test_members_train_side_by_side_and_match_members_trained_alone(tiny_prior):
    """At two threads the two members train at once, one process of one thread each; each is the network
    its seed gives at one thread in this process (the lanes change the wall time, not the weights)."""
    import torch
    from training.skeleton_prior import PriorTrainConfig, member_lanes, train

    assert member_lanes(2, 2) == (2, 1) and member_lanes(2, 1) == (1, 1) and member_lanes(3, 2) == (2, 1)
    assert member_lanes(2, 16) == (2, 8) and member_lanes(1, 4) == (1, 4)
    inp, truth = tiny_prior.data
    valid = np.ones(truth.shape[:2], bool)
    config = PriorTrainConfig(steps=3, hidden=16, batch=8, members=2)
    side_by_side = train(inp, truth, valid, config, progress=False, threads=2)
    threads = torch.get_num_threads()
    alone = train(inp, truth, valid, config, progress=False, threads=1)  # one after the other, at one thread
    assert torch.get_num_threads() == threads  # (restored)
    f, c = torch.from_numpy(inp.joint_features), torch.from_numpy(inp.context)
    with torch.no_grad():
        for a, b in zip(side_by_side.members, alone.members):
            for x, y in zip(a(f, c), b(f, c)):
                torch.testing.assert_close(x, y, rtol=0, atol=0)
        assert (side_by_side.members[0](f, c)[0] - side_by_side.members[1](f, c)[0]).abs().max() > 1e-5


def test_flip_test_averages_the_mirrored_answer_and_makes_the_prior_mirror_symmetric(tiny_prior):
    """With the flip test the prior's answer for a scene seen in a mirror is its answer mirrored, exactly;
    the answer is the mean of the plain one and the mirrored pair's answer mirrored back."""
    prior = SkeletonPrior.load(tiny_prior.path)
    P, X = _rig(), _skeleton(4)
    uv, conf, valid = _observe(P, X)
    conf = conf * np.linspace(0.3, 1.0, NUM_JOINTS)
    valid[1, 3] = False  # a joint one view misses: not symmetric by construction
    S = np.diag([-1.0, 1.0, 1.0, 1.0])
    F = np.array([[-1.0, 0, SIZE - 1], [0, 1, 0], [0, 0, 1]])
    Pm = [F @ p @ S for p in P]
    uvm, _, _ = _observe(Pm, X * [-1.0, 1.0, 1.0])
    flip = list(FLIP_INDEX)
    seen = prior.estimate(uv, conf, valid, P)
    in_mirror = prior.estimate(uvm[:, flip], conf[:, flip], valid[:, flip], Pm)
    np.testing.assert_allclose(in_mirror.points[flip] * [-1.0, 1.0, 1.0], seen.points, atol=1e-5)
    np.testing.assert_allclose(in_mirror.expected_error_m[flip], seen.expected_error_m, rtol=1e-5)
    plain = prior.estimate(uv, conf, valid, P, flip_test=False)
    plain_mirror = prior.estimate(uvm[:, flip], conf[:, flip], valid[:, flip], Pm, flip_test=False)
    np.testing.assert_allclose(seen.points, 0.5 * (plain.points + plain_mirror.points[flip] * [-1.0, 1.0, 1.0]),
                               atol=1e-5)
    np.testing.assert_allclose(seen.expected_error_m,
                               0.5 * (plain.expected_error_m + plain_mirror.expected_error_m[flip]), rtol=1e-5)
    # without it the (3-step) network is not symmetric: the test above is not vacuous
    assert np.abs(plain_mirror.points[flip] * [-1.0, 1.0, 1.0] - plain.points).max() > 1e-4


def test_bad_files_are_refused_with_the_file_named(tiny_prior, tmp_path):
    with pytest.raises(ModelLoadError, match="no such skeleton prior file"):
        SkeletonPrior.load(tmp_path / "nope.onnx")
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(tiny_prior.path.read_bytes()[:500])
    with pytest.raises(ModelLoadError, match=str(broken)):
        SkeletonPrior.load(broken)
    import onnx

    m = onnx.load(str(tiny_prior.path))
    for p in m.metadata_props:
        if p.key == "ghnerf_skeleton.feature_version":
            p.value = "999"
    other = tmp_path / "other.onnx"
    onnx.save(m, str(other))
    with pytest.raises(ModelContractError, match="feature_version") as e:
        SkeletonPrior.load(other)
    assert str(other) in str(e.value)


def test_a_prior_whose_inputs_have_another_rank_is_refused(tiny_prior, tmp_path):
    # the last dimension was read before the rank was checked: a scalar input raised IndexError
    import onnx
    from onnx import TensorProto, helper

    graph = helper.make_graph(
        [helper.make_node("Identity", ["joint_features"], ["joints"]),
         helper.make_node("Identity", ["context"], ["log_error"])], "odd_prior",
        [helper.make_tensor_value_info("joint_features", TensorProto.FLOAT, []),
         helper.make_tensor_value_info("context", TensorProto.FLOAT, ["N", 8])],
        [helper.make_tensor_value_info("joints", TensorProto.FLOAT, []),
         helper.make_tensor_value_info("log_error", TensorProto.FLOAT, ["N", 8])])
    m = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    m.ir_version = 8
    for p in onnx.load(str(tiny_prior.path)).metadata_props:  # the real file's version and joint count
        m.metadata_props.add(key=p.key, value=p.value)
    odd = tmp_path / "scalar.onnx"
    onnx.save(m, str(odd))
    with pytest.raises(ModelContractError, match="input 'joint_features' of width 17 expected") as e:
        SkeletonPrior.load(odd)
    assert str(odd) in str(e.value) and e.value.key == "joint_features"


def test_config_rejects_unknown_modes():
    with pytest.raises(ConfigError, match="skeleton_prior"):
        Joints3DConfig(skeleton_prior="maybe")
    # 'on' with a method that never runs the prior was a load error claiming the folder had no prior
    with pytest.raises(ConfigError, match=r"'on' needs method 'triangulate'.*'volumetric'") as e:
        Joints3DConfig(method="volumetric", skeleton_prior="on")
    assert e.value.key == "Joints3DConfig.skeleton_prior"
    with pytest.raises(ConfigError, match="max_prior_error_m"):
        Joints3DConfig(max_prior_error_m=0.0)
    with pytest.raises(ConfigError, match="prior_flip_test"):
        Joints3DConfig(prior_flip_test="yes")


# ------------------------------------------------------------------------------------------- in the estimator
sim = pytest.importorskip("drivers.sim")


@pytest.fixture(scope="module")
def model_with_prior(tmp_path_factory, tiny_prior):
    from tests.ghnerf_runtime.test_session import export_tiny

    folder = tmp_path_factory.mktemp("with-prior") / "tiny"
    shutil.copytree(export_tiny(tmp_path_factory.mktemp("ghnerf-model")), folder)
    shutil.copy(tiny_prior.path, folder / FILE_NAME)
    return folder


def _config(folder: Path, **joints3d) -> EstimatorConfig:
    cfg = EstimatorConfig()
    return replace(cfg, session=replace(cfg.session, model_dir=str(folder), warmup=False),
                   joints3d=replace(cfg.joints3d, **joints3d), presence=replace(cfg.presence, enabled=False),
                   tracking=replace(cfg.tracking, refine_cold_start=False))  # one pass a pair: prior calls counted


def test_a_prior_beside_another_encoder_than_its_own_is_refused(model_with_prior, tiny_prior, tmp_path):
    """The prior learnt one encoder's 2D errors: the file it names must be the one it was trained on."""
    import hashlib

    from ghnerf_runtime.estimator import load_session
    from training.skeleton_prior import export

    folder = tmp_path / "m"
    shutil.copytree(model_with_prior, folder)
    digest = hashlib.sha256((folder / "encoder.onnx").read_bytes()).hexdigest()
    export(tiny_prior.net, folder / FILE_NAME, {"trained_on": "test", "encoder_file": "encoder.onnx",
                                                "encoder_sha256": digest})
    cfg = _config(folder)
    assert load_session(cfg).skeleton_prior is not None  # its own encoder: taken
    (folder / "encoder.onnx").write_bytes((folder / "encoder.onnx").read_bytes() + b"\0")  # another file
    with pytest.raises(ModelContractError) as e:
        load_session(cfg)
    assert e.value.key == "ghnerf_skeleton.encoder_sha256" and "encoder.onnx" in str(e.value)
    assert "retrain it" in str(e.value) and str(folder / FILE_NAME) in str(e.value)
    export(tiny_prior.net, folder / FILE_NAME, {"trained_on": "test", "encoder_file": "human.int8.onnx",
                                                "encoder_sha256": digest})
    with pytest.raises(ModelContractError, match="human.int8.onnx, which .* does not have") as e:
        load_session(cfg)
    assert e.value.key == "ghnerf_skeleton.encoder_file"


def test_a_prior_naming_an_encoder_file_no_file_can_be_is_refused_by_key(model_with_prior, tiny_prior, tmp_path):
    """A damaged ``encoder_file`` longer than a file name may be was a bare ``OSError: File name too long`` from
    the daemon's start."""
    from ghnerf_runtime.estimator import load_session
    from training.skeleton_prior import export

    folder = tmp_path / "m"
    shutil.copytree(model_with_prior, folder)
    export(tiny_prior.net, folder / FILE_NAME, {"trained_on": "test", "encoder_file": "e" * 300,
                                                "encoder_sha256": "0" * 64})
    with pytest.raises(ModelContractError, match="names the encoder file 'e{60}'\\.\\.\\., which no file in") as e:
        load_session(_config(folder))
    assert e.value.key == "ghnerf_skeleton.encoder_file" and e.value.path == str(folder / FILE_NAME)


def test_a_prior_whose_encoder_file_this_user_may_not_read_is_a_load_error_naming_it(model_with_prior, tiny_prior,
                                                                                    tmp_path):
    """The encoder the prior names need not be a graph the configuration loads (the keypoint path runs
    ``human``): hashing it raised a bare PermissionError, a traceback from the daemon's start."""
    import hashlib
    import subprocess
    import sys

    from tests.unprivileged import unprivileged_prefix
    from training.skeleton_prior import export

    folder = tmp_path / "m"
    shutil.copytree(model_with_prior, folder)
    digest = hashlib.sha256((folder / "encoder.onnx").read_bytes()).hexdigest()
    export(tiny_prior.net, folder / FILE_NAME, {"trained_on": "test", "encoder_file": "encoder.onnx",
                                                "encoder_sha256": digest})
    (folder / "encoder.onnx").chmod(0)
    script = ("import sys\n"
              "from ghnerf_runtime.config import EstimatorConfig, SessionConfig\n"
              "from ghnerf_runtime.estimator import load_session\n"
              "try:\n"
              "    load_session(EstimatorConfig(session=SessionConfig(model_dir=sys.argv[1], warmup=False)))\n"
              "except Exception as e:\n"
              "    print(f'{type(e).__name__}|{e}')\n")
    repo = Path(__file__).resolve().parents[2]
    proc = subprocess.run([*unprivileged_prefix(), sys.executable, "-c", script, str(folder)], capture_output=True,
                          text=True, timeout=120, cwd=repo, env={**os.environ, "PYTHONPATH": str(repo)})
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    kind, message = proc.stdout.strip().split("|", 1)
    assert kind == "ModelLoadError" and message.startswith(f"{folder / 'encoder.onnx'}: cannot read the encoder file")
    assert "Permission denied" in message


@pytest.mark.parametrize("errno_, reason", [(13, "Permission denied"), (5, "Input/output error")])
def test_looking_for_the_encoder_file_failing_is_a_load_error_naming_it_not_no_such_name(tmp_path, monkeypatch,
                                                                                          errno_, reason):
    """Any OSError from looking for the recorded encoder read as "no file can have that name" (the key's fault);
    a folder this user may not search (EACCES: the host runs as root, so stat is made to raise) or a bad disk
    is the file system's, said naming the file and the reason. A missing file is still the prior's mismatch."""
    encoder = tmp_path / "encoder.onnx"
    prior = SkeletonPrior(None, tmp_path / FILE_NAME, {"ghnerf_skeleton.encoder_file": "encoder.onnx",
                                                       "ghnerf_skeleton.encoder_sha256": "0" * 64})
    real_stat = Path.stat

    def failing_stat(path: Path, **kw):
        if path == encoder:
            raise OSError(errno_, os.strerror(errno_), str(path))
        return real_stat(path, **kw)

    with pytest.raises(ModelContractError, match="which .* does not have") as e:  # no such file: the prior's fault
        prior.check_encoder(tmp_path)
    assert e.value.key == "ghnerf_skeleton.encoder_file"
    monkeypatch.setattr(Path, "stat", failing_stat)
    with pytest.raises(ModelLoadError) as e:
        prior.check_encoder(tmp_path)
    assert not isinstance(e.value, ModelContractError) and e.value.path == str(encoder)
    assert str(e.value).startswith(f"{encoder}: cannot look for the encoder file encoder.onnx")
    assert reason in str(e.value)


def test_an_encoder_name_that_is_a_link_loop_is_no_name_a_file_can_have(tmp_path):
    """A link loop is among the names no file can have (``_NO_SUCH_NAME``), but ``Path.is_file`` answered False for
    it, so the check said the folder "does not have" the encoder; ``stat`` says why (too many levels of links)."""
    (tmp_path / "encoder.onnx").symlink_to("encoder.onnx")
    prior = SkeletonPrior(None, tmp_path / FILE_NAME, {"ghnerf_skeleton.encoder_file": "encoder.onnx",
                                                       "ghnerf_skeleton.encoder_sha256": "0" * 64})
    with pytest.raises(ModelContractError, match=r"names the encoder file 'encoder\.onnx', which no file in .* can be "
                                                 r"\(Too many levels of symbolic links\)") as e:
        prior.check_encoder(tmp_path)
    assert e.value.key == "ghnerf_skeleton.encoder_file"


def test_the_prior_replaces_the_single_view_fallback_and_its_graphs(model_with_prior):
    """single_view_fallback beside the prior: the prior places those joints, so the fallback's volume and
    render_heat graphs are neither loaded nor run (they once ran every pair and were never read)."""
    from ghnerf_runtime.estimator import Estimator, load_session

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    both = _config(model_with_prior, single_view_fallback=True, max_prior_error_m=100.0)
    session = load_session(both)
    assert session.skeleton_prior is not None and not session.has("volume") and not session.has("render_heat")
    est = Estimator(session, rig, both)
    assert not est.config.joints3d.single_view_fallback
    est.estimate(frames, sequence=0)
    assert set(session.run_counts) & {"volume", "render_heat"} == set()
    off = _config(model_with_prior, single_view_fallback=True, skeleton_prior="off")  # the fallback alone
    plain = load_session(off)
    assert plain.has("volume") and plain.has("render_heat")
    Estimator(plain, rig, off).estimate(frames, sequence=0)
    assert plain.run_counts["volume"] == plain.run_counts["render_heat"] == 1


def test_estimator_uses_the_prior_when_the_folder_has_one(model_with_prior, tmp_path):
    from ghnerf_runtime.estimator import Estimator, load_session

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)

    calls = []
    auto = _config(model_with_prior, max_prior_error_m=100.0)
    session = load_session(auto)
    assert isinstance(session.skeleton_prior, SkeletonPrior)
    real = session.skeleton_prior.estimate
    session.skeleton_prior.estimate = lambda *a, **k: calls.append(1) or real(*a, **k)
    est = Estimator(session, rig, auto)
    r = est.estimate(frames, sequence=0)
    assert calls == [1]
    # an expected-error gate that nothing passes leaves no joint; the prior is not asked when it is off
    assert Estimator(session, rig, _config(model_with_prior, max_prior_error_m=1e-9)).estimate(frames).missing.all()
    Estimator(session, rig, _config(model_with_prior, skeleton_prior="off")).estimate(frames)
    assert len(calls) == 2
    dc = _config(model_with_prior, method="depth_centroid")  # not a triangulation: nothing to refine
    assert Estimator(load_session(dc), rig, dc).skeleton_prior is None
    assert np.isfinite(r.joints_3d).all() and np.isfinite(r.confidence).all()
    assert ((r.confidence > 0) == ~r.missing).all() and (r.confidence <= 1).all()

    # "on" with a folder without the file: an error that says what to do
    bare = tmp_path / "bare"
    shutil.copytree(model_with_prior, bare)
    (bare / FILE_NAME).unlink()
    on = _config(bare, skeleton_prior="on")
    with pytest.raises(ModelError, match="skeleton_prior.onnx"):
        Estimator(load_session(on), rig, on)
    assert load_session(_config(bare)).skeleton_prior is None


def test_a_joint_the_gate_admits_is_reported_however_large_its_expected_error(model_with_prior):
    """Confidence is exp(-expected error / 0.1 m): past about 10.4 m it underflowed to 0 in float32, and a joint
    with no confidence is missing, so a gate of up to 100 m (``max_prior_error_m``'s range) reported nothing the
    prior expected more than 10.4 m off. Such a joint is reported, with the smallest confidence there is."""
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.skeleton_prior import SkeletonEstimate

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    centre = 0.5 * (rig.volume.min_corner + rig.volume.max_corner)  # inside every box gate
    cfg = _config(model_with_prior, max_prior_error_m=100.0)
    session = load_session(cfg)
    for error_m, expect in ((20.0, True), (101.0, False)):
        session.skeleton_prior.estimate = lambda *a, e=error_m, **k: SkeletonEstimate(
            np.tile(centre, (NUM_JOINTS, 1)), np.full(NUM_JOINTS, e), np.ones(NUM_JOINTS, bool))
        r = Estimator(session, rig, cfg).estimate(frames, sequence=0)
        assert (~r.missing).all() == expect and (r.missing.all() != expect), (error_m, r.missing)
        assert ((r.confidence > 0) == ~r.missing).all() and (r.confidence < 1e-30).all()


def test_inputs_triangulate_as_the_general_dlt():
    """prior_inputs solves each pair with the lean two-view solver; its points, reprojection errors and ray
    angles are triangulate_dlt's (the features the shipped prior was trained on), noisy and hidden joints too."""
    from ghnerf_runtime.geometry.triangulation import triangulate_dlt

    rng = np.random.default_rng(7)
    P = np.stack(_rig(yaw_deg=25.0, shift=(0.4, -0.2)))
    X = _skeleton(3)
    uv, _, valid = _observe(list(P), X)
    uv = uv + rng.normal(0.0, 1.5, uv.shape)
    conf = rng.uniform(0.05, 1.0, valid.shape)
    valid[0, 4] = valid[1, 9] = False
    inp = prior_inputs(uv[None], conf[None], valid[None], P[None])
    ref = triangulate_dlt(np.where(valid[..., None], uv, 0.0), list(P), np.where(valid, np.maximum(conf, 1e-3), 0.0))
    tri = inp.triangulated[0]
    assert tri.sum() == NUM_JOINTS - 2 and not tri[4] and not tri[9]
    f = inp.joint_features[0]
    np.testing.assert_allclose(inp.frame.to_rig(f[None, :, :3].astype(np.float64))[0][tri], ref.points[tri], atol=2e-5)
    np.testing.assert_allclose(f[tri, 6:8], np.clip(ref.reprojection_error[tri], 0, 20) / 5.0, atol=1e-5)
    np.testing.assert_allclose(f[tri, 8], ref.ray_angle_deg[tri] / 10.0, atol=1e-5)


def test_disagreement_is_the_median_distance_over_the_triangulated_joints():
    from ghnerf_runtime.errors import ShapeError
    from ghnerf_runtime.skeleton_prior import MIN_CHECK_JOINTS, disagreement_m

    X = _skeleton(1)
    moved = X.copy()
    moved[:, 2] += np.linspace(0.0, 0.48, NUM_JOINTS)  # 0, 0.02, ..., 0.48 m apart
    every = np.ones(NUM_JOINTS, bool)
    assert disagreement_m(moved, X, every) == pytest.approx(0.24)
    few = np.zeros(NUM_JOINTS, bool)
    few[-MIN_CHECK_JOINTS:] = True  # 0.40 ... 0.48: the untriangulated joints do not count
    assert disagreement_m(moved, X, few) == pytest.approx(0.44)
    few[-MIN_CHECK_JOINTS] = False
    assert disagreement_m(moved, X, few) is None  # too few to tell
    with pytest.raises(ShapeError, match="triangulated"):
        disagreement_m(moved, X, every[:-1])


@pytest.mark.parametrize("offset_m, limit_m, falls_back", [(0.5, 0.25, True), (0.05, 0.25, False), (0.5, 0.0, False)])
def test_a_prior_that_disagrees_with_the_triangulation_falls_back_to_it(model_with_prior, monkeypatch, offset_m,
                                                                        limit_m, falls_back):
    """A prior skeleton far from the well-triangulated joints (a pose the prior never learnt: lying, upside down)
    is not reported: the pair gets the triangulated joints, as without the prior, and says so. One that agrees
    keeps the prior's joints; ``max_prior_disagreement_m: 0`` turns the check off."""
    from ghnerf_runtime import estimator as estimator_module
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.joints3d import Joints3D, ViewAgreement
    from ghnerf_runtime.skeleton_prior import SkeletonEstimate

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    centre = 0.5 * (rig.volume.min_corner + rig.volume.max_corner)  # inside every box gate
    truth = centre + 0.3 * (_skeleton(2) - _skeleton(2).mean(0))
    tri = Joints3D(truth, np.full(NUM_JOINTS, 0.9, np.float32), np.ones(NUM_JOINTS, bool), np.zeros((NUM_JOINTS, 2)))
    # the estimator's one solve (joints and the views' agreement, since session 53)
    solve = (tri, ViewAgreement(None, 0, 0))
    monkeypatch.setattr(estimator_module, "triangulate_joints_checked", lambda *a, **k: solve)
    cfg = _config(model_with_prior, max_prior_disagreement_m=limit_m)
    session = load_session(cfg)
    prior_points = truth + [0.0, 0.0, offset_m]
    session.skeleton_prior.estimate = lambda *a, **k: SkeletonEstimate(
        prior_points, np.full(NUM_JOINTS, 0.02), np.ones(NUM_JOINTS, bool))
    r = Estimator(session, rig, cfg).estimate(frames, sequence=0)
    assert not r.missing.any()
    np.testing.assert_allclose(r.joints_3d, truth if falls_back else prior_points, atol=1e-9)
    np.testing.assert_allclose(r.confidence, 0.9 if falls_back else np.exp(-0.2), rtol=1e-6)
    assert r.prior_fallback is falls_back and r.prior_disagreement_m == pytest.approx(offset_m)
    obj = r.to_json()
    assert obj["prior_fallback"] is falls_back and obj["prior_disagreement_m"] == pytest.approx(offset_m)


def test_the_crop_follows_every_joint_the_follow_gate_keeps(model_with_prior):
    """The crop follows the prior's joints expected within ``_PRIOR_FOLLOW_MAX_ERROR_M`` (0.25 m), or the report
    gate if looser (docs/runtime.md). Their score exp(-error / 0.1 m) is below tracking.min_confidence (0.1) past
    0.23 m, and the track dropped them: a skeleton expected 0.24 m off, or 0.4 m off under a 0.5 m report gate,
    held no track. The gate itself still holds: 0.26 m (default report gate) forms none."""
    from ghnerf_runtime.estimator import _PRIOR_FOLLOW_MAX_ERROR_M, Estimator, load_session
    from ghnerf_runtime.skeleton_prior import SkeletonEstimate

    assert _PRIOR_FOLLOW_MAX_ERROR_M == 0.25  # the case below sits between 0.23 m and it
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    centre = 0.5 * (rig.volume.min_corner + rig.volume.max_corner)  # inside every box gate
    skeleton = centre + np.linspace(-0.3, 0.3, NUM_JOINTS)[:, None] * np.array([0.3, 1.0, 0.2])
    for report_m, error_m, tracked in ((0.15, 0.24, True), (0.15, 0.26, False), (0.5, 0.4, True), (0.5, 0.55, False)):
        cfg = _config(model_with_prior, max_prior_error_m=report_m)
        session = load_session(cfg)
        session.skeleton_prior.estimate = lambda *a, e=error_m, **k: SkeletonEstimate(
            skeleton, np.full(NUM_JOINTS, e), np.ones(NUM_JOINTS, bool))
        est = Estimator(session, rig, cfg)
        r = est.estimate(frames, sequence=0)
        assert r.missing.all() == (error_m > report_m), (report_m, error_m)
        assert (est.tracker.track is not None) == tracked, (report_m, error_m)
        if tracked:
            np.testing.assert_allclose(est.tracker.track.joints, skeleton, atol=1e-6)


@pytest.mark.parametrize("subject_joints, someone", [(3, False), (8, True)])
def test_two_people_the_subject_s_own_peaks_must_make_someone_with_the_prior_as_without(model_with_prior, monkeypatch,
                                                                                       subject_joints, someone):
    """A several_people pair reports the tracked subject only if the subject's own peaks make someone (the presence
    gate's ``min_joints``, 6): without the prior the kept joints were gated, with it not, and the prior, fed both
    people's peaks, placed a whole skeleton near the track from 3 of the subject's joints. Stubbed: the second
    pair's triangulation is the subject's for ``subject_joints`` joints and a second person's 0.3 m off elsewhere
    (all strong: the pair shows someone), and the pairings of peaks and runner-ups add nothing."""
    from ghnerf_runtime import estimator as estimator_module
    from ghnerf_runtime import subject as subject_module
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.joints3d import Joints3D, ViewAgreement
    from ghnerf_runtime.skeleton_prior import SkeletonEstimate

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    frames = tuple(scene.render(c, 0.0, with_truth=False)[0] for c in rig.pair)
    centre = 0.5 * (rig.volume.min_corner + rig.volume.max_corner)  # inside every box gate
    truth = centre + 0.3 * (_skeleton(2) - _skeleton(2).mean(0))
    strong, every = np.full(NUM_JOINTS, 0.9, np.float32), np.ones(NUM_JOINTS, bool)
    alone = Joints3D(truth, strong, every, np.zeros((NUM_JOINTS, 2)))
    mixed = np.where((np.arange(NUM_JOINTS) < subject_joints)[:, None], truth, truth + [0.3, 0.0, 0.0])
    pair = {"tri": alone, "several": False}
    def pairings(uv, *a, **k):  # the four pairings (J each): the decoded peaks' is the pair's, the rest none
        assert np.shape(uv)[1] == 4 * NUM_JOINTS
        t = pair["tri"]
        return Joints3D(np.tile(t.points, (4, 1)), np.tile(t.confidence, 4),
                        np.concatenate([t.valid, np.zeros(3 * NUM_JOINTS, bool)]), np.tile(t.reprojection_px, (4, 1)))

    def checked(uv, *a, **k):  # the pair's peaks, or (both people's figures, since session 57) the four pairings
        tri = pairings(uv) if np.shape(uv)[1] == 4 * NUM_JOINTS else pair["tri"]
        return tri, ViewAgreement(None, 0, 0)

    for module in (estimator_module, subject_module):  # the pair's peaks, and the subject's pairings
        monkeypatch.setattr(module, "triangulate_joints_checked", checked)
        monkeypatch.setattr(module, "triangulate_joints", pairings)
    found = {}
    for mode in ("on", "off"):
        cfg = _config(model_with_prior, skeleton_prior=mode)
        cfg = replace(cfg, presence=replace(cfg.presence, enabled=True))
        session = load_session(cfg)
        if mode == "on":
            session.skeleton_prior.estimate = lambda *a, **k: SkeletonEstimate(truth, np.full(NUM_JOINTS, 0.02), every)
        est = Estimator(session, rig, cfg)
        monkeypatch.setattr(est.subject_selector, "several_people", lambda kp, held: pair["several"])
        pair.update(tri=alone, several=False)
        assert est.estimate(frames, sequence=0).num_found == NUM_JOINTS and est.tracker.track is not None
        pair.update(tri=Joints3D(mixed, strong, every, np.zeros((NUM_JOINTS, 2))), several=True)
        r = est.estimate(frames, sequence=1)
        assert r.several_people
        found[mode] = r.num_found
        if someone:  # the subject's joints only (the prior's skeleton near the track, or the triangulated ones)
            assert np.linalg.norm(r.joints_3d[~r.missing] - truth[~r.missing], axis=-1).max() < 0.15, mode
    assert (found["on"] > 0, found["off"] > 0) == (someone, someone), found


def _collected(n: int, seed: int = 0) -> dict:
    """``n`` noisy pairs of the test rig as :func:`training.skeleton_prior.collect` returns them."""
    rng = np.random.default_rng(seed)
    P = np.stack(_rig())
    truth = np.stack([_skeleton(s) for s in range(n)])
    obs = [_observe(P, X) for X in truth]
    return {"uv": np.stack([o[0] for o in obs]) + rng.normal(0, 1.0, (n, 2, NUM_JOINTS, 2)),
            "confidence": np.stack([o[1] for o in obs]), "valid": np.stack([o[2] for o in obs]),
            "P": np.broadcast_to(P, (n, 2, 3, 4)).copy(), "joints_3d": truth,
            "joints_3d_valid": np.ones((n, NUM_JOINTS), bool), "encoder_file": np.array("human.int8.onnx")}


def test_a_tilted_copy_keeps_the_2d_inputs_and_turns_the_body_against_the_rigs_up():
    """``tilt_scenes`` turns scenes as a whole (true joints and cameras): the cameras see what they saw, so the
    collected peaks are exactly the tilted scene's and every 2D feature is unchanged, while in the canonical
    frame (the rig's up kept) the body now lies at the tilt's angle."""
    pytest.importorskip("torch")
    from training.skeleton_prior import inputs_of, scene_tilt, tilt_scenes

    arrays = _collected(8)
    out = tilt_scenes(arrays, 0.5, seed=3)
    assert len(out["uv"]) == 12 and str(out["encoder_file"]) == "human.int8.onnx"
    for k in ("uv", "confidence", "valid", "P", "joints_3d"):
        np.testing.assert_array_equal(out[k][:8], arrays[k])  # the scenes themselves stay
    # which scenes were copied: their peaks are the copies' peaks, unchanged
    src = [int(np.flatnonzero((arrays["uv"] == u).all((1, 2, 3)))[0]) for u in out["uv"][8:]]
    assert len(set(src)) == 4
    for k in ("uv", "confidence", "valid", "joints_3d_valid"):
        np.testing.assert_array_equal(out[k][8:], arrays[k][src])
    # the tilted cameras project the tilted joints onto the same pixels (the 2D peaks are exact images)
    for i, s in enumerate(src):
        for v in range(2):
            def pix(P, X):
                h = np.c_[X, np.ones(len(X))] @ P.T
                return h[:, :2] / h[:, 2:]
            np.testing.assert_allclose(pix(out["P"][8 + i, v], out["joints_3d"][8 + i]),
                                       pix(arrays["P"][s, v], arrays["joints_3d"][s]), atol=1e-6)
    base, base_truth = inputs_of({k: v[src] if k != "encoder_file" else v for k, v in arrays.items()})
    tilt, tilt_truth = inputs_of({k: v[8:] if k != "encoder_file" else v for k, v in out.items()})
    assert (tilt.triangulated == base.triangulated).all()
    # what the peaks alone give is the same: triangulated or not, peak values, rays' angle, decoded flags
    for cols in (slice(3, 6), slice(8, 9), slice(15, 17)):
        np.testing.assert_array_equal(tilt.joint_features[..., cols], base.joint_features[..., cols])
    # the DLT's algebraic minimum (a unit 4-vector) depends a little on where the world's origin lies: with a
    # pixel of noise the reprojection error moves between the views (their sum by under 0.1 px) and a point
    # by a millimetre or so (more along a poorly conditioned depth), what the device itself would give there
    rep = lambda f: 5.0 * f[..., 6:8].sum(-1)  # noqa: E731
    np.testing.assert_allclose(rep(tilt.joint_features), rep(base.joint_features), rtol=0, atol=0.1)
    # the triangulated points are the same points, moved with the scene
    G = np.stack([scene_tilt(arrays["joints_3d"][s], np.ones(NUM_JOINTS, bool), 0.0, 0.0) for s in src])
    assert np.allclose(G, np.eye(4))  # (no tilt is no motion)
    X_base = base.frame.to_rig(base.joint_features[..., :3].astype(np.float64))
    X_tilt = tilt.frame.to_rig(tilt.joint_features[..., :3].astype(np.float64))
    moved = [np.linalg.lstsq(np.c_[arrays["joints_3d"][s], np.ones(NUM_JOINTS)],
                             np.c_[out["joints_3d"][8 + i], np.ones(NUM_JOINTS)], rcond=None)[0].T
             for i, s in enumerate(src)]
    apart = [np.linalg.norm((np.c_[X_base[i], np.ones(NUM_JOINTS)] @ moved[i].T)[:, :3] - X_tilt[i], axis=-1)
             for i in range(4)]
    assert np.median(apart) < 0.005 and np.max(apart) < 0.1  # the DLT's own error here: 75 mm median
    # the canonical body is turned: its principal (long) axis was vertical, now it is not, by the drawn angles
    def long_axis(J):
        return np.linalg.svd(J - J.mean(0))[2][0]
    tilt_deg = [np.degrees(np.arccos(abs(long_axis(a) @ long_axis(b)))) for a, b in zip(base_truth, tilt_truth)]
    assert max(tilt_deg) > 20.0
    assert all(abs(long_axis(a)[1]) > 0.7 for a in base_truth)  # the test skeletons are tall, upright
    # a tilt rests the body on the floor it stood on: its lowest joint as high as before
    np.testing.assert_allclose(out["joints_3d"][8:, :, 1].max(1), arrays["joints_3d"][src, :, 1].max(1), atol=1e-9)


def test_tilt_share_is_checked_and_its_draws_are_the_seeds():
    pytest.importorskip("torch")
    from training.skeleton_prior import PriorTrainConfig, tilt_scenes

    arrays = _collected(10)
    assert tilt_scenes(arrays, 0.0, seed=0) is arrays
    a, b, c = (tilt_scenes(arrays, 0.3, seed=s) for s in (1, 1, 2))
    assert len(a["uv"]) == 13
    np.testing.assert_array_equal(a["joints_3d"], b["joints_3d"])  # the same seed, the same copies
    assert not np.allclose(a["joints_3d"][10:], c["joints_3d"][10:])
    arrays["joints_3d_valid"][:9] = False  # only scene 9 has a true joint: the only one worth a copy
    one = tilt_scenes(arrays, 1.0, seed=0)
    assert len(one["uv"]) == 11 and np.array_equal(one["uv"][10], arrays["uv"][9])
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="tilt"):
            tilt_scenes(arrays, bad, seed=0)
        with pytest.raises(ValueError, match=f"tilt_share must be a share from 0 to 1, not {bad!r}"):
            PriorTrainConfig(tilt_share=bad)


def test_a_turned_body_is_seen_by_the_same_cameras_with_the_encoders_errors_carried_over():
    """``turn_bodies`` turns the body alone: the cameras stay where they stood (their crops refitted, a pixel
    scale and shift), each peak is the turned joint's image plus the collected peak's own error, and a peak that
    leaves the crop is not decoded."""
    pytest.importorskip("torch")
    from ghnerf_runtime.skeleton_prior import _centres
    from training.skeleton_prior import _project, inputs_of, turn_bodies

    arrays = _collected(8)
    out = turn_bodies(arrays, 0.5, seed=3, size=SIZE)
    assert len(out["uv"]) == 12
    for k in ("uv", "confidence", "valid", "P", "joints_3d"):
        np.testing.assert_array_equal(out[k][:8], arrays[k])
    # which scenes were copied: a turned body rests as low as it stood (the test skeletons' lowest joints differ)
    src = [int(np.flatnonzero(np.isclose(arrays["joints_3d"][:, :, 1].max(1), Y[:, 1].max(), rtol=0, atol=1e-9))[0])
           for Y in out["joints_3d"][8:]]
    assert len(set(src)) == 4
    for i, s in enumerate(src):
        X, Y = arrays["joints_3d"][s], out["joints_3d"][8 + i]
        # a rigid turn of the body, set on the floor it stood on; the cameras' centres did not move
        np.testing.assert_allclose(np.linalg.norm(Y - Y.mean(0), axis=-1), np.linalg.norm(X - X.mean(0), axis=-1))
        np.testing.assert_allclose(_centres(out["P"][8 + i]), _centres(arrays["P"][s]), atol=1e-9)
        for v in range(2):
            err = arrays["uv"][s, v] - _project(arrays["P"][s, v], X)[0]  # the collected peaks' 2D errors
            dec = out["valid"][8 + i, v]
            np.testing.assert_allclose(out["uv"][8 + i, v][dec], (_project(out["P"][8 + i, v], Y)[0] + err)[dec],
                                       atol=1e-9)
    tilted, truth = inputs_of({k: (v[8:] if k != "encoder_file" else v) for k, v in out.items()})
    assert tilted.triangulated.mean() > 0.9
    # in the canonical frame (the rig's up) the tall test bodies no longer all stand
    assert min(abs(np.linalg.svd(J - J.mean(0))[2][0][1]) for J in truth) < 0.7
    # a crop too small for the body: peaks outside it are not decoded (and keep no pixels)
    small = turn_bodies(arrays, 0.5, seed=3, size=40)
    lost = ~small["valid"][8:] & out["valid"][8:]
    assert lost.any() and (small["uv"][8:][lost] == 0).all()
    assert ((small["uv"][8:][small["valid"][8:]] >= 0) & (small["uv"][8:][small["valid"][8:]] <= 39)).all()


def test_the_out_of_range_measure_reads_the_prior_it_is_given(tiny_prior, tmp_path, capsys, monkeypatch):
    """``measure_prior_out_of_range.py --prior FILE`` measures that file (here beside a model folder with none),
    and refuses ``--held-out``, which runs the model folder's own prior."""
    import runpy
    import sys

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "measure_prior_out_of_range.py"

    def run(*args):
        monkeypatch.setattr(sys, "argv", [str(path), *args])
        with pytest.raises(SystemExit) as e:
            runpy.run_path(str(path), run_name="__main__")
        return e.value.code, capsys.readouterr()

    code, out = run("--model-dir", str(tmp_path), "--scenes", "1", "--prior", str(tiny_prior.path))
    assert code == 0
    rows = [line for line in out.out.splitlines() if line.startswith(("upright", "lying", "upside"))]
    assert len(rows) == 4 and all("mm" in r for r in rows)
    code, out = run("--prior", str(tiny_prior.path), "--held-out", str(tmp_path))
    assert code == 2 and "--held-out runs the model folder's own prior" in out.err


def _noisy_cases(P: np.ndarray, count: int = 3) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``count`` pairs' peaks, values and decoded flags of skeletons in the cameras ``P`` ``(1, 2, 3, 4)``: noisy,
    some joints undecoded, values from 0.24 to 0.8."""
    rng = np.random.default_rng(1)
    cases = []
    for seed in range(count):
        uv, conf, valid = _observe(list(P[0]), _skeleton(seed))
        valid = valid & (rng.random(valid.shape) > 0.2)
        cases.append((uv[None] + rng.normal(0, 1.0, uv.shape), conf[None] * rng.uniform(0.3, 1.0, conf.shape),
                      valid[None]))
    return cases


def _same_inputs(got, want) -> None:
    for name in ("joint_features", "context", "triangulated"):
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert np.array_equal(got.frame.rotation, want.frame.rotation)
    assert np.array_equal(got.frame.origin, want.frame.origin)


def test_inputs_with_the_cameras_terms_given_are_the_same_to_the_bit(monkeypatch):
    """The crop cameras' centres, heading and inverses (PriorCameras.from_P), computed once where a tracked crop
    keeps its cameras for many pairs, give the inputs computed without them; without them every call computes
    them (no state kept between calls); terms of other matrices are refused by name."""
    from ghnerf_runtime import skeleton_prior
    from ghnerf_runtime.errors import GeometryError
    from ghnerf_runtime.skeleton_prior import PriorCameras

    P = np.stack(_rig(20.0, (0.3, -0.2)))[None]
    cases = _noisy_cases(P)
    calls = []
    real = skeleton_prior._centres
    monkeypatch.setattr(skeleton_prior, "_centres", lambda p: calls.append(1) or real(p))
    fresh = [prior_inputs(uv, conf, valid, P) for uv, conf, valid in cases]
    assert len(calls) == len(cases)
    calls.clear()
    terms = PriorCameras.from_P(P)
    for (uv, conf, valid), want in zip(cases, fresh):
        _same_inputs(prior_inputs(uv, conf, valid, P.copy(), cameras=terms), want)
    assert len(calls) == 1
    moved = P.copy()
    moved[..., 3] += 0.1  # the caller's array changed in place: other cameras
    assert terms.is_for(P) and not terms.is_for(moved)
    with pytest.raises(GeometryError, match="other matrices"):
        prior_inputs(*cases[0], moved, cameras=terms)


def _rigs_of_every_handedness() -> list[np.ndarray]:
    """``(2, 3, 4)`` crop camera pairs: turned, shifted, scaled by a negative factor (a determinant's sign flipped,
    a ray's way to the scene with it) and mirrored (one camera's)."""
    rigs = [np.stack(_rig(yaw, shift)) for yaw, shift in ((0.0, (0.0, 0.0)), (20.0, (0.3, -0.2)), (-75.0, (1.1, 0.4)))]
    flipped = rigs[1] * np.array([-1.0, 2.5])[:, None, None]  # (a P scaled by -1 is the same camera)
    mirrored = rigs[2].copy()
    mirrored[0] = mirrored[0] @ np.diag([-1.0, 1.0, 1.0, 1.0])
    return rigs + [flipped, mirrored]


def test_prior_terms_built_from_the_two_view_terms_are_from_p_s_to_the_bit_and_solve_in_them(monkeypatch):
    """PriorCameras.from_two_view takes the inverses and the determinants' signs from the two-view solver's terms
    (the estimator built both from its crop matrices, inverting them twice): every term is from_P's to the bit, the
    inputs built with them are those built without, and each pair's peaks are solved in the kept two-view terms (none
    computed again); terms of other matrices are refused by name, before any solve."""
    from ghnerf_runtime.errors import GeometryError, ShapeError
    from ghnerf_runtime.geometry import triangulation
    from ghnerf_runtime.geometry.triangulation import TwoViewCameras
    from ghnerf_runtime.skeleton_prior import PriorCameras

    for P2 in _rigs_of_every_handedness():
        P = P2[None]
        kept = PriorCameras.from_two_view([TwoViewCameras.from_P(P2)])
        fresh = PriorCameras.from_P(P)
        for name in ("P", "centres", "mid", "heading", "inverse", "towards_scene"):
            got, want = getattr(kept, name), getattr(fresh, name)
            assert got.shape == want.shape and got.tobytes() == want.tobytes(), name
            assert not got.flags.writeable, name
        assert fresh.two_view is None and kept.two_view[0].is_for(P2)
        terms = []
        real_terms = triangulation.TwoViewCameras.from_P
        monkeypatch.setattr(triangulation.TwoViewCameras, "from_P", lambda p: terms.append(1) or real_terms(p))
        for uv, conf, valid in _noisy_cases(P, 2):
            want = prior_inputs(uv, conf, valid, P)
            calls = len(terms)
            _same_inputs(prior_inputs(uv, conf, valid, P.copy(), cameras=kept), want)
            assert len(terms) == calls  # solved in the kept terms
        monkeypatch.undo()
    moved = P.copy()
    moved[..., 3] += 0.1
    with pytest.raises(GeometryError, match="prior's camera terms .* other matrices"):
        prior_inputs(*_noisy_cases(P, 1)[0], moved, cameras=kept)
    with pytest.raises(ShapeError, match="from_two_view"):
        PriorCameras.from_two_view([])


def test_inputs_reuse_a_solve_of_their_own_peaks_and_the_camera_terms_of_another(monkeypatch):
    """The estimator passes the pair's solve of the joints' peaks: where the prior's weights are the joints' (every
    decoded peak's value in [0.001, 1]) the inputs take it whole (no DLT of their own), else they solve with its
    camera terms; the inputs are the same to the bit either way, and a solve per pair is needed."""
    from ghnerf_runtime.errors import ShapeError
    from ghnerf_runtime.geometry import triangulation
    from ghnerf_runtime.geometry.triangulation import solve_two_views

    P = np.stack(_rig(-10.0, (0.1, 0.4)))[None]
    uv, conf, valid = _noisy_cases(P, 1)[0]
    want = prior_inputs(uv, conf, valid, P)
    weights = np.where(valid, conf, 0.0)[0]  # the prior's weights: these values are all in [0.001, 1]
    own = solve_two_views(np.where(valid[..., None], uv, 0.0)[0], P[0], weights)
    other = solve_two_views(np.where(valid[..., None], uv, 0.0)[0], P[0], np.where(valid, 1.0, 0.0)[0])
    svd, terms = [], []
    real_svd, real_terms = triangulation._solve_two_views, triangulation.TwoViewCameras.from_P
    monkeypatch.setattr(triangulation, "_solve_two_views", lambda *a: svd.append(1) or real_svd(*a))
    monkeypatch.setattr(triangulation.TwoViewCameras, "from_P", lambda p: terms.append(1) or real_terms(p))
    _same_inputs(prior_inputs(uv, conf, valid, P, solutions=[own]), want)
    assert (len(svd), len(terms)) == (0, 0)
    _same_inputs(prior_inputs(uv, conf, valid, P, solutions=[other]), want)
    assert (len(svd), len(terms)) == (1, 0)
    _same_inputs(prior_inputs(uv, conf, valid, P, solutions=[None]), want)
    assert (len(svd), len(terms)) == (2, 1)
    with pytest.raises(ShapeError, match="one per pair"):
        prior_inputs(uv, conf, valid, P, solutions=[own, own])


class _InputsPrior:
    """A stand-in prior that records what the estimator feeds it (``fed``: the arguments of each call, the camera
    terms and solve included) and answers the triangulation of the peaks."""

    def __init__(self) -> None:
        self.fed: list[tuple] = []

    def estimate(self, uv_model, confidence, valid, P, flip_test=True, *, cameras=None, solutions=None):
        from ghnerf_runtime.geometry.triangulation import triangulate_two_views
        from ghnerf_runtime.skeleton_prior import SkeletonEstimate

        P = np.asarray([np.asarray(p, np.float64) for p in P])
        self.fed.append((uv_model[None], confidence[None], valid[None], P[None], cameras, solutions))
        r = triangulate_two_views(uv_model, P, np.where(valid, confidence, 0.0), cameras=solutions[0].cameras)
        return SkeletonEstimate(r.points, np.where(r.valid, 0.02, np.inf), r.valid)


def test_the_estimator_keeps_the_crop_cameras_terms_while_its_crops_keep_their_cameras(monkeypatch):
    """The estimator computes its crop cameras' terms (the two-view solver's, the prior's) when the crops' matrices
    change, and reuses them while they stay (compared by value); reset() forgets them. One DLT a pass serves the
    joints and the prior's inputs, and the inputs built with what the estimator passes are those built without."""
    from benchmarks.bench_runtime_common import OracleSession, edge128_contract
    from ghnerf_runtime import estimator as estimator_module
    from ghnerf_runtime.estimator import Estimator
    from ghnerf_runtime.geometry import triangulation
    from ghnerf_runtime.geometry.triangulation import TwoViewCameras
    from ghnerf_runtime.skeleton_prior import PriorCameras

    made, made_prior, passes, solves = [], [], [], []
    real_two, real_prior = TwoViewCameras.from_P, PriorCameras.from_two_view
    monkeypatch.setattr(TwoViewCameras, "from_P", lambda p: made.append(1) or real_two(p))
    # (the prior's terms are built from the two-view solver's: PriorCameras.from_two_view)
    monkeypatch.setattr(PriorCameras, "from_two_view", lambda pairs: made_prior.append(1) or real_prior(pairs))
    real_peaks = estimator_module.solve_two_view_peaks

    def peaks(uv, conf, valid, crops, config, *, terms):
        passes.append((np.stack([c.P for c in crops]), terms))
        return real_peaks(uv, conf, valid, crops, config, terms=terms)

    monkeypatch.setattr(estimator_module, "solve_two_view_peaks", peaks)
    real_solve = triangulation._solve_two_views
    monkeypatch.setattr(triangulation, "_solve_two_views", lambda *a: solves.append(1) or real_solve(*a))

    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=5, motion="wave"))
    oracle = OracleSession(edge128_contract())
    oracle.skeleton_prior = prior = _InputsPrior()
    with Estimator(oracle, rig, EstimatorConfig(joints3d=Joints3DConfig(skeleton_prior="on"))) as est:
        for i in range(8):
            t = i / 30.0
            oracle.set_truth(scene.joints_3d(t))
            est.estimate(tuple(scene.render(c, t, with_truth=False)[0] for c in rig.pair))
        changes = 1 + sum(not np.array_equal(a[0], b[0]) for a, b in zip(passes, passes[1:]))
        kept = sum(a[1] is b[1] for a, b in zip(passes, passes[1:]))
        assert len(passes) >= 8 and 2 <= changes and kept >= 3, (len(passes), changes, kept)
        assert len(made) == len(made_prior) == changes  # once per crop cameras' change, never per pass
        for (P_a, terms_a), (P_b, terms_b) in zip(passes, passes[1:]):
            assert (terms_a is terms_b) == np.array_equal(P_a, P_b)
            assert terms_b.is_for(P_b)
        solved = len(solves)
        for *args, cameras, solutions in prior.fed:  # the inputs with the terms and solve passed, and without
            _same_inputs(prior_inputs(*args, cameras=cameras, solutions=solutions), prior_inputs(*args))
        assert len(prior.fed) == len(passes)
        est.reset()
        assert est._crop_terms is None
    assert solved == 2 * len(passes)  # a pass's DLT for the joints and the prior's inputs, and the stand-in's own
