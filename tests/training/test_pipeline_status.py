"""``python -m training.pipeline --status``: which stages ``make model`` would run now, and why, writing nothing."""
from __future__ import annotations

import json

import pytest

import training.pipeline as pipeline
from training.pipeline import PipelineConfig, Stages, status


def test_a_stamp_names_the_input_that_changed(tmp_path):
    out = tmp_path / "graph.onnx"
    out.write_text("graph")
    st = Stages(tmp_path, ())
    inputs = {"checkpoint": {"runs/last.pt": "ab"}, "settings": {"opset": 17, "contract": "1.2.0"}}
    st.run("export_ghnerf", inputs, lambda: ([out], {}))
    assert st.why_not_done("export_ghnerf", inputs) is None
    why = st.why_not_done("export_ghnerf", {**inputs, "settings": {"opset": 17, "contract": "1.3.0"}})
    assert why == 'inputs changed: settings.contract ("1.2.0" -> "1.3.0")'
    why = st.why_not_done("export_ghnerf", {**inputs, "settings": {"opset": 17, "contract": "1.2.0", "new": 1}})
    assert why == "inputs changed: settings.new (<absent> -> 1)"
    out.write_text("another graph")
    assert st.why_not_done("export_ghnerf", inputs).startswith(f"output {out} changed since the stamp")
    out.unlink()
    assert st.why_not_done("export_ghnerf", inputs) == f"output {out} is missing"
    assert st.why_not_done("quantize_ghnerf", inputs) == "no stamp"
    assert Stages(tmp_path, ("export",)).why_not_done("export_ghnerf", inputs) == "forced (--force)"


def test_a_stamp_made_before_inputs_were_recorded_says_only_that_they_differ(tmp_path):
    st = Stages(tmp_path, ())
    (tmp_path / ".stages" / "export_ghnerf.json").write_text(json.dumps({"inputs": "0123456789abcdef",
                                                                          "outputs": {}}))
    assert st.why_not_done("export_ghnerf", {"a": 1}) == \
        "inputs changed (the stamp predates recorded inputs: the digest alone differs)"


@pytest.fixture
def stand_ins(monkeypatch):
    """Every stage a stand-in writing one small file; the training configs small dicts; runs finished."""
    def stage(kind):
        def fn(cfg, *args, **kwargs):
            variant = next(iter(args[0])) if args and isinstance(args[0], dict) else (args[0] if args else "all")
            path = cfg.out / ("model_card.json" if kind == "card" else f"{kind}_{variant}.out")
            path.write_text(json.dumps(f"{kind} {variant}"))
            return [path], {}
        return fn

    for kind in ("data", "pretrain", "train", "export", "quantize", "prior", "eval", "card"):
        monkeypatch.setattr(pipeline, f"stage_{kind}", stage(kind))
    monkeypatch.setattr(pipeline, "_run_finished", lambda cfg, v: True)
    monkeypatch.setattr(pipeline, "train_inputs", lambda cfg, preset: {"preset": preset})
    monkeypatch.setattr(pipeline, "expected_model", lambda cfg, v: {})
    monkeypatch.setattr(pipeline, "pretrain_block", lambda cfg, v: {"iterations": 1} if v == "ghnerf" else {})
    monkeypatch.setattr(pipeline, "pretrain_inputs", lambda cfg, v: {"iterations": 1})
    return monkeypatch


def _rows(cfg):
    return {r.stage: r for r in status(cfg)}


