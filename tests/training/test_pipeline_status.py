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
            if kind == "pretrain":  # where the pretraining leaves its encoder (--status reads it there)
                path = pipeline.pretrain_dir(cfg, variant) / "human.pt"
                path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(f"{kind} {variant}"))
            return [path], {}
        return fn

    for kind in ("data", "pretrain", "train", "export", "quantize", "prior", "eval", "card"):
        monkeypatch.setattr(pipeline, f"stage_{kind}", stage(kind))
    monkeypatch.setattr(pipeline, "_run_finished", lambda cfg, v: True)
    monkeypatch.setattr(pipeline, "_warn_if_replacing_another_recipe", lambda cfg: None)  # (the stand-in card)
    monkeypatch.setattr(pipeline, "train_inputs", lambda cfg, preset: {"preset": preset})
    monkeypatch.setattr(pipeline, "expected_model", lambda cfg, v: {})
    monkeypatch.setattr(pipeline, "pretrain_block", lambda cfg, v: {"iterations": 1} if v == "ghnerf" else {})
    monkeypatch.setattr(pipeline, "pretrain_inputs", lambda cfg, v: {"iterations": 1})
    return monkeypatch


def _rows(cfg):
    return {r.stage: r for r in status(cfg)}


def test_status_follows_run_and_names_why_a_stage_would_run(tmp_path, stand_ins):
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", parallel_train=False)
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
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", parallel_train=False)
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
        return [pipeline.pretrain_stage_inputs(cfg, "ghnerf", {}), pipeline.train_stage_inputs(cfg, "ghnerf", {}, None)]

    assert inputs(2) == inputs(16)


def _record(monkeypatch, calls: list[str], kinds=("pretrain", "train", "export", "quantize", "prior", "eval")):
    """Wrap the stand-in stages so each call appends ``<kind>_<variant>`` to ``calls``."""
    for kind in kinds:
        fn = getattr(pipeline, f"stage_{kind}")

        def wrapped(cfg, *args, _fn=fn, _kind=kind, **kwargs):
            variant = next(iter(args[0])) if isinstance(args[0], dict) else args[0]
            calls.append(f"{_kind}_{variant}")
            return _fn(cfg, *args, **kwargs)
        monkeypatch.setattr(pipeline, f"stage_{kind}", wrapped)


def test_a_pretraining_done_again_trains_the_joint_run_again(tmp_path, stand_ins):
    """The train stage's inputs hold the pretraining's output (``human.pt``'s sha256), not only its config: a
    pretraining made again with the same config (``--force pretrain_ghnerf``, a folder made again) is another
    encoder to start from, and the joint run trained from the old one used to be skipped as up to date."""
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", parallel_train=False)
    pipeline.run(cfg)
    human = pipeline.pretrain_dir(cfg, "ghnerf") / "human.pt"
    human.write_text("another encoder, same config")
    stand_ins.setattr(pipeline, "_pretrain_finished", lambda cfg, v: True)  # (it is taken, and stamped again)
    rows = _rows(cfg)
    assert rows["pretrain_ghnerf"].why.startswith(f"output {human} changed since the stamp")
    assert rows["train_ghnerf"].why.startswith(f"inputs changed: pretrain_outputs.{human} (")
    assert not rows["train_baseline"].runs and not rows["export_baseline"].runs

    stand_ins.setattr(pipeline, "stage_pretrain", lambda cfg, v: ([human], {}))  # the finished one, as it is
    calls: list[str] = []
    _record(stand_ins, calls)
    pipeline.run(cfg)
    assert calls[:2] == ["pretrain_ghnerf", "train_ghnerf"], calls
    assert "train_baseline" not in calls
    assert [s for s, r in _rows(cfg).items() if r.runs] == ["card"]

    # forced: the pretraining trains anew, so the joint run trains after it (--status before run() moves it aside)
    forced = PipelineConfig(out=cfg.out, runs=cfg.runs, parallel_train=False, force=("pretrain_ghnerf",))
    stand_ins.setattr(pipeline, "_pretrain_finished", lambda cfg, v: False)
    rows = _rows(forced)
    assert rows["pretrain_ghnerf"].why == "forced (--force)"
    assert rows["train_ghnerf"].why == (f"it trains in {cfg.runs / 'edge128'} from the new pretraining's human.pt; "
                                        "after pretrain_ghnerf, whose files are its inputs")
    assert rows["export_ghnerf"].why == "after train_ghnerf, whose files are its inputs"
    assert not rows["train_baseline"].runs


