"""Evaluation metrics on fake model outputs with known answers (``training.evaluate``)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch")

from ghnerf_runtime.contract import ray_grid  # noqa: E402
from ghnerf_runtime.flip_test import unmirror_heatmaps  # noqa: E402
from ghnerf_runtime.keypoints import model_to_heatmap_pixels  # noqa: E402
from ghnerf_runtime.metrics import gaussian_heatmaps  # noqa: E402
from training.evaluate import (Accumulator, evaluate, keypoints_from_heatmaps, psnr_by_angle,  # noqa: E402
                               scene_metrics, source_angles_deg)


def _scene(data64, i=0):
    from training.data.torch_dataset import MultiViewDataset

    return {k: v.numpy() for k, v in MultiViewDataset(data64, "val")[i].items()}


def test_keypoints_are_decoded_in_crop_pixels():
    joints = np.array([[[10.0, 20.0], [33.3, 41.7], [0.0, 0.0]]])  # model pixels of a 64 px crop
    vis = np.array([[True, True, False]])
    hm = gaussian_heatmaps(model_to_heatmap_pixels(joints, 16, 64), vis, 16, 1.5)
    uv = keypoints_from_heatmaps(hm, 64)
    assert np.allclose(uv[0, :2], joints[0, :2], atol=0.05)
    assert np.isnan(uv[0, 2]).all()  # no peak: missing, never (0, 0)


def test_perfect_outputs_score_perfectly(data64):
    sc = _scene(data64)
    nov = np.flatnonzero(~sc["tgt_is_source"])
    m = sc["tgt_masks"][nov][:, None]
    truth = sc["tgt_images"][nov] * m
    offset = np.where(truth > 0.5, -0.1, 0.1) * m  # |error| 0.1 on every mask pixel and channel: PSNR 20 dB
    r = scene_metrics(sc, sc["tgt_heatmaps"][:2], truth + offset, nov)
    assert r["heatmap_mse"].value == 0.0
    assert r["pck"].value == 1.0 and r["pck"].num_evaluated == sc["tgt_visible"][:2].sum()
    both = sc["tgt_visible"][0] & sc["tgt_visible"][1]
    assert r["mpjpe"].num_evaluated == both.sum()  # a joint needs both views to be triangulated
    assert r["mpjpe"].value < 0.5  # mm: decoding + DLT of exact Gaussians
    assert r["psnr"].value == pytest.approx(20.0, abs=1e-9)
    # SSIM of that offset: a plain per-pixel evaluation of the documented definition (11x11 Gaussian window,
    # sigma 1.5, restricted to the mask; K1 0.01, K2 0.03), mean over mask pixels, channels, then views
    expected = np.mean([np.mean([_reference_ssim((truth + offset)[i, c], truth[i, c], m[i, 0] > 0.5)
                                 for c in range(3)]) for i in range(len(nov))])
    assert 0.55 < expected < 0.75  # 0.64 for this scene: far from the 1.0 of identical images
    assert r["ssim"].value == pytest.approx(expected, abs=1e-6)
    assert r["ssim"].per_image.shape == (len(nov),)
    exact = scene_metrics(sc, sc["tgt_heatmaps"][:2], truth, nov)  # no offset at all
    assert exact["ssim"].value == pytest.approx(1.0, abs=1e-9) and exact["psnr"].value == np.inf


def _reference_ssim(x, y, mask):
    """Masked Gaussian-window SSIM of one channel, pixel by pixel (no blur)."""
    k = np.exp(-(np.arange(11) - 5.0) ** 2 / (2 * 1.5 ** 2))
    kernel = np.outer(k, k)
    H, W = mask.shape
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    values = []
    for r, c in np.argwhere(mask):
        r0, r1, c0, c1_ = max(r - 5, 0), min(r + 6, H), max(c - 5, 0), min(c + 6, W)
        w = kernel[r0 - r + 5:r1 - r + 5, c0 - c + 5:c1_ - c + 5] * mask[r0:r1, c0:c1_]
        w = w / w.sum()
        a, b = x[r0:r1, c0:c1_].astype(np.float64), y[r0:r1, c0:c1_].astype(np.float64)
        ma, mb = (w * a).sum(), (w * b).sum()
        va, vb = (w * a * a).sum() - ma * ma, (w * b * b).sum() - mb * mb
        cov = (w * a * b).sum() - ma * mb
        values.append((2 * ma * mb + c1) * (2 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2)))
    return np.mean(values)


def test_shifted_joints_and_pooling(data64):
    sc = _scene(data64)
    S = 2
    true2d = sc["tgt_joints_2d"][:S]
    vis = sc["tgt_visible"][:S]
    # move every joint of view 0 by 2 torso lengths: wrong; view 1 exact: right
    neck, mid = true2d[0, 1], true2d[0, 8]
    shift = 2.0 * np.linalg.norm(neck - mid)
    moved = true2d.copy()
    moved[0, :, 0] += shift
    hm = gaussian_heatmaps(model_to_heatmap_pixels(moved.astype(np.float64), 16, 64), vis, 16, 1.5)
    r = scene_metrics(sc, hm, None, np.array([], int))
    expected = vis[1].sum() / (vis[0].sum() + vis[1].sum())
    assert r["pck"].value == pytest.approx(expected)
    assert not r["pck"].correct[0].any() and r["pck"].correct[1].sum() == vis[1].sum()
    assert r["heatmap_mse"].value > 0
    acc = Accumulator()
    acc.add(r)
    acc.add(r)
    res = acc.result()
    assert res["scenes"] == 2 and res["pck@0.2"] == pytest.approx(expected)
    assert res["pck_evaluated_joints"] == 2 * r["pck"].num_evaluated


def test_pck_by_body_part(data64):
    from ghnerf_runtime.body25 import BODY_PARTS

    sc = _scene(data64)
    true2d = sc["tgt_joints_2d"][:2]
    vis = sc["tgt_visible"][:2]
    arms = list(BODY_PARTS["arms"])
    moved = true2d.copy()
    moved[:, arms, 0] += 2.0 * np.linalg.norm(true2d[0, 1] - true2d[0, 8])  # every arm joint wrong
    hm = gaussian_heatmaps(model_to_heatmap_pixels(moved.astype(np.float64), 16, 64), vis, 16, 1.5)
    acc = Accumulator()
    acc.add(scene_metrics(sc, hm, None, np.array([], int), encoder_heatmaps=sc["tgt_heatmaps"][:2]))
    res = acc.result()
    parts = res["pck@0.2_by_part"]
    assert set(parts) == set(BODY_PARTS)
    evaluated = {p: int(vis[:, list(j)].sum()) for p, j in BODY_PARTS.items()}
    assert evaluated["arms"] > 0 and parts["arms"] == 0.0
    for part, score in parts.items():
        if part != "arms":
            assert score == (1.0 if evaluated[part] else None), part
    # the parts pool to the overall score
    correct = sum((parts[p] or 0.0) * evaluated[p] for p in parts)
    assert correct / sum(evaluated.values()) == pytest.approx(res["pck@0.2"])
    assert res["encoder_heatmaps_pck@0.2_by_part"]["arms"] == (1.0 if evaluated["arms"] else None)


class _Oracle:
    """A renderer that returns the truth: the dataset's heatmaps and composited images."""

    height = width = 64
    heatmap_stride = 4
    background = 0.0

    def __init__(self, ds):
        self.ds = ds

    def _item(self, scene):
        return {k: v.numpy() for k, v in self.ds[int(scene["index"])].items()}

    def heatmaps(self, scene, targets, ray_uv):
        hm = self._item(scene)["tgt_heatmaps"][targets]  # (T, J, h, w)
        assert len(ray_uv) == hm.shape[-1] * hm.shape[-2]
        return hm.reshape(len(targets), hm.shape[1], -1).transpose(0, 2, 1)

    def colour(self, scene, targets, ray_uv):
        it = self._item(scene)
        img = it["tgt_images"][targets] * it["tgt_masks"][targets][:, None]
        assert np.array_equal(ray_uv, ray_grid(64, 64, 1))
        return img.transpose(0, 2, 3, 1).reshape(len(targets), -1, 3)


