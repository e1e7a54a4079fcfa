"""Human-encoder pretraining (``training.pretrain_human``): the real loop on ``tiny``, resume, and loading the
result into the joint trainer."""
from __future__ import annotations

import json
import math
from dataclasses import asdict

import pytest

torch = pytest.importorskip("torch")

from ghnerf_runtime.body25 import FLIP_INDEX  # noqa: E402
from tests.training.test_trainer import log_records, strict_loads, tiny_cfg  # noqa: E402  (data64: conftest)
from training import pretrain_checkpoint  # noqa: E402
from training.model.config import ConfigError  # noqa: E402
from training.pretrain_human import (PretrainConfig, load_human, main, pretrain, pretrain_step,  # noqa: E402
                                     trunk_input_scale, view_batch)
from training.train import train  # noqa: E402


def tiny_pretrain(data, **kw) -> PretrainConfig:
    base = {"preset": "tiny", "data": str(data), "iterations": 2, "scenes_per_step": 1, "checkpoint_every": 1,
            "log_every": 1, "eval_every": 1, "eval_scenes": 2, "threads": 2}
    base.update(kw)
    return PretrainConfig.from_dict(base)


@pytest.mark.parametrize("data, key", [
    ({"iterations": 0}, "iterations"),
    ({"lr": 0.0}, "lr"),
    ({"lr_decay_gamma": 2.0}, "lr_decay_gamma"),
    ({"preset": "edge128_baseline"}, "preset"),  # no human encoder to pretrain
    ({"scenes_per_step": 0}, "scenes_per_step"),
    ({"itterations": 3}, "itterations"),
    ({"iterations": "many"}, "iterations"),  # typed: a clear error, not a TypeError in validation
    ({"device": "tpu"}, "device"),
    ({"loader_workers": -1}, "loader_workers"),
    ({"centroid_weight": -0.1}, "centroid_weight"),
    ({"augment": {"rotation_deg": -5}}, "augment.rotation_deg"),
    ({"augment": {"zoom": 0.1}}, "zoom"),
    ({"precision": "fp16"}, "precision"),
    ({"coarse_steps": -1}, "coarse_steps"),
    ({"stop_at": -1}, "stop_at"),
    ({"coarse_steps": 100, "coarse_input_scale": 0.3}, "coarse_input_scale"),  # 38.4 px: not a multiple of 16
    ({"coarse_steps": 100, "coarse_input_scale": 1.5}, "coarse_input_scale"),
])
def test_config_errors_name_the_key(data, key):
    with pytest.raises(ConfigError, match=key):
        PretrainConfig.from_dict(data)


def test_view_batch_mirrors_images_and_swaps_left_right(data64):
    from training.data.torch_dataset import MultiViewDataset

    it = MultiViewDataset(data64, "train")[0]
    images, heat = view_batch([it], flip=True)
    n = it["tgt_images"].shape[0]
    assert images.shape[0] == heat.shape[0] == 2 * n
    assert torch.equal(images[n], torch.flip(it["tgt_images"][0], dims=(-1,)))
    r_wrist, l_wrist = 4, 7
    assert FLIP_INDEX[r_wrist] == l_wrist
    assert torch.equal(heat[n, l_wrist], torch.flip(it["tgt_heatmaps"][0, r_wrist], dims=(-1,)))
    plain, _ = view_batch([it], flip=False)
    assert plain.shape[0] == n


def test_view_batch_augments_before_mirroring(data64):
    from training.augment import AugmentConfig
    from training.data.torch_dataset import MultiViewDataset

    it = MultiViewDataset(data64, "train")[0]
    aug = AugmentConfig(rotation_deg=30.0, scale=0.2, shift=0.1)
    images, heat = view_batch([it], flip=True, augment=aug, generator=torch.Generator().manual_seed(0))
    again, _ = view_batch([it], flip=True, augment=aug, generator=torch.Generator().manual_seed(0))
    n = it["tgt_images"].shape[0]
    assert torch.equal(images, again) and not torch.equal(images[:n], it["tgt_images"])
    assert torch.equal(images[n:], torch.flip(images[:n], dims=(-1,)))  # the mirror of the transformed view
    assert heat.shape == (2 * n, *it["tgt_heatmaps"].shape[1:]) and float(heat.max()) <= 1.0