def test_a_dataset_made_again_reruns_the_stages_that_read_it(tmp_path, stand_ins):
    """Quantize (calibration scenes) and eval (held-out scenes) read the dataset, not only the checkpoint's files:
    their stamps hold the data stage's too, as the prior's did."""
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", parallel_train=False)
    pipeline.run(cfg)
    stand_ins.setattr(pipeline, "_pretrain_finished", lambda cfg, v: True)  # the runs are taken as they are
    manifest = cfg.out / "data_all.out"
    manifest.write_text("another dataset")
    rows = _rows(cfg)
    assert rows["data"].why.startswith(f"output {manifest} changed since the stamp")
    for stage, after in {"quantize_ghnerf": "data", "prior_ghnerf": "data, quantize_ghnerf",
                         "eval_ghnerf": "data, quantize_ghnerf, prior_ghnerf", "quantize_baseline": "data",
                         "eval_baseline": "data, quantize_baseline"}.items():
        assert rows[stage].why == f"after {after}, whose files are its inputs", (stage, rows[stage])
    assert not rows["export_ghnerf"].runs  # the reused runs' checkpoints are the same

    def data_again(cfg):
        manifest.write_text("the dataset made again")
        return [manifest], {}
    stand_ins.setattr(pipeline, "stage_data", data_again)
    calls: list[str] = []
    _record(stand_ins, calls)
    pipeline.run(cfg)
    assert {"quantize_ghnerf", "prior_ghnerf", "eval_ghnerf", "quantize_baseline", "eval_baseline"} <= set(calls)
    assert not {"export_ghnerf", "export_baseline"} & set(calls), calls


def test_a_joint_run_is_taken_only_with_the_encoder_it_started_from(tmp_path):
    """A run folder records the sha256 of the ``human_init`` it started from (``human_init.sha256``): after a
    pretraining made again the run is not taken as finished, nor resumed; a run without the record is taken on
    trust (as runs without ``dataset.sha256`` are)."""
    torch = pytest.importorskip("torch")
    from training.train import build_config

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    tc = pipeline.train_inputs(cfg, "edge128")
    human = pipeline.Path(tc["human_init"])
    human.parent.mkdir(parents=True)
    human.write_bytes(b"encoder one")
    run = cfg.runs / "edge128"
    pipeline._mark_human_init(run, tc)  # a fresh run: the encoder it starts from
    assert (run / pipeline.HUMAN_MARKER).exists()
    (run / "config.json").write_text(json.dumps(tc))
    (run / "summary.json").write_text(json.dumps({"steps": tc["iterations"], "stopped_early": False}))
    torch.save({"model_config": build_config(tc).model_config().to_dict()}, run / "last.pt")
    assert pipeline._run_finished(cfg, "ghnerf")

    human.write_bytes(b"encoder two")  # the pretraining made again
    pipeline._mark_human_init(run, tc)  # a resume keeps the record: its checkpoint holds the first encoder
    assert not pipeline._run_finished(cfg, "ghnerf")
    with pytest.raises(RuntimeError, match=r"holds a run of another pretraining: it started from another .*human\.pt"
                                           r" \(human_init\.sha256 [0-9a-f]{12}, the file now [0-9a-f]{12}\); "
                                           "--force train_ghnerf sets it aside"):
        pipeline._check_run_folder(cfg, "ghnerf")
    rows = {r.stage: r for r in status(PipelineConfig(out=cfg.out, runs=cfg.runs, data=cfg.data, until="train"))}
    assert rows["data"].why == "no stamp"  # (nothing stamped here: the rest waits; the run is judged above)

    (run / pipeline.HUMAN_MARKER).unlink()  # a run made before the record
    assert pipeline._run_finished(cfg, "ghnerf")


