"""The synthetic dataset end to end on a tiny set (64x64): determinism, split disjointness, geometry, tensors."""
from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drivers.sim import RigPlacement
from ghnerf_runtime.preprocess import roi_from_volume
from training.data.cache import MANIFEST, ShardedSplit
from training.data.errors import DataConfigError, DatasetError
from training.data.generate import generate, main
from training.data.sample import FIELDS
from drivers.sim import random_scene
from training.data.cache import read_manifest, write_manifest
from training.data.splits import (HELD_OUT_BASELINE_M, HELD_OUT_MOTIONS, ROUTINE_MOTIONS, SPLITS, TRAIN_MOTIONS,
                                  SplitSpec, split_spec)
from training.data.synthetic import SyntheticConfig, make_sample
from training.data.targets import KEYS, TargetConfig

RES = 64
COUNTS = {"train": 6, "val": 4}
CONFIG = SyntheticConfig(resolution=RES, novel_views=2, cold_start_fraction=0.3)


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("synth") / "ds"
    report = generate(root, COUNTS, CONFIG, dataset_seed=3, workers=2, shard_size=4)
    assert report.samples_rendered == sum(COUNTS.values())
    assert report.shards_written == 3  # train: 4 + 2, val: 4
    return root


# ------------------------------------------------------------------ determinism and resumption
def test_same_seed_gives_identical_bytes_whatever_the_worker_count(dataset, tmp_path):
    again = tmp_path / "again"
    generate(again, COUNTS, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    assert _digest(again) == _digest(dataset)


def test_another_seed_gives_other_samples(dataset, tmp_path):
    other = tmp_path / "other"
    generate(other, {"train": 1}, CONFIG, dataset_seed=4, workers=1, shard_size=4)
    a = ShardedSplit(dataset, "train").arrays(0)["images"]
    b = ShardedSplit(other, "train").arrays(0)["images"]
    assert not np.array_equal(a, b)


def test_resume_skips_complete_shards_and_extends(dataset, tmp_path):
    root = tmp_path / "grow"
    generate(root, {"train": 2}, CONFIG, dataset_seed=3, workers=1, shard_size=4)  # one short shard
    report = generate(root, {"train": 5}, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    assert (report.shards_written, report.samples_rendered) == (2, 5)  # the short shard is redone
    report = generate(root, {"train": 5}, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    assert (report.shards_written, report.shards_skipped) == (0, 2)
    grown, reference = ShardedSplit(root, "train"), ShardedSplit(dataset, "train")
    for i in range(5):
        assert all(np.array_equal(grown.arrays(i)[k], reference.arrays(i)[k]) for k in FIELDS)


def test_resume_with_another_config_names_the_field(dataset):
    with pytest.raises(DatasetError, match="source_config") as err:
        generate(dataset, {"train": 1}, SyntheticConfig(resolution=RES, novel_views=2, cold_start_fraction=0.5),
                 dataset_seed=3, workers=1, shard_size=4)
    assert err.value.path.endswith(MANIFEST)


def test_resume_under_another_split_recipe_is_refused(dataset, tmp_path):
    # A dataset of the routines only must not be extended with freestyle scenes (or the reverse).
    root = tmp_path / "old_recipe"
    generate(root, {"train": 1}, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    manifest = read_manifest(root)
    manifest["splits"]["train"]["spec"] = split_spec("train", 0.25).to_json()
    write_manifest(root, manifest)
    with pytest.raises(DatasetError, match="'train' was generated with spec .*new folder"):
        generate(root, {"train": 2}, CONFIG, dataset_seed=3, workers=1, shard_size=4)


def test_a_cache_of_another_generator_version_is_refused_and_an_unversioned_one_is_version_1(tmp_path, monkeypatch):
    import json

    import training.data.generate as gen
    import training.pipeline as pipeline

    root = tmp_path / "versioned"
    config = SyntheticConfig(resolution=RES)  # what the pipeline's data stage asks generate for
    generate(root, {"train": 1}, config, workers=1, shard_size=4)
    assert read_manifest(root)["generator_version"] == gen.GENERATOR_VERSION == 1
    manifest = read_manifest(root)
    del manifest["generator_version"]  # a cache made before the field: version 1, extended as before
    write_manifest(root, manifest)
    generate(root, {"train": 2}, config, workers=1, shard_size=4)
    assert "generator_version" not in read_manifest(root)  # left as it was: its pipeline stamp still matches
    cfg = pipeline.PipelineConfig(out=tmp_path / "m", data=root, train=2, val=0, val_seen_motions=0, res=RES,
                                  freestyle_share=0.0)
    assert pipeline.dataset_matches(cfg) and "generator" not in pipeline.data_request(cfg)

    monkeypatch.setattr(gen, "GENERATOR_VERSION", 2)  # the renderer changed since
    with pytest.raises(DatasetError, match="generated by generator version 1, this code renders version 2") as err:
        generate(root, {"train": 3}, config, workers=1, shard_size=4)
    assert err.value.path.endswith(MANIFEST)
    assert not pipeline.dataset_matches(cfg) and pipeline.data_request(cfg)["generator"] == 2
    assert json.loads((root / MANIFEST).read_text())["splits"]["train"]["count"] == 2


def test_the_pipeline_trains_on_the_requested_count_not_on_a_larger_dataset(tmp_path):
    """Review 52: dataset_matches took a split generated larger than asked (count >= requested), and the trainer
    reads every scene dataset.json counts: a pipeline asked for 2 scenes trained on 3, its stamp and card saying 2.
    A larger split is not a match now; the data stage's generate call shrinks the manifest's count to the request
    without rendering, and the split then serves exactly the requested scenes."""
    import training.pipeline as pipeline

    root = tmp_path / "data"
    config = SyntheticConfig(resolution=RES)  # what the pipeline's data stage asks generate for
    generate(root, {"train": 3}, config, workers=1, shard_size=2)
    cfg = pipeline.PipelineConfig(out=tmp_path / "m", data=root, train=2, val=0, val_seen_motions=0, res=RES,
                                  freestyle_share=0.0)
    assert len(ShardedSplit(root, "train")) == 3
    assert not pipeline.dataset_matches(cfg)
    report = generate(root, {"train": 2}, config, workers=1, shard_size=2)  # as stage_data asks it
    assert report.samples_rendered == 0  # the first two scenes were there: nothing rendered
    assert pipeline.dataset_matches(cfg) and len(ShardedSplit(root, "train")) == 2
    assert (root / "train" / "shard_000001").is_dir()  # the third scene's shard kept for a later larger count
    assert not pipeline.dataset_matches(replace(cfg, train=3))  # fewer than asked: still generate's to extend


@pytest.mark.parametrize("made_with", [
    {"config": {"cold_start_fraction": 0.5}},
    {"config": {"novel_views": 1}},
    {"config": {"supersample": 1}},
    {"config": {"freestyle_share": 0.5}},  # the pipeline below asks for the routines only
    {"seed": 1},
])
def test_the_pipeline_does_not_train_on_a_dataset_made_with_other_generator_settings(tmp_path, made_with):
    import training.pipeline as pipeline

    root = tmp_path / "by_hand"
    config = replace(SyntheticConfig(resolution=RES), **made_with.get("config", {}))
    generate(root, {"train": 2}, config, dataset_seed=made_with.get("seed", 0), workers=1, shard_size=4)
    cfg = pipeline.PipelineConfig(out=tmp_path / "m", data=root, train=2, val=0, val_seen_motions=0, res=RES,
                                  freestyle_share=0.0)
    # the same counts, specs, resolution and generator version: only the generator's settings differ
    assert not pipeline.dataset_matches(cfg)
    generate(tmp_path / "default", {"train": 2}, SyntheticConfig(resolution=RES), workers=1, shard_size=4)
    assert pipeline.dataset_matches(replace(cfg, data=tmp_path / "default"))


def test_the_pipelines_data_stage_refuses_a_dataset_made_with_other_settings(tmp_path, capfd):
    import subprocess

    import training.pipeline as pipeline

    root = tmp_path / "by_hand"
    generate(root, {"train": 2}, SyntheticConfig(resolution=RES, cold_start_fraction=0.5), workers=1, shard_size=4)
    before = (root / MANIFEST).read_bytes()
    cfg = pipeline.PipelineConfig(out=tmp_path / "m", data=root, train=2, val=0, val_seen_motions=0, res=RES,
                                  freestyle_share=0.0, workers=1)
    with pytest.raises(subprocess.CalledProcessError):  # generate exits 2, naming the manifest and the key
        pipeline.stage_data(cfg)
    assert "source_config" in capfd.readouterr().err and (root / MANIFEST).read_bytes() == before


def test_a_second_generate_into_a_folder_being_generated_is_refused(tmp_path, monkeypatch):
    # Two writers of one folder: the second's start deleted the first's unfinished shards (*.tmp-*) and both
    # rewrote the manifest. Here a second generate starts while the first renders its first sample.
    import subprocess
    import sys

    import training.data.generate as gen

    root, repo = tmp_path / "ds", Path(__file__).resolve().parents[2]
    cmd = [sys.executable, "-m", "training.data.generate", "--out", str(root), "--train", "2", "--res", str(RES),
           "--shard-size", "1", "--workers", "1"]
    second, real = [], gen.make_sample

    def rendering(*args, **kwargs):
        if not second:
            second.append(subprocess.run(cmd, cwd=repo, capture_output=True, text=True, timeout=120))
        return real(*args, **kwargs)

    monkeypatch.setattr(gen, "make_sample", rendering)
    report = generate(root, {"train": 2}, SyntheticConfig(resolution=RES), workers=1, shard_size=1)
    assert second[0].returncode == 2, second[0].stderr
    assert "dataset.lock: another process holds this lock" in second[0].stderr
    assert report.samples_rendered == 2 and len(ShardedSplit(root, "train")) == 2
    # the lock goes with its process: the same command afterwards finds the folder whole and free
    done = subprocess.run(cmd, cwd=repo, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "0 shards written, 2 skipped" in done.stderr


def test_freestyle_joins_train_only_on_request():
    assert "freestyle" not in SPLITS["train"].motions and SPLITS["train"].motion_weights is None
    assert SPLITS["val_seen_motions"].motions == ROUTINE_MOTIONS == TRAIN_MOTIONS
    mixed = split_spec("train", 0.25)
    weights = dict(zip(mixed.motions, mixed.motion_weights))
    assert weights["freestyle"] == pytest.approx(0.25) and sum(weights.values()) == pytest.approx(1.0)
    assert split_spec("val", 0.25) == SPLITS["val"]  # the held-out splits never change
    # Uniform splits keep the manifest format older datasets were written with; so does share 0.
    assert "motion_weights" not in SPLITS["train"].to_json() and "motion_weights" in mixed.to_json()
    assert "freestyle_share" not in CONFIG.to_json()
    assert SyntheticConfig.from_json(replace(CONFIG, freestyle_share=0.25).to_json()).freestyle_share == 0.25
    with pytest.raises(DataConfigError, match="motion_weights"):
        SplitSpec("x", 0, ("stand", "wave"), ((0.1, 0.5),), (1.0,))
    with pytest.raises(DataConfigError, match="motion_weights"):
        SplitSpec("x", 0, ("stand", "wave"), ((0.1, 0.5),), (0.0, 0.0))
    with pytest.raises(DataConfigError, match="freestyle_share"):
        SyntheticConfig(freestyle_share=1.0)


def test_a_freestyle_dataset_draws_its_share_and_never_a_held_out_motion():
    config = replace(CONFIG, freestyle_share=0.5)
    spec = split_spec("train", config.freestyle_share)
    motions = [random_scene(spec.scene_seed(0, i), motions=spec.motions, motion_weights=spec.motion_weights).config.motion
               for i in range(60)]
    assert 18 <= motions.count("freestyle") <= 42 and not set(motions) & set(HELD_OUT_MOTIONS)
    sample = make_sample(spec, 0, next(i for i, m in enumerate(motions) if m == "freestyle"), config)
    assert sample.metadata["motion"] == "freestyle"


# ------------------------------------------------------------------ split disjointness
def test_held_out_split_shares_no_body_motion_or_rig_with_train(dataset):
    train = list(ShardedSplit(dataset, "train").all_metadata())
    val = list(ShardedSplit(dataset, "val").all_metadata())
    assert len(train) == COUNTS["train"] and len(val) == COUNTS["val"]
    manifest_ranges = {s: ShardedSplit(dataset, s).info["seed_range"] for s in COUNTS}

    # Bodies and appearance: disjoint seed ranges, and no body or look in common.
    for split, metas in (("train", train), ("val", val)):
        lo, hi = manifest_ranges[split]
        assert all(lo <= m["scene_seed"] < hi for m in metas)
    assert not {m["scene_seed"] for m in train} & {m["scene_seed"] for m in val}
    assert not {m["body_fingerprint"] for m in train} & {m["body_fingerprint"] for m in val}
    assert not {m["appearance_fingerprint"] for m in train} & {m["appearance_fingerprint"] for m in val}
    lo_t, hi_t = manifest_ranges["train"]
    lo_v, hi_v = manifest_ranges["val"]
    assert hi_t <= lo_v or hi_v <= lo_t

    # Motions: held-out motions only in val, never in train.
    assert {m["motion"] for m in train} <= set(TRAIN_MOTIONS)
    assert {m["motion"] for m in val} <= set(HELD_OUT_MOTIONS)
    assert not set(TRAIN_MOTIONS) & set(HELD_OUT_MOTIONS)

    # Rigs: the baseline gap separates them.
    band_lo, band_hi = HELD_OUT_BASELINE_M
    assert all(not band_lo <= m["placement"]["baseline_m"] < band_hi for m in train)
    assert all(band_lo <= m["placement"]["baseline_m"] < band_hi for m in val)


def test_split_specs_are_disjoint_by_construction():
    train, val = SPLITS["train"], SPLITS["val"]
    for seed in (0, 1, 99_999):
        t_lo, t_hi = train.seed_range(seed)
        for other in SPLITS.values():
            if other is not train:
                o_lo, o_hi = other.seed_range(0)[0], other.seed_range(99_999)[1]
                assert t_hi <= o_lo or o_hi <= t_lo
    rng = np.random.default_rng(0)
    baselines = [train.placement(rng).baseline_m for _ in range(300)]
    assert not any(HELD_OUT_BASELINE_M[0] <= b < HELD_OUT_BASELINE_M[1] for b in baselines)
    assert all(HELD_OUT_BASELINE_M[0] <= val.placement(rng).baseline_m < HELD_OUT_BASELINE_M[1] for _ in range(50))


# ------------------------------------------------------------------ geometry of stored samples
def test_stored_joints_are_the_crop_camera_projection_of_the_3d_joints(dataset):
    for split in COUNTS:
        data = ShardedSplit(dataset, split)
        for i in range(len(data)):
            sample = data[i]
            assert sample.joints_3d_valid.all()
            for view in sample.views:
                uv, z = view.camera().project(sample.joints_3d)
                front = z > 0
                err = np.linalg.norm(uv[front] - view.joints_2d[front], axis=-1)
                assert err.max() < 0.5, (split, i, view.name, err.max())
                assert not np.any(view.visible & ~front)
                # Visible joints lie inside the crop.
                vis = view.joints_2d[view.visible]
                assert np.all((vis >= -0.5) & (vis < RES - 0.5))


def test_mask_agrees_with_depth_and_depth_is_plausible(dataset):
    data = ShardedSplit(dataset, "train")
    for i in range(len(data)):
        sample = data[i]
        centre = sample.bbox.mean(axis=0)
        for view in sample.views:
            assert view.has_depth
            assert np.array_equal(view.mask, view.depth > 0)
            assert 0.01 < view.mask.mean() < 0.9, view.name
            d = view.depth[view.mask].astype(np.float64)
            dist = float(np.linalg.norm(view.camera().to_camera(centre)))
            assert abs(np.median(d) - dist) < 1.0


def test_sources_come_from_the_rig_and_cold_start_rois_from_the_volume(dataset):
    data = ShardedSplit(dataset, "train")
    metas = list(data.all_metadata())
    for i, meta in enumerate(metas):
        rec = data.arrays(i)
        assert list(rec["roi_from_volume"]) == [meta["cold_start"]] * 2 + [False] * CONFIG.novel_views
        src = data[i].views[:2]
        baseline = np.linalg.norm(src[0].camera().center - src[1].camera().center)
        assert baseline == pytest.approx(meta["placement"]["baseline_m"], abs=1e-6)
        assert rec["full_size"][0].tolist() == [640, 480]


def test_cold_start_rois_come_from_the_working_volume():
    config = SyntheticConfig(resolution=32, novel_views=0, cold_start_fraction=1.0)
    sample = make_sample(SPLITS["train"], 0, 0, config)
    placement = sample.metadata["placement"]
    rig = replace(RigPlacement(), **{k: tuple(v) if isinstance(v, list) else v for k, v in placement.items()}).build()
    for view, cam in zip(sample.views, rig.cameras):
        assert view.roi_from_volume and view.roi == roi_from_volume(cam, rig.volume)


def test_config_errors_name_the_field():
    for kwargs, field in (({"resolution": 60}, "resolution"), ({"novel_views": 7}, "novel_views"),
                          ({"margin_frac": (0.3, 0.1)}, "margin_frac"), ({"cold_start_fraction": 2.0}, "cold_start_fraction")):
        with pytest.raises(DataConfigError, match=f"SyntheticConfig.{field}") as err:
            SyntheticConfig(**kwargs)
        assert err.value.field == f"SyntheticConfig.{field}"
    with pytest.raises(DataConfigError, match="TargetConfig.heatmap_sigma"):
        TargetConfig(heatmap_sigma=0.0)
    with pytest.raises(DataConfigError, match="SplitSpec.motions"):
        type(SPLITS["val"])("x", 0, ("moonwalk",), ((0.2, 0.3),))
    with pytest.raises(DataConfigError, match="counts.train"):
        generate("/nonexistent-never-created", {"train": -1}, CONFIG)


# ------------------------------------------------------------------ tensors
def test_torch_dataset_returns_documented_shapes_and_dtypes(dataset):
    torch = pytest.importorskip("torch")
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(dataset, "val", TargetConfig(heatmap_stride=4, heatmap_sigma=1.5))
    assert len(ds) == COUNTS["val"]
    item = ds[1]
    V, S, h = 2 + CONFIG.novel_views, RES, RES // 4
    sizes = {"V": V, "S": S, "h": h}
    assert set(item) == set(KEYS) | {"index"}
    for key, (shape, dtype, _) in KEYS.items():
        expect = tuple(sizes[d] if d in sizes else int(d) for d in shape.strip("()").replace(" ", "").split(",") if d)
        assert tuple(item[key].shape) == expect, key
        assert item[key].dtype == getattr(torch, dtype), key
    assert 0.0 <= float(item["tgt_images"].min()) and float(item["tgt_images"].max()) <= 1.0
    assert torch.equal(item["images"], item["tgt_images"][:2])
    near, far = item["near_far"][:, 0], item["near_far"][:, 1]
    assert bool(torch.all((near > 0) & (far > near)))
    # Heatmap peaks sit at the visible joints (heatmap pixels).
    hm = item["tgt_heatmaps"][0]
    vis = item["tgt_visible"][0]
    j = int(torch.nonzero(vis)[0])
    peak = divmod(int(torch.argmax(hm[j])), h)
    uv = (item["tgt_joints_2d"][0, j] + 0.5) / 4 - 0.5
    assert abs(peak[1] - float(uv[0])) <= 0.5 + 1e-6 and abs(peak[0] - float(uv[1])) <= 0.5 + 1e-6
    assert float(hm[~vis].abs().sum()) == 0.0  # joints not visible have empty maps
    # DataLoader round trip (one scene per item).
    loader = torch.utils.data.DataLoader(ds, batch_size=None, shuffle=False, num_workers=0)
    assert next(iter(loader))["tgt_images"].shape == (V, 3, S, S)


def test_cli_main(tmp_path, caplog):
    out = tmp_path / "cli"
    assert main(["--out", str(out), "--train", "1", "--res", "32", "--workers", "1", "--novel-views", "1"]) == 0
    assert ShardedSplit(out, "train")[0].views[2].image.shape == (32, 32, 3)
    assert main(["--out", str(out), "--train", "1", "--res", "30"]) == 2
    assert "SyntheticConfig.resolution" in caplog.text


def test_ctrl_c_stops_a_parallel_generation_and_its_workers(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) must end the run and its workers; the
    pool used to restart the killed workers and wait forever for their lost shards."""
    import os
    import signal
    import subprocess
    import sys
    import time

    log = tmp_path / "gen.log"
    # enough shards to be mid-run at the signal, few enough that the pool's task feeder stays small
    cmd = [sys.executable, "-m", "training.data.generate", "--out", str(tmp_path / "ds"), "--train", "4000",
           "--res", "32", "--novel-views", "0", "--supersample", "1", "--shard-size", "2", "--workers", "2"]
    with open(log, "wb") as fh:
        # SIGINT as a terminal leaves it: a suite started in the background (nohup ... &) ignores it, and the
        # child would inherit that and never see the Ctrl-C this test sends
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, start_new_session=True,
                                cwd=Path(__file__).resolve().parents[2],
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 240  # the workers are rendering once a shard is logged (slow on a busy box)
        while " shard " not in log.read_text() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert proc.poll() is None, log.read_text()[-2000:]
        os.killpg(proc.pid, signal.SIGINT)
        rc = proc.wait(timeout=300)  # it hung forever before (seconds when idle; a loaded CI box is slower)
        assert rc == 130, log.read_text()[-2000:]
        assert "run the same command again to resume" in log.read_text()
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:  # no worker survives its parent
            try:
                os.killpg(proc.pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.2)
        else:
            pytest.fail("generation workers still run after Ctrl-C")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()


def test_a_manifest_split_without_shard_size_is_named(tmp_path):
    import json

    out = tmp_path / "ds"
    config = SyntheticConfig(resolution=32, novel_views=0, supersample=1)
    generate(out, {"train": 1}, config, workers=1)
    manifest = json.loads((out / MANIFEST).read_text())
    del manifest["splits"]["train"]["shard_size"]
    (out / MANIFEST).write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="splits.train.shard_size") as err:
        generate(out, {"train": 2}, config, workers=1)
    assert err.value.path == str(out / MANIFEST)


def test_a_smaller_count_shrinks_a_split_without_rendering_and_a_larger_one_reuses_its_shards(dataset, tmp_path,
                                                                                                caplog):
    # generate again with fewer samples re-rendered the now-shorter last shard, and extending back rendered it
    # once more; the manifest says the count and readers read no shard past it
    import logging
    import shutil

    root = tmp_path / "shrink"
    shutil.copytree(dataset, root)
    before = _digest(root / "train")
    with caplog.at_level(logging.INFO, logger="training.data.generate"):
        report = generate(root, {"train": 3}, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    assert (report.shards_written, report.samples_rendered, report.shards_skipped) == (0, 0, 1)
    assert "train: 1 shard(s) past the 3 samples asked for are kept on disk, unread (shard_000001..shard_000001)" \
        in caplog.text
    assert _digest(root / "train") == before  # nothing rewritten, nothing deleted
    assert read_manifest(root)["splits"]["train"]["count"] == 3
    small, reference = ShardedSplit(root, "train"), ShardedSplit(dataset, "train")
    assert len(small) == 3 and len(list(small.all_metadata())) == 3
    for i in range(3):
        assert all(np.array_equal(small.arrays(i)[k], reference.arrays(i)[k]) for k in FIELDS)
        assert small.metadata(i) == reference.metadata(i)
    with pytest.raises(IndexError, match="of 3 samples"):
        small.arrays(3)
    # the report's bytes per sample is of the shards read: shard 0's bytes over its 4 samples
    assert report.samples_on_disk == 4 + COUNTS["val"]
    assert report.bytes_on_disk == sum(p.stat().st_size for d in ("train/shard_000000", "val")
                                       for p in (root / d).rglob("*") if p.is_file())

    report = generate(root, {"train": 6}, CONFIG, dataset_seed=3, workers=1, shard_size=4)
    assert (report.shards_written, report.samples_rendered) == (0, 0)
    assert _digest(root / "train") == before and len(ShardedSplit(root, "train")) == 6


# ------------------------------------------------------------------ damage, a full disk
_SMALL = ["--res", "32", "--novel-views", "0", "--supersample", "1", "--shard-size", "1", "--workers", "1"]


def test_a_damaged_or_half_written_shard_is_rendered_again_not_trusted(tmp_path, caplog):
    out = tmp_path / "ds"
    assert main(["--out", str(out), "--train", "3", *_SMALL]) == 0
    whole = _digest(out)
    images = out / "train" / "shard_000000" / "images.npy"
    images.write_bytes(images.read_bytes()[:-1])  # a power cut before the data reached the disk
    (out / "train" / "shard_000001" / "meta.json").write_text("")
    (out / "train" / "shard_000002.tmp-99999").mkdir()  # a killed run's unfinished shard
    with pytest.raises(DatasetError, match="cut short"):
        ShardedSplit(out, "train")  # readers refuse it, naming the file ...
    caplog.set_level("INFO")
    assert main(["--out", str(out), "--train", "3", *_SMALL]) == 0  # ... and a rerun renders it again
    assert "2 shards (2 samples) to render, 1 already complete" in caplog.text
    assert _digest(out) == whole


def test_a_sigterm_stops_generation_with_143_a_line_and_no_half_written_shard(tmp_path, monkeypatch, caplog):
    """``timeout`` or ``kill`` mid-run: one line saying the finished shards are kept and how to resume, exit 143,
    the lock freed and no ``*.tmp-*`` shard left; the rerun renders only what is missing. SIGTERM killed the
    generator silently before (exit 143, nothing said, the cut shard's temporary folder left)."""
    import os

    import training.data.generate as gen
    from ghnerf_runtime.cli.sigterm import sigterm_raises
    from tests.sigterm_here import sigterm_here

    out = tmp_path / "ds"
    real, calls = gen._render_shard, []

    def render(task):
        calls.append(1)
        if len(calls) == 2:
            (task[4].parent / f"{task[4].name}.tmp-{os.getpid()}").mkdir()  # the shard being written when it came
            sigterm_here("the generator renders")
        return real(task)

    monkeypatch.setattr(gen, "_render_shard", render)
    caplog.set_level("INFO")
    assert main(["--out", str(out), "--train", "3", *_SMALL]) == 143
    assert "stopped (SIGTERM): the finished shards are kept; run the same command again to resume" in caplog.text
    assert sorted(p.name for p in (out / "train").iterdir()) == ["shard_000000"]
    assert (out / "dataset.lock").read_text() == ""  # freed: the holder's line is emptied on the way out
    assert not sigterm_raises()  # the handler before it is back
    monkeypatch.setattr(gen, "_render_shard", real)
    caplog.clear()
    assert main(["--out", str(out), "--train", "3", *_SMALL]) == 0
    assert "2 shards (2 samples) to render, 1 already complete" in caplog.text


def test_a_stop_inside_the_manifest_write_leaves_the_old_manifest_and_no_temporary(tmp_path, monkeypatch):
    """A Ctrl-C or SIGTERM landing in the manifest's write (its fsync, say) left ``manifest.json.tmp`` behind: only
    an OSError removed it."""
    import json
    import os

    from ghnerf_runtime.cli.sigterm import Terminated

    write_manifest(tmp_path, {"old": True})

    def stopped(*a):
        raise Terminated("SIGTERM")

    monkeypatch.setattr(os, "replace", stopped)
    with pytest.raises(Terminated):
        write_manifest(tmp_path, {"new": True})
    monkeypatch.undo()
    assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST]
    assert json.loads((tmp_path / MANIFEST).read_text()) == {"old": True}


def test_a_full_disk_during_generation_exits_2_naming_the_folder_and_the_rerun_resumes(tmp_path, monkeypatch,
                                                                                          caplog):
    import errno

    out = tmp_path / "ds"
    real, calls = np.save, []

    def save(file, arr, *args, **kwargs):  # the second shard's third array meets a full disk halfway
        calls.append(1)
        if len(calls) == len(FIELDS) + 3:
            if hasattr(file, "write"):
                file.write(b"\x93NUMPY")
            else:  # (a path: how the writer called it before)
                Path(file).write_bytes(b"\x93NUMPY")
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(file, arr, *args, **kwargs)

    monkeypatch.setattr(np, "save", save)
    caplog.set_level("INFO")
    assert main(["--out", str(out), "--train", "2", *_SMALL]) == 2  # was an OSError traceback
    error = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(error) == 1 and "no space left on the device" in error[0], error
    assert str(out / "train" / "shard_000001") in error[0] and "run the same command again" in error[0]
    assert sorted(p.name for p in (out / "train").iterdir()) == ["shard_000000"]  # no partial shard, no temporary
    monkeypatch.undo()
    caplog.clear()
    assert main(["--out", str(out), "--train", "2", *_SMALL]) == 0
    assert "1 shards (1 samples) to render, 1 already complete" in caplog.text
    assert len(ShardedSplit(out, "train")) == 2



@pytest.mark.parametrize("option, value, says", [
    ("--seed", "4", "dataset_seed 0, now 4 (--seed)"),
    ("--freestyle-share", "0.5", "synthetic.freestyle_share absent, now 0.5 (--freestyle-share)"),
    ("--cold-start", "0.5", "synthetic.cold_start_fraction 0.2, now 0.5 (--cold-start)"),
    ("--res", "40", "resolution (32, now 40)"),
])
def test_a_rerun_with_other_options_on_an_interrupted_folder_is_refused_naming_the_option(tmp_path, caplog, option,
                                                                                        value, says):
    # a first run stopped before its manifest recorded any split: the rerun must not mix two recipes either
    out = tmp_path / "ds"
    assert main(["--out", str(out), "--train", "1", *_SMALL]) == 0
    manifest = read_manifest(out)
    manifest["splits"] = {}  # as the run left it when stopped before its end
    write_manifest(out, manifest)
    args = ["--out", str(out), "--train", "2", *_SMALL]
    if option in args:
        args[args.index(option) + 1] = value
    else:
        args += [option, value]
    caplog.set_level("INFO")
    caplog.clear()
    assert main(args) == 2
    error = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(error) == 1 and says in error[0] and str(out / MANIFEST) in error[0], error
    assert sorted(p.name for p in (out / "train").iterdir()) == ["shard_000000"]  # nothing rendered