def test_evaluate_loop_with_an_oracle(data64):
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data64, "val")
    res = evaluate(_Oracle(ds), ds, progress=False)
    assert res["scenes"] == 2 and res["pck@0.2"] == 1.0 and res["heatmap_mse"] == 0.0
    assert res["psnr_masked"] >= 100.0  # identical renders: capped (PSNR_CAP_DB), not an infinite mean
    assert res["novel_views"] == 4 and res["mpjpe_mm"] < 0.5
    with pytest.raises(ValueError, match="limit must be >= 0"):  # min(-1, len) used to evaluate nothing
        evaluate(_Oracle(ds), ds, limit=-1, progress=False)


def test_the_cli_refuses_a_negative_limit(tmp_path, capsys):
    from training.evaluate import main

    with pytest.raises(SystemExit) as e:
        main(["--model", str(tmp_path / "never_loaded.pt"), "--limit", "-1"])
    assert e.value.code == 2 and "--limit: must be >= 0" in capsys.readouterr().err


def test_encoder_heatmaps_are_scored_like_the_rendered_ones(data64):
    sc = _scene(data64)
    truth = sc["tgt_heatmaps"][:2]
    r = scene_metrics(sc, truth, None, np.array([], int), encoder_heatmaps=np.zeros_like(truth))
    assert r["pck"].value == 1.0
    assert r["encoder_pck"].value == 0.0 and r["encoder_pck"].num_pred_missing == r["encoder_pck"].num_evaluated
    r2 = scene_metrics(sc, np.zeros_like(truth), None, np.array([], int), encoder_heatmaps=truth)
    assert r2["encoder_pck"].value == 1.0 and r2["encoder_mpjpe"].value < 0.5
    acc = Accumulator()
    acc.add(r)
    acc.add(r2)
    res = acc.result()
    assert res["encoder_heatmaps_pck@0.2"] == pytest.approx(0.5)
    assert res["encoder_heatmaps_mpjpe_mm"] < 0.5
    none = Accumulator()
    none.add(scene_metrics(sc, truth, None, np.array([], int)))
    assert none.result()["encoder_heatmaps_pck@0.2"] is None
    assert none.result()["encoder_heatmaps_flip_pck@0.2"] is None
    # the flip test's heatmaps are scored on their own
    r3 = scene_metrics(sc, truth, None, np.array([], int), encoder_heatmaps=np.zeros_like(truth),
                       encoder_heatmaps_flip=truth)
    assert r3["encoder_pck"].value == 0.0 and r3["encoder_flip_pck"].value == 1.0
    acc3 = Accumulator()
    acc3.add(r3)
    assert acc3.result()["encoder_heatmaps_flip_pck@0.2"] == 1.0 and acc3.result()["encoder_heatmaps_pck@0.2"] == 0.0
    # per source view: one view right, the other wrong
    half = truth.copy()
    half[1] = 0.0
    acc4 = Accumulator()
    acc4.add(scene_metrics(sc, half, None, np.array([], int), encoder_heatmaps=half))
    assert acc4.result()["pck@0.2_by_view"] == [1.0, 0.0]
    assert acc4.result()["encoder_heatmaps_pck@0.2_by_view"] == [1.0, 0.0]
    # MPJPE by visibility: the classes hold every triangulated joint once, with the scene's own split
    res = acc.result()
    for key in ("mpjpe_by_visibility", "encoder_heatmaps_mpjpe_by_visibility"):
        assert key in res
    by = res["encoder_heatmaps_mpjpe_by_visibility"]
    assert sum(c["joints"] for c in by.values()) == acc.encoder.mpjpe_joints
    vis = sc["tgt_visible"][:2]
    both = int(vis.all(0).sum())
    assert by["all_views"]["joints"] == both  # r2 alone triangulated (r's encoder maps were empty)
    # the truth's heatmaps are empty where a view cannot see the joint: such joints never triangulate
    assert by["some_views"]["joints"] == by["no_view"]["joints"] == 0 and (~vis.all(0)).any()
    assert all(c["mpjpe_mm"] is None or c["mpjpe_mm"] < 0.5 for c in by.values())


