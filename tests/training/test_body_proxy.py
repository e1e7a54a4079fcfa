"""The body proxy built from 3D joints (``training.body_proxy``), the device's joints it is built from
(``training.device_joints``) and the painter's caches on it (``training.fill_features``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from ghnerf_runtime.body25 import JOINT_INDEX  # noqa: E402
from training.body_proxy import (ProxyTemplate, _depth_error, fit_scale, iou, proxy_body, proxy_depth,  # noqa: E402
                                 proxy_scene, tune, view_camera)
from training.device_joints import JointsCacheError, cache_joints, cache_true_joints, load_found, load_joints  # noqa: E402
from training.fill_features import MASK_BIT, TRUTH_BIT, cache_split, load_cache  # noqa: E402

SHIPPED = Path(__file__).resolve().parents[2] / "models" / "ghnerf"


def _scenes(data, split="val"):
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data, split=split)
    return [{k: v.numpy() for k, v in ds[i].items()} for i in range(len(ds))]


def test_the_proxy_from_the_true_joints_lies_on_the_true_surface(data64):
    for scene in _scenes(data64):
        body = proxy_body(scene["joints_3d"], scene["joints_3d_valid"])
        for v in range(len(scene["tgt_is_source"])):
            depth, mask = proxy_depth(body, view_camera(scene, v)), scene["tgt_masks"][v]
            both = mask & (depth > 0)
            assert iou(depth > 0, mask) > 0.6  # 64 px: the thin limbs are a pixel or two
            assert np.median(np.abs(depth - scene["tgt_depth"][v])[both]) < 0.03


def test_the_view_camera_projects_the_joints_where_the_dataset_does(data64):
    scene = _scenes(data64)[0]
    for v in range(len(scene["tgt_is_source"])):
        uv, _ = view_camera(scene, v).project(scene["joints_3d"].astype(np.float64))
        ok = scene["tgt_visible"][v]
        assert np.allclose(uv[ok], scene["tgt_joints_2d"][v][ok], atol=1e-3)


def test_the_girth_scale_is_recovered_from_silhouettes_and_widens_the_proxy(data64):
    scene = _scenes(data64)[0]
    j, ok = scene["joints_3d"], scene["joints_3d_valid"]
    cams = [view_camera(scene, v) for v in (0, 1)]
    wide = proxy_body(j, ok, scale=1.2)
    masks = [proxy_depth(wide, c) > 0 for c in cams]
    assert fit_scale(j, ok, cams, masks) == pytest.approx(1.2)
    assert sum(m.sum() for m in masks) > sum((proxy_depth(proxy_body(j, ok), c) > 0).sum() for c in cams)


def test_joints_that_are_not_valid_leave_their_primitives_out():
    rng = np.random.default_rng(0)
    joints = rng.normal(0.0, 0.3, (25, 3)) + np.array([0.0, 1.0, 3.0])
    every = proxy_body(joints, np.ones(25, bool))
    valid = np.ones(25, bool)
    valid[JOINT_INDEX["RKnee"]] = False
    fewer = proxy_body(joints, valid)
    assert len(fewer.cone_a) == len(every.cone_a) - 2  # thigh and shin
    assert len(proxy_body(joints, np.zeros(25, bool)).cone_a) == 0


def test_a_proxy_scene_carries_the_proxy_depth_and_its_masks(data64):
    scene = _scenes(data64)[0]
    out, s = proxy_scene(scene, scene["joints_3d"], scene["joints_3d_valid"], scale=None)
    assert 0.7 <= s <= 1.5
    assert out["tgt_depth"].shape == scene["tgt_depth"].shape
    assert np.array_equal(out["tgt_masks"], out["tgt_depth"] > 0)
    assert out["images"] is scene["images"]
    fixed, s1 = proxy_scene(scene, scene["joints_3d"], scene["joints_3d_valid"], template=ProxyTemplate())
    assert s1 == 1.0 and fixed["tgt_masks"].any()


def test_tuning_the_template_never_makes_it_worse(data64):
    scene = _scenes(data64)[0]
    start = ProxyTemplate(thigh=(0.06, 0.04))  # thighs too thin

    def cost(t):
        e, i = _depth_error(scene, t, 1.0, list(range(len(scene["tgt_is_source"]))))
        return e + 0.1 * (1 - i)

    tuned = tune([scene], rounds=1, start=start, log=lambda *_: None)
    assert cost(tuned) < cost(start) and tuned.thigh[0] > 0.06


@pytest.fixture(scope="module")
def data128(tmp_path_factory):
    """One 128 px val scene: the shipped model's resolution."""
    from training.data.generate import main as generate

    out = tmp_path_factory.mktemp("data128")
    generate(["--out", str(out), "--train", "0", "--val", "1", "--val-seen-motions", "0", "--res", "128",
              "--workers", "1"])
    return out


