"""``make model`` plumbing without training: restartable stages and the model card."""
from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from training.model_card import render_markdown, sha256, write_card
from training.pipeline import STAGES, PipelineConfig, Stages


def test_stages_skip_finished_work_and_redo_changed_work(tmp_path):
    out = tmp_path / "thing.txt"
    calls = []

    def make(text):
        def fn():
            calls.append(text)
            out.write_text(text)
            return [out], {"text": text}
        return fn

    st = Stages(tmp_path, ())
    st.run("export_ghnerf", {"a": 1}, make("one"))
    st.run("export_ghnerf", {"a": 1}, make("two"))  # same inputs, intact output: skipped
    assert calls == ["one"]
    st.run("export_ghnerf", {"a": 2}, make("three"))  # inputs changed
    out.write_text("tampered")
    st.run("export_ghnerf", {"a": 2}, make("four"))  # output changed
    assert calls == ["one", "three", "four"]
    stamp = json.loads((tmp_path / ".stages" / "export_ghnerf.json").read_text())
    assert stamp["outputs"] == {str(out): sha256(out)} and stamp["info"] == {"text": "four"}
    Stages(tmp_path, ("export",)).run("export_ghnerf", {"a": 2}, make("five"))  # --force export
    assert calls[-1] == "five"
    assert {"data", "train_ghnerf", "eval_baseline", "prior_ghnerf", "card"} <= set(STAGES)
    # the prior learns the quantized encoder's errors, and the eval scores it
    assert STAGES.index("quantize_ghnerf") < STAGES.index("prior_ghnerf") < STAGES.index("eval_ghnerf")


def test_card_renders_metrics_and_missing_values(tmp_path):
    card = {
        "name": "test", "summary": "s", "quick": True, "command": "python -m training.pipeline --quick",
        "hardware": {"cpu": "cpu", "cores": 2}, "wall_time_s": {"data": 60.0, "train_ghnerf": 120.0},
        "data": {"path": "d", "splits": {"train": 3}, "eval_split": "val", "eval_scenes": 2,
                 "motions": {"train": "stand 50 %, freestyle 50 %", "val": "reach"}},
        "training": {"ghnerf": {"config": {"preset": "edge128", "targets_per_iter": 4, "heat_rays": 512,
                                           "patch_size": 16, "lr": 5e-4, "lr_decay_gamma": 0.5,
                                           "lr_decay_every": 2500}, "steps": 8000, "wall_s": 1800,
                                "device": "cuda:0", "gpu": "NVIDIA H100 80GB HBM3", "threads": 16},
                     "ghnerf_human_pretraining": {
                         "config": {"preset": "edge128", "lr": 1e-3, "lr_decay_gamma": 0.5, "lr_decay_every": 4000},
                         "steps": 24000, "wall_s": 6391.6, "images_per_step": 16, "threads": 1,
                         "segments": [{"steps": 12000, "wall_s": 2603.6, "threads": 2},
                                      {"steps": 12000, "wall_s": 3788.0, "threads": 1}]}},
        "metrics": {"ghnerf_int8": {"kind": "onnx-int8", "pck@0.2": 0.5, "mpjpe_mm": None, "psnr_masked": 20.0,
                                    "ssim_masked": 0.9, "heatmap_mse": 0.001, "pck_undecoded": 3,
                                    "pck_evaluated_joints": 10, "encoder_heatmaps_pck@0.2": 0.8,
                                    "mpjpe_gated_mm": 61.25, "mpjpe_gated_found": 0.62,
                                    "mpjpe_gated_median_mm": 40.04,
                                    "encoder_heatmaps_mpjpe_mm": 100.0, "encoder_heatmaps_flip_pck@0.2": 0.81,
                                    "encoder_heatmaps_flip_mpjpe_mm": None,
                                    "encoder_heatmaps_flip_pck@0.2_by_part": {"head": 0.5, "arms": 1.0},
                                    "pck@0.2_by_view": [0.4, 0.6], "encoder_heatmaps_flip_pck@0.2_by_view": [0.9, None],
                                    "pck@0.2_by_part": {"head": 0.75, "arms": None}, "novel_views": 3,
                                    "encoder_heatmaps_mpjpe_by_visibility": {
                                        "all_views": {"mpjpe_mm": 80.0, "joints": 30},
                                        "some_views": {"mpjpe_mm": 150.0, "joints": 10},
                                        "no_view": {"mpjpe_mm": None, "joints": 0}},
                                    "psnr_masked_by_source_angle": [
                                        {"range_deg": [0.0, 15.0], "views": 2, "psnr": 22.5},
                                        {"range_deg": [15.0, 180.0], "views": 0, "psnr": None}]}},
        "parity": {"ghnerf": {"pipeline": {"heatmaps": {"max_abs": 0.01, "mean_abs": 1e-4}, "peak_shift_rays": 0.1,
                                           "depth_mean_abs_m": 0.001}}},
        "files": {"ghnerf/encoder.onnx": {"bytes": 10, "sha256": "ab"}},
    }
    j, m = write_card(tmp_path, card)
    assert json.loads(j.read_text())["metrics"]["ghnerf_int8"]["pck@0.2"] == 0.5
    md = m.read_text()
    assert md == render_markdown(card)
    assert "| ghnerf_int8 | onnx-int8 | 0.500 | n/a | 61.2 / 40.0 (62 %) | 20.00 | 0.900 | 0.001 | 3/10 |" in md
    assert "3.0 min summed" in md and "Smoke-test build" in md and "| 8000 | 3072 |" in md
    assert "| 2 (12000 steps), then 1 (12000 steps) | 106.5 min |" in md  # a resumed run: both invocations
    bf16_card = json.loads(json.dumps(card))
    bf16_card["training"]["ghnerf_human_pretraining"]["precision"] = "bf16"
    assert "| 2 (12000 steps), then 1 (12000 steps), bf16 | 106.5 min |" in render_markdown(bf16_card)
    assert "Recipe:" not in md  # a smoke test has none
    assert "- Recipe: `gpu`" in render_markdown({**card, "recipe": "gpu"})
    assert "| NVIDIA H100 80GB HBM3 | 30.0 min |" in md  # trained on a GPU machine, not the card's hardware
    assert "| model | heatmaps | head | arms |" in md and "| ghnerf_int8 | rendered | 0.750 | n/a |" in md
    # plain and flip-tested encoder; the gated MPJPE only where the metrics have it (older cards: n/a)
    assert "| ghnerf_int8 | onnx-int8 | 0.800 | 100.0 | n/a | 0.810 | n/a | n/a |" in md
    # the plain MPJPE with the share of the joints it covers (decoded in both views), where the metrics have it
    covered = json.loads(json.dumps(card))
    covered["metrics"]["ghnerf_int8"].update({"mpjpe_mm": 128.7, "mpjpe_found": 0.975,
                                              "encoder_heatmaps_mpjpe_found": 0.72})
    cmd = render_markdown(covered)
    assert "| ghnerf_int8 | onnx-int8 | 0.500 | 128.7 (98 %) | 61.2 / 40.0 (62 %) |" in cmd
    assert "| ghnerf_int8 | onnx-int8 | 0.800 | 100.0 (72 %) | n/a | 0.810 | n/a | n/a |" in cmd
    assert "| ghnerf_int8 | encoder, flip test | 0.500 | 1.000 |" in md
    assert "| model | heatmaps | view 0 | view 1 |" in md and "| ghnerf_int8 | rendered | 0.400 | 0.600 |" in md
    assert "| ghnerf_int8 | encoder, flip test | 0.900 | n/a |" in md
    assert "| model | heatmaps | all views | some views | no view |" in md
    assert "| ghnerf_int8 | encoder | 80.0 (75 %) | 150.0 (25 %) | n/a (0 %) |" in md
    # where the metrics have the gated split (what the runtime reports), the table shows it instead
    gated_card = json.loads(json.dumps(card))
    gated_card["metrics"]["ghnerf_int8"]["mpjpe_gated_by_visibility"] = {
        "all_views": {"mpjpe_mm": 70.0, "joints": 9}, "some_views": {"mpjpe_mm": 130.0, "joints": 1},
        "no_view": {"mpjpe_mm": None, "joints": 0}}
    gmd = render_markdown(gated_card)
    assert "MPJPE (mm, gated) by how many" in gmd and "| ghnerf_int8 | rendered | 70.0 (90 %) | 130.0 (10 %) |" in gmd
    assert "| model | 0-15 deg | 15-180 deg |" in md and "| ghnerf_int8 | 22.50 (2) | n/a (0) |" in md
    assert "- Motions: train: stand 50 %, freestyle 50 %; val: reach" in md
    assert "Skeleton prior" not in md and "skeleton prior" not in md  # a card without one
    # the eval scored the folder's prior: two more columns in the encoder table, n/a where none ran
    scored = json.loads(json.dumps(card))
    scored["metrics"]["ghnerf_int8"].update({"skeleton_prior_mpjpe_mm": 38.64, "skeleton_prior_mpjpe_median_mm": 24.3,
                                             "skeleton_prior_gated_mpjpe_mm": 35.91,
                                             "skeleton_prior_gated_found": 0.987, "skeleton_prior_gate_m": 0.15})
    scored["metrics"]["ghnerf_torch"] = {"kind": "torch", "encoder_heatmaps_pck@0.2": 0.8}
    smd = render_markdown(scored)
    assert "| MPJPE mm, skeleton prior | MPJPE mm, skeleton prior, gated |" in smd
    assert "| 0.810 | n/a | n/a | 38.6 / 24.3 | 35.9 (99 % within 0.15 m) |" in smd
    assert "| ghnerf_torch | torch | 0.800 | n/a | n/a | n/a | n/a | n/a | n/a | n/a |" in smd
    prior = {"split": "val", "scenes": 2, "train_scenes": 12, "train_s": 3.5, "config": {"steps": 4},
             "metrics": {"triangulation_gated": {"mean_mm": 73.4, "median_mm": 34.1, "found": 0.72},
                         "gated": {"0.05": {"mean_mm": 37.3, "median_mm": 26.8, "p90_mm": 70.0, "found": 0.95},
                                   "inf": {"mean_mm": 47.2, "median_mm": 28.1, "p90_mm": None, "found": 1.0}}}}
    pmd = render_markdown({**card, "skeleton_prior": {"ghnerf": prior, "baseline": None}})
    assert "### Skeleton prior (`ghnerf/skeleton_prior.onnx`)" in pmd and "73.4 mean / 34.1 median mm over 72 %" in pmd
    assert "| 0.05 m | 37.3 | 26.8 | 70.0 | 95 % |" in pmd and "| inf | 47.2 | 28.1 | n/a | 100 % |" in pmd
    assert "copies" not in pmd  # no turned copies: the line says nothing of them
    # a prior trained with --tilt-share says how many turned copies it learnt from, and what turned
    tilted = {**prior, "tilted_scenes": 3, "config": {"steps": 4, "tilt_share": 0.25, "tilt_mode": "body"}}
    tmd = render_markdown({**card, "skeleton_prior": {"ghnerf": tilted}})
    assert ("on 12 training scenes and 3 copies of them with the body turned to any angle (`--tilt-share 0.25`), "
            "trained in 3.5 s)") in tmd
    # the run's other part, where the report has it: the encoder's joints of every training scene, collected first
    timed = render_markdown({**card, "skeleton_prior": {"ghnerf": {**prior, "collect_s": 1.25}}})
    assert "on 12 training scenes, trained in 3.5 s after 1.25 s collecting its 2D joints)" in timed
    from training.pipeline import motion_mix
    assert motion_mix({"motions": ["a", "b"], "motion_weights": [1.0, 3.0]}) == "a 25 %, b 75 %"
    assert motion_mix({"motions": ["a", "b"]}) == "a, b"