def test_the_plain_mpjpe_of_every_heatmap_source_says_how_many_joints_it_covers(data64):
    """The plain MPJPE scores only the joints decoded in both views. The rendered source reported the rest
    (``mpjpe_pred_missing``); the encoder's and the flip test's did not, so an MPJPE over ~72 % of the joints
    of the shipped model read as one over every joint (docs/training.md said so)."""
    sc = _scene(data64)
    truth = sc["tgt_heatmaps"][:2]
    both = sc["tgt_visible"][:2].all(0)
    lost = int(np.flatnonzero(both)[0])  # a joint both views see, not decoded in view 0 below
    enc = truth.copy()
    enc[0, lost] = 0.0
    acc = Accumulator()
    acc.add(scene_metrics(sc, truth, None, np.array([], int), encoder_heatmaps=enc, encoder_heatmaps_flip=truth))
    res = acc.result()
    known = int(np.asarray(sc["joints_3d_valid"]).sum())
    assert known == 25 and both.sum() < known  # the synthetic truth knows every joint, hidden ones too
    for prefix, placed in (("", both.sum()), ("encoder_heatmaps_", both.sum() - 1),
                           ("encoder_heatmaps_flip_", both.sum())):
        key = f"{prefix}mpjpe" if prefix else "mpjpe"
        assert res[f"{prefix}mpjpe_evaluated_joints" if prefix else "mpjpe_evaluated_joints"] == placed
        assert res[f"{key}_pred_missing"] == known - placed
        assert res[f"{key}_found"] == pytest.approx(placed / known)
    # by hand: the encoder's MPJPE pools only its placed joints
    assert res["encoder_heatmaps_mpjpe_mm"] < 0.5 and res["encoder_heatmaps_mpjpe_found"] < res["mpjpe_found"]
    empty = Accumulator()
    empty.add(scene_metrics(sc, truth, None, np.array([], int)))
    assert empty.result()["encoder_heatmaps_mpjpe_found"] is None  # no encoder heatmaps: nothing to cover