def test_two_iterations_resume_and_joint_training_starts_from_it(data64, tmp_path):
    aug = {"rotation_deg": 20.0, "scale": 0.2, "shift": 0.05}  # resumed runs draw the same transforms too
    straight = pretrain(tiny_pretrain(data64, augment=aug), tmp_path / "a", quiet=True)
    assert straight["steps"] == 2 and not straight["stopped_early"]
    assert 0.0 <= straight["eval_pck@0.2"] <= 1.0
    log = [json.loads(line) for line in (tmp_path / "a" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2] and all(r["loss"] > 0 for r in log)

    first = pretrain(tiny_pretrain(data64, iterations=1, augment=aug), tmp_path / "b", quiet=True)
    resumed = pretrain(tiny_pretrain(data64, augment=aug), tmp_path / "b", resume=True, quiet=True)
    assert [g["steps"] for g in resumed["segments"]] == [1, 1]
    # the first segment is the first invocation's time up to its last checkpoint, which precedes its summary
    assert 0 <= resumed["segments"][0]["wall_s"] <= first["wall_s"]
    a = torch.load(tmp_path / "a" / "human.pt", weights_only=True)
    b = torch.load(tmp_path / "b" / "human.pt", weights_only=True)
    assert a["step"] == b["step"] == 2
    for k in a["human"]:
        assert torch.equal(a["human"][k], b["human"][k]), k

    # the joint trainer starts from the pretrained encoder (lr ~0: the weights stay as loaded)
    _, model = train(tiny_cfg(data64, iterations=1, lr=1e-12, pck_every=0, human_init=str(tmp_path / "a" / "human.pt")),
                     tmp_path / "joint", quiet=True)
    got = model.human.state_dict()
    for k, v in a["human"].items():
        if v.is_floating_point() and "running" not in k:
            assert torch.allclose(got[k], v, atol=1e-6), k


def test_a_run_split_by_stop_at_and_thread_count_learns_what_a_straight_one_does(data64, tmp_path):
    """The pipeline's split: the first steps at one thread (``stop_at``), the rest resumed at two. The
    second part trains on the same batches from the same state, so the split run is the straight run of the
    same thread counts; a resume at or past ``stop_at`` does nothing."""
    straight = tmp_path / "straight"
    pretrain(tiny_pretrain(data64, iterations=3, threads=1, eval_every=0), straight, quiet=True)
    pretrain(tiny_pretrain(data64, iterations=4, threads=2, eval_every=0), straight, resume=True, quiet=True)

    split = tmp_path / "split"
    first = pretrain(tiny_pretrain(data64, iterations=4, threads=1, eval_every=0, stop_at=3, checkpoint_every=2),
                     split, quiet=True)
    assert first["steps"] == 3 and first["stopped_early"]  # saved at the stop, not only at its checkpoints
    again = pretrain(tiny_pretrain(data64, iterations=4, threads=1, eval_every=0, stop_at=3), split, resume=True,
                     quiet=True)
    assert again["steps"] == 3 and again["stopped_early"]
    done = pretrain(tiny_pretrain(data64, iterations=4, threads=2, eval_every=0), split, resume=True, quiet=True)
    assert done["steps"] == 4 and not done["stopped_early"]
    assert [(g["steps"], g["threads"]) for g in done["segments"]] == [(3, 1), (1, 2)]
    a = torch.load(straight / "human.pt", weights_only=True)
    b = torch.load(split / "human.pt", weights_only=True)
    for k in a["human"]:
        assert torch.equal(a["human"][k], b["human"][k]), k


def test_a_resumed_pretraining_logs_the_records_an_uninterrupted_one_does(data64, tmp_path):
    # as the joint trainer's: the losses since the last record and the last PCK were not kept, so the first
    # record after a resume averaged only the resumed steps and carried pck NaN, and so did the summary
    kw = {"iterations": 4, "log_every": 2, "eval_every": 3, "checkpoint_every": 10, "threads": 1}
    straight = pretrain(tiny_pretrain(data64, **kw), tmp_path / "straight", quiet=True)
    first = pretrain(tiny_pretrain(data64, stop_at=3, **kw), tmp_path / "cut", quiet=True)  # saved at step 3
    assert first["steps"] == 3 and first["stopped_early"]
    resumed = pretrain(tiny_pretrain(data64, **kw), tmp_path / "cut", resume=True, quiet=True)
    expect = log_records(tmp_path / "straight")
    assert [r["step"] for r in expect] == [2, 4] and expect[1]["pck"] is not None  # step 3's PCK
    assert log_records(tmp_path / "cut") == expect
    assert resumed["eval_pck@0.2"] == straight["eval_pck@0.2"]


def test_pretraining_resume_refuses_another_config(data64, tmp_path):
    from training.model.config import ConfigError

    pretrain(tiny_pretrain(data64, iterations=1), tmp_path / "p", quiet=True)
    with pytest.raises(ConfigError, match=r"\(lr 0\.001 in the run, 0\.5 now; seed 0 in the run, 9 now\)"):
        pretrain(tiny_pretrain(data64, lr=0.5, seed=9), tmp_path / "p", resume=True, quiet=True)
    assert pretrain(tiny_pretrain(data64, max_minutes=5.0), tmp_path / "p", resume=True, quiet=True)["steps"] == 2
    # without --resume a folder holding a run is refused before anything in it is overwritten
    before = {f.name: f.read_bytes() for f in (tmp_path / "p").iterdir() if f.is_file()}
    with pytest.raises(ConfigError, match=r"holds a training run \(last\.pt\); pass --resume"):
        pretrain(tiny_pretrain(data64, iterations=1), tmp_path / "p", quiet=True)
    assert {f.name: f.read_bytes() for f in (tmp_path / "p").iterdir() if f.is_file()} == before


def test_pretraining_resume_refuses_a_weights_only_file_and_keeps_one_log_record_per_step(data64, tmp_path):
    import shutil

    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, iterations=2, checkpoint_every=1), run, quiet=True)
    # a crash after step 1's checkpoint, with step 2 already logged: the resumed run logs step 2 once
    kept = run / "kept.pt"
    shutil.copy(run / "last.pt", kept)
    ck = torch.load(kept, weights_only=False)
    ck["step"] = 1
    torch.save(ck, run / "last.pt")
    with open(run / "log.jsonl", "a") as fh:
        fh.write('{"step": 3, "loss": 1.0')  # a line a crash cut short
    pretrain(tiny_pretrain(data64, iterations=2, checkpoint_every=1), run, resume=True, quiet=True)
    assert [json.loads(line)["step"] for line in (run / "log.jsonl").read_text().splitlines()] == [1, 2]

    # human.pt (the weights alone) put in place of last.pt: named, before config.json is touched
    shutil.copy(run / "human.pt", run / "last.pt")
    before = (run / "config.json").read_bytes()
    with pytest.raises(ConfigError, match=r"last\.pt: not a training checkpoint --resume can continue from: no "
                                          r"optimizer"):
        pretrain(tiny_pretrain(data64, iterations=3), run, resume=True, quiet=True)
    assert (run / "config.json").read_bytes() == before


def test_pretraining_names_a_missing_dataset_before_writing_anything(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["--out", str(out), "--set", "preset=\"tiny\"", "--data", str(tmp_path / "nowhere")]) == 2
    assert "nowhere" in capsys.readouterr().err
    assert not out.exists()


def _gauss(cy, cx, size=32, sigma=1.5):
    ys, xs = torch.meshgrid(torch.arange(size).float(), torch.arange(size).float(), indexing="ij")
    return torch.exp(-((ys - cy) ** 2 + (xs - cx) ** 2) / (2 * sigma ** 2))


def test_window_centroid_loss_measures_where_the_peak_sits():
    from training.losses import window_centroid_loss

    target = torch.stack([_gauss(10.3, 20.7), _gauss(5.0, 5.0), torch.zeros(32, 32)])[None]
    assert float(window_centroid_loss(target, target)) < 1e-5
    # a peak one cell off counts about a cell (the window's truncation pulls it in a little); the hidden
    # joint (target all 0) is left out, whatever its prediction
    shifted = torch.stack([_gauss(10.3, 21.7), _gauss(5.0, 5.0), _gauss(1.0, 1.0)])[None]
    assert 0.35 < float(window_centroid_loss(shifted, target)) < 0.5  # (~0.86 + 0) / 2
    assert float(window_centroid_loss(shifted, torch.zeros_like(target))) == 0.0
    # an all-zero prediction (an untrained head) gives a finite loss and gradient
    pred = torch.zeros_like(target, requires_grad=True)
    loss = window_centroid_loss(pred, target)
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(pred.grad).all()


