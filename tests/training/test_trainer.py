"""The trainer: config validation, the real loop on ``tiny`` (2 CPU iterations), checkpoint + resume."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from training.model.config import ConfigError  # noqa: E402
from training.train import (  # noqa: E402
    HEATMAP_SIGMA_HM_PX, apply_overrides, build_config, heatmaps_at, load_config_file, main, sample_rays, train,
)


def tiny_cfg(data, **kw):
    base = {"preset": "tiny", "data": str(data), "iterations": 2, "targets_per_iter": 2, "heat_rays": 32,
            "patch_size": 8, "checkpoint_every": 1, "log_every": 1, "pck_every": 1, "threads": 2,
            "loss": {"coord_weight": 0.01}}
    base.update(kw)
    return build_config(base)


# ----------------------------------------------------------------------------------------- config
@pytest.mark.parametrize("data, key", [
    ({"iterationz": 3}, "iterationz"),
    ({"loss": {"heat_wieght": 0.5}}, "loss.heat_wieght"),
    ({"iterations": "many"}, "iterations"),
    ({"iterations": 0}, "iterations"),
    ({"lr": -1.0}, "lr"),
    ({"mask_fraction": 1.5}, "mask_fraction"),
    ({"preset": "huge"}, "preset"),
    ({"device": "tpu"}, "device"),
    ({"loss": {"ssim_weight": -0.1}}, "loss.ssim_weight"),
    ({"patch_size": 1}, "patch_size"),
    ({"patch_size": 129}, "patch_size"),  # larger than the 128x128 model input: rays off the image
    ({"grad_clip": float("nan")}, "grad_clip"),
    ({"max_minutes": float("nan")}, "max_minutes"),
    ({"max_minutes": -1.0}, "max_minutes"),
    # torch takes these as C integers: accepted here, they failed the run after config.json was written
    ({"seed": -1}, "seed"),
    ({"seed": 2 ** 63}, "seed"),
    ({"threads": 2 ** 31}, "threads"),
    ({"pretrain_human": {"seed": 2 ** 63}}, "pretrain_human.seed"),
    ({"pretrain_human": {"threads": 2 ** 31}}, "pretrain_human.threads"),
    ({"loss": {"level_weights": [-1.0, 2.0]}}, "loss.level_weights"),
    ({"loss": {"level_weights": [1.0, 1.0, 1.0]}}, "loss.level_weights"),  # edge128 has 2 levels
])
def test_config_errors_name_the_key(data, key):
    with pytest.raises(ConfigError) as e:
        build_config(data)
    assert str(e.value).startswith(key)


def test_config_files_and_overrides(tmp_path):
    (tmp_path / "a.toml").write_text('preset = "tiny"\niterations = 5\n[loss]\nheat_weight = 0.25\n')
    d = apply_overrides(load_config_file(tmp_path / "a.toml"), ["loss.ssim_weight=0", "data=\"x\""])
    cfg = build_config(d)
    assert (cfg.preset, cfg.iterations, cfg.loss.heat_weight, cfg.loss.ssim_weight, cfg.data) == \
        ("tiny", 5, 0.25, 0.0, "x")
    for name in ("edge128", "edge128_baseline"):  # the shipped schedules validate
        build_config(load_config_file(f"training/train_configs/{name}.json"))


def test_seed_and_threads_at_their_limits_validate():
    from training.run_limits import MAX_SEED, MAX_THREADS

    cfg = build_config({"seed": MAX_SEED, "threads": MAX_THREADS, "pretrain_human": {"seed": MAX_SEED}})
    assert (cfg.seed, cfg.threads) == (MAX_SEED, MAX_THREADS)


@pytest.mark.parametrize("name, text, says", [
    ("deep.json", "[" * 100_000 + "]" * 100_000, "not valid JSON (nested too deeply)"),  # was a RecursionError
    ("deep.toml", "x = " + "[" * 100_000 + "]" * 100_000, "not valid TOML (nested too deeply)"),
    # the 5 was taken silently
    ("twice.json", '{"iterations": 100, "iterations": 5}', "duplicate key 'iterations' (JSON keeps only its last value)"),
    ("empty.json", "", "file is empty"),
])
def test_config_file_errors_name_the_file(tmp_path, name, text, says):
    (tmp_path / name).write_text(text)
    with pytest.raises(ConfigError) as e:
        load_config_file(tmp_path / name)
    assert str(e.value) == f"config file {tmp_path / name}: {says}"


@pytest.mark.parametrize("item, says", [
    ("=1", "=1: override key '' has an empty part"),  # was "': unknown key for TrainConfig"
    ("loss..heat_weight=1", "override key 'loss..heat_weight' has an empty part"),
    ("model=" + "[" * 50_000 + "]" * 50_000, "model: the value is nested too deeply"),  # was a RecursionError
])
def test_bad_overrides_are_config_errors(item, says):
    with pytest.raises(ConfigError) as e:
        apply_overrides({}, [item])
    assert says in str(e.value)


def test_cli_reports_config_error(tmp_path, capsys):
    (tmp_path / "c.json").write_text(json.dumps({"bogus": 1}))
    assert main(["--config", str(tmp_path / "c.json"), "--out", str(tmp_path / "o")]) == 2
    assert "bogus" in capsys.readouterr().err
    (tmp_path / "list.json").write_text("[1, 2]")  # JSON, but not a table of settings
    assert main(["--config", str(tmp_path / "list.json"), "--out", str(tmp_path / "o")]) == 2
    assert f"config file {tmp_path / 'list.json'}: must hold a JSON object" in capsys.readouterr().err


@pytest.mark.parametrize("marks", [["encoder.onnx", "volume.int8.onnx"], ["model_card.json"]])
@pytest.mark.parametrize("resume", [False, True])
def test_a_model_folder_is_refused_as_the_run_folder(tmp_path, capsys, marks, resume):
    """``--out models/ghnerf`` (a path copied from a ghnerf-run command) trained into it: last.pt, config.json and
    log.jsonl beside the graphs. Refused naming the folder and what marks it, before anything is written."""
    (tmp_path / "c.json").write_text(json.dumps({"preset": "tiny", "data": str(tmp_path / "nowhere")}))
    folder = tmp_path / "models"
    folder.mkdir()
    for name in marks:
        (folder / name).write_bytes(b"graph")
    assert main(["--config", str(tmp_path / "c.json"), "--out", str(folder), *["--resume"] * resume]) == 2
    err = capsys.readouterr().err
    assert f"{folder}: is a model folder (it holds {', '.join(marks)}), not a run folder" in err
    assert "give a new one" in err
    assert sorted(p.name for p in folder.iterdir()) == marks


def test_cli_reports_the_run_folders_config_errors(tmp_path, capsys):
    """ConfigErrors of the run itself (not of the config file) exit 2 too, before anything is written."""
    (tmp_path / "c.json").write_text(json.dumps({"preset": "tiny", "data": str(tmp_path / "nowhere")}))
    run = tmp_path / "run"
    run.mkdir()
    (run / "last.pt").write_bytes(b"not a checkpoint")
    assert main(["--config", str(tmp_path / "c.json"), "--out", str(run)]) == 2  # a run, and no --resume
    err = capsys.readouterr().err
    assert f"{run}: holds a training run (last.pt)" in err and "--resume" in err
    assert main(["--config", str(tmp_path / "c.json"), "--out", str(run), "--resume"]) == 2
    assert f"{run / 'last.pt'}: unreadable checkpoint" in capsys.readouterr().err
    assert sorted(p.name for p in run.iterdir()) == ["last.pt"]


# --------------------------------------------------------------------------------------- sampling
def test_rays_and_targets():
    g = torch.Generator().manual_seed(0)
    masks = torch.zeros(2, 64, 64, dtype=torch.bool)
    masks[:, 20:40, 24:36] = True
    uv = sample_rays(masks, 40, 6, 4, 0.75, g)
    assert uv.shape == (2, 40 + 36, 2)
    grid = uv[:, :40]
    assert torch.all(((grid + 0.5) / 4 - 0.5) % 1 == 0)  # on the stride-4 grid (contract.ray_grid)
    inside = masks[0][grid[0, :, 1].long(), grid[0, :, 0].long()] | \
        masks[0][(grid[0, :, 1] + 0.5).long(), (grid[0, :, 0] + 0.5).long()]
    assert inside.float().mean() >= 0.7
    patch = uv[0, 40:].reshape(6, 6, 2)
    assert torch.all(patch[:, 1:, 0] - patch[:, :-1, 0] == 1) and torch.all(patch[1:, :, 1] - patch[:-1, :, 1] == 1)


def test_heatmaps_at_rays_match_the_dataset_heatmaps(data64):
    from ghnerf_runtime.contract import ray_grid
    from training.data.torch_dataset import MultiViewDataset

    item = MultiViewDataset(data64, "train")[0]
    V = item["tgt_heatmaps"].shape[0]
    uv = torch.from_numpy(ray_grid(64, 64, 4))[None].expand(V, -1, -1)
    h = heatmaps_at(item["tgt_joints_2d"], item["tgt_visible"], uv, HEATMAP_SIGMA_HM_PX * 4)
    ref = item["tgt_heatmaps"].flatten(2).transpose(1, 2)
    assert torch.allclose(h, ref, atol=1e-5)


def test_batch_mask_is_the_subject_mask_at_the_rays(data64):
    from training.configs import preset
    from training.data.torch_dataset import MultiViewDataset
    from training.train import TrainConfig, make_batch

    item = MultiViewDataset(data64, "train")[0]
    cfg = TrainConfig(data=str(data64), targets_per_iter=2, heat_rays=64, patch_size=4)
    batch = make_batch(item, cfg, preset("tiny"), torch.Generator().manual_seed(0))
    uv = batch["ray_uv"]
    masks = item["tgt_masks"][batch["targets"]].float()
    # heat rays sit at heatmap-cell centres (between 2x2 pixels: their mean), patch rays on pixel centres
    lo = uv.floor().long()
    frac = uv - lo
    assert torch.all((frac == 0) | (frac == 0.5))
    hi = torch.where(frac > 0, lo + 1, lo)
    want = torch.stack([(masks[b, lo[b, :, 1], lo[b, :, 0]] + masks[b, lo[b, :, 1], hi[b, :, 0]]
                         + masks[b, hi[b, :, 1], lo[b, :, 0]] + masks[b, hi[b, :, 1], hi[b, :, 0]]) / 4
                        for b in range(len(uv))])
    assert batch["mask"].shape == batch["rgb"].shape[:2]
    assert torch.allclose(batch["mask"], want, atol=1e-6)
    assert 0 < float(batch["mask"].mean()) < 1  # rays inside and outside the subject


def test_batch_depth_is_the_true_depth_on_the_subject_only(data64):
    from training.configs import preset
    from training.data.torch_dataset import MultiViewDataset
    from training.train import TrainConfig, make_batch

    item = MultiViewDataset(data64, "train")[0]
    cfg = TrainConfig(data=str(data64), targets_per_iter=2, heat_rays=64, patch_size=4)
    assert "depth" not in make_batch(item, cfg, preset("tiny"), torch.Generator().manual_seed(0))  # off: not built
    cfg.loss.depth_weight = 0.1
    batch = make_batch(item, cfg, preset("tiny"), torch.Generator().manual_seed(0))
    valid, t = batch["depth_valid"], batch["targets"]
    assert valid.shape == batch["depth"].shape == batch["rgb"].shape[:2]
    assert valid.any() and not valid.all()
    assert torch.all(batch["mask"][valid] > 0.999)  # every bilinear tap on the subject
    # on pixel-centre rays the depth is the dataset's pixel
    uv = batch["ray_uv"]
    on_pixel = valid & (uv.frac() == 0).all(-1)
    b, r = torch.nonzero(on_pixel, as_tuple=True)
    want = item["tgt_depth"][t[b], uv[b, r, 1].long(), uv[b, r, 0].long()]
    assert len(b) and torch.allclose(batch["depth"][b, r], want)
    # a view without depth (ZJU-MoCap) counts nowhere
    item = dict(item, tgt_has_depth=torch.zeros_like(item["tgt_has_depth"]))
    assert not make_batch(item, cfg, preset("tiny"), torch.Generator().manual_seed(0))["depth_valid"].any()


# ------------------------------------------------------------------------------------------- loop
def test_two_iterations_and_resume_is_identical(data64, tmp_path):
    straight, m_straight = train(tiny_cfg(data64), tmp_path / "a", quiet=True)
    assert straight["steps"] == 2 and not straight["stopped_early"]
    log = [json.loads(l) for l in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2] and all(set(r) >= {"loss", "psnr", "pck"} for r in log)
    assert (tmp_path / "a" / "ckpt_0000002.pt").exists()
    ck = torch.load(tmp_path / "a" / "last.pt", weights_only=False)
    assert {"model", "optimizer", "step", "config", "rng"} <= set(ck) and ck["step"] == 2

    first, _ = train(tiny_cfg(data64, iterations=1), tmp_path / "b", quiet=True)
    assert first["steps"] == 1
    # last.pt lost: --resume continues from the newest ckpt_*.pt (it used to start again from step 0)
    import shutil

    shutil.copytree(tmp_path / "b", tmp_path / "c")
    (tmp_path / "c" / "last.pt").unlink()
    (tmp_path / "c" / "ckpt_0000000.pt").write_bytes(b"older and damaged: never reached")
    from_ckpt, m_from_ckpt = train(tiny_cfg(data64), tmp_path / "c", resume=True, quiet=True)
    assert from_ckpt["steps"] == 2 and [g["steps"] for g in from_ckpt["segments"]] == [1, 1]
    resumed, m_resumed = train(tiny_cfg(data64), tmp_path / "b", resume=True, quiet=True)
    assert resumed["steps"] == 2
    # the summary's wall time covers both invocations, each listed with its steps and threads
    assert "segments" not in straight and [g["steps"] for g in resumed["segments"]] == [1, 1]
    assert resumed["wall_s"] == pytest.approx(sum(g["wall_s"] for g in resumed["segments"]), abs=0.11)
    # the first segment is what the first invocation's last checkpoint stored: its time up to that save
    # (the save itself and the summary come after, so it can be shorter than that run's summary on a busy box)
    assert 0 <= resumed["segments"][0]["wall_s"] <= first["wall_s"]
    a, b = m_straight.state_dict(), m_resumed.state_dict()
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
        assert torch.equal(a[k], m_from_ckpt.state_dict()[k]), k
    # and training moved the weights at all
    init = torch.load(tmp_path / "b" / "ckpt_0000001.pt", weights_only=False)["model"]
    assert any(not torch.equal(init[k], a[k]) for k in a if a[k].is_floating_point())


def test_resume_refuses_another_config_and_names_a_damaged_checkpoint(data64, tmp_path):
    from training.model.config import ConfigError

    train(tiny_cfg(data64, iterations=1), tmp_path / "r", quiet=True)
    before = (tmp_path / "r" / "config.json").read_text()
    with pytest.raises(ConfigError, match=r"\(lr 0\.0005 in the run, 0\.1 now; seed 0 in the run, 5 now\)"):
        train(tiny_cfg(data64, lr=0.1, seed=5), tmp_path / "r", resume=True, quiet=True)
    assert (tmp_path / "r" / "config.json").read_text() == before  # the run's record untouched
    last = tmp_path / "r" / "last.pt"
    saved = {p.name: p.read_bytes() for p in (tmp_path / "r").iterdir()}

    # a new run in the folder (no resume) would overwrite the run's config.json, last.pt and ckpt_*.pt
    with pytest.raises(ConfigError, match=r"holds a training run \(last.pt, ckpt_0000001.pt\); pass --resume"):
        train(tiny_cfg(data64, lr=0.1), tmp_path / "r", quiet=True)
    assert {p.name: p.read_bytes() for p in (tmp_path / "r").iterdir()} == saved

    # another process count: each rank's scenes and random state depend on it
    ck = torch.load(last, weights_only=False)
    assert ck["extra"]["world_size"] == 1
    for extra in ({"world_size": 2}, {"rng_ranks": [ck["rng"], ck["rng"]]}):  # the latter: saved before world_size
        torch.save({**ck, "extra": {k: v for k, v in {**ck["extra"], **extra}.items()
                                    if k != "world_size" or "world_size" in extra}}, last)
        with pytest.raises(ConfigError, match=r"last.pt: saved by a run of 2 process\(es\), resumed with 1"):
            train(tiny_cfg(data64), tmp_path / "r", resume=True, quiet=True)
    assert (tmp_path / "r" / "config.json").read_text() == before

    last.write_bytes(last.read_bytes()[:1000])
    with pytest.raises(ConfigError, match="last.pt: unreadable checkpoint"):
        train(tiny_cfg(data64), tmp_path / "r", resume=True, quiet=True)


def test_a_damaged_last_pt_of_a_run_without_step_checkpoints_is_not_sent_to_a_ckpt_that_is_not_there(tmp_path):
    # a run shorter than checkpoint_every has last.pt alone: the advice "delete it (--resume then continues from
    # the newest ckpt_*.pt)" named files that were not there, and deleting it started the run again from step 0
    from training.model.config import ConfigError
    from training.train import load_checkpoint

    last = tmp_path / "last.pt"
    last.write_bytes(b"PK\x03\x04 torn")
    with pytest.raises(ConfigError, match=r"last.pt: unreadable checkpoint .*; the run has no ckpt_\*\.pt to go "
                                          r"back to: restore last.pt from a copy, or delete it and --resume starts "
                                          r"the run again from step 0"):
        load_checkpoint(last)
    (tmp_path / "ckpt_0000100.pt").write_bytes(b"")
    with pytest.raises(ConfigError, match=r"delete it \(--resume then continues from the newest ckpt_\*\.pt\)"):
        load_checkpoint(last)


def test_resuming_the_other_trainers_run_folder_names_which_tool_made_it(tmp_path):
    # both tools keep a last.pt: each called the other's "a weights-only file?" and sent the user to a ckpt_*.pt
    # (which the pretraining never writes)
    from training.model.config import ConfigError
    from training.pretrain_human import RESUME_KEYS as PRETRAIN_KEYS
    from training.train import RESUME_KEYS, require_resume_keys

    pretraining = {"human": {}, "optimizer": {}, "step": 2, "config": {}, "model_config": {}}
    joint = {"model": {}, "optimizer": {}, "step": 2, "config": {}, "model_config": {}, "rng": {}, "extra": {}}
    last = tmp_path / "last.pt"
    with pytest.raises(ConfigError, match=r"last.pt: a human-encoder pretraining checkpoint \(python -m "
                                          r"training.pretrain_human's\), which this tool's --resume cannot continue"):
        require_resume_keys(pretraining, last, RESUME_KEYS)
    with pytest.raises(ConfigError, match=r"last.pt: a training checkpoint of the whole model \(ghnerf-train's\)"):
        require_resume_keys(joint, last, PRETRAIN_KEYS)
    with pytest.raises(ConfigError, match=r"no optimizer, step, config, rng \(a weights-only file\?\)"):
        require_resume_keys({"model": {}, "model_config": {}}, last, RESUME_KEYS)  # make model's <variant>.pt
    require_resume_keys(joint, last, RESUME_KEYS)
    require_resume_keys(pretraining, last, PRETRAIN_KEYS)


def test_an_unreadable_checkpoint_is_named_with_torchs_words_cut_after_a_sentence(tmp_path):
    """torch's text was cut at 200 characters, mid-sentence: "...there is a high likelihood that your checkpoint
    file is)". It now ends after the last sentence that fits, and still names the file."""
    from training.train import load_checkpoint

    damaged = tmp_path / "last.pt"
    torch.save({"w": torch.zeros(3)}, damaged)
    damaged.write_bytes(damaged.read_bytes()[:-10])  # the zip's central directory lost
    with pytest.raises(ConfigError) as e:
        load_checkpoint(damaged)
    said = str(e.value)
    assert said.startswith(f"{damaged}: unreadable checkpoint (RuntimeError: ")
    words = said.split("(RuntimeError: ", 1)[1].split("); ", 1)[0]
    assert words.endswith("."), words
    assert "failed finding central directory." in words and len(words) <= 200