class _EncoderOracle(_Oracle):
    """Also the encoder's heatmaps: the truth, and for mirrored sources the mirror person's (left and
    right swapped, mirrored), as a perfect encoder would see them."""

    def encoder_heatmaps(self, scene):
        if "index" in scene:
            self.last = scene
            return self._item(scene)["tgt_heatmaps"][:2]
        assert np.array_equal(scene["images"], self.last["images"][..., ::-1])  # evaluate's mirrored pass
        return unmirror_heatmaps(self._item(self.last)["tgt_heatmaps"][:2])


def test_evaluate_scores_the_flip_test_of_the_encoder_heatmaps(data64):
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data64, "val")
    res = evaluate(_EncoderOracle(ds), ds, novel=False, progress=False)
    assert res["encoder_heatmaps_pck@0.2"] == 1.0 and res["encoder_heatmaps_flip_pck@0.2"] == 1.0
    assert res["encoder_heatmaps_flip_mpjpe_mm"] < 0.5 and res["encoder_heatmaps_flip_pck@0.2_by_part"]["arms"] == 1.0
    assert res["pck@0.2_by_view"] == [1.0, 1.0] and res["encoder_heatmaps_flip_pck@0.2_by_view"] == [1.0, 1.0]


def _look_from(eye, centre=(0.0, 0.0, 0.0)):
    """A ``tgt_c2w`` row whose camera centre is ``eye`` (only the centre column matters here)."""
    c2w = np.zeros((3, 4))
    c2w[:, :3] = np.eye(3)
    c2w[:, 3] = eye
    return c2w