def test_centroid_weight_adds_the_localisation_term(data64, tmp_path):
    plain = pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), tmp_path / "a", quiet=True)
    with_term = pretrain(tiny_pretrain(data64, iterations=1, eval_every=0, centroid_weight=1.0), tmp_path / "b",
                         quiet=True)
    loss = [json.loads((tmp_path / d / "log.jsonl").read_text().splitlines()[0])["loss"] for d in ("a", "b")]
    assert plain["steps"] == with_term["steps"] == 1 and loss[1] > loss[0] > 0  # same batch, one more term


def test_bf16_forward_pass_trains_float32_weights_close_to_the_fp32_run(data64, tmp_path):
    """``precision: bf16`` changes the arithmetic of the forward pass only: the loss is finite and close to the
    fp32 run's on the same batches, the weights stay float32, and the summary names what ran."""
    kw = {"iterations": 2, "eval_every": 0}
    fp32 = pretrain(tiny_pretrain(data64, **kw), tmp_path / "fp32", quiet=True)
    bf16 = pretrain(tiny_pretrain(data64, precision="bf16", **kw), tmp_path / "bf16", quiet=True)
    assert (fp32["precision"], bf16["precision"]) == ("fp32", "bf16")
    loss = [[json.loads(line)["loss"] for line in (tmp_path / d / "log.jsonl").read_text().splitlines()]
            for d in ("fp32", "bf16")]
    assert all(v > 0 for v in loss[1]) and loss[0] != loss[1]  # computed in another arithmetic
    assert loss[1][0] == pytest.approx(loss[0][0], rel=0.05)  # the same first batch and weights
    weights = torch.load(tmp_path / "bf16" / "human.pt", weights_only=True)["human"]
    assert all(w.dtype in (torch.float32, torch.int64) for w in weights.values())


def test_auto_precision_asks_the_hardware(monkeypatch):
    from training.pretrain_human import resolve_precision

    cpu = torch.device("cpu")
    assert resolve_precision("fp32", cpu) == "fp32" and resolve_precision("bf16", cpu) == "bf16"

    def host(avx2: bool, avx512_bf16: bool, amx: bool, onednn_bf16: bool) -> str:
        for name, value in (("_is_avx2_supported", avx2), ("_is_avx512_bf16_supported", avx512_bf16),
                            ("_is_amx_tile_supported", amx)):
            monkeypatch.setattr(torch.cpu, name, lambda v=value: v)
        monkeypatch.setattr(torch.ops.mkldnn, "_is_mkldnn_bf16_supported", lambda: onednn_bf16)
        return resolve_precision("auto", cpu)

    assert host(avx2=True, avx512_bf16=True, amx=False, onednn_bf16=True) == "bf16"  # this EPYC
    assert host(avx2=True, avx512_bf16=False, amx=True, onednn_bf16=True) == "bf16"  # AMX
    assert host(avx2=True, avx512_bf16=False, amx=False, onednn_bf16=True) == "fp32"  # plain AVX-512: emulated
    assert host(avx2=True, avx512_bf16=False, amx=False, onednn_bf16=False) == "fp32"  # AVX2 only
    assert host(avx2=False, avx512_bf16=False, amx=False, onednn_bf16=True) == "bf16"  # aarch64 with bf16


def test_auto_precision_on_a_bf16_cpu_times_both_per_scale_and_leaves_the_run_as_it_was(data64, tmp_path,
                                                                                          monkeypatch):
    """Bfloat16 instructions do not make bf16 the faster (session 38's Intel Xeon: 0.30 s against 0.21 s a
    step), so ``auto`` on such a CPU times both on copies at each trunk scale and runs the faster. The probe
    touches neither the weights nor the random state: a run whose probe picks fp32 is the fp32 run."""
    import training.pretrain_human as ph

    monkeypatch.setattr(ph, "cpu_has_native_bf16", lambda: True)
    picks = []

    def probe_then_fp32(*args, **kw):
        picked, seconds = real(*args, **kw)
        picks.append((picked, seconds))
        return "fp32", seconds

    real = ph.fastest_precision
    monkeypatch.setattr(ph, "fastest_precision", probe_then_fp32)
    kw = {"iterations": 3, "eval_every": 0, "coarse_steps": 2, "coarse_input_scale": 0.5}
    auto = pretrain(tiny_pretrain(data64, precision="auto", **kw), tmp_path / "auto", quiet=True)
    fp32 = pretrain(tiny_pretrain(data64, **kw), tmp_path / "fp32", quiet=True)
    assert len(picks) == 2  # once per trunk input scale, not per step
    assert all(p in ("fp32", "bf16") and set(s) == {"fp32", "bf16"} and min(s.values()) > 0 for p, s in picks)
    # bf16 only where it is at least BF16_MIN_SPEEDUP times as fast (a near tie, as the tiny net can give, is fp32)
    assert all(p == ("bf16" if s["fp32"] >= ph.BF16_MIN_SPEEDUP * s["bf16"] else "fp32") for p, s in picks)
    assert auto["precision"] == "fp32" and set(auto["precision_probe"]) == {"0.5", "full"}
    assert "precision_probe" not in fp32
    a, b = (torch.load(tmp_path / d / "human.pt", weights_only=True)["human"] for d in ("auto", "fp32"))
    assert all(torch.equal(a[k], b[k]) for k in a)  # bit for bit: the probe changed nothing in the run