@pytest.mark.parametrize("text, said", [
    ("short and whole", "short and whole"),
    ("first line\nsecond line", "first line"),
    ("a clause, " + "x" * 250, "a clause"),  # no sentence ends within the limit: the last clause that does
    ("y" * 250, "y" * 250),  # no boundary at all: kept whole rather than cut mid-word
    # torch's load_state_dict error: its first line alone ("...for GHNeRF:") named no key
    ("Error(s) in loading state_dict for GHNeRF:\n\tMissing key(s) in state_dict: \"a.weight\".",
     'Error(s) in loading state_dict for GHNeRF: Missing key(s) in state_dict: "a.weight".'),
])
def test_error_words_keep_a_complete_first_line_or_sentence(text, said):
    from training.train import error_words

    assert error_words(RuntimeError(text)) == said


def test_resume_without_last_pt_passes_over_a_damaged_ckpt_for_the_next_older(data64, tmp_path, capsys):
    """The newest ckpt_*.pt that loads is taken; the one passed over was named with last.pt's advice ("delete it
    (--resume then continues from the newest ckpt_*.pt)"), which it was already doing."""
    run = tmp_path / "r"
    train(tiny_cfg(data64, iterations=3, pck_every=0), run, quiet=True)
    (run / "last.pt").unlink()
    newest = run / "ckpt_0000003.pt"
    newest.write_bytes(newest.read_bytes()[:1000])
    summary, _ = train(tiny_cfg(data64, iterations=3, pck_every=0), run, resume=True, quiet=True)
    err = capsys.readouterr().err
    assert f"skipping {newest}: unreadable checkpoint (" in err
    assert "; passed over: --resume tries the next older ckpt_*.pt\n" in err
    assert "delete it" not in err
    assert f"{run / 'last.pt'} is missing: resuming from ckpt_0000002.pt" in err
    assert summary["steps"] == 3 and torch.load(run / "last.pt", weights_only=False)["step"] == 3