def test_source_angles_are_measured_at_the_subject_centre():
    centre = np.array([0.5, -1.0, 3.0])
    joints = np.tile(centre, (25, 1)) + np.linspace(-0.2, 0.2, 25)[:, None] * np.array([0.0, 1.0, 0.0])
    r = 3.0
    def at(deg):  # a camera on the horizontal circle of radius r around the centre
        a = np.radians(deg)
        return centre + r * np.array([np.sin(a), 0.0, -np.cos(a)])
    scene = {"joints_3d": joints, "joints_3d_valid": np.ones(25, bool),
             "tgt_c2w": np.stack([_look_from(at(d)) for d in (-10.0, 10.0, 0.0, 40.0, 180.0, -100.0)]),
             "tgt_is_source": np.array([True, True, False, False, False, False])}
    ang = source_angles_deg(scene, np.arange(6))
    assert np.allclose(ang, [0.0, 0.0, 10.0, 30.0, 170.0, 90.0], atol=1e-9)
    scene["joints_3d_valid"] = np.zeros(25, bool)
    assert np.isnan(source_angles_deg(scene, np.array([2]))).all()



def _old_source_angles_deg(scene, targets):
    """The training-side formula before it used the device's rule: the reference for ordinary views."""
    valid = np.asarray(scene["joints_3d_valid"], bool)
    centre = np.asarray(scene["joints_3d"], np.float64)[valid].mean(axis=0)
    eyes = np.asarray(scene["tgt_c2w"], np.float64)[:, :, 3] - centre
    dirs = eyes / np.linalg.norm(eyes, axis=-1, keepdims=True)
    cos = np.clip(dirs[targets] @ dirs[np.asarray(scene["tgt_is_source"], bool)].T, -1.0, 1.0)
    return np.degrees(np.arccos(cos.max(axis=1)))


def test_source_angles_follow_the_devices_rule_and_a_camera_at_the_centre_is_at_0():
    """ghnerf-eval's bins and the painter's gate share one rule (novel_painter.angle_from_centres_deg): on
    ordinary views the figures are the old formula's; a camera exactly at the subject's centre was NaN
    (its direction normalised to 0/0, in no bin) and is 0 now, and a source there is left out."""
    from ghnerf_runtime.geometry.camera import Camera, intrinsics_from_fov
    from ghnerf_runtime.novel_painter import angle_from_sources_deg

    rng = np.random.default_rng(53)
    joints = rng.normal([0.2, -1.0, 3.0], 0.3, (25, 3))
    valid = rng.random(25) > 0.2
    eyes = rng.normal([0.2, -1.0, 3.0], 2.5, (12, 3))
    scene = {"joints_3d": joints, "joints_3d_valid": valid, "tgt_c2w": np.stack([_look_from(e) for e in eyes]),
             "tgt_is_source": np.arange(12) < 3}
    got = source_angles_deg(scene, np.arange(12))
    # to 1e-5 degrees: arccos near 1 turns a last-bit rounding into ~1e-6 degrees (a source itself, 0 or 1.2e-6)
    assert np.allclose(got, _old_source_angles_deg(scene, np.arange(12)), rtol=0.0, atol=1e-5)
    # one implementation: the device's angle for the same cameras, bit for bit
    cams = [Camera(f"c{i}", 64, 64, intrinsics_from_fov(64, 64, 40.0), np.zeros(5), np.eye(3), -e)
            for i, e in enumerate(eyes)]
    assert got.tolist() == [angle_from_sources_deg(c, cams[:3], joints, valid) for c in cams]

    centre = joints[valid].mean(axis=0)
    scene["tgt_c2w"][5, :, 3] = centre  # a target standing at the subject's centre
    assert source_angles_deg(scene, np.array([5]))[0] == 0.0
    scene["tgt_c2w"][0, :, 3] = centre  # a source there sees from no side: the other two give the angles
    scene["tgt_is_source"] = np.array([True, True, True] + [False] * 9)
    without = dict(scene, tgt_is_source=np.array([False, True, True] + [False] * 9))
    assert np.array_equal(source_angles_deg(scene, np.arange(6, 12)), source_angles_deg(without, np.arange(6, 12)))
    assert np.isfinite(source_angles_deg(scene, np.arange(12))).all()