def test_the_precision_probe_restores_every_random_state_and_leaves_the_weights(data64):
    import random

    import numpy as np

    from training.data.torch_dataset import MultiViewDataset
    from training.model import GHNeRF
    from training.pretrain_human import fastest_precision

    cfg = tiny_pretrain(data64, eval_every=0)
    model = GHNeRF(cfg.model_config()).train()
    images, heat = view_batch([MultiViewDataset(data64, "train")[0]], flip=False)
    before = {k: v.clone() for k, v in model.state_dict().items()}
    torch.manual_seed(5), np.random.seed(5), random.seed(5)
    states = torch.random.get_rng_state(), np.random.get_state()[1].copy(), random.getstate()
    picked, seconds = fastest_precision(model, images, heat, cfg, None, steps=2, warmup=1)
    assert picked in ("fp32", "bf16") and set(seconds) == {"fp32", "bf16"}
    assert torch.equal(torch.random.get_rng_state(), states[0])
    assert np.array_equal(np.random.get_state()[1], states[1]) and random.getstate() == states[2]
    assert all(torch.equal(before[k], v) for k, v in model.state_dict().items())  # BN statistics too


def test_bf16_is_picked_only_when_clearly_faster(data64, monkeypatch):
    import training.pretrain_human as ph
    from training.data.torch_dataset import MultiViewDataset
    from training.model import GHNeRF

    cfg = tiny_pretrain(data64, eval_every=0)
    model = GHNeRF(cfg.model_config()).train()
    images, heat = view_batch([MultiViewDataset(data64, "train")[0]], flip=False)
    for bf16_s, picked in ((0.95, "fp32"), (0.85, "bf16"), (1.5, "fp32")):
        order: list[str] = []
        monkeypatch.setattr(ph, "pretrain_step", lambda *a, _o=order: _o.append(a[5]) or 1.0)
        now, counted = [0.0], [0]

        def clock(_o=order, _bf16=bf16_s):  # a step takes 1 s in fp32, bf16_s in bf16
            for precision in _o[counted[0]:]:
                now[0] += _bf16 if precision == "bf16" else 1.0
            counted[0] = len(_o)
            return now[0]

        got, seconds = ph.fastest_precision(model, images, heat, cfg, None, clock=clock)
        assert got == picked and seconds == pytest.approx({"fp32": 1.0, "bf16": bf16_s}), bf16_s
        assert order[:4] == ["bf16", "fp32", "fp32", "bf16"]  # in turn, each first every other step


def test_a_resumed_run_keeps_the_precision_its_checkpoint_picked(data64, tmp_path, monkeypatch, capsys):
    import training.pretrain_human as ph

    monkeypatch.setattr(ph, "cpu_has_native_bf16", lambda: True)
    calls = []

    def pick_bf16(*args, **kw):
        calls.append(args[4])  # the trunk input scale
        return "bf16", {"fp32": 2.0, "bf16": 1.0}

    monkeypatch.setattr(ph, "fastest_precision", pick_bf16)
    kw = {"eval_every": 0, "coarse_steps": 2, "coarse_input_scale": 0.5, "precision": "auto"}
    pretrain(tiny_pretrain(data64, iterations=1, **kw), tmp_path / "r", quiet=True)
    assert calls == [0.5]
    # the pick is logged under --quiet too (the pipeline's train.log)
    err = capsys.readouterr().err
    assert "precision auto at trunk input scale 0.5: bf16 (s/step fp32 2.000, bf16 1.000)" in err
    # a run that ends inside its coarse steps is allowed (to be extended, as here), with a warning
    assert "coarse_steps=2 >= iterations=1: every step feeds the trunk at input scale 0.5" in err
    monkeypatch.setattr(ph, "fastest_precision", lambda *a, **k: ("fp32", {"fp32": 1.0, "bf16": 2.0}))
    summary = pretrain(tiny_pretrain(data64, iterations=3, **kw), tmp_path / "r", resume=True, quiet=True)
    # the 0.5 scale kept its bf16; the full scale, new at the resume, was probed then
    assert summary["precision_probe"]["0.5"]["picked"] == "bf16"
    assert summary["precision_probe"]["full"]["picked"] == "fp32"
    assert summary["precision"] == "bf16 at 0.5, fp32 at full"
    log = [json.loads(line) for line in (tmp_path / "r" / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2, 3]


def test_auto_precision_probes_only_where_the_cpu_has_bf16(data64, tmp_path, monkeypatch):
    import training.pretrain_human as ph

    monkeypatch.setattr(ph, "cpu_has_native_bf16", lambda: False)
    monkeypatch.setattr(ph, "fastest_precision", lambda *a, **k: pytest.fail("probed a CPU without bf16"))
    summary = pretrain(tiny_pretrain(data64, precision="auto", iterations=1, eval_every=0), tmp_path / "r",
                       quiet=True)
    assert summary["precision"] == "fp32" and "precision_probe" not in summary


def test_worker_processes_load_the_same_batches_as_the_trainer(data64, tmp_path):
    """``loader_workers`` changes where the batches are made, not which: the same weights, step for step,
    across an epoch boundary (data64's train split, one scene per step) and with the random transforms."""
    from training.data.torch_dataset import MultiViewDataset
    from training.pretrain_human import StepBatches

    aug = {"rotation_deg": 20.0, "scale": 0.2, "shift": 0.05}
    n = len(MultiViewDataset(data64, "train"))
    kw = {"iterations": n + 1, "checkpoint_every": n + 1, "eval_every": 0, "augment": aug}
    pretrain(tiny_pretrain(data64, **kw), tmp_path / "here", quiet=True)
    pretrain(tiny_pretrain(data64, loader_workers=2, **kw), tmp_path / "workers", quiet=True)
    a = torch.load(tmp_path / "here" / "human.pt", weights_only=True)["human"]
    b = torch.load(tmp_path / "workers" / "human.pt", weights_only=True)["human"]
    for k in a:
        assert torch.equal(a[k], b[k]), k
    # the step's scenes follow the epoch's shuffle: epoch 1 starts over with another order of the same scenes
    batches = StepBatches(MultiViewDataset(data64, "train"), tiny_pretrain(data64, **kw))
    assert not torch.equal(batches[0][0], batches[n][0]) or n == 1
    assert torch.equal(batches[3][0], batches[3][0])


def test_a_mismatched_or_missing_encoder_is_refused(data64, tmp_path):
    from dataclasses import replace

    from training.configs import preset
    from training.model import GHNeRF

    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), tmp_path / "a", quiet=True)
    tiny = preset("tiny")
    other = GHNeRF(replace(tiny, human=replace(tiny.human, out_channels=16)))
    with pytest.raises(ConfigError, match="out_channels"):
        load_human(other, tmp_path / "a" / "human.pt")
    with pytest.raises(ConfigError, match="cannot read"):
        load_human(GHNeRF(tiny), tmp_path / "nope.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="junk.pt"):
        load_human(GHNeRF(tiny), tmp_path / "junk.pt")


def test_cli_reads_the_block_of_a_train_config(data64, tmp_path, capsys):
    cfg = {"preset": "tiny", "data": str(data64),
           "pretrain_human": {"iterations": 1, "scenes_per_step": 1, "eval_every": 0, "log_every": 1}}
    (tmp_path / "train.json").write_text(json.dumps(cfg))
    assert main(["--config", str(tmp_path / "train.json"), "--out", str(tmp_path / "run"), "--quiet"]) == 0
    assert json.loads(capsys.readouterr().out)["steps"] == 1
    assert main(["--config", str(tmp_path / "train.json"), "--out", str(tmp_path / "r2"), "--set", "lr=-1"]) == 2
    assert "pretrain_human.lr" in capsys.readouterr().err


def test_cli_writes_strict_json_when_no_evaluation_ran(data64, tmp_path, capsys):
    """eval_every 0: eval_pck@0.2 and each record's pck are NaN, written as null (a bare NaN is no JSON)."""
    run = tmp_path / "run"
    assert main(["--out", str(run), "--data", str(data64), "--iterations", "1", "--quiet", "--set", 'preset="tiny"',
                 "--set", "scenes_per_step=1", "--set", "eval_every=0", "--set", "log_every=1"]) == 0
    assert strict_loads(capsys.readouterr().out)["eval_pck@0.2"] is None
    assert strict_loads((run / "summary.json").read_text())["eval_pck@0.2"] is None
    assert [strict_loads(line)["pck"] for line in (run / "log.jsonl").read_text().splitlines()] == [None]


@pytest.mark.parametrize("resume", [False, True])
def test_a_model_folder_is_refused_as_the_run_folder(tmp_path, capsys, resume):
    """As the trainer (``tests/training/test_trainer.py``): its last.pt and config.json went beside the graphs."""
    folder = tmp_path / "ghnerf"
    folder.mkdir()
    (folder / "encoder.onnx").write_bytes(b"graph")
    assert main(["--out", str(folder), "--set", 'preset="tiny"', "--data", str(tmp_path / "nowhere"),
                 *["--resume"] * resume]) == 2
    assert f"{folder}: is a model folder (it holds encoder.onnx), not a run folder" in capsys.readouterr().err
    assert [p.name for p in folder.iterdir()] == ["encoder.onnx"]


def test_score_reports_the_heatmap_pck_of_a_human_pt(data64, tmp_path, capsys):
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), tmp_path / "a", quiet=True)
    assert main(["--score", str(tmp_path / "a" / "human.pt"), "--data", str(data64), "--split", "val"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["step"] == 1 and got["scenes"] == 2 and 0.0 <= got["pck@0.2"] <= 1.0
    assert {"error_px_median", "error_px_p90"} <= set(got)
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    assert main(["--score", str(tmp_path / "junk.pt"), "--data", str(data64)]) == 2
    assert "junk.pt" in capsys.readouterr().err


def test_score_does_not_read_a_model_human_init_moved_since_the_pretraining(data64, tmp_path, capsys):
    """``human.pt`` holds every encoder weight: ``--score`` built the model by reading the ``model.human.init`` its
    model config names, and a file moved since the pretraining stopped it (``model.human.init: ...``)."""
    from tests.training.test_resnet18_names import fake_state_dict

    weights = tmp_path / "resnet18.pth"
    torch.save(fake_state_dict(), weights)
    model = {"human": {"init": str(weights)}}
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0, model=model), tmp_path / "a", quiet=True)
    argv = ["--score", str(tmp_path / "a" / "human.pt"), "--data", str(data64), "--split", "val", "--scenes", "1"]
    assert main(argv) == 0
    before = json.loads(capsys.readouterr().out)
    weights.rename(tmp_path / "moved.pth")
    assert main(argv) == 0, capsys.readouterr().err
    assert json.loads(capsys.readouterr().out) == before  # the same weights scored