def test_two_iterations_with_every_view_and_mirrored_encoder_images(data64, tmp_path):
    cfg = tiny_cfg(data64, encoder_views="all", encoder_flip=True, loss={"coord_weight": 0.01, "mask_weight": 0.1,
                                                                                         "depth_weight": 0.1})
    summary, model = train(cfg, tmp_path / "r", quiet=True)
    assert summary["steps"] == 2
    assert all(torch.isfinite(p).all() for p in model.parameters())


def test_init_loads_torchvision_weights_into_the_human_encoder(data64, tmp_path):
    from training.configs import preset
    from training.model import GHNeRF

    torch.manual_seed(123)
    donor = GHNeRF(preset("tiny")).human.trunk
    state = {k: v.clone() for k, v in donor.state_dict().items()}
    state["fc.weight"] = torch.zeros(1000, 512)  # torchvision extras are dropped
    torch.save(state, tmp_path / "resnet18.pth")
    cfg = tiny_cfg(data64, iterations=1, init=str(tmp_path / "resnet18.pth"), lr=1e-12, pck_every=0)
    _, model = train(cfg, tmp_path / "run", quiet=True)
    got = model.human.trunk.state_dict()
    assert all(torch.allclose(got[k].float(), state[k].float(), atol=1e-6) for k in got if "num_batches" not in k
               and "running" not in k)
    with pytest.raises(ConfigError, match="^init"):  # the baseline has no human encoder
        train(build_config({"preset": "edge128_baseline", "data": str(data64), "init": "x.pth"}), tmp_path / "r2")