def _prior_card(flip_gated: dict, triangulation: dict, encoder_file: str = "human.int8.onnx") -> dict:
    """A card whose ghnerf_int8 row scored the flip-tested encoder joints' gated triangulation (``flip_gated``: mean,
    median, found) and whose prior's own run scored the same (``triangulation``)."""
    row = {f"encoder_heatmaps_flip_mpjpe_gated_{k}": v for k, v in
           (("mm", flip_gated["mean"]), ("median_mm", flip_gated["median"]), ("found", flip_gated["found"]))}
    prior = {"split": "val", "scenes": 256, "train_scenes": 25000, "train_s": 1580.5, "config": {"steps": 30000},
             "encoder_file": encoder_file, "flip_test": True,
             "metrics": {"triangulation_gated": {"mean_mm": triangulation["mean"], "median_mm": triangulation["median"],
                                                 "found": triangulation["found"]},
                         "gated": {"inf": {"mean_mm": 37.8, "median_mm": 23.7, "p90_mm": 69.5, "found": 1.0}}}}
    return {"data": {"eval_split": "val"}, "metrics": {"ghnerf_int8": {"kind": "onnx-int8", **row}},
            "skeleton_prior": {"ghnerf": prior}}


def test_the_prior_section_names_the_run_of_its_triangulation_figure_and_the_tables_other_run():
    # session 62: the prior's section said 73.4 / 33.9 mm and the encoder table 73.4 / 34.1 mm for "the runtime's
    # gated triangulation of the same joints", with nothing to say they were two runs (two hosts) of one calculation
    md = render_markdown(_prior_card({"mean": 73.374, "median": 34.107, "found": 0.7214},
                                     {"mean": 73.433, "median": 33.899, "found": 0.7214}))
    assert ("against the runtime's gated triangulation of the same joints, scored in the prior's own run: "
            "73.4 mean / 33.9 median mm over 72 % of the joints (the encoder table's `ghnerf_int8` row, "
            "`MPJPE mm, flip test, gated`, has 73.4 / 34.1 (72 %) from the evaluation's run of the same "
            "triangulation on the same joints;") in md
    # one run's figures (a pipeline's prior stage and eval stage on one host): nothing to tell apart
    same = render_markdown(_prior_card({"mean": 73.374, "median": 34.107, "found": 0.7214},
                                       {"mean": 73.38, "median": 34.11, "found": 0.7214}))
    assert "scored in the prior's own run: 73.4 mean / 34.1 median mm over 72 % of the joints. The prior" in same
    assert "evaluation's run" not in same
    # a prior on the fp32 encoder is compared with the fp32 row, which this card lacks: no clause
    fp32 = render_markdown(_prior_card({"mean": 73.374, "median": 34.107, "found": 0.7214},
                                       {"mean": 73.433, "median": 33.899, "found": 0.7214}, "human.onnx"))
    assert "evaluation's run" not in fp32


def test_the_shipped_card_is_what_the_writer_renders_from_its_json():
    # a hand-edited MODEL_CARD.md would be lost at the next --card or --prior-metrics, and a regenerated card
    # must carry the labels the shipped one shows
    models = Path(__file__).resolve().parents[2] / "models"
    card = json.loads((models / "model_card.json").read_text())
    assert (models / "MODEL_CARD.md").read_text() == render_markdown(card)


def test_a_finished_run_is_reused_only_for_the_same_config_and_architecture(tmp_path):
    """``make model`` reuses runs/<preset> when its train config *and* model config match: a run saved
    before a train-config key existed still matches (defaults), a changed preset does not."""
    import pytest

    torch = pytest.importorskip("torch")
    from dataclasses import asdict

    from training.configs import preset
    from training.pipeline import PipelineConfig, _run_finished, train_inputs

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    run = cfg.runs / "edge128_baseline"
    run.mkdir(parents=True)
    tc = train_inputs(cfg, "edge128_baseline")
    old_style = {k: v for k, v in tc.items() if k not in ("encoder_views", "encoder_flip", "model")}
    (run / "config.json").write_text(json.dumps(old_style))
    (run / "summary.json").write_text(json.dumps({"steps": tc["iterations"], "stopped_early": False}))
    mc = preset("edge128_baseline").to_dict()
    del mc["human"]["decoder"]  # a checkpoint from before the key existed
    torch.save({"model_config": mc}, run / "last.pt")
    assert _run_finished(cfg, "baseline")

    # A run the pipeline started records the dataset it trained on: regenerated data is not that run's.
    from training.pipeline import DATA_MARKER, _check_run_folder, _mark_data

    cfg.data.mkdir(parents=True)
    (cfg.data / "dataset.json").write_text('{"splits": {"train": {"spec": {"motions": ["stand"]}}}}')
    _mark_data(cfg, run)
    assert (run / DATA_MARKER).exists() and _run_finished(cfg, "baseline")
    (cfg.data / "dataset.json").write_text('{"splits": {"train": {"spec": {"motions": ["stand", "freestyle"]}}}}')
    assert not _run_finished(cfg, "baseline")
    with pytest.raises(RuntimeError, match="another dataset"):
        _check_run_folder(cfg, "baseline")
    (run / DATA_MARKER).unlink()

    other = preset("edge128_baseline")
    other.levels[0].regularizer.channels = 4  # the preset's architecture changed since
    torch.save({"model_config": other.to_dict()}, run / "last.pt")
    assert not _run_finished(cfg, "baseline")
    assert asdict(other) != asdict(preset("edge128_baseline"))