def test_psnr_is_split_by_source_angle():
    bins = psnr_by_angle([20.0, 22.0, 15.0, 12.0, 30.0], [5.0, 14.9, 15.0, 180.0, np.nan])
    assert [b["views"] for b in bins] == [2, 1, 0, 0, 1]  # NaN angles fall in no bin; 180 in the last
    assert bins[0]["psnr"] == pytest.approx(21.0) and bins[1]["psnr"] == 15.0 and bins[2]["psnr"] is None
    assert bins[-1]["range_deg"] == [90.0, 180.0] and bins[-1]["psnr"] == 12.0


def test_the_accumulator_keeps_each_psnr_with_its_angle(data64):
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data64, "val")
    res = evaluate(_Oracle(ds), ds, progress=False)
    bins = res["psnr_masked_by_source_angle"]
    assert sum(b["views"] for b in bins) == res["novel_views"] == 4


def test_the_gated_mpjpe_drops_joints_whose_views_disagree_as_the_runtime_does(data64):
    """``*_mpjpe_gated``: the runtime's triangulation (reprojection gate) on the eval's crops. One joint moved
    off its epipolar line in one view is triangulated anyway by the ungated DLT (a large error) and dropped
    by the gate; the other joints are the same in both."""
    sc = _scene(data64)
    true2d, vis = sc["tgt_joints_2d"][:2].astype(np.float64), sc["tgt_visible"][:2]
    both = vis.all(0)
    k = int(np.flatnonzero(both)[0])
    moved = true2d.copy()
    moved[1, k] += [12.0, -12.0]  # model pixels of the 64 px crop: far beyond the 6 px gate
    hm = gaussian_heatmaps(model_to_heatmap_pixels(moved, 16, 64), vis, 16, 1.5)
    r = scene_metrics(sc, hm, None, np.array([], int), encoder_heatmaps=hm)
    plain, gated = r["mpjpe"], r["mpjpe_gated"]
    assert plain.num_evaluated == both.sum() and plain.errors[k] > 20.0
    assert gated.num_evaluated == both.sum() - 1 and not gated.evaluated[k] and gated.num_pred_missing >= 1
    others = both.copy()
    others[k] = False
    assert np.allclose(gated.errors[others], plain.errors[others], atol=0.01)  # mm; the gated DLT weighs by confidence
    assert gated.value < 0.5
    acc = Accumulator()
    acc.add(r)
    res = acc.result()
    assert res["mpjpe_gated_mm"] < 0.5 < res["mpjpe_mm"]
    assert res["mpjpe_gated_median_mm"] == pytest.approx(float(np.median(gated.errors[gated.evaluated])))
    n = sc["joints_3d_valid"].sum()
    assert res["mpjpe_gated_found"] == pytest.approx((both.sum() - 1) / n)
    assert res["encoder_heatmaps_mpjpe_gated_mm"] == pytest.approx(res["mpjpe_gated_mm"])
    assert sum(c["joints"] for c in res["mpjpe_gated_by_visibility"].values()) == both.sum() - 1


class _ShiftedPrior:
    """A stand-in skeleton prior: the truth moved 10 mm along x, sure of the even joints only. It checks it is
    fed the flip-tested encoder joints in crop pixels with the crop cameras."""

    def __init__(self, dataset):
        self.dataset, self.calls = dataset, 0

    def estimate(self, uv_model, confidence, valid, P):
        scene = {k: v.numpy() for k, v in self.dataset[self.calls].items()}
        self.calls += 1
        vis = scene["tgt_visible"][:2]
        assert valid[vis].all() and np.allclose(uv_model[vis], scene["tgt_joints_2d"][:2][vis], atol=0.3)
        assert np.array_equal(P, scene["src_P"]) and (confidence[vis] > 0.5).all()
        from ghnerf_runtime.skeleton_prior import SkeletonEstimate

        J = len(scene["joints_3d"])
        return SkeletonEstimate(scene["joints_3d"] + [0.01, 0.0, 0.0], np.where(np.arange(J) % 2 == 0, 0.01, 1.0),
                                valid.all(0))