def test_heatmap_scores_of_the_true_heatmaps(data64):
    """A head that answers the training targets themselves: PCK 1 and a 2D error of the decoder's own (well
    under a model pixel), the p90 no smaller than the median."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset
    from training.pretrain_human import heatmap_scores

    ds = MultiViewDataset(data64, "val", TargetConfig(heatmap_stride=4))

    class TruthHead(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.config = type("C", (), {"height": ds[0]["tgt_images"].shape[-1]})()
            self.i = 0

        def encode_human(self, images):
            it = ds[self.i]
            self.i += 1
            return it["tgt_heatmaps"][torch.nonzero(it["tgt_is_source"]).flatten()]

    got = heatmap_scores(TruthHead(), ds, len(ds), torch.device("cpu"))
    assert got["pck@0.2"] == 1.0
    assert 0.0 <= got["error_px_median"] <= got["error_px_p90"] < 1.0, got


def test_a_frozen_encoder_stays_as_pretrained_while_the_rest_trains(data64, tmp_path):
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), tmp_path / "pre", quiet=True)
    pre = torch.load(tmp_path / "pre" / "human.pt", weights_only=True)["human"]
    cfg = tiny_cfg(data64, iterations=2, lr=1e-2, pck_every=1, human_init=str(tmp_path / "pre" / "human.pt"),
                   freeze_human=True, encoder_views="all", encoder_flip=True)
    _, model = train(cfg, tmp_path / "joint", quiet=True)
    assert model.human.frozen and not model.human.training
    got = model.human.state_dict()
    for k, v in pre.items():  # weights and BatchNorm statistics alike
        assert torch.equal(got[k], v), k
    start = torch.load(tmp_path / "joint" / "ckpt_0000001.pt", weights_only=False)["model"]
    end = model.state_dict()
    assert any(not torch.equal(start[k], end[k])
               for k in end if not k.startswith("human.") and end[k].is_floating_point())
    model.train()  # a later train() keeps it frozen
    assert not model.human.training and model.feature_net.training


def test_coarse_steps_feed_the_trunk_a_smaller_image_then_the_models(data64, tmp_path, capsys):
    """Progressive resizing (``coarse_steps``): the first steps' trunk input is ``coarse_input_scale`` of the
    image, the rest the model's; the heatmaps keep their size, and ``human.pt`` records the model's scale."""
    from training.data.torch_dataset import MultiViewDataset
    from training.model import GHNeRF

    cfg = tiny_pretrain(data64, iterations=3, eval_every=0, coarse_steps=2, coarse_input_scale=0.5)
    assert [cfg.input_scale_at(s) for s in range(3)] == [0.5, 0.5, None]
    model = GHNeRF(cfg.model_config()).train()
    sizes = []
    model.human.trunk.conv1.register_forward_hook(lambda m, i, o: sizes.append(i[0].shape[-1]))
    images, heat = view_batch([MultiViewDataset(data64, "train")[0]], flip=False)
    opt = torch.optim.Adam(model.human.parameters(), lr=1e-3)
    for scale in (0.5, None):
        assert pretrain_step(model, opt, images, heat, cfg, "fp32", scale) > 0  # heatmaps fit the targets
    assert sizes == [32, 64] and model.config.human.input_scale == 1.0

    summary = pretrain(cfg, tmp_path / "run", quiet=True)
    assert "warning" not in capsys.readouterr().err  # coarse steps < iterations: no warning
    log = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert summary["steps"] == 3 and [r.get("input_scale") for r in log] == [0.5, 0.5, None]
    saved = torch.load(tmp_path / "run" / "human.pt", weights_only=True)["model_config"]["human"]
    assert saved["input_scale"] == 1.0


def test_trunk_input_scale_is_restored_when_the_step_fails():
    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    with pytest.raises(RuntimeError, match="boom"):
        with trunk_input_scale(model, 0.5):
            assert model.human.config.input_scale == 0.5
            raise RuntimeError("boom")
    assert model.human.config.input_scale == 1.0


def test_a_damaged_pretraining_checkpoint_is_named_without_the_trainers_advice(data64, tmp_path):
    """The pretraining keeps only last.pt: the trainer's advice for a damaged one (delete it, --resume continues
    from the newest ckpt_*.pt) would silently restart hours of pretraining from step 0 here."""
    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, iterations=1), run, quiet=True)
    (run / "last.pt").write_bytes((run / "last.pt").read_bytes()[:1000])  # torn
    with pytest.raises(ConfigError, match="last.pt: unreadable checkpoint") as e:
        pretrain(tiny_pretrain(data64), run, resume=True, quiet=True)
    assert "ckpt_" not in str(e.value) and "no other checkpoint" in str(e.value)
    assert "from step 0" in str(e.value)


@pytest.mark.parametrize("poison", ["loss", "gradient"])
def test_a_non_finite_pretraining_step_leaves_the_weights_untouched(data64, poison):
    """The loss was checked after opt.step(): a NaN gradient of a finite loss was applied, and last.pt (the
    pretraining's only checkpoint) could save it. Now the step stops before the update."""
    from training.data.torch_dataset import MultiViewDataset
    from training.model import GHNeRF

    cfg = tiny_pretrain(data64, eval_every=0)
    model = GHNeRF(cfg.model_config()).train()
    images, heat = view_batch([MultiViewDataset(data64, "train")[0]], flip=False)
    if poison == "loss":
        heat = heat.clone()
        heat.view(-1)[0] = float("nan")
    else:  # a finite loss whose gradient is not (an overflow in the backward pass)
        next(p for p in model.human.parameters() if p.requires_grad).register_hook(lambda g: g * float("nan"))
    opt = torch.optim.Adam(model.human.parameters(), lr=1e-3)
    weights = {k: v.clone() for k, v in model.human.state_dict().items() if v.is_floating_point()}
    with pytest.raises(FloatingPointError, match=f"non-finite {poison}.*not updated"):
        pretrain_step(model, opt, images, heat, cfg, "fp32")
    assert all(torch.equal(weights[k], v) for k, v in model.human.state_dict().items() if k in weights
               and "running" not in k)  # BatchNorm's statistics move in the forward pass; the weights did not


def _steps_of(path) -> int:
    return int(torch.load(path, weights_only=False)["step"])


@pytest.mark.parametrize("damage", ["torn", "non-finite", "missing"])
def test_a_damaged_last_pt_resumes_from_prev_pt_which_is_kept(data64, tmp_path, capsys, damage):
    """The pretraining kept last.pt alone: one file corrupted after it was written (or a NaN saved) lost the
    whole run. The checkpoint before it is kept as prev.pt; --resume falls back to it in one line naming both,
    and learns what the undamaged run did. The damaged last.pt is overwritten, never rotated over prev.pt."""
    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, eval_every=0), run, quiet=True)  # checkpoints at steps 1 and 2
    assert _steps_of(run / "last.pt") == 2 and _steps_of(run / "prev.pt") == 1
    want = torch.load(run / "human.pt", weights_only=True)["human"]
    if damage == "torn":
        (run / "last.pt").write_bytes((run / "last.pt").read_bytes()[:1000])
    elif damage == "non-finite":
        ck = torch.load(run / "last.pt", weights_only=False)
        w = next(v for v in ck["human"].values() if v.is_floating_point())
        w[(0,) * w.dim()] = float("nan")
        torch.save(ck, run / "last.pt")
    else:  # a crash between prev.pt's rename and last.pt's
        (run / "last.pt").unlink()
    capsys.readouterr()
    summary = pretrain(tiny_pretrain(data64, eval_every=0), run, resume=True, quiet=True)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{run / 'last.pt'} " in err[0] and f"{run / 'prev.pt'} (step 1)" in err[0]
    assert ("is missing" if damage == "missing" else "cannot be used") in err[0]
    assert summary["steps"] == 2 and [g["steps"] for g in summary["segments"]] == [1, 1]
    assert _steps_of(run / "last.pt") == 2 and _steps_of(run / "prev.pt") == 1  # the good prev.pt kept
    got = torch.load(run / "human.pt", weights_only=True)["human"]
    assert all(torch.equal(got[k], v) for k, v in want.items())
    assert [json.loads(line)["step"] for line in (run / "log.jsonl").read_text().splitlines()] == [1, 2]