def test_human_encoder_overrides_leave_the_baseline_run_reusable(tmp_path):
    """``--set model.human.*`` changes the model's run but not the baseline's, which has no human encoder:
    a recipe that changes only the encoder reuses a finished baseline; any other override does not."""
    import pytest

    torch = pytest.importorskip("torch")
    from training.configs import preset
    from training.pipeline import PipelineConfig, _result_keys, _run_finished, train_inputs

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    run = cfg.runs / "edge128_baseline"
    run.mkdir(parents=True)
    tc = train_inputs(cfg, "edge128_baseline")
    (run / "config.json").write_text(json.dumps(tc))
    (run / "summary.json").write_text(json.dumps({"steps": tc["iterations"], "stopped_early": False}))
    torch.save({"model_config": preset("edge128_baseline").to_dict()}, run / "last.pt")
    assert _run_finished(cfg, "baseline")

    scaled = PipelineConfig(out=cfg.out, runs=cfg.runs, data=cfg.data, train_overrides=["model.human.input_scale=1.0"])
    assert train_inputs(scaled, "edge128_baseline")["model"] == {"human": {"input_scale": 1.0}}
    assert _run_finished(scaled, "baseline")
    # The model's own run does change with it.
    assert _result_keys(train_inputs(scaled, "edge128")) != _result_keys(train_inputs(cfg, "edge128"))
    for other in ("iterations=20", "model.features.norm=\"batch\""):
        changed = PipelineConfig(out=cfg.out, runs=cfg.runs, data=cfg.data, train_overrides=[other])
        assert not _run_finished(changed, "baseline"), other


def test_a_pretrain_block_adds_a_stage_and_points_the_joint_run_at_its_encoder(tmp_path):
    """A ``pretrain_human`` block (in the train config or a ``--set`` override): the pipeline pretrains into
    ``runs/<preset>_human`` with the block's settings and the joint run loads that ``human.pt``."""
    import pytest

    pytest.importorskip("torch")
    from training.pipeline import (PipelineConfig, _pretrain_cmd, _pretrain_finished, _train_cmd, pretrain_block,
                                   pretrain_inputs, train_inputs)

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    assert pretrain_block(cfg, "baseline") == {} and "pretrain_ghnerf" in STAGES
    cfg.train_overrides = ['pretrain_human={"iterations": 5, "lr": 0.002}']
    tc = train_inputs(cfg, "edge128")
    assert tc["human_init"] == str(tmp_path / "runs" / "edge128_human" / "human.pt")
    # the joint run is told to start from it (the config file alone does not say where it is)
    train_cmd = _train_cmd(cfg, "edge128", cfg.runs / "edge128")
    assert f'human_init="{tc["human_init"]}"' in train_cmd
    plain = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    assert not any("human_init" in c for c in _train_cmd(plain, "edge128_baseline", cfg.runs / "edge128_baseline"))
    pc = pretrain_inputs(cfg, "ghnerf")
    assert (pc["preset"], pc["iterations"], pc["lr"], pc["data"]) == ("edge128", 5, 0.002, str(cfg.data))
    cmd = _pretrain_cmd(cfg, "ghnerf", ["threads=1"])
    run = tmp_path / "runs" / "edge128_human"
    assert json.loads((run / "requested.json").read_text()) == pc
    assert cmd[cmd.index("--config") + 1] == str(run / "requested.json") and cmd[-2:] == ["--set", "threads=1"]
    assert not _pretrain_finished(cfg, "ghnerf")
    (run / "human.pt").write_bytes(b"x")
    (run / "config.json").write_text(json.dumps({**pc, "threads": 1}))  # runtime keys do not matter
    (run / "summary.json").write_text(json.dumps({"steps": 5}))
    assert _pretrain_finished(cfg, "ghnerf")
    older = {k: v for k, v in pc.items() if k != "augment"}  # made before the setting existed: its default
    (run / "config.json").write_text(json.dumps(older))
    assert _pretrain_finished(cfg, "ghnerf")
    (run / "config.json").write_text(json.dumps({**pc, "lr": 0.001}))  # another recipe: not this run
    assert not _pretrain_finished(cfg, "ghnerf")
    (run / "config.json").write_text(json.dumps({**pc, "augment": {"rotation_deg": 30.0}}))
    assert not _pretrain_finished(cfg, "ghnerf")
    # Both ways of starting the pretraining (its own stage, or side by side) refuse to resume a
    # checkpoint made on another dataset.
    from training.pipeline import DATA_MARKER, _check_pretrain_folder

    (run / "config.json").write_text(json.dumps(pc))
    (run / "last.pt").write_bytes(b"x")
    cfg.data.mkdir(parents=True, exist_ok=True)
    (cfg.data / "dataset.json").write_text("{}")
    (run / DATA_MARKER).write_text("another dataset\n")
    assert not _pretrain_finished(cfg, "ghnerf")
    with pytest.raises(RuntimeError, match="another dataset"):
        _check_pretrain_folder(cfg, "ghnerf")


def test_a_pretrain_override_reaches_the_joint_runs_config(tmp_path):
    """``--pretrain-set iterations=N`` pretrains longer; the joint run records that block, so a joint run
    made on another pretraining is not reused (runtime keys such as threads do not count)."""
    import pytest

    pytest.importorskip("torch")
    from training.pipeline import _train_cmd, train_inputs

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data",
                         pretrain_overrides=["iterations=777", "threads=1"])
    plain = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    block = train_inputs(cfg, "edge128")["pretrain_human"]
    assert block["iterations"] == 777 and "threads" not in block
    assert train_inputs(plain, "edge128")["pretrain_human"]["iterations"] != 777
    cmd = _train_cmd(cfg, "edge128", cfg.runs / "edge128")
    assert "pretrain_human.iterations=777" in cmd and not any("threads=1" in c for c in cmd)
    assert not any("pretrain_human" in c for c in _train_cmd(cfg, "edge128_baseline", cfg.runs / "b"))
    from training.train import apply_overrides, build_config, load_config_file
    from training.pipeline import CONFIG_DIR
    # what the trainer makes of that command is what the pipeline expects its config.json to hold
    sets = [cmd[i + 1] for i, c in enumerate(cmd) if c == "--set"]
    got = build_config(apply_overrides(load_config_file(CONFIG_DIR / "edge128.json"),
                                       [f"data={json.dumps(str(cfg.data))}", *sets]))
    assert got.pretrain_human == train_inputs(cfg, "edge128")["pretrain_human"]


def test_side_by_side_pretrains_with_every_core_then_trains_the_variants_at_once(tmp_path):
    """The encoder pretraining is the long pole: it gets every core first; then the joint run and the
    baseline share the cores, one lane each; a finished pretraining is not planned again."""
    import pytest

    pytest.importorskip("torch")
    from training.pipeline import side_by_side_plan

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")

    def threads(cmd):
        return [c for c in cmd if c.startswith("threads=")]

    phases = side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2)
    assert [len(phase) for phase in phases] == [1, 2]
    pre, = phases[0][0]
    assert "training.pretrain_human" in pre.cmd and threads(pre.cmd) == ["threads=2"]
    assert pre.log == cfg.runs / "edge128_human" / "train.log" and pre.run_folder
    joint = [lane[0] for lane in phases[1]]
    assert [step.log for step in joint] == [cfg.runs / "edge128" / "train.log",
                                            cfg.runs / "edge128_baseline" / "train.log"]
    assert all("training.train" in step.cmd and threads(step.cmd) == ["threads=1"] for step in joint)
    run = cfg.runs / "edge128_human"
    (run / "human.pt").write_bytes(b"x")
    (run / "config.json").write_text((run / "requested.json").read_text())
    (run / "summary.json").write_text(json.dumps({"steps": 24000}))
    assert [len(phase) for phase in side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2)] == [2]
    assert side_by_side_plan(cfg, ["baseline"], cores=1)[0][0][0].cmd.count("threads=1") == 1