@pytest.mark.skipif(not (SHIPPED / "skeleton_prior.onnx").exists(), reason="no shipped model folder")
def test_the_device_joints_come_from_the_shipped_model_near_the_truth(data128, tmp_path):
    path = cache_joints(data128, "val", SHIPPED, tmp_path / "j.npz", log=lambda *_: None)
    joints = load_joints(path, 1)
    scene = _scenes(data128)[0]
    err = np.linalg.norm(joints[0] - scene["joints_3d"], axis=-1)[scene["joints_3d_valid"]]
    assert np.isfinite(joints).all() and np.median(err) < 0.08


def test_the_true_joints_cache_holds_the_dataset_joints(data64, tmp_path):
    path = cache_true_joints(data64, "val", tmp_path / "t.npz", log=lambda *_: None)
    scenes = _scenes(data64)
    joints = load_joints(path, len(scenes))
    assert np.allclose(joints, np.stack([s["joints_3d"] for s in scenes]))


def test_a_broken_joints_cache_is_named(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(JointsCacheError, match="bad.npz"):
        load_joints(bad)
    np.savez(tmp_path / "shape.npz", joints=np.zeros((2, 24, 3)))
    with pytest.raises(JointsCacheError, match=r"\(2, 24, 3\)"):
        load_joints(tmp_path / "shape.npz")
    np.savez(tmp_path / "short.npz", joints=np.zeros((2, 25, 3)))
    with pytest.raises(JointsCacheError, match="holds 2 scenes, 5 asked for"):
        load_joints(tmp_path / "short.npz", 5)


def test_a_cut_joints_cache_is_named_and_a_cache_is_written_whole(data64, tmp_path, monkeypatch, capsys):
    import os

    from training.device_joints import main

    path = cache_true_joints(data64, "val", tmp_path / "t.npz", log=lambda *_: None)
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])  # a write cut short
    for load in (load_joints, load_found):
        with pytest.raises(JointsCacheError, match="cut.npz"):
            load(tmp_path / "cut.npz")

    def stop(*args):
        raise KeyboardInterrupt("stopped")

    monkeypatch.setattr(os, "replace", stop)  # stopped before the new cache takes the old one's place
    with pytest.raises(KeyboardInterrupt):
        cache_true_joints(data64, "val", path, limit=1, log=lambda *_: None)
    monkeypatch.undo()
    assert path.read_bytes() == data and sorted(p.name for p in tmp_path.iterdir()) == ["cut.npz", "t.npz"]
    with pytest.raises(ValueError, match="limit"):
        cache_true_joints(data64, "val", tmp_path / "n.npz", limit=-1, log=lambda *_: None)
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["--data", str(data64), "--truth", "--limit", "-1", "--out", str(tmp_path / "m.npz")])
    assert e.value.code == 2 and "--limit must be 0 (all scenes) or more" in capsys.readouterr().err


def test_the_found_joints_are_those_the_runtimes_error_gate_passes(tmp_path):
    from ghnerf_runtime.config import Joints3DConfig

    gate = Joints3DConfig().max_prior_error_m
    errors = np.full((2, 25), gate / 2)
    errors[0, 3], errors[1, 7] = gate * 1.01, gate  # just past the gate: left out; on it: reported
    np.savez(tmp_path / "j.npz", joints=np.zeros((2, 25, 3)), expected_error_m=errors)
    found = load_found(tmp_path / "j.npz", 2)
    assert found.shape == (2, 25) and (~found).sum() == 1 and not found[0, 3] and found[1, 7]
    assert load_found(tmp_path / "j.npz", max_error_m=gate / 4).sum() == 0
    np.savez(tmp_path / "old.npz", joints=np.zeros((2, 25, 3)))
    with pytest.raises(JointsCacheError, match=r"old\.npz: not a joints cache with expected errors"):
        load_found(tmp_path / "old.npz")
    with pytest.raises(JointsCacheError, match=r"expected \(N >= 5, 25\)"):
        load_found(tmp_path / "j.npz", 5)