def test_when_neither_checkpoint_reads_the_error_names_both_before_anything_is_written(data64, tmp_path):
    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, eval_every=0), run, quiet=True)
    for name in ("last.pt", "prev.pt"):
        (run / name).write_bytes((run / name).read_bytes()[:1000])
    before = (run / "config.json").read_bytes()
    with pytest.raises(ConfigError, match=r"last\.pt: unreadable checkpoint .*prev\.pt, cannot be used either "
                                          r"\(unreadable checkpoint .*from step 0") as e:
        pretrain(tiny_pretrain(data64, eval_every=0, iterations=3), run, resume=True, quiet=True)
    assert "ckpt_" not in str(e.value)
    assert (run / "config.json").read_bytes() == before
    (run / "last.pt").unlink()  # prev.pt alone still holds a run: a new run there is refused
    with pytest.raises(ConfigError, match=r"holds a training run \(prev\.pt\); pass --resume"):
        pretrain(tiny_pretrain(data64, eval_every=0), run, quiet=True)


def test_resume_takes_model_overrides_that_build_the_same_encoder(data64, tmp_path):
    """``model.human.num_layers=2`` on a ``tiny`` pretraining restates the preset: the same encoder, yet the resume
    was refused (``model.human None in the run, {'num_layers': 2} now``); another value is named with both."""
    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), run, quiet=True)
    pretrain(tiny_pretrain(data64, eval_every=0, model={"human": {"num_layers": 2}}), run, resume=True, quiet=True)
    assert torch.load(run / "last.pt", weights_only=False)["step"] == 2
    with pytest.raises(ConfigError, match=r"another model config \(human\.num_layers 2 in the checkpoint, 3 now"):
        pretrain(tiny_pretrain(data64, iterations=3, eval_every=0, model={"human": {"num_layers": 3}}), run,
                 resume=True, quiet=True)