def test_shared_lanes_put_the_baseline_beside_the_pretraining_and_the_prior_beside_the_joint_run(tmp_path):
    """The cpu recipe's lanes on two cores: the pretraining's first steps at one thread beside the baseline and
    the prior's extra scenes; the rest of it at two; then the joint run beside the early prior, whose job file
    says what the prior stage will compare. Never more threads than cores in a phase."""
    import pytest

    pytest.importorskip("torch")
    from training.early_prior import JOB_FILE
    from training.pipeline import early_prior_dir, side_by_side_plan

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    cfg.apply_recipe("cpu", cores=2)
    assert cfg.shared_pretrain_steps > 0

    def threads(step):
        found = [int(c.split("=")[1]) for c in step.cmd if c.startswith("threads=")]
        if "--threads" in step.cmd:
            found.append(int(step.cmd[step.cmd.index("--threads") + 1]))
        if "--workers" in step.cmd:
            found.append(int(step.cmd[step.cmd.index("--workers") + 1]))
        return found

    data_key = {"request": {"train": 5000}, "manifest": {"dataset.json": "abc"}}
    phases = side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2, data=data_key)
    assert [[[s.log.name for s in lane] for lane in phase] for phase in phases] == [
        [["train.log"], ["train.log"]], [["prior_extra.log"]], [["train.log"]], [["train.log"], ["early_prior.log"]]]
    (pre,), (base,) = phases[0]
    assert "training.pretrain_human" in pre.cmd and f"stop_at={cfg.shared_pretrain_steps}" in pre.cmd
    assert base.log.parent == cfg.runs / "edge128_baseline" and "training.train" in base.cmd
    (extra,), = phases[1]
    assert "training.data.generate" in extra.cmd and not extra.run_folder
    (rest,), = phases[2]
    assert "training.pretrain_human" in rest.cmd and not any(c.startswith("stop_at") for c in rest.cmd)
    (joint,), (early,) = phases[3]
    assert joint.log.parent == cfg.runs / "edge128" and "training.early_prior" in early.cmd and not early.run_folder
    for phase in phases:  # (the early prior's threads are in its job file: checked below)
        assert sum(max(threads(s), default=1) for s in (lane[0] for lane in phase)) <= 2, phase
    assert [threads(s) for s in (pre, base, extra, rest, joint)] == [[1], [1], [2], [2], [1]]

    job = json.loads((early_prior_dir(cfg, "ghnerf") / JOB_FILE).read_text())
    assert job["train_config"]["human_init"] == str(cfg.runs / "edge128_human" / "human.pt")
    argv = job["prior_argv"]
    assert argv[argv.index("--model-dir") + 1] == str(early_prior_dir(cfg, "ghnerf"))
    assert argv[argv.index("--threads") + 1] == "1" and argv[argv.index("--members") + 1] == "2"
    assert job["request"]["data"] == data_key and job["request"]["members"] == 2
    # the early prior is the shipped kind too: bodies at any angle, and its request says so
    assert argv[argv.index("--tilt-share") + 1] == "0.3" and argv[argv.index("--tilt-mode") + 1] == "body"
    assert job["request"]["tilt"] == {"share": 0.3, "mode": "body"}

    # a pretraining resumed at or past the shared steps: the baseline and extra scenes finish with both cores
    log_file = cfg.runs / "edge128_human" / "log.jsonl"
    log_file.write_text(json.dumps({"step": cfg.shared_pretrain_steps}) + "\n{\"step\": 9")  # its last line cut short
    resumed = side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2, data=data_key)
    assert [[[s.log.name for s in lane] for lane in phase] for phase in resumed] == [
        [["train.log"]], [["prior_extra.log"]], [["train.log"]], [["train.log"], ["early_prior.log"]]]
    assert threads(resumed[0][0][0]) == [2]
    log_file.unlink()
    # a share as long as the pretraining itself would run all of it at one thread: not shared
    cfg.pretrain_overrides.append(f"iterations={cfg.shared_pretrain_steps}")
    assert [len(p) for p in side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2, data=data_key)] == [1, 2]
    cfg.pretrain_overrides.pop()
    # a one-network prior would train at two threads in its stage, at one beside the joint run: not planned early
    cfg.prior_members = 1
    assert [len(p) for p in side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2, data=data_key)] == [2, 1, 1, 1]
    cfg.prior_members = 2
    # without the dataset's stamp (or with --until) there is no early prior: the joint run gets both cores
    assert [len(p) for p in side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2)] == [2, 1, 1, 1]
    cfg.until = "train"
    last = side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=2, data=data_key)
    assert [[s.log.name for s in lane] for lane in last[0]] == [["train.log"], ["train.log"]]  # no extra scenes
    assert threads(last[-1][0][0]) == [2]
    # one core: nothing shared
    cfg.until = None
    assert [len(p) for p in side_by_side_plan(cfg, ["ghnerf", "baseline"], cores=1, data=data_key)] == [1, 2]


def test_the_early_prior_is_adopted_only_for_the_same_keypoint_graphs_and_request(tmp_path):
    """The prior stage takes the early prior only when the model folder's keypoint graphs have the hashes it
    recorded, the request is the same and the file is intact; anything else leaves the folder alone."""
    from training.early_prior import REQUEST_FILE
    from training.pipeline import adopt_early_prior, early_prior_dir, early_prior_request

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    data_key = {"request": {"train": 12}, "manifest": {"dataset.json": "abc"}}
    folder, staged = cfg.out / "ghnerf", early_prior_dir(cfg, "ghnerf")
    folder.mkdir(parents=True)
    staged.mkdir(parents=True)
    for name, body in (("human.onnx", b"fp32"), ("human.int8.onnx", b"int8"), ("render.onnx", b"other")):
        (folder / name).write_bytes(body)
    prior = staged / "skeleton_prior.onnx"
    prior.write_bytes(b"prior")
    prior.with_suffix(".json").write_text(json.dumps({"file": str(prior), "metrics": {}}))

    def record(keypoints, request=None, prior_sha=None):
        request = request or early_prior_request(cfg, keypoints, data_key, cfg.threads)
        (staged / REQUEST_FILE).write_text(json.dumps({"request": request, "prior": str(prior),
                                                        "prior_sha256": prior_sha or sha256(prior)}))

    graphs = {"human.onnx": sha256(folder / "human.onnx"), "human.int8.onnx": sha256(folder / "human.int8.onnx")}
    record({**graphs, "human.int8.onnx": "0" * 64})  # another int8 encoder
    assert not adopt_early_prior(cfg, "ghnerf", data_key) and not (folder / "skeleton_prior.onnx").exists()
    record(graphs)
    assert not adopt_early_prior(cfg, "ghnerf", {**data_key, "manifest": {"dataset.json": "new"}})  # other data
    cfg.prior_steps += 1
    assert not adopt_early_prior(cfg, "ghnerf", data_key)  # another recipe
    cfg.prior_steps -= 1
    record(graphs, prior_sha="1" * 64)  # the staged file changed since
    assert not adopt_early_prior(cfg, "ghnerf", data_key)
    (staged / REQUEST_FILE).write_text("null")  # unreadable: trained here, no crash
    assert not adopt_early_prior(cfg, "ghnerf", data_key)
    record(graphs)
    assert adopt_early_prior(cfg, "ghnerf", data_key)
    assert (folder / "skeleton_prior.onnx").read_bytes() == b"prior"
    report = json.loads((folder / "skeleton_prior.json").read_text())
    assert report["file"] == str(folder / "skeleton_prior.onnx") and report["trained_in"] == str(prior)


def test_an_early_prior_of_another_tilt_is_not_adopted(tmp_path):
    """A prior trained upright only (the request of the code before the tilt keys: none) or with another share or
    mode of turned bodies is not the tilted recipe's: the stage trains its own. An upright recipe still takes the
    upright priors recorded before the keys existed (a missing tilt is a share of 0)."""
    from training.early_prior import REQUEST_FILE
    from training.pipeline import adopt_early_prior, early_prior_dir, early_prior_request

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    data_key = {"request": {"train": 12}, "manifest": {"dataset.json": "abc"}}
    folder, staged = cfg.out / "ghnerf", early_prior_dir(cfg, "ghnerf")
    folder.mkdir(parents=True)
    staged.mkdir(parents=True)
    for name, body in (("human.onnx", b"fp32"), ("human.int8.onnx", b"int8")):
        (folder / name).write_bytes(body)
    graphs = {n: sha256(folder / n) for n in ("human.onnx", "human.int8.onnx")}
    prior = staged / "skeleton_prior.onnx"
    prior.write_bytes(b"prior")
    prior.with_suffix(".json").write_text(json.dumps({"file": str(prior), "metrics": {}}))

    def record(share, mode="body", legacy=False):
        trained = PipelineConfig(out=cfg.out, runs=cfg.runs, data=cfg.data, prior_tilt_share=share,
                                 prior_tilt_mode=mode)
        request = early_prior_request(trained, graphs, data_key, cfg.threads)
        if legacy:  # written before the tilt keys: no "tilt" at all
            request = {k: v for k, v in request.items() if k != "tilt"}
        (staged / REQUEST_FILE).write_text(json.dumps({"request": request, "prior": str(prior),
                                                        "prior_sha256": sha256(prior)}))

    cfg.prior_tilt_share, cfg.prior_tilt_mode = 0.3, "body"  # the recipes' prior
    for share, mode, legacy in ((0.0, "body", True), (0.0, "body", False), (0.3, "scene", False),
                                (0.5, "body", False)):
        record(share, mode, legacy)
        assert not adopt_early_prior(cfg, "ghnerf", data_key), (share, mode, legacy)
        assert not (folder / "skeleton_prior.onnx").exists()
    record(0.3, "body")
    assert adopt_early_prior(cfg, "ghnerf", data_key)
    (folder / "skeleton_prior.onnx").unlink()
    cfg.prior_tilt_share = 0.0  # upright only: the mode does not matter, and the older requests still match
    for mode in ("scene", "body"):
        cfg.prior_tilt_mode = mode
        record(0.0, legacy=True)
        assert adopt_early_prior(cfg, "ghnerf", data_key)