def test_a_pretraining_about_to_run_refuses_a_joint_run_of_an_earlier_one(tmp_path):
    """Before hours of pretraining: the joint run there started from an encoder this pretraining replaces (a run
    made before ``human_init.sha256`` has no record to tell, so the check is made here)."""
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    pipeline._check_pretrain_folder(cfg, "ghnerf")  # no joint run: nothing to refuse
    (cfg.runs / "edge128").mkdir(parents=True)
    (cfg.runs / "edge128" / "last.pt").write_bytes(b"a joint run's checkpoint")
    with pytest.raises(RuntimeError, match=r"edge128 holds a joint run started from an earlier pretraining: .*"
                                           "--force train_ghnerf sets that run aside"):
        pipeline._check_pretrain_folder(cfg, "ghnerf")


def test_a_lane_records_the_encoder_when_the_joint_run_starts(tmp_path, monkeypatch):
    """In the lanes the pretraining runs in an earlier step: the record is of the encoder it left, not of the
    one there when the plan was made."""
    import sys

    from training.model_card import sha256

    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", data=tmp_path / "data")
    human, run = tmp_path / "runs" / "edge128_human" / "human.pt", tmp_path / "runs" / "edge128"
    human.parent.mkdir(parents=True)
    human.write_bytes(b"the encoder before")
    pretrain = [sys.executable, "-c", f"open({str(human)!r}, 'wb').write(b'the new encoder')"]
    plan = [[[pipeline.LaneStep(pretrain, tmp_path / "pretrain.log", run_folder=False),
              pipeline.LaneStep([sys.executable, "-c", "pass"], run / "train.log", run_folder=False,
                                train_config={"human_init": str(human)})]]]
    monkeypatch.setattr(pipeline, "side_by_side_plan", lambda *a: plan)
    pipeline.train_side_by_side(cfg, [])
    assert (run / pipeline.HUMAN_MARKER).read_text().strip() == sha256(human)


def test_status_under_force_says_what_run_sets_aside_first(tmp_path, stand_ins):
    """``run()`` moves a forced stage's folder aside before any stage (``_set_aside_forced``): a forced pretraining
    is made again, not the finished one reused, so the joint run starts from a new encoder, and a joint run folder
    from the earlier one stops ``make model`` unless ``--force train_ghnerf`` sets it aside too. ``--status`` judged
    the folders as they lie (it moves nothing): a forced pretraining read "reused: only its stamp is written
    again" and its joint run as before, ``--force train_ghnerf`` read "the finished run ... is reused", and with
    both forced it said ``make model`` would stop on the joint run's folder."""
    cfg = PipelineConfig(out=tmp_path / "models", runs=tmp_path / "runs", parallel_train=False)
    pipeline.run(cfg)
    stand_ins.setattr(pipeline, "_pretrain_finished", lambda cfg, v: True)  # the finished folder, still there
    joint = cfg.runs / "edge128"
    joint.mkdir(parents=True, exist_ok=True)
    (joint / "last.pt").write_bytes(b"the joint run of the pretraining before")

    def rows(*force):
        return _rows(PipelineConfig(out=cfg.out, runs=cfg.runs, parallel_train=False, force=force))

    new_encoder = f"it trains in {joint} from the new pretraining's human.pt; after pretrain_ghnerf, whose files are its inputs"
    r = rows("pretrain_ghnerf")
    assert r["pretrain_ghnerf"].why == (f"forced (--force); make model stops first: {joint} holds a joint run of an "
                                        "earlier pretraining (--force train_ghnerf sets it aside)")
    assert r["train_ghnerf"].why == new_encoder
    r = rows("pretrain_ghnerf", "train_ghnerf")
    assert r["pretrain_ghnerf"].why == "forced (--force)"
    assert r["train_ghnerf"].why == new_encoder
    r = rows("train_ghnerf")
    assert not r["pretrain_ghnerf"].runs
    assert r["train_ghnerf"].why == "forced (--force)"
    assert r["export_ghnerf"].why == "after train_ghnerf, whose files are its inputs"