def test_evaluate_scores_the_skeleton_prior_on_the_flip_tested_joints(data64):
    """The folder's skeleton prior, fed as the runtime feeds it: MPJPE over every true joint and over those its
    expected error keeps under the runtime's default gate."""
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data64, "val")
    oracle = _EncoderOracle(ds)
    assert evaluate(oracle, ds, novel=False, progress=False)["skeleton_prior_mpjpe_mm"] is None  # none: None
    oracle.skeleton_prior = _ShiftedPrior(ds)
    res = evaluate(oracle, ds, novel=False, progress=False)
    assert oracle.skeleton_prior.calls == len(ds)
    assert res["skeleton_prior_mpjpe_mm"] == pytest.approx(10.0)
    assert res["skeleton_prior_gated_mpjpe_mm"] == pytest.approx(10.0)
    valid = np.stack([ds[i]["joints_3d_valid"].numpy() for i in range(len(ds))])
    even = valid & (np.arange(valid.shape[1]) % 2 == 0)
    assert res["skeleton_prior_gated_found"] == pytest.approx(even.sum() / valid.sum())
    assert res["skeleton_prior_gate_m"] == 0.15


def test_a_broken_prediction_is_counted_not_hidden_and_pck_accounts_for_every_joint(data64):
    """A NaN heatmap or render used to drop out of the means as if its mask were empty; one identical
    view used to make the split's PSNR infinite (reported as null)."""
    sc = _scene(data64)
    nov = np.flatnonzero(~sc["tgt_is_source"])
    m = sc["tgt_masks"][nov][:, None]
    truth = sc["tgt_images"][nov] * m
    good = scene_metrics(sc, sc["tgt_heatmaps"][:2], truth + np.where(truth > 0.5, -0.1, 0.1) * m, nov)
    hm = sc["tgt_heatmaps"][:2].copy()
    hm[0, 0, 0, 0] = np.nan
    rgb = truth.copy()
    rgb[0, 0, 0, 0] = np.nan
    broken = scene_metrics(sc, hm, rgb, nov)
    acc = Accumulator()
    acc.add(good)
    acc.add(broken)
    res = acc.result()
    assert res["nonfinite_scenes"] == 1 and res["nonfinite_views"] == 1
    assert res["novel_views"] == len(nov) + len(nov) - 1  # the identical second view counts, capped
    assert np.isfinite(res["psnr_masked"])
    p = good["pck"]
    assert res["pck_unreferenced"] == 2 * p.num_unreferenced
    assert res["pck_views"] == 2 * int((p.reference > 0).sum()) and 0 <= res["pck_fallback_views"] <= res["pck_views"]
    total = int(np.asarray(sc["tgt_visible"][:2]).sum()) * 2
    assert res["pck_evaluated_joints"] + res["pck_unreferenced"] == total  # every visible joint accounted for


@pytest.mark.parametrize("bad", [np.inf, -np.inf])
def test_an_infinite_render_is_counted_not_clipped_into_a_score(data64, bad):
    sc = _scene(data64)
    nov = np.flatnonzero(~sc["tgt_is_source"])
    truth = sc["tgt_images"][nov] * sc["tgt_masks"][nov][:, None]
    rgb = truth.copy()
    ys, xs = np.nonzero(sc["tgt_masks"][nov[0]])
    rgb[0, :, ys[0], xs[0]] = bad  # np.clip used to make it a 1 (or 0) and score the view
    acc = Accumulator()
    acc.add(scene_metrics(sc, sc["tgt_heatmaps"][:2], rgb, nov))
    res = acc.result()
    assert res["nonfinite_views"] == 1 and res["novel_views"] == len(nov) - 1


# ------------------------------------------------------------------------------------------ the CLI's inputs
@pytest.fixture
def tiny_pt(tmp_path):
    """An untrained tiny checkpoint (64 px) as the trainer's files carry it."""
    import torch

    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    path = tmp_path / "tiny.pt"
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "step": 0}, path)
    return path