def test_the_recipes_train_the_prior_with_bodies_at_any_angle(tmp_path):
    """``cpu`` and ``gpu`` train the prior as the shipped one (``--tilt-share 0.3 --tilt-mode body``); the quick
    and default configs stay upright only (no tilt flags, the stage inputs of the priors before); a prior stage
    stamped for another tilt is not reused."""
    from training.pipeline import PipelineConfig, prior_argv, prior_stage_inputs

    graphs = {"m/ghnerf/human.int8.onnx": "h2"}
    plain = PipelineConfig(out=tmp_path)
    for name in ("cpu", "gpu"):
        cfg = PipelineConfig(out=tmp_path)
        cfg.apply_recipe(name, cores=2)
        argv = prior_argv(cfg, tmp_path / "ghnerf", tmp_path / "p.onnx", 2)
        assert argv[argv.index("--tilt-share") + 1] == "0.3" and argv[argv.index("--tilt-mode") + 1] == "body"
        assert prior_stage_inputs(cfg, graphs) != prior_stage_inputs(plain, graphs)  # an upright stamp: retrained
        scene = PipelineConfig(out=tmp_path)
        scene.apply_recipe(name, cores=2)
        scene.prior_tilt_mode = "scene"
        assert prior_stage_inputs(scene, graphs) != prior_stage_inputs(cfg, graphs)
    for cfg in (plain, PipelineConfig.quick_defaults(tmp_path)):
        argv = prior_argv(cfg, tmp_path / "ghnerf", tmp_path / "p.onnx", 2)
        assert "--tilt-share" not in argv and "--tilt-mode" not in argv
        assert "tilt" not in prior_stage_inputs(cfg, graphs)  # the keys of the stamps written before them


def test_an_early_prior_already_done_for_the_finished_pretraining_is_not_planned_again(tmp_path):
    """After a stop in the last phase, with the early prior done for the encoder the pretraining finished with,
    the joint run gets every core (no lane for a job with nothing left to do)."""
    pytest.importorskip("torch")
    from training.early_prior import JOB_FILE, REQUEST_FILE
    from training.pipeline import early_prior_dir, side_by_side_plan

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    cfg.apply_recipe("cpu", cores=2)
    data_key = {"request": {"train": 5000}, "manifest": {"dataset.json": "abc"}}
    assert side_by_side_plan(cfg, ["ghnerf"], cores=2, data=data_key)[-1][1][-1].log.name == "early_prior.log"
    run = cfg.runs / "edge128_human"
    (run / "human.pt").write_bytes(b"encoder")
    (run / "config.json").write_text((run / "requested.json").read_text())
    (run / "summary.json").write_text(json.dumps({"steps": 44000}))
    staged = early_prior_dir(cfg, "ghnerf")
    job = json.loads((staged / JOB_FILE).read_text())
    prior = staged / "skeleton_prior.onnx"
    prior.write_bytes(b"prior")
    done = {"request": {**job["request"], "keypoints": {"human.onnx": "ab"}}, "prior": str(prior),
            "prior_sha256": sha256(prior), "human_sha256": sha256(run / "human.pt")}
    (staged / REQUEST_FILE).write_text(json.dumps(done))
    last = side_by_side_plan(cfg, ["ghnerf"], cores=2, data=data_key)
    assert len(last) == 1 and len(last[0]) == 1 and "threads=2" in last[0][0][0].cmd
    (run / "human.pt").write_bytes(b"another encoder")  # the pretraining was redone since: train it again
    assert side_by_side_plan(cfg, ["ghnerf"], cores=2, data=data_key)[-1][1][-1].log.name == "early_prior.log"


def test_a_failed_optional_lane_step_warns_and_a_failed_training_stops(tmp_path, monkeypatch, caplog):
    """The early prior is optional (the prior stage trains one anyway): its failure is logged and the lane goes
    on; a training that fails stops the pipeline, naming its log."""
    import logging
    import sys

    import training.pipeline as pipeline
    from training.pipeline import LaneStep

    cfg = PipelineConfig(out=tmp_path / "m", runs=tmp_path / "runs", data=tmp_path / "data")
    fail, ok = [sys.executable, "-c", "raise SystemExit(3)"], [sys.executable, "-c", "print('fine')"]
    plan = [[[LaneStep(fail, tmp_path / "a.log", run_folder=False, optional=True),
              LaneStep(ok, tmp_path / "b.log", run_folder=False)]]]
    monkeypatch.setattr(pipeline, "side_by_side_plan", lambda *a: plan)
    caplog.set_level(logging.WARNING, logger="training.pipeline")
    pipeline.train_side_by_side(cfg, [])
    assert "fine" in (tmp_path / "b.log").read_text() and "a.log" in caplog.text
    plan[0][0] = [LaneStep(fail, tmp_path / "c.log", run_folder=False), LaneStep(ok, tmp_path / "d.log")]
    with pytest.raises(RuntimeError, match="c.log"):
        pipeline.train_side_by_side(cfg, [])
    assert not (tmp_path / "d.log").exists()


def test_the_cli_sets_the_dataset_request_and_records_the_command(tmp_path, monkeypatch):
    import training.pipeline as pipeline

    seen = []
    monkeypatch.setattr(pipeline, "run", lambda cfg: seen.append(cfg))
    argv = ["--out", str(tmp_path / "m"), "--data", str(tmp_path / "d"), "--train", "2500", "--freestyle-share", "0.25",
            "--pretrain-set", "iterations=12000"]
    assert pipeline.main(argv) == 0
    cfg = seen[0]
    default = PipelineConfig(out=tmp_path)
    assert (default.train, default.freestyle_share) == (5000, 0.5)  # the shipped model's recipe
    assert (cfg.train, cfg.freestyle_share, cfg.val) == (2500, 0.25, default.val)
    assert cfg.pretrain_overrides[-1] == "iterations=12000"  # after the recipe's own, so it wins
    assert "--train 2500" in cfg.command and "--freestyle-share 0.25" in cfg.command
    pipeline.main([*argv, "--force", "eval_ghnerf", "--force=export", "--variants", "baseline"])  # not the recipe
    assert seen[-1].command == cfg.command and seen[-1].force == ("eval_ghnerf", "export")
    # where and how far it runs is not the recipe either: train on a GPU machine, finish elsewhere
    pipeline.main([*argv, "--until", "train", "--workers", "16"])
    assert seen[-1].command == cfg.command and (seen[-1].until, seen[-1].workers) == ("train", 16)
    pipeline.main(["--out", str(tmp_path / "m")])
    assert seen[-1].train == PipelineConfig(out=tmp_path).train  # the default request is unchanged
    assert seen[-1].until is None
    with pytest.raises(SystemExit):
        pipeline.main(["--out", str(tmp_path / "m"), "--until", "export"])  # only data, pretrain, train
    with pytest.raises(SystemExit):
        pipeline.main(["--out", str(tmp_path / "m"), "--workers", "0"])
    with pytest.raises(SystemExit):
        pipeline.main(["--out", str(tmp_path / "m"), "--train", "0"])
    # the lanes: the recipe's shared start unless the flag says otherwise (0: the pretraining alone first)
    pipeline.main(["--out", str(tmp_path / "m"), "--recipe", "cpu"])
    assert seen[-1].shared_pretrain_steps == pipeline.RECIPES["cpu"].shared_pretrain_steps > 0
    pipeline.main(["--out", str(tmp_path / "m"), "--recipe", "cpu", "--shared-pretrain-steps", "0"])
    assert seen[-1].shared_pretrain_steps == 0 and "--shared-pretrain-steps 0" in seen[-1].command
    with pytest.raises(SystemExit):
        pipeline.main(["--out", str(tmp_path / "m"), "--shared-pretrain-steps", "-5"])