def test_a_resume_does_not_need_the_init_file_the_checkpoint_replaces(data64, tmp_path):
    # --resume refused a run whose torchvision file had since been moved ("init: ...: no such file"), though the
    # checkpoint's weights replace whatever init loads; a fresh start still needs it
    from training.configs import preset
    from training.model import GHNeRF

    torch.manual_seed(5)
    torch.save(GHNeRF(preset("tiny")).human.trunk.state_dict(), tmp_path / "resnet18.pth")
    cfg = tiny_cfg(data64, iterations=2, init=str(tmp_path / "resnet18.pth"), pck_every=0)
    _, straight = train(cfg, tmp_path / "a", quiet=True)
    train(tiny_cfg(data64, iterations=1, init=str(tmp_path / "resnet18.pth"), pck_every=0), tmp_path / "b", quiet=True)
    (tmp_path / "resnet18.pth").unlink()
    summary, resumed = train(cfg, tmp_path / "b", resume=True, quiet=True)
    assert summary["steps"] == 2
    a, b = straight.state_dict(), resumed.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    with pytest.raises(ConfigError, match="^init: .*no such file"):  # nothing to resume from: the file is needed
        train(cfg, tmp_path / "c", resume=True, quiet=True)


def test_step_losses_keep_every_loss_setting():
    from dataclasses import replace

    from training.losses import LossConfig, compute_losses
    from training.train import step_losses

    g = torch.Generator().manual_seed(0)
    P, R = 4, 10
    out = {"levels": [{"rgb": torch.rand(2, R + P * P, 3, generator=g),
                       "heatmaps": torch.rand(2, R + P * P, 25, generator=g)}]}
    batch = {"rgb": torch.rand(2, R + P * P, 3, generator=g), "heatmaps": torch.rand(2, R + P * P, 25, generator=g)}
    for w in (0.0, 20.0):
        cfg = build_config({"preset": "tiny", "patch_size": P, "loss": {"heat_positive_weight": w}})
        terms = step_losses(out, batch, cfg)
        ref = compute_losses(out, batch, replace(cfg.loss, ssim_weight=0.0))
        assert torch.equal(terms["l0_heat"], ref["l0_heat"])
        ssim = compute_losses({"levels": [{"rgb": out["levels"][0]["rgb"][:, -P * P:]}]},
                              {"rgb": batch["rgb"][:, -P * P:]}, LossConfig(colour_weight=0, heat_weight=0),
                              patch_shape=(P, P))["l0_ssim"]
        assert torch.allclose(terms["loss"], ref["loss"] + cfg.loss.ssim_weight * ssim)