def test_status_follows_run_and_names_why_a_stage_would_run(tmp_path, stand_ins):
    cfg = PipelineConfig(out=tmp_path / "models", parallel_train=False)
    pipeline.run(cfg)
    rows = _rows(cfg)
    assert sorted(rows) == sorted(pipeline.STAGES)
    assert [s for s, r in rows.items() if r.runs] == ["card"], rows  # run() just ran: only the card is rewritten

    # the contract's version moves on (as 1.3.0 did in session 56): both exports, and everything after them
    settings = pipeline.export_settings()
    stand_ins.setattr(pipeline, "export_settings", lambda: {**settings, "contract": "9.9.9"})
    rows = _rows(cfg)
    assert rows["export_ghnerf"].why == f'inputs changed: settings.contract ("{settings["contract"]}" -> "9.9.9")'
    assert rows["export_baseline"].runs and rows["eval_baseline"].runs
    assert rows["prior_ghnerf"].why == "after export_ghnerf, quantize_ghnerf, whose files are its inputs"
    assert not rows["data"].runs and not rows["train_ghnerf"].runs
    stand_ins.setattr(pipeline, "export_settings", lambda: settings)

    # an output replaced by hand (a prior trained outside the pipeline): that stage and the eval scoring it
    (cfg.out / "prior_ghnerf.out").write_text("another prior")
    rows = _rows(cfg)
    assert rows["prior_ghnerf"].why.startswith(f"output {cfg.out / 'prior_ghnerf.out'} changed since the stamp")
    assert rows["eval_ghnerf"].why == "after prior_ghnerf, whose files are its inputs"
    assert [s for s, r in rows.items() if r.runs] == ["prior_ghnerf", "eval_ghnerf", "card"]

    # a run folder without the finished run: it trains, and the stages after it wait on its checkpoint
    stand_ins.setattr(pipeline, "_run_finished", lambda cfg, v: v != "baseline")
    rows = _rows(cfg)
    assert "holds no finished run of this config" in rows["train_baseline"].why
    assert rows["export_baseline"].why == "after train_baseline, whose files are its inputs"


def test_status_writes_nothing(tmp_path, capsys):
    out = tmp_path / "models"
    assert pipeline.main(["--out", str(out), "--data", str(tmp_path / "data"), "--runs", str(tmp_path / "runs"),
                          "--recipe", "cpu", "--status"]) == 0
    assert not out.exists() and not (tmp_path / "data").exists() and not (tmp_path / "runs").exists()
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:3] == ["data", "runs", "no"]  # "no stamp"
    assert all("waits for data" in line for line in lines[1:]), lines


def test_a_reused_run_is_only_stamped_again_and_the_stages_after_it_keep_theirs(tmp_path, stand_ins):
    """A new train-config key (as frame_padding was in session 55) over finished runs of the same result."""
    cfg = PipelineConfig(out=tmp_path / "models", parallel_train=False)
    pipeline.run(cfg)
    stand_ins.setattr(pipeline, "train_inputs", lambda cfg, preset: {"preset": preset, "frame_padding": True})
    stand_ins.setattr(pipeline, "pretrain_inputs", lambda cfg, v: {"iterations": 1, "frame_padding": True})
    stand_ins.setattr(pipeline, "_pretrain_finished", lambda cfg, v: True)
    rows = _rows(cfg)
    assert rows["pretrain_ghnerf"].why == ("inputs changed: config.frame_padding (<absent> -> true); the finished "
                                           "pretraining there is reused: only its stamp is written again")
    assert rows["train_ghnerf"].why == ("inputs changed: config.frame_padding (<absent> -> true), "
                                        "pretrain.frame_padding (<absent> -> true); the finished run in "
                                        f"{cfg.runs / 'edge128'} is reused: only its stamp is written again")
    assert [s for s, r in rows.items() if r.runs] == ["pretrain_ghnerf", "train_ghnerf", "train_baseline", "card"]


def test_the_machine_s_cores_change_no_stamp_input():
    """The ``gpu`` recipe sizes the pretraining's loader workers by the cores (12 on 16, none on 2): a runtime key,
    which made the pretrain and train stages' inputs differ on every machine but the one that trained."""
    def inputs(cores):
        cfg = PipelineConfig(out=pipeline.Path("models"))
        cfg.apply_recipe("gpu", cores=cores)
        assert ("loader_workers=12" in cfg.pretrain_overrides) == (cores == 16)
        return [f(cfg, "ghnerf", {}) for f in (pipeline.pretrain_stage_inputs, pipeline.train_stage_inputs)]

    assert inputs(2) == inputs(16)