def test_a_recipe_puts_its_overrides_first_and_the_card_names_it(tmp_path, monkeypatch):
    """``--recipe gpu`` trains the shipped model's settings (``--set`` / ``--pretrain-set`` still win);
    ``auto`` picks it where torch sees a GPU; the card's command names the recipe that ran, never "auto"."""
    import torch

    import training.pipeline as pipeline

    seen = []
    monkeypatch.setattr(pipeline, "run", lambda cfg: seen.append(cfg))
    out = ["--out", str(tmp_path / "m"), "--data", str(tmp_path / "d")]
    pipeline.main([*out, "--recipe", "gpu", "--pretrain-set", "iterations=5"])
    cfg = seen[-1]
    assert cfg.recipe == "gpu" and cfg.command.endswith("--recipe gpu")
    assert cfg.train_overrides[0] == "model.human.input_scale=1.0"
    assert cfg.pretrain_overrides[0] == "iterations=27000" and cfg.pretrain_overrides[-1] == "iterations=5"
    tc = pipeline.train_inputs(cfg, "edge128")
    assert tc["model"]["human"]["input_scale"] == 1.0
    assert (tc["pretrain_human"]["iterations"], tc["pretrain_human"]["scenes_per_step"]) == (5, 4)

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    pipeline.main(out)
    assert seen[-1].recipe == "gpu" and "auto" not in seen[-1].command
    pipeline.main([*out, "--recipe", "gpu", "--workers", "3"])  # --workers wins over the recipe's
    assert seen[-1].workers == 3 and seen[-1].command == seen[-2].command
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    pipeline.main(out)
    assert seen[-1].recipe == "cpu" and seen[-1].command.endswith("--recipe cpu")
    assert seen[-1].train_overrides == ["model.human.input_scale=1.0"]  # both recipes: the trunk at 128x128
    tc = pipeline.train_inputs(seen[-1], "edge128")
    assert (tc["pretrain_human"]["iterations"], tc["pretrain_human"]["lr_decay_every"],
            tc["pretrain_human"]["coarse_steps"], tc["pretrain_human"]["precision"]) == (44000, 8800, 17600, "auto")
    assert pipeline.pretrain_inputs(seen[-1], "ghnerf")["coarse_steps"] == 17600  # what the pretraining runs
    pipeline.main([*out, "--quick"])  # a smoke test keeps its own tiny settings
    assert "model.human.input_scale=1.0" not in seen[-1].train_overrides and "--recipe" not in seen[-1].command

    # Worker counts follow the machine: speed only, never the result.
    small, big = PipelineConfig(out=tmp_path), PipelineConfig(out=tmp_path)
    small.apply_recipe("gpu", cores=2)
    big.apply_recipe("gpu", cores=16)
    assert (small.workers, big.workers) == (2, 16)
    assert not any(o.startswith("loader_workers") for o in small.pretrain_overrides)
    assert "loader_workers=12" in big.pretrain_overrides

    def result(c):
        full = pipeline.pretrain_inputs(c, "ghnerf")
        return {k: v for k, v in full.items() if k not in pipeline.PRETRAIN_RUNTIME_KEYS}

    assert result(small) == result(big)
    with pytest.raises(ValueError, match="unknown 'tpu'"):
        pipeline.resolve_recipe("tpu")


def test_prior_set_overrides_the_recipes_prior_and_the_card_records_it(tmp_path, monkeypatch, capsys):
    """``--prior-set`` (the measured trade of docs/training.md: the two-core recipe's prior, larger or smaller)
    wins over the recipe's prior, reaches the prior stage's inputs, and bad values are refused by name."""
    import training.pipeline as pipeline

    seen = []
    monkeypatch.setattr(pipeline, "run", lambda cfg: seen.append(cfg))
    out = ["--out", str(tmp_path / "m"), "--data", str(tmp_path / "d"), "--recipe", "cpu"]
    pipeline.main(out)
    plain = seen[-1]
    assert (plain.prior_steps, plain.prior_extra_train, plain.prior_members) == (30000, 20000, 2)
    pipeline.main([*out, "--prior-set", "extra_train=0", "--prior-set", "steps=15000",
                   "--prior-set", "members=1"])  # session 17's cpu prior
    cfg = seen[-1]
    assert (cfg.prior_steps, cfg.prior_extra_train, cfg.prior_members) == (15000, 0, 1)
    assert "--prior-set extra_train=0 --prior-set steps=15000 --prior-set members=1" in cfg.command
    q = {"ghnerf/human.int8.onnx": "ab"}
    assert pipeline.prior_stage_inputs(cfg, q) != pipeline.prior_stage_inputs(plain, q)  # a new prior is trained
    assert (plain.prior_tilt_share, plain.prior_tilt_mode) == (0.3, "body")
    pipeline.main([*out, "--prior-set", "tilt_share=0.5", "--prior-set", "tilt_mode=scene"])
    tilted = seen[-1]
    assert (tilted.prior_tilt_share, tilted.prior_tilt_mode) == (0.5, "scene")
    assert pipeline.prior_stage_inputs(tilted, q) != pipeline.prior_stage_inputs(plain, q)
    argv = pipeline.prior_argv(tilted, tmp_path / "m" / "ghnerf", tmp_path / "p.onnx", 2)
    assert argv[argv.index("--tilt-share") + 1] == "0.5" and argv[argv.index("--tilt-mode") + 1] == "scene"
    pipeline.main([*out, "--prior-set", "tilt_share=0"])  # the upright-only prior: no tilt flags
    assert "--tilt-share" not in pipeline.prior_argv(seen[-1], tmp_path / "m" / "ghnerf", tmp_path / "p.onnx", 2)
    for bad, says in (("epochs=3", "KEY one of"), ("steps=many", "whole number"), ("members=0", "at least 1"),
                      ("extra_train", "KEY=VALUE"), ("tilt_share=1.5", "tilt_share must be a number from 0 to 1"),
                      ("tilt_share=-0.1", "from 0 to 1, got '-0.1'"), ("tilt_share=nan", "from 0 to 1"),
                      ("tilt_share=lots", "got 'lots'"), ("tilt_mode=sideways", "tilt_mode must be one of"),
                      ("tilt_mode=", "got ''")):
        with pytest.raises(SystemExit):
            pipeline.main([*out, "--prior-set", bad])
        assert says in capsys.readouterr().err


def test_the_prior_stage_follows_the_keypoint_graph_and_the_data_not_the_rendering_graphs():
    """A longer joint run (the encoder frozen) re-exports every graph but ``human``: the prior is kept."""
    from training.pipeline import PipelineConfig, keypoint_graphs, prior_stage_inputs

    cfg = PipelineConfig(out=Path("m"))
    graphs = {"m/ghnerf/ghnerf.pt": "c0", "m/ghnerf/human.onnx": "h1", "m/ghnerf/human.int8.onnx": "h2",
              "m/ghnerf/encoder.int8.onnx": "e1", "m/ghnerf/render.int8.onnx": "r1"}
    assert keypoint_graphs(graphs) == {"m/ghnerf/human.onnx": "h1", "m/ghnerf/human.int8.onnx": "h2"}
    before = prior_stage_inputs(cfg, graphs, {"manifest": 1})
    retrained = {**graphs, "m/ghnerf/ghnerf.pt": "c9", "m/ghnerf/encoder.int8.onnx": "e9",
                 "m/ghnerf/render.int8.onnx": "r9"}
    assert prior_stage_inputs(cfg, retrained, {"manifest": 1}) == before
    assert prior_stage_inputs(cfg, {**graphs, "m/ghnerf/human.int8.onnx": "h9"}, {"manifest": 1}) != before
    assert prior_stage_inputs(cfg, graphs, {"manifest": 2}) != before  # another dataset: other scenes to learn from
    # a model without a human graph decodes its joints from the encoder's heatmaps: that one counts then
    no_human = {k: v for k, v in graphs.items() if "human" not in k}
    assert keypoint_graphs(no_human) == {"m/ghnerf/encoder.int8.onnx": "e1"}


def test_a_run_of_another_recipe_over_a_model_folder_says_it_will_replace_it(tmp_path):
    from training.pipeline import _warn_if_replacing_another_recipe

    cfg = PipelineConfig(out=tmp_path / "models")
    cfg.apply_recipe("cpu", cores=2)
    assert _warn_if_replacing_another_recipe(cfg) is None  # nothing there yet
    cfg.out.mkdir()
    (cfg.out / "model_card.json").write_text(json.dumps({"recipe": "gpu"}))
    msg = _warn_if_replacing_another_recipe(cfg)
    assert msg and "'gpu' recipe" in msg and "--recipe gpu" in msg and str(cfg.out) in msg
    cfg.recipe = "gpu"
    assert _warn_if_replacing_another_recipe(cfg) is None
    (cfg.out / "model_card.json").write_text("{not json")  # a broken card is the card stage's to redo
    assert _warn_if_replacing_another_recipe(cfg) is None