def test_resume_under_another_preset_name_that_builds_the_same_encoder(data64, tmp_path, monkeypatch):
    """Another preset's name building the same model was refused on ``preset``; it is compared by the model."""
    from training.configs import PRESETS, tiny

    monkeypatch.setitem(PRESETS, "tiny_again", tiny)
    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), run, quiet=True)
    pretrain(tiny_pretrain(data64, eval_every=0, preset="tiny_again"), run, resume=True, quiet=True)
    assert torch.load(run / "last.pt", weights_only=False)["step"] == 2


def test_resume_does_not_read_a_model_human_init_moved_since_the_run_began(data64, tmp_path):
    """``last.pt`` holds the encoder's weights: a resume read ``model.human.init`` again, and stopped on a file
    moved since the run began; it now gives the weights of an uninterrupted run."""
    from tests.training.test_resnet18_names import fake_state_dict

    weights = tmp_path / "resnet18.pth"
    torch.save(fake_state_dict(), weights)
    model = {"human": {"init": str(weights)}}
    pretrain(tiny_pretrain(data64, eval_every=0, model=model), tmp_path / "a", quiet=True)
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0, model=model), tmp_path / "b", quiet=True)
    weights.rename(tmp_path / "moved.pth")
    pretrain(tiny_pretrain(data64, eval_every=0, model=model), tmp_path / "b", resume=True, quiet=True)
    a, b = (torch.load(tmp_path / r / "last.pt", weights_only=False)["human"] for r in ("a", "b"))
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_resume_refuses_a_checkpoint_of_another_model_before_anything_is_written(data64, tmp_path, monkeypatch):
    """The preset changed since the checkpoint (same config, another encoder size): named by setting, not a
    load_state_dict traceback after config.json was rewritten; a checkpoint from before model_config was stored
    is named by its weights."""
    import dataclasses

    import training.pretrain_human as ph

    run = tmp_path / "p"
    pretrain(tiny_pretrain(data64, iterations=1, eval_every=0), run, quiet=True)
    real = ph.model_config_of

    def wider(name, overrides):
        m = real(name, overrides)
        return dataclasses.replace(m, human=dataclasses.replace(m.human, out_channels=16))

    monkeypatch.setattr(ph, "model_config_of", wider)
    before = (run / "config.json").read_bytes()
    with pytest.raises(ConfigError, match=r"last\.pt: resuming under another model config \(human\.out_channels"):
        pretrain(tiny_pretrain(data64, eval_every=0), run, resume=True, quiet=True)
    assert (run / "config.json").read_bytes() == before
    ck = torch.load(run / "last.pt", weights_only=False)
    del ck["model_config"]  # as saved before it was stored
    torch.save(ck, run / "last.pt")
    with pytest.raises(ConfigError, match=r"last\.pt: its encoder weights do not fit the 'tiny' model"):
        pretrain(tiny_pretrain(data64, eval_every=0), run, resume=True, quiet=True)


def test_an_interrupted_resume_leaves_no_stale_summary_and_no_lock(data64, tmp_path, monkeypatch):
    """summary.json describes the invocation that wrote it (as the trainer's): a stop_at part's "stopped early at
    step 1" stayed beside a later last.pt when the resume was interrupted. Ctrl-C also removes train.pid."""
    import training.pretrain_human as ph

    run = tmp_path / "p"
    first = pretrain(tiny_pretrain(data64, iterations=3, stop_at=1, eval_every=0), run, quiet=True)
    assert first["stopped_early"] and (run / "summary.json").exists() and not (run / "train.pid").exists()
    seen = []
    real_step = ph.pretrain_step

    def ctrl_c_at_step_3(*a, **kw):
        seen.append((run / "train.pid").read_text())
        if len(seen) == 2:
            raise KeyboardInterrupt
        return real_step(*a, **kw)

    monkeypatch.setattr(ph, "pretrain_step", ctrl_c_at_step_3)
    with pytest.raises(KeyboardInterrupt):
        pretrain(tiny_pretrain(data64, iterations=3, eval_every=0), run, resume=True, quiet=True)
    import os
    assert seen[0].split()[0] == str(os.getpid())  # held while it ran (then its start: training.run_lock)
    assert not (run / "summary.json").exists() and not (run / "train.pid").exists()
    assert _steps_of(run / "last.pt") == 2