def test_a_run_folder_in_use_is_refused(tmp_path):
    import os

    (tmp_path / "train.pid").write_text(str(os.getppid()))  # a live process that is not us
    with pytest.raises(RuntimeError, match="another training process"):
        train(build_config({"preset": "tiny", "data": "nowhere"}), tmp_path)
    assert not (tmp_path / "config.json").exists()


def test_the_step_timing_benchmark_runs_the_trainers_step(data64, capsys):
    """``benchmarks/time_train_step.py`` times ``training.train.train_step`` for both variants and both
    arithmetics and prints one row each (here on the tiny preset; the figures are the host's)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "time_train_step.py"
    spec = importlib.util.spec_from_file_location("time_train_step", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--data", str(data64), "--threads", "1", "--steps", "1", "--set", 'preset="tiny"']) == 0
    rows = [line.split("|")[1:-1] for line in capsys.readouterr().out.splitlines() if line.startswith("| ")]
    rows = [[c.strip() for c in r] for r in rows if r[0].strip() in ("ghnerf", "baseline")]
    assert [(r[0], r[2]) for r in rows] == [("ghnerf", "fp32"), ("ghnerf", "bf16"),
                                            ("baseline", "fp32"), ("baseline", "bf16")]
    assert all(float(r[3]) > 0 for r in rows) and rows[1][5].endswith("x")
    with pytest.raises(SystemExit):
        bench.main(["--data", str(data64), "--precisions", "fp16"])


# ------------------------------------------------------------------------------ review: config and resume
@pytest.mark.parametrize("model, key", [
    ({"heatmap_stride": 0}, "model.heatmap_stride"),  # used to pass, then a ZeroDivisionError after config.json
    ({"cost_volume": {"groups": 0}}, "model.cost_volume.groups"),
    ({"levels": {"0": {"volume_stride": 0}}}, "model.levels[0].volume_stride"),
    ({"human": {"out_stride": 0}}, "model.human.out_stride"),
])
def test_the_merged_model_config_is_validated(model, key):
    with pytest.raises(ConfigError) as e:
        build_config({"preset": "tiny", "model": model})
    assert str(e.value).startswith(key)


def test_list_overrides_merge_onto_the_presets_entries():
    from training.configs import preset

    base = preset("edge128")
    cfg = build_config({"model": {"levels": [{"planes": 32}, {}]}}).model_config()
    assert cfg.levels[0].planes == 32 and cfg.levels[0].range_scale == base.levels[0].range_scale == 1.5
    assert cfg.levels[1] == base.levels[1]
    by_index = apply_overrides({}, ["model.levels.0.planes=32"])  # --set with an index
    assert build_config(by_index).model_config().levels == cfg.levels
    # another length replaces the list: then every entry must be whole, not half class defaults
    with pytest.raises(ConfigError, match=r"^model.levels\[0\]: the override has 1 entries for the preset's 2.*"
                                          r"missing volume_stride"):
        build_config({"model": {"levels": [{"planes": 16}]}})
    whole = [{**base.to_dict()["levels"][0], "planes": 16}]
    assert [lv.planes for lv in build_config({"model": {"levels": whole}}).model_config().levels] == [16]


def _resume_run(data64, tmp_path):
    """A one-step run to resume, and its config.json as written."""
    run = tmp_path / "r"
    train(tiny_cfg(data64, iterations=1, pck_every=0), run, quiet=True)
    return run, (run / "config.json").read_text()


def test_resume_under_another_config_names_each_setting_with_both_values(data64, tmp_path):
    """It named the keys alone (``loss, lr differ from the run's``): which loss weight, and what it was, had to be
    dug out of config.json."""
    run, before = _resume_run(data64, tmp_path)
    with pytest.raises(ConfigError) as e:
        train(tiny_cfg(data64, pck_every=0, lr=1e-3, loss={"coord_weight": 0.01, "heat_weight": 1.0}), run,
              resume=True, quiet=True)
    assert "resuming under another config (loss.heat_weight 0.5 in the run, 1.0 now; lr 0.0005 in the run, " \
           "0.001 now); resume changes only iterations" in str(e.value)
    assert (run / "config.json").read_text() == before


def test_resume_refuses_another_model_config_and_a_weights_only_file(data64, tmp_path):
    run, before = _resume_run(data64, tmp_path)
    last = run / "last.pt"
    ck = torch.load(last, weights_only=False)
    ck["model_config"]["levels"][0]["samples"] = 2  # the preset changed since the run started
    torch.save(ck, last)
    with pytest.raises(ConfigError, match=rf"^{last}: resuming under another model config \(levels\[0\].samples "):
        train(tiny_cfg(data64, pck_every=0), run, resume=True, quiet=True)
    assert (run / "config.json").read_text() == before

    ck["model_config"]["levels"][0]["samples"] = 4
    torch.save({k: ck[k] for k in ("model", "model_config", "step")}, last)  # what make model ships
    with pytest.raises(ConfigError, match=rf"^{last}: not a training checkpoint .*no optimizer, config, rng"):
        train(tiny_cfg(data64, pck_every=0, lr=0.1), run, resume=True, quiet=True)
    assert (run / "config.json").read_text() == before


def test_resume_takes_model_overrides_that_build_the_same_model(data64, tmp_path):
    """``--set model.use_human_encoder=true`` on a ``tiny`` run restates the preset: the same model, yet the
    resume was refused (``model.use_human_encoder None in the run, True now``), and the other way round."""
    run, _ = _resume_run(data64, tmp_path)
    same = {"use_human_encoder": True, "heatmap_stride": 4}
    assert train(tiny_cfg(data64, iterations=2, pck_every=0, model=same), run, resume=True, quiet=True)[0]["steps"] == 2
    assert train(tiny_cfg(data64, iterations=3, pck_every=0), run, resume=True, quiet=True)[0]["steps"] == 3


def test_resume_under_another_preset_name_that_builds_the_same_model(data64, tmp_path, monkeypatch):
    """``--preset edge128 --set model.use_human_encoder=false`` on an ``edge128_baseline`` run builds the same
    model, yet was refused on ``preset``: the preset is compared by the model it builds, as the overrides are."""
    from dataclasses import replace

    from training.configs import PRESETS, tiny

    monkeypatch.setitem(PRESETS, "tiny_baseline", lambda: replace(tiny(), use_human_encoder=False))
    run = tmp_path / "r"
    train(tiny_cfg(data64, preset="tiny_baseline", iterations=1, pck_every=0), run, quiet=True)
    same = tiny_cfg(data64, iterations=2, pck_every=0, model={"use_human_encoder": False})
    assert train(same, run, resume=True, quiet=True)[0]["steps"] == 2
    with pytest.raises(ConfigError) as e:  # a preset building another model: named by the setting that differs
        train(tiny_cfg(data64, iterations=3, pck_every=0), run, resume=True, quiet=True)
    assert "another model config (use_human_encoder False in the checkpoint, True now" in str(e.value)


def test_resume_does_not_read_a_model_human_init_moved_since_the_run_began(data64, tmp_path):
    """The checkpoint holds the weights ``model.human.init`` gave the run's start: a resume built the model by
    reading the file again, so one moved since stopped it (``model.human.init: ...: no such file``)."""
    from tests.training.test_resnet18_names import fake_state_dict
    from training.train import load_model

    weights = tmp_path / "resnet18.pth"
    torch.save(fake_state_dict(), weights)
    cfg = tiny_cfg(data64, pck_every=0, model={"human": {"init": str(weights)}})
    _, m_straight = train(cfg, tmp_path / "a", quiet=True)
    train(tiny_cfg(data64, iterations=1, pck_every=0, model={"human": {"init": str(weights)}}), tmp_path / "b",
          quiet=True)
    weights.rename(tmp_path / "moved.pth")
    summary, m_resumed = train(cfg, tmp_path / "b", resume=True, quiet=True)
    assert summary["steps"] == 2
    a, b = m_straight.state_dict(), m_resumed.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    ck = torch.load(tmp_path / "b" / "last.pt", weights_only=False)  # the run's model config, unchanged
    assert ck["model_config"]["human"]["init"] == str(weights)
    loaded, _ = load_model(tmp_path / "b" / "last.pt")  # evaluation reads the checkpoint's weights alone too
    assert all(torch.equal(a[k], v) for k, v in loaded.state_dict().items())


def test_resume_under_other_model_overrides_names_the_setting_with_both_values(data64, tmp_path):
    """A baseline override on a model run: named with the checkpoint's value and the new one, not ``None``."""
    run, before = _resume_run(data64, tmp_path)
    with pytest.raises(ConfigError) as e:
        train(tiny_cfg(data64, pck_every=0, model={"use_human_encoder": False}), run, resume=True, quiet=True)
    assert "resuming under another model config (use_human_encoder True in the checkpoint, False now" in str(e.value)
    assert "None" not in str(e.value)
    assert (run / "config.json").read_text() == before


def test_a_key_one_config_lacks_is_named_unset_not_none(tmp_path):
    from training.train import refuse_another_config

    with pytest.raises(ConfigError, match=r"\(pretrain_human\.iterations unset in the run, 5 now\)"):
        refuse_another_config(tmp_path / "last.pt", {"pretrain_human": {}}, {"pretrain_human": {"iterations": 5}}, ())


def test_resume_drops_the_log_records_past_the_checkpoint(data64, tmp_path):
    import shutil

    run = tmp_path / "r"
    train(tiny_cfg(data64, pck_every=0), run, quiet=True)
    shutil.copyfile(run / "ckpt_0000001.pt", run / "last.pt")  # the step-2 checkpoint lost
    with open(run / "log.jsonl", "a") as fh:
        fh.write('{"step": 3, "lo')  # and a line cut short by a crash
    train(tiny_cfg(data64, pck_every=0), run, resume=True, quiet=True)
    assert [json.loads(line)["step"] for line in (run / "log.jsonl").read_text().splitlines()] == [1, 2]


def strict_loads(text: str):
    """``text`` read as strict JSON: a bare ``NaN`` / ``Infinity`` (which ``jq`` and ``JSON.parse`` refuse) fails."""
    def refuse(name):
        raise ValueError(f"not strict JSON: {name}")

    return json.loads(text, parse_constant=refuse)


def test_cli_writes_strict_json_when_no_pck_was_scored(data64, tmp_path, capsys):
    """pck_every 0 leaves every record's pck NaN: log.jsonl, summary.json and stdout write it as null."""
    (tmp_path / "c.json").write_text(json.dumps({"preset": "tiny", "data": str(data64), "iterations": 1,
                                                 "targets_per_iter": 2, "heat_rays": 32, "patch_size": 8,
                                                 "log_every": 1, "pck_every": 0, "threads": 2}))
    run = tmp_path / "run"
    assert main(["--config", str(tmp_path / "c.json"), "--out", str(run), "--quiet"]) == 0
    assert strict_loads(capsys.readouterr().out)["steps"] == 1
    assert strict_loads((run / "summary.json").read_text())["steps"] == 1
    assert [strict_loads(line)["pck"] for line in (run / "log.jsonl").read_text().splitlines()] == [None]


def log_records(run: Path) -> list[dict]:
    """``run``'s log.jsonl records without their wall times, NaN as None (so two runs' logs compare equal)."""
    import math

    out = []
    for line in (run / "log.jsonl").read_text().splitlines():
        rec = json.loads(line)
        rec.pop("time_s")
        out.append({k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in rec.items()})
    return out


def test_a_resumed_run_logs_the_records_an_uninterrupted_one_does(data64, tmp_path):
    # the log window (steps since the last record) and the last PCK were not kept: the first record after a resume
    # averaged only the resumed steps and carried pck NaN until the next pck_every step
    import shutil

    cfg = tiny_cfg(data64, iterations=4, log_every=2, pck_every=3)
    train(cfg, tmp_path / "straight", quiet=True)
    shutil.copytree(tmp_path / "straight", tmp_path / "cut")
    shutil.copyfile(tmp_path / "cut" / "ckpt_0000003.pt", tmp_path / "cut" / "last.pt")  # killed after step 3
    train(cfg, tmp_path / "cut", resume=True, quiet=True)
    straight = log_records(tmp_path / "straight")
    assert [r["step"] for r in straight] == [2, 4] and straight[1]["pck"] is not None  # step 3's PCK
    assert log_records(tmp_path / "cut") == straight


def test_a_zero_heat_weight_trains_and_ddp_is_told_of_unused_heads(data64, tmp_path):
    summary, _ = train(tiny_cfg(data64, iterations=1, pck_every=0, loss={"heat_weight": 0.0}), tmp_path / "r",
                       quiet=True)
    assert summary["steps"] == 1  # it used to stop at step 1 with KeyError 'l1_heat'
    from training.train import ddp_find_unused

    full = {"encoder_heat_weight": 0.5, "coord_weight": 0.01}
    cfg = build_config({"preset": "tiny", "loss": full})
    assert not ddp_find_unused(cfg, cfg.model_config())
    for loss in ({"heat_weight": 0.0}, {"colour_weight": 0.0, "ssim_weight": 0.0}, {"level_weights": [0.0, 1.0]},
                 {"coord_weight": 0.0}, {"encoder_heat_weight": 0.0}):
        cfg = build_config({"preset": "tiny", "loss": {**full, **loss}})
        assert ddp_find_unused(cfg, cfg.model_config()), loss


@pytest.mark.parametrize("sets, says", [
    (['data="{missing}"'], "{missing}/dataset.json: no dataset manifest here"),
    (['split="trian"'], "has no split 'trian'"),
    (['preset="edge128"'], "holds 64 px scenes, the 'edge128' model takes 128x128"),
])
def test_cli_names_a_bad_dataset_in_one_line_before_writing(data64, tmp_path, capsys, sets, says):
    missing = tmp_path / "nowhere"
    argv = ["--set", 'preset="tiny"', "--set", f"data={json.dumps(str(data64))}", "--iterations", "1",
            "--out", str(tmp_path / "o"), "--quiet"]
    for s in sets:  # later --set win
        argv += ["--set", s.format(missing=missing)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert says.format(missing=missing) in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_run_records_and_checkpoints_are_written_whole(data64, tmp_path, monkeypatch):
    import os

    import training.train as tr

    written, events = [], []
    real_write, real_fsync, real_replace = tr.write_atomic, os.fsync, os.replace
    monkeypatch.setattr(tr, "write_atomic",
                        lambda path, data: written.append(Path(path).name) or real_write(path, data))
    monkeypatch.setattr(tr.os, "fsync", lambda fd: events.append("fsync") or real_fsync(fd))
    monkeypatch.setattr(tr.os, "replace", lambda a, b: events.append(Path(b).name) or real_replace(a, b))
    train(tiny_cfg(data64, iterations=1, pck_every=0), tmp_path / "r", quiet=True)
    assert {"config.json", "summary.json"} <= set(written)
    assert events[events.index("last.pt") - 1] == "fsync"  # the checkpoint reached the disk before the rename


@pytest.mark.parametrize("where", ["loss", "gradient"])
def test_a_non_finite_step_stops_before_the_update_naming_the_step_and_the_term(data64, tmp_path, monkeypatch,
                                                                                 capsys, where):
    """A NaN loss term, or a NaN gradient of a finite loss, stops the run in one line naming the step and what
    went non-finite, before the weights take that step: the last checkpoint stays finite (a NaN gradient
    used to be stepped into the weights and saved as last.pt, which every resume then diverged from)."""
    import training.train as tr

    real = tr.step_losses
    calls = []

    def poisoned(out, batch, cfg):
        terms = real(out, batch, cfg)
        calls.append(1)
        if len(calls) == 2:  # the second step
            if where == "loss":
                terms["l1_heat"] = terms["l1_heat"] * float("nan")
                terms["loss"] = terms["loss"] + terms["l1_heat"]
            else:  # d sqrt(x)/dx at 0 is inf: a finite loss (0 added) whose gradient is NaN
                w = out["levels"][-1]["rgb"]
                terms["loss"] = terms["loss"] + 0.0 * torch.sqrt((w - w.detach()).abs().sum())
        return terms

    monkeypatch.setattr(tr, "step_losses", poisoned)
    argv = ["--set", 'preset="tiny"', "--set", f"data={json.dumps(str(data64))}", "--iterations", "3",
            "--set", "checkpoint_every=1", "--set", "pck_every=0", "--set", "heat_rays=32", "--set", "patch_size=8",
            "--set", "targets_per_iter=2", "--out", str(tmp_path / "r"), "--quiet"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "ghnerf-train: diverged: step 2 (scene" in err and "last.pt holds step 1" in err
    assert ("l1_heat=nan" in err) if where == "loss" else ("non-finite gradient norm (nan)" in err)
    ck = torch.load(tmp_path / "r" / "last.pt", weights_only=False)
    assert ck["step"] == 1 and all(torch.isfinite(v).all() for v in ck["model"].values() if v.is_floating_point())
    assert not (tmp_path / "r" / "ckpt_0000002.pt").exists()


def test_a_checkpoint_that_cannot_be_written_is_named_and_leaves_no_half_file(data64, tmp_path, monkeypatch,
                                                                               capsys):
    """A full disk while a checkpoint is written: one line naming the file, the half-written ``.tmp`` removed
    (it used to stay, keeping the disk full), the previous ``last.pt`` whole, and ``--resume`` continues."""
    import errno

    import training.train as tr

    train(tiny_cfg(data64, iterations=1, pck_every=0), tmp_path / "r", quiet=True)
    real_save = tr.torch.save

    def disk_full(state, fh, *a, **k):
        fh.write(b"\0" * 4096)  # part of the file, then the disk is full
        raise RuntimeError("[enforce fail at inline_container.cc:672] . PytorchStreamWriter failed writing file "
                           f"data/0: file write failed ({errno.errorcode[errno.ENOSPC]})")

    monkeypatch.setattr(tr.torch, "save", disk_full)
    argv = ["--set", 'preset="tiny"', "--set", f"data={json.dumps(str(data64))}", "--iterations", "2",
            "--set", "checkpoint_every=1", "--set", "pck_every=0", "--set", "heat_rays=32", "--set", "patch_size=8",
            "--set", "targets_per_iter=2", "--set", "loss.coord_weight=0.01", "--set", "threads=2",
            "--set", "log_every=1", "--out", str(tmp_path / "r"), "--resume", "--quiet"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert f"{tmp_path / 'r' / 'last.pt'}: cannot write the checkpoint" in err
    assert "the previous last.pt is as it was" in err and "ENOSPC" in err
    assert not list((tmp_path / "r").glob("*.tmp"))
    assert torch.load(tmp_path / "r" / "last.pt", weights_only=False)["step"] == 1
    monkeypatch.setattr(tr.torch, "save", real_save)
    assert main(argv) == 0  # space freed: it resumes from step 1
    assert torch.load(tmp_path / "r" / "last.pt", weights_only=False)["step"] == 2


def test_a_resumed_run_that_is_interrupted_leaves_no_stale_summary(data64, tmp_path, monkeypatch):
    """summary.json is written when an invocation ends; a resumed invocation cut short (Ctrl-C) must not leave
    the previous one's ("stopped early at step 1") beside a last.pt of a later step."""
    import training.train as tr

    run = tmp_path / "r"
    cfg = tiny_cfg(data64, iterations=3, pck_every=0)
    monkeypatch.setattr(tr.RunClock, "elapsed", lambda self: 1e9)  # past any max_minutes at once
    first, _ = train(tiny_cfg(data64, iterations=3, pck_every=0, max_minutes=1.0), run, quiet=True)
    assert first["stopped_early"] and first["steps"] == 1
    monkeypatch.undo()
    real, calls = tr.train_step, []

    def ctrl_c_at_the_second(*a, **k):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(tr, "train_step", ctrl_c_at_the_second)
    with pytest.raises(KeyboardInterrupt):
        train(cfg, run, resume=True, quiet=True)
    assert torch.load(run / "last.pt", weights_only=False)["step"] == 2
    assert not (run / "summary.json").exists()
    monkeypatch.setattr(tr, "train_step", real)
    done, _ = train(cfg, run, resume=True, quiet=True)
    assert json.loads((run / "summary.json").read_text()) == json.loads(json.dumps(done)) and done["steps"] == 3


class _CtrlCWhilePickled:
    """Sends this process a SIGINT while torch.save pickles it: a Ctrl-C in the middle of a checkpoint write."""

    def __reduce__(self):
        import os
        import signal

        os.kill(os.getpid(), signal.SIGINT)
        return (dict, ())


def test_a_ctrl_c_during_a_checkpoint_write_stops_after_it_with_the_checkpoint_whole(tmp_path):
    # It was raised inside the write: the checkpoint was lost, and when it came inside torch's writer it was a
    # RuntimeError ("unexpected pos") reported as a failed write with advice to free space.
    import torch

    from training.train import save_atomic

    path = tmp_path / "last.pt"
    with pytest.raises(KeyboardInterrupt):
        save_atomic({"step": 7, "w": torch.arange(4.0), "mark": _CtrlCWhilePickled()}, path)
    saved = torch.load(path, weights_only=False)
    assert saved["step"] == 7 and saved["w"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert not path.with_suffix(".tmp").exists()
    import signal

    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # Python's own handler is back


class _SigtermWhilePickled:
    """Sends this process a SIGTERM while torch.save pickles it: ``timeout`` or ``kill`` during a checkpoint write."""

    def __reduce__(self):
        import os
        import signal

        os.kill(os.getpid(), signal.SIGTERM)
        return (dict, ())


def test_a_sigterm_during_a_checkpoint_write_stops_after_it_with_the_checkpoint_whole(tmp_path):
    # Under the command line's sigterm_as_interrupt it was raised inside the write, as Ctrl-C was before
    # the checkpoint's signal hold: the checkpoint was lost. The signal is held and raised once the file is in place.
    import signal

    import torch

    from ghnerf_runtime.cli.sigterm import Terminated, sigterm_as_interrupt, sigterm_raises
    from training.train import save_atomic

    path = tmp_path / "last.pt"
    with sigterm_as_interrupt():
        with pytest.raises(Terminated):
            save_atomic({"step": 7, "w": torch.arange(4.0), "mark": _SigtermWhilePickled()}, path)
        assert sigterm_raises()  # the command line's handler is back for the next step
    saved = torch.load(path, weights_only=False)
    assert saved["step"] == 7 and saved["w"].tolist() == [0.0, 1.0, 2.0, 3.0]
    assert not path.with_suffix(".tmp").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


class _CtrlCThenSigtermWhilePickled:
    """Sends this process a Ctrl-C, then a SIGTERM, while torch.save pickles it."""

    def __reduce__(self):
        import os
        import signal

        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGTERM)
        return (dict, ())


def test_the_first_stop_held_over_a_checkpoint_write_is_the_one_raised(tmp_path):
    # Ctrl-C then SIGTERM during the write: the Ctrl-C (exit 130) is raised after it, as every other held block
    # raises the first; the checkpoint's own helper raised the SIGTERM (143), whichever came first
    import torch

    from ghnerf_runtime.cli.sigterm import Terminated, sigterm_as_interrupt
    from training.train import save_atomic

    path = tmp_path / "last.pt"
    with sigterm_as_interrupt():
        with pytest.raises(KeyboardInterrupt) as stopped:
            save_atomic({"step": 3, "mark": _CtrlCThenSigtermWhilePickled()}, path)
    assert not isinstance(stopped.value, Terminated)
    assert torch.load(path, weights_only=False)["step"] == 3


def test_a_sigterm_mid_run_leaves_whole_checkpoints_no_lock_and_a_run_that_resumes(data64, tmp_path):
    """The command line, killed as ``timeout`` kills it: it died at once (status -15, nothing said), leaving
    ``train.pid`` and, when the signal came in a write, a half-written ``last.tmp``."""
    import os
    import signal
    import subprocess
    import sys
    import time

    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "training.train", "--preset", "tiny", "--data", str(data64), "--out", str(run),
           "--threads", "1", "--quiet", "--set", "checkpoint_every=1", "--set", "targets_per_iter=2",
           "--set", "heat_rays=64"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    proc = subprocess.Popen([*cmd, "--iterations", "1000"], stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.monotonic() + 120
    while not (run / "ckpt_0000002.pt").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=120)[1]
    assert proc.returncode == 143, err
    assert f"ghnerf-train: stopped (SIGTERM); `--resume --out {run}` continues" in err
    assert not (run / "train.pid").exists() and not list(run.glob("*.tmp"))
    step = torch.load(run / "last.pt", weights_only=False)["step"]
    done = subprocess.run([*cmd, "--iterations", str(step + 1), "--resume"], capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.splitlines()[-1])["steps"] == step + 1


def test_progress_writes_to_the_stderr_of_the_moment_not_of_the_import(monkeypatch):
    """``Progress``'s stream defaulted to the ``sys.stderr`` of ``training.train``'s import: a run after that
    stream was replaced and closed (a test's capture, a redirection) failed in ``isatty`` before its first step."""
    import io
    import sys

    from training.train import Progress

    now = io.StringIO()
    monkeypatch.setattr(sys, "stderr", now)
    Progress(2, 0).update(1, {"loss": 0.5})
    assert "loss" in now.getvalue()