def test_until_stops_after_the_named_stages(tmp_path, monkeypatch):
    """``--until train`` runs data, pretraining and training, and neither export nor the card."""
    import training.pipeline as pipeline

    ran = []

    def stage(name):
        def fn(cfg, *a):
            ran.append(name)
            out = cfg.out / f"{name}.out"
            out.write_text(name)
            return [out], {}
        return fn

    monkeypatch.setattr(pipeline, "stage_data", stage("data"))
    monkeypatch.setattr(pipeline, "stage_pretrain", stage("pretrain"))
    monkeypatch.setattr(pipeline, "stage_train", stage("train"))
    monkeypatch.setattr(pipeline, "stage_export", stage("export"))
    monkeypatch.setattr(pipeline, "_run_finished", lambda cfg, v: False)
    monkeypatch.setattr(pipeline, "train_inputs", lambda cfg, preset: {"preset": preset})
    monkeypatch.setattr(pipeline, "expected_model", lambda cfg, v: {})
    monkeypatch.setattr(pipeline, "pretrain_block", lambda cfg, v: {"iterations": 1} if v == "ghnerf" else {})
    monkeypatch.setattr(pipeline, "pretrain_inputs", lambda cfg, v: {"iterations": 1})
    for until, stages in (("data", ["data"]), ("pretrain", ["pretrain"]), ("train", ["pretrain", "train", "train"])):
        ran.clear()
        cfg = PipelineConfig(out=tmp_path / until, parallel_train=False, until=until)
        assert pipeline.run(cfg) is None
        assert ran == (stages if until == "data" else ["data", *stages]), until
    # on a CPU the variants train side by side, pretraining included: not with --until pretrain
    monkeypatch.setattr(pipeline, "train_side_by_side", lambda cfg, todo, data=None: ran.append("side by side"))
    for until, stages in (("pretrain", ["pretrain"]), ("train", ["side by side", "pretrain", "train", "train"])):
        ran.clear()
        cfg = PipelineConfig(out=tmp_path / f"cpu_{until}", parallel_train=True, until=until)
        assert pipeline.run(cfg) is None
        assert ran == ["data", *stages], until


def test_a_failed_stage_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    """A refused run folder or a failing step (say, data made by another recipe) ends the pipeline with
    its reason on one line, not a traceback."""
    import subprocess

    import training.pipeline as pipeline

    def refuse(cfg):
        raise RuntimeError("runs/edge128 holds a run with another config; move it away or pass --runs")

    monkeypatch.setattr(pipeline, "run", refuse)
    assert pipeline.main(["--out", str(tmp_path / "m")]) == 2
    assert "error: runs/edge128 holds a run with another config" in capsys.readouterr().err

    def step_fails(cfg):
        raise subprocess.CalledProcessError(2, ["python", "-m", "training.data.generate"])

    monkeypatch.setattr(pipeline, "run", step_fails)
    assert pipeline.main(["--out", str(tmp_path / "m")]) == 2
    assert "training.data.generate" in capsys.readouterr().err


def test_quick_pipeline_end_to_end_scores_its_prior_and_a_new_prior_re_evaluates(tmp_path, caplog):
    """``--quick`` from nothing (~25 s on two cores): every stage, the prior before the eval that scores it;
    a second run redoes nothing but the card; a damaged prior file is remade; another prior is re-evaluated."""
    import logging

    from training.pipeline import main

    out = tmp_path / "quick"
    assert main(["--quick", "--out", str(out)]) == 0
    assert not list(out.glob("*.staging"))  # the export and quantize stages moved their checked files in
    metrics = json.loads((out / "metrics_ghnerf.json").read_text())["models"]
    assert metrics["ghnerf_int8"]["skeleton_prior_mpjpe_mm"] > 0  # the eval found the prior beside the graphs
    assert metrics["ghnerf_torch"]["skeleton_prior_mpjpe_mm"] is None
    prior_file = out / "ghnerf" / "skeleton_prior.onnx"
    assert str(prior_file) in json.loads((out / ".stages" / "prior_ghnerf.json").read_text())["outputs"]
    assert "MPJPE mm, skeleton prior" in (out / "MODEL_CARD.md").read_text()
    import torch

    lanes = (os.cpu_count() or 1) >= 2 and not torch.cuda.is_available()
    if lanes:  # the lanes ran: the prior learnt beside the joint run is the one taken
        assert json.loads((out / ".stages" / "prior_ghnerf.json").read_text())["info"] == {"early": True}
        report = json.loads(prior_file.with_suffix(".json").read_text())
        assert report["file"] == str(prior_file) and "edge128_prior" in report["trained_in"]
        assert "trained beside the joint run" in (out / "MODEL_CARD.md").read_text()

    def ran() -> list[str]:
        return [r.getMessage().split()[1].rstrip(":") for r in caplog.records
                if r.getMessage().startswith("stage ") and r.getMessage().endswith("running")]

    caplog.set_level(logging.INFO, logger="training.pipeline")
    caplog.clear()
    assert main(["--quick", "--out", str(out)]) == 0
    assert ran() == ["card"]
    prior_file.write_bytes(prior_file.read_bytes() + b"\0")  # not the file the stage wrote: remade
    caplog.clear()
    assert main(["--quick", "--out", str(out)]) == 0
    assert ran()[0] == "prior_ghnerf" and ran()[-1] == "card"  # (the same file again needs no new eval)
    caplog.clear()
    assert main(["--quick", "--out", str(out), "--prior-set", "steps=5"]) == 0  # another prior: re-evaluated
    assert ran() == ["prior_ghnerf", "eval_ghnerf", "card"]
    if lanes:  # --force prior trains it here, not from the early prior (which had 4 steps, not 5, anyway)
        caplog.clear()
        assert main(["--quick", "--out", str(out), "--force", "prior_ghnerf"]) == 0
        assert ran()[0] == "prior_ghnerf"
        assert json.loads((out / ".stages" / "prior_ghnerf.json").read_text())["info"] == {}
        assert "trained_beside" not in json.loads(prior_file.with_suffix(".json").read_text())


def test_a_run_stopped_at_its_cap_is_resumed_and_force_trains_anew(tmp_path, capsys):
    """A run that hit ``max_minutes`` is no finished stage: the pipeline says so, and running it again
    resumes the run (its stamp used to keep the partial model for good). ``--force train`` trains anew,
    the old run moved aside, not deleted."""
    from training.pipeline import main

    out, runs = tmp_path / "q", tmp_path / "q" / "runs"
    capped = ["--quick", "--out", str(out), "--until", "train", "--set", "max_minutes=0.00001", "--set", "log_every=1"]
    assert main(capped) == 2
    assert "stopped at its max_minutes cap" in capsys.readouterr().err
    summary = json.loads((runs / "edge128" / "summary.json").read_text())
    assert summary["stopped_early"] and summary["steps"] < summary["iterations"]
    assert main(["--quick", "--out", str(out), "--until", "train"]) == 0  # the cap lifted: resumed
    for run in ("edge128", "edge128_baseline"):
        summary = json.loads((runs / run / "summary.json").read_text())
        assert summary["steps"] == summary["iterations"] and not summary["stopped_early"]
    first = sha256(runs / "edge128" / "last.pt")
    assert main(["--quick", "--out", str(out), "--until", "train", "--force", "train_ghnerf"]) == 0
    aside = [p for p in runs.iterdir() if p.name.startswith("edge128.replaced-")]
    assert len(aside) == 1 and sha256(aside[0] / "last.pt") == first
    assert (runs / "edge128" / "summary.json").exists() and (runs / "edge128_baseline").exists()


def test_force_sets_aside_only_what_this_run_redoes_and_never_a_live_run(tmp_path):
    import os

    from training.pipeline import PipelineConfig, _set_aside_forced

    cfg = PipelineConfig(out=tmp_path / "m", runs=tmp_path / "runs", data=tmp_path / "data")
    cfg.variants = ("ghnerf",)
    for run in ("edge128", "edge128_baseline"):
        (cfg.runs / run).mkdir(parents=True)
    _set_aside_forced(cfg, {"train_ghnerf", "train_baseline"})
    names = sorted(p.name for p in cfg.runs.iterdir())
    assert names[0].startswith("edge128.replaced-") and names[1:] == ["edge128_baseline"]  # only the variant asked for
    cfg.until = "pretrain"
    (cfg.runs / "edge128").mkdir()
    _set_aside_forced(cfg, {"train_ghnerf"})
    assert (cfg.runs / "edge128").exists()  # this invocation trains nothing
    cfg.until = None
    (cfg.runs / "edge128" / "train.pid").write_text(str(os.getpid()))  # a live trainer
    with pytest.raises(RuntimeError, match="in use by a training run"):
        _set_aside_forced(cfg, {"train_ghnerf"})