def _wait_for(cond, seconds: float, what: str) -> None:
    import time

    deadline = time.monotonic() + seconds
    while not cond():
        if time.monotonic() > deadline:
            pytest.fail(f"{what} within {seconds} s")
        time.sleep(0.2)


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGKILL"])
def test_a_pretraining_stopped_by_a_signal_is_resumed_or_forced_at_once_and_a_live_one_refused(data64, tmp_path,
                                                                                               sig):
    """The pipeline took a pretraining folder with a fresh log.jsonl and no summary.json for a run in progress:
    ``--force pretrain`` right after a Ctrl-C was refused for three minutes, and a live pretraining in another
    process was never refused by the resume. The pretraining now holds train.pid as the trainer does."""
    import os
    import signal
    import subprocess
    import sys
    from pathlib import Path

    from training.pipeline import PipelineConfig, _check_pretrain_folder, _set_aside_forced

    pcfg = PipelineConfig(out=tmp_path / "m", runs=tmp_path / "runs", data=tmp_path / "data")
    pcfg.variants = ("ghnerf",)
    run = tmp_path / "runs" / "edge128_human"
    conf = tmp_path / "pre.json"
    conf.write_text(json.dumps({**asdict(tiny_pretrain(data64)), "iterations": 100000, "eval_every": 0}))
    repo = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(repo), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.Popen([sys.executable, "-m", "training.pretrain_human", "--config", str(conf), "--out",
                             str(run), "--quiet"], cwd=repo, env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: (run / "log.jsonl").exists() and (run / "last.pt").exists() or proc.poll() is not None,
                  180, "no checkpoint")
        assert proc.poll() is None, proc.stderr.read()
        assert (run / "train.pid").read_text().split()[0] == str(proc.pid)  # (then its start: training.run_lock)
        with pytest.raises(RuntimeError, match=f"in progress \\(process {proc.pid} holds its train.pid\\)"):
            _check_pretrain_folder(pcfg, "ghnerf")
        with pytest.raises(RuntimeError, match=f"in use by a training run \\(process {proc.pid}"):
            _set_aside_forced(pcfg, {"pretrain_ghnerf"})
        with pytest.raises(RuntimeError, match=f"another training process \\({proc.pid}\\)"):
            pretrain(tiny_pretrain(data64, iterations=100000, eval_every=0), run, resume=True, quiet=True)
        proc.send_signal(getattr(signal, sig))
        proc.wait(60)
        stderr = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if sig != "SIGKILL":  # one line and 130 / 143, as ghnerf-train: no traceback (SIGTERM killed it silently)
        assert proc.returncode == {"SIGINT": 130, "SIGTERM": 143}[sig], stderr
        assert "Traceback" not in stderr and f"stopped ({'Ctrl-C' if sig == 'SIGINT' else sig}); `--resume --out" \
            in stderr, stderr
    # SIGINT, SIGTERM: the lock removed on the way out; SIGKILL: left naming a dead process (as the trainer's)
    assert (run / "train.pid").exists() == (sig == "SIGKILL")
    # a SIGKILL between the checkpoint's two renames leaves prev.pt and no last.pt (train.save_atomic), which
    # --resume falls back to: the step it resumes from, not last.pt's (missing then: the test failed now and then)
    step = int(pretrain_checkpoint.resume_point(run)[1]["step"])
    resumed = pretrain(tiny_pretrain(data64, iterations=step + 1, eval_every=0), run, resume=True, quiet=True)
    assert resumed["steps"] == step + 1
    (run / "summary.json").unlink()  # as if that resume was stopped too: a fresh log, no summary, no live pid
    _set_aside_forced(pcfg, {"pretrain_ghnerf"})  # at once, not three minutes later
    assert not run.exists() and len(list(run.parent.glob("edge128_human.replaced-*"))) == 1


def test_the_cli_names_a_failed_checkpoint_write_or_a_divergence_in_one_line(data64, tmp_path, monkeypatch, capsys):
    """ghnerf-train stops on these in one line (exit 1); the pretraining's CLI printed a traceback."""
    import training.pretrain_human as ph
    from training.train import CheckpointWriteError

    for exc, kind in ((CheckpointWriteError("p/last.pt: cannot write the checkpoint (disk full)"), "checkpoint not "
                       "written"), (FloatingPointError("step 3: non-finite loss (nan)"), "diverged")):
        def fail(*a, **kw):
            raise exc

        monkeypatch.setattr(ph, "pretrain", fail)
        assert main(["--out", str(tmp_path / "p"), "--set", 'preset="tiny"', "--data", str(data64)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"error: {kind}: {exc}"]


def test_window_centroid_loss_of_a_prediction_with_no_mass_is_the_targets_offset_from_the_window_centre():
    """A clamped total (1e-6) used to put an empty window's centroid at the map's corner (cell 0, 0): the
    loss was the joint's distance from that corner (23 cells at (10.3, 20.7)), and a map of 1e-9 everywhere
    had slopes of 2e7. With the prior mass at the window's centre both stay small wherever the joint is."""
    from training.losses import CENTROID_PRIOR_MASS, window_centroid_loss

    for cy, cx in ((10.3, 20.7), (25.0, 28.0)):
        target = _gauss(cy, cx, sigma=1.0)[None, None]
        # the window is centred on cell (10, 21) / (25, 28): the target's centroid is about (0.3, -0.3) / 0 off it
        offset = math.hypot(cy - round(cy), cx - round(cx))
        assert float(window_centroid_loss(torch.zeros_like(target), target)) == pytest.approx(offset, abs=0.05)
        faint = torch.full_like(target, 1e-9, requires_grad=True)
        window_centroid_loss(faint, target).backward()
        assert float(faint.grad.abs().max()) < 10 * 3 * math.sqrt(2) / CENTROID_PRIOR_MASS


def test_window_centroid_loss_hand_computed():
    """Target symmetric about cell (16, 16): centroid offset 0. Prediction: mass 1 at cell (16, 17) only, so its
    centroid is 1 / (1 + prior mass) cells to the right of the window's centre."""
    from training.losses import CENTROID_PRIOR_MASS, window_centroid_loss

    target = _gauss(16.0, 16.0, sigma=1.0)[None, None]
    pred = torch.zeros_like(target)
    pred[0, 0, 16, 17] = 1.0
    assert float(window_centroid_loss(pred, target)) == pytest.approx(1.0 / (1.0 + CENTROID_PRIOR_MASS), rel=1e-6)