def _one_line_exit_2(capsys, argv, says):
    from training.evaluate import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_the_cli_names_bad_inputs_in_one_line_before_rendering(data64, tiny_pt, tmp_path, capsys, monkeypatch):
    import training.evaluate as ev

    rendered = []
    monkeypatch.setattr(ev, "evaluate", lambda *a, **kw: rendered.append(a) or {"scenes": 0})
    base = ["--data", str(data64), "--split", "val"]
    damaged = tmp_path / "damaged.pt"
    damaged.write_bytes(tiny_pt.read_bytes()[:500])
    err = _one_line_exit_2(capsys, [*base, "--model", f"good={tiny_pt}", "--model", f"bad={damaged}"],
                           f"{damaged}: unreadable checkpoint")
    assert "--resume" not in err  # training advice, not for a file given to evaluate
    _one_line_exit_2(capsys, ["--data", str(data64), "--split", "vall", "--model", str(tiny_pt)],
                     "has no split 'vall'")
    (tmp_path / "graphs").mkdir()
    _one_line_exit_2(capsys, [*base, "--model", str(tiny_pt), "--model", f"{tmp_path / 'graphs'}#int8"],
                     f"{tmp_path / 'graphs'}: missing ONNX graphs encoder.int8.onnx")
    # a real 128 px dataset (one scene): readable, but not the model's size. (The 64 px shards under a 128 px
    # manifest no longer open since session 54: the arrays' shapes are checked against the manifest first.)
    from training.data.generate import main as generate

    big = tmp_path / "data128"
    generate(["--out", str(big), "--train", "0", "--val", "1", "--val-seen-motions", "0", "--res", "128",
              "--novel-views", "0", "--workers", "1"])
    _one_line_exit_2(capsys, ["--data", str(big), "--split", "val", "--model", f"m={tiny_pt}"],
                     f"{big}: holds 128 px scenes, model m takes 64x64")
    assert rendered == []  # every spec checked before the first is evaluated


def test_an_empty_split_is_refused_not_scored_as_null(data64, tiny_pt, tmp_path, capsys, monkeypatch):
    """A split of no scenes was "evaluated": exit 0, "scenes": 0 and every metric null (nan)."""
    import json
    import shutil

    import training.evaluate as ev

    empty = tmp_path / "empty"
    shutil.copytree(data64, empty)
    manifest = json.loads((empty / "dataset.json").read_text())
    manifest["splits"]["val"]["count"] = 0
    (empty / "dataset.json").write_text(json.dumps(manifest))
    out = tmp_path / "metrics.json"
    # refused as the split is opened (since session 54, by the dataset reader itself), in one line
    _one_line_exit_2(capsys, ["--data", str(empty), "--split", "val", "--model", f"m={tiny_pt}", "--out", str(out)],
                     f"{empty / 'dataset.json'}: split 'val' holds no samples (count 0)")
    assert not out.exists()
    with pytest.raises(ev.EvalInputError, match="no scenes"):  # the library call too
        evaluate(_Oracle([]), [], progress=False)


def test_the_cli_keeps_each_finished_model_when_a_later_one_fails(data64, tiny_pt, tmp_path, monkeypatch):
    import json

    import training.evaluate as ev

    def evaluate(renderer, ds, limit, novel):
        if evaluate.calls:
            raise RuntimeError("the second model crashed")
        evaluate.calls += 1
        return {"scenes": 2, "pck@0.2": 0.5}

    evaluate.calls = 0
    monkeypatch.setattr(ev, "evaluate", evaluate)
    out = tmp_path / "metrics.json"
    with pytest.raises(RuntimeError, match="second model"):
        ev.main(["--data", str(data64), "--split", "val", "--model", f"a={tiny_pt}", "--model", f"b={tiny_pt}",
                 "--out", str(out)])
    assert json.loads(out.read_text())["models"]["a"]["pck@0.2"] == 0.5