def test_force_right_after_a_ctrl_c_sets_the_run_aside_at_once(tmp_path):
    """A trainer or a pretraining stopped by Ctrl-C leaves a fresh log.jsonl, no summary.json and no train.pid
    (both remove it on the way out): ``--force`` used to take that for a run in use for three minutes."""
    import os
    import subprocess
    import sys

    from training.pipeline import PipelineConfig, _set_aside_forced

    cfg = PipelineConfig(out=tmp_path / "m", runs=tmp_path / "runs", data=tmp_path / "data")
    cfg.variants = ("ghnerf",)
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    for stage, name, pid in (("train_ghnerf", "edge128", None), ("pretrain_ghnerf", "edge128_human", None),
                             ("pretrain_ghnerf", "edge128_human", gone.stdout.strip())):  # kill: a dead pid
        run = cfg.runs / name
        run.mkdir(parents=True)
        (run / "log.jsonl").write_text('{"step": 50, "loss": 0.1}\n')  # written a moment ago
        if pid:
            (run / "train.pid").write_text(pid)
        _set_aside_forced(cfg, {stage})
        assert not run.exists()
    assert len(list(cfg.runs.glob("edge128_human.replaced-*"))) == 2
    (cfg.runs / "edge128_human").mkdir()
    (cfg.runs / "edge128_human" / "train.pid").write_text(str(os.getpid()))  # a live pretraining
    with pytest.raises(RuntimeError, match=f"in use by a training run \\(process {os.getpid()} holds"):
        _set_aside_forced(cfg, {"pretrain_ghnerf"})


def test_the_lanes_benchmark_estimates_each_plan_from_its_rates(tmp_path):
    """``benchmarks/time_lanes.py``: rates from a run's log after its warm-up records, and each plan's phases
    from the rates and the recipe's counts (hand-computed here; the benchmark itself runs real jobs)."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "time_lanes.py"
    spec = importlib.util.spec_from_file_location("time_lanes", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)

    (tmp_path / "log.jsonl").write_text("\n".join(json.dumps({"step": s, "time_s": t})
                                                  for s, t in [(10, 30.0), (20, 31.0), (30, 32.0), (40, 34.0)]))
    assert bench.log_rate(tmp_path) == pytest.approx(0.2)  # the first two records (warm-up, probe) left out
    (tmp_path / "log.jsonl").write_text(json.dumps({"step": 10, "time_s": 30.0}))
    with pytest.raises(RuntimeError, match="too few"):
        bench.log_rate(tmp_path)
    (tmp_path / "log.jsonl").unlink()  # a job stopped before its first log record writes none
    with pytest.raises(RuntimeError, match=r"too few log records for a rate \(0\); give more --seconds"):
        bench.log_rate(tmp_path)

    cfg = PipelineConfig(out=tmp_path)
    cfg.apply_recipe("cpu", cores=2)  # 17600 + 26400 pretraining steps, 25256 scenes collected
    cfg.shared_pretrain_steps = 25000  # (the recipe shares the 17600 64x64 steps; here some 128x128 ones too)
    r = {"pre64_2": 0.1, "pre128_2": 0.2, "ghnerf_1_b": 0.3, "baseline_1_g": 0.25, "extras_2": 0.02,
         "collect_2": 0.01, "prior_1_1": 0.03, "pre64_1_b": 0.15, "pre128_1_b": 0.3, "baseline_1_p": 0.28,
         "baseline_1_p2": 0.26, "collect_1_g": 0.015, "prior_1_g": 0.035, "ghnerf_1_q": 0.31, "ghnerf_1_c": 0.29}
    est = bench.plans(cfg, r)
    alone, shared = est["alone first"], est["shared"]
    assert alone["pretraining, every core"] == pytest.approx(17600 * 0.1 + 26400 * 0.2)
    assert alone["joint run beside the baseline"] == pytest.approx(10000 * 0.3)
    assert alone["prior's networks side by side"] == pytest.approx(30000 * 0.03)  # two members at once
    assert alone["prior's collection, every core"] == pytest.approx(25256 * 0.01)
    phase1, extras, phase2, phase3 = shared.values()
    beside64 = 17600 * 0.15 / 0.28  # the baseline's steps while the pretraining's lane is at 64x64
    assert phase1 == pytest.approx(max(17600 * 0.15 + 7400 * 0.3, beside64 * 0.28 + (10000 - beside64) * 0.26))
    assert extras == pytest.approx(20000 * 0.02)
    assert phase2 == pytest.approx(19000 * 0.2)
    collecting = 25256 * 0.015  # the joint run's steps beside the collection at its rate there, then the rest
    assert phase3 == pytest.approx(max(collecting + (10000 - collecting / 0.29) * 0.31,
                                       collecting + 2 * 30000 * 0.035))


def test_the_workers_help_names_the_recipes_own_counts(capsys):
    """--help said "default 2" while the gpu recipe (the default where torch sees a GPU) takes 16."""
    from training import pipeline

    with pytest.raises(SystemExit):
        pipeline.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    start = text.index("--workers WORKERS dataset")
    workers = text[start:text.index("--until", start)]
    assert f"default {PipelineConfig.workers};" in workers
    for name, recipe in pipeline.RECIPES.items():
        if recipe.workers:
            assert f"the {name} recipe's {recipe.workers}, at most the cores" in workers


def test_a_run_stopped_by_ctrl_c_resumes_at_once_and_a_live_one_is_refused(tmp_path):
    """A trainer stopped by Ctrl-C (or killed) leaves a fresh log.jsonl and no summary.json; running the command
    again right away must resume it (a fresh log alone used to read as a run in progress for three minutes).
    Only a train.pid naming a live process is a run in progress."""
    import subprocess
    import sys

    from training.pipeline import PipelineConfig, _check_run_folder

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    run = cfg.runs / "edge128_baseline"
    run.mkdir(parents=True)
    (run / "log.jsonl").write_text('{"step": 50, "loss": 0.1}\n')  # written a moment ago, then Ctrl-C
    _check_run_folder(cfg, "baseline")  # no train.pid: the trainer removed it on the way out
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    (run / "train.pid").write_text(gone.stdout)  # kill -9: a stale lock naming a dead process
    _check_run_folder(cfg, "baseline")
    (run / "train.pid").write_text(str(os.getpid()))  # a live trainer
    with pytest.raises(RuntimeError, match=f"in progress \\(process {os.getpid()} holds its train.pid\\)"):
        _check_run_folder(cfg, "baseline")


def test_a_damaged_checkpoint_in_a_run_folder_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    """A torn ``last.pt`` is named with what to do (delete it: the run resumes from its newest ckpt_*.pt), not
    a traceback of the ConfigError that names it."""
    import training.pipeline as pipeline

    runs = tmp_path / "runs"
    (runs / "edge128_baseline").mkdir(parents=True)
    (runs / "edge128_baseline" / "last.pt").write_bytes(b"PK\x03\x04 torn by a power cut")
    monkeypatch.setattr(pipeline, "run", lambda cfg: pipeline._check_run_folder(cfg, "baseline"))
    assert pipeline.main(["--out", str(tmp_path / "m"), "--runs", str(runs), "--recipe", "cpu"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len([line for line in err.splitlines() if "error:" in line]) == 1
    assert "edge128_baseline/last.pt: unreadable checkpoint" in err and "delete it" in err


def test_card_names_the_quantizer_version_that_made_the_int8_graphs():
    """The calibration line says which ``QUANTIZER_VERSION`` made each variant's int8 graphs, where the card records
    it (the first quantized the colour head's second call): a card made before the record reads as it did."""
    base = {"name": "test", "summary": "s", "quick": True, "command": "c"}
    recorded = {**base, "calibration": {"ghnerf": {"split": "train", "scenes": 16, "quantizer_version": 2},
                                        "baseline": {"split": "train", "scenes": 16, "quantizer_version": None}}}
    md = render_markdown(recorded)
    assert ("int8 calibration (static QDQ activation ranges): ghnerf on 16 scenes of the `train` split by quantizer "
            "version 2; baseline on 16 scenes of the `train` split (evenly spaced,") in md
    older = {**base, "calibration": {"ghnerf": {"split": "train", "scenes": 16}}}
    assert "ghnerf on 16 scenes of the `train` split (evenly spaced," in render_markdown(older)
    # int8 graphs of several versions (the card stage reads each file, training.pipeline.card_quantizer_version)
    mixed = {**base, "calibration": {"ghnerf": {"split": "train", "scenes": 16,
                                                "quantizer_version": {"render": 1, "render_rgb": 2}}}}
    assert ("ghnerf on 16 scenes of the `train` split by quantizer versions 1 (`render`), 2 (`render_rgb`) "
            "(evenly spaced,") in render_markdown(mixed)