def test_a_proxy_cache_takes_its_geometry_and_joints_from_the_device_joints(data64, tmp_path):
    from training.configs import preset
    from training.model import GHNeRF

    scenes = _scenes(data64)
    joints = np.stack([s["joints_3d"] + 0.01 for s in scenes]).astype(np.float32)  # 1 cm off the truth
    # as training.device_joints writes a cache: the joints and their expected errors (all within the gate here)
    np.savez(tmp_path / "joints.npz", joints=joints, expected_error_m=np.zeros(joints.shape[:2], np.float32))
    model = GHNeRF(preset("tiny"))
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, tmp_path / "tiny.pt")
    path = cache_split(data64, "val", tmp_path / "val.npz", workers=1, model=tmp_path / "tiny.pt",
                       joints=tmp_path / "joints.npz", log=lambda *_: None)
    a = load_cache(path)
    assert (a["geometry"] == "proxy").all()
    for k in range(len(a["angle"])):
        scene = scenes[int(a["scene"][k])]
        t = int(a["view"][k])
        body = proxy_body(joints[int(a["scene"][k])], np.ones(25, bool))
        proxy_mask = proxy_depth(body, view_camera(scene, t)) > 0
        assert np.array_equal((a["flags"][k] & MASK_BIT) > 0, proxy_mask)
        assert np.array_equal((a["flags"][k] & TRUTH_BIT) > 0, scene["tgt_masks"][t])
        uv, _ = view_camera(scene, t).project(joints[int(a["scene"][k])].astype(np.float64))
        assert np.allclose(a["joints"][k][:, :2], uv, atol=1e-2)
    with pytest.raises(ValueError, match="takes a model"):
        cache_split(data64, "val", tmp_path / "x.npz", workers=1, joints=tmp_path / "joints.npz")
    np.savez(tmp_path / "one.npz", joints=joints[:1], expected_error_m=np.zeros((1, joints.shape[1]), np.float32))
    with pytest.raises(JointsCacheError, match="holds 1 scenes"):
        cache_split(data64, "val", tmp_path / "y.npz", workers=1, model=tmp_path / "tiny.pt",
                    joints=tmp_path / "one.npz", log=lambda *_: None)


def test_a_joints_cache_of_another_split_or_dataset_is_refused_before_it_is_paired_by_index(data64, tmp_path):
    # the joints are taken by scene index: val's first two scenes' joints must not become train's first two
    import json
    import shutil

    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, tmp_path / "tiny.pt")
    val = cache_true_joints(data64, "val", tmp_path / "joints_val.npz", log=lambda *_: None)
    with pytest.raises(JointsCacheError, match=r"joints_val.npz: holds the joints of split 'val', not 'train'"):
        cache_split(data64, "train", tmp_path / "t.npz", limit=2, workers=1, model=tmp_path / "tiny.pt",
                    joints=val, log=lambda *_: None)
    other = tmp_path / "regenerated"  # the same folder name and split, other data (its manifest differs)
    shutil.copytree(data64, other)
    manifest = json.loads((other / "dataset.json").read_text())
    manifest["source_config"]["dataset_seed"] = 7
    (other / "dataset.json").write_text(json.dumps(manifest))
    with pytest.raises(JointsCacheError, match=r"joints_val.npz: was made from another dataset"):
        cache_split(other, "val", tmp_path / "v.npz", workers=1, model=tmp_path / "tiny.pt", joints=val,
                    log=lambda *_: None)
    # its own split and dataset: taken (the scene count is checked as before)
    assert cache_split(data64, "val", tmp_path / "v.npz", workers=1, model=tmp_path / "tiny.pt", joints=val,
                       log=lambda *_: None).is_file()
