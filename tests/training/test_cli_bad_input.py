"""The training command lines on bad input: a missing dataset or model folder, a file that is no checkpoint, a run
folder in use, an out-of-range number. Each ends with exit status 2 and an error naming the argument or file, never
a traceback, and before anything is written (each of these was a traceback or an exit past the first minutes)."""
from __future__ import annotations

import argparse
import os

import pytest

pytest.importorskip("torch")


def run(main, argv: list[str], capsys) -> tuple[int, str]:
    """``main(argv)``'s exit status (argparse's SystemExit too) and its stderr."""
    capsys.readouterr()
    try:
        rc = main(argv)
    except SystemExit as e:
        rc = e.code
    return rc, capsys.readouterr().err


def one_error_line(err: str) -> str:
    """The error line of ``err`` (argparse's usage lines before it are allowed), with no traceback around it."""
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith(("usage:", " "))]
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def live_other_pid() -> int:
    """A live process that is not this one (the test runner's parent)."""
    pid = os.getppid()
    os.kill(pid, 0)
    return pid


@pytest.mark.parametrize("tool", ["train", "pretrain"])
def test_a_run_folder_held_by_a_live_process_is_one_line_exit_2(tool, data64, tmp_path, capsys, live_other_pid):
    from training.pretrain_human import main as pretrain_main
    from training.train import main as train_main

    out = tmp_path / "run"
    out.mkdir()
    (out / "train.pid").write_text(str(live_other_pid))
    argv = ["--out", str(out), "--data", str(data64), "--iterations", "1", "--resume", "--quiet"]
    main = train_main if tool == "train" else pretrain_main
    rc, err = run(main, [*argv, *(["--preset", "tiny"] if tool == "train" else ["--set", 'preset="tiny"'])], capsys)
    assert rc == 2
    line = one_error_line(err)
    assert f"{out}: another training process ({live_other_pid}) is using this run folder" in line
    assert sorted(p.name for p in out.iterdir()) == ["train.pid"]


def test_pretraining_out_that_is_a_file_and_score_inputs_are_named(data64, tmp_path, capsys):
    from training.pretrain_human import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    rc, err = run(main, ["--out", str(afile), "--set", 'preset="tiny"', "--data", str(data64), "--iterations", "1"],
                  capsys)
    assert rc == 2 and f"{afile}: is a file; --out names the run folder" in one_error_line(err)
    assert afile.read_text() == "x"
    # --score: the option that named the file (not human_init), a missing dataset, a negative scene count
    rc, err = run(main, ["--score", str(tmp_path / "no.pt"), "--data", str(data64)], capsys)
    assert rc == 2 and f"--score: cannot read {tmp_path / 'no.pt'}: no such file" in one_error_line(err)
    rc, err = run(main, ["--score", str(afile), "--data", str(data64), "--split", "nosplit"], capsys)
    assert rc == 2 and "--score: cannot read" in one_error_line(err)
    rc, err = run(main, ["--score", str(tmp_path / "no.pt"), "--scenes", "-1"], capsys)
    assert rc == 2 and "argument --scenes: must be at least 0, got -1" in one_error_line(err)
    rc, err = run(main, ["--out", str(tmp_path / "p"), "--threads", "-1"], capsys)
    assert rc == 2 and "argument --threads: must be at least 0, got -1" in one_error_line(err)
    assert not (tmp_path / "p").exists()


@pytest.mark.parametrize("argv, words", [
    (["--split", "train"], "--split: read only with --score HUMAN_PT; the pretraining's split is its config's"),
    (["--scenes", "4", "--split", "val"], "--split, --scenes: read only with --score HUMAN_PT"),
    (["--score", "PT", "--iterations", "10"], "--iterations: not read with --score HUMAN_PT, which only scores it"),
    (["--score", "PT", "--out", "RUN", "--resume"], "--out, --resume: not read with --score HUMAN_PT"),
    (["--score", "PT", "--set", "lr=1"], "--set: not read with --score HUMAN_PT"),
])
def test_an_option_of_the_other_pretraining_mode_is_refused_before_the_work(argv, words, tmp_path, capsys,
                                                                              monkeypatch):
    """``--out RUN --split train`` pretrained on the config's split (``--split`` is --score's), and ``--score
    HUMAN_PT --iterations 10`` scored the file and trained nothing, each without a word."""
    from training import pretrain_human

    monkeypatch.setattr(pretrain_human, "pretrain", lambda *a, **k: pytest.fail("the pretraining ran"))
    monkeypatch.setattr(pretrain_human, "score_human", lambda *a, **k: pytest.fail("the file was scored"))
    argv = [str(tmp_path / a) if a in ("PT", "RUN") else a for a in argv]
    if "--score" not in argv:
        argv = ["--out", str(tmp_path / "run"), *argv]
    rc, err = run(pretrain_human.main, argv, capsys)
    assert rc == 2 and words in one_error_line(err)
    assert not (tmp_path / "run").exists() and not (tmp_path / "RUN").exists()


def test_pretraining_score_of_a_missing_dataset_is_one_line(data64, tmp_path, capsys):
    from training.pretrain_human import main

    assert main(["--out", str(tmp_path / "a"), "--set", 'preset="tiny"', "--data", str(data64), "--iterations", "1",
                 "--set", "eval_every=0", "--quiet"]) == 0
    rc, err = run(main, ["--score", str(tmp_path / "a" / "human.pt"), "--data", str(tmp_path / "nowhere")], capsys)
    assert rc == 2 and f"{tmp_path / 'nowhere' / 'dataset.json'}: no dataset manifest here" in one_error_line(err)


@pytest.mark.parametrize("more, says", [
    ([], "--model-dir: {model}: no file for graph 'encoder'"),
    (["--steps", "0"], "argument --steps: must be at least 1, got 0"),
    (["--hidden", "0"], "argument --hidden: must be at least 1, got 0"),
    (["--threads", "0"], "argument --threads: must be at least 1, got 0"),
    (["--lr", "-1"], "--lr must be a finite number above 0, not -1.0"),
    (["--lr", "nan"], "--lr must be a finite number above 0, not nan"),
])
def test_skeleton_prior_names_a_model_folder_without_graphs_and_bad_numbers(data64, tmp_path, capsys, more, says):
    from training import skeleton_prior as sp

    model = tmp_path / "ghnerf"
    model.mkdir()
    out = tmp_path / "out" / "prior.onnx"
    rc, err = run(sp.main, ["--model-dir", str(model), "--data", str(data64), "--out", str(out), *more], capsys)
    assert rc == 2 and says.format(model=model) in one_error_line(err)
    assert not out.exists()


@pytest.mark.parametrize("more, says", [
    (["--data", "{tmp}/nowhere"], "{tmp}/nowhere/dataset.json: no dataset manifest here"),
    (["--data", "{tmp}/nowhere", "--truth"], "{tmp}/nowhere/dataset.json: no dataset manifest here"),
    (["--split", "nosplit", "--truth"], "dataset.json: has no split 'nosplit'"),
    (["--model", "{tmp}/empty"], "{tmp}/empty: missing ONNX graphs"),
    (["--model", "{tmp}/empty", "--threads", "0"], "argument --threads: must be at least 1, got 0"),
])
def test_device_joints_names_a_missing_dataset_or_model_folder(data64, tmp_path, capsys, more, says):
    from training.device_joints import main

    (tmp_path / "empty").mkdir()
    argv = ["--data", str(data64), "--out", str(tmp_path / "j.npz"), *(a.format(tmp=tmp_path) for a in more)]
    rc, err = run(main, argv, capsys)
    assert rc == 2 and says.format(tmp=tmp_path) in one_error_line(err)
    assert not (tmp_path / "j.npz").exists()


def test_body_proxy_names_a_missing_dataset_and_a_bad_limit(tmp_path, capsys):
    from training.body_proxy import main

    rc, err = run(main, ["score", "--data", str(tmp_path / "nowhere")], capsys)
    assert rc == 2 and f"{tmp_path / 'nowhere' / 'dataset.json'}: no dataset manifest here" in one_error_line(err)
    rc, err = run(main, ["score", "--data", str(tmp_path), "--limit", "-1"], capsys)
    assert rc == 2 and "argument --limit: must be at least 1, got -1" in one_error_line(err)


def test_convert_norm_names_a_file_that_is_no_checkpoint(tmp_path, capsys):
    from training.convert_norm import main

    junk = tmp_path / "junk.pt"
    junk.write_text("not a checkpoint")
    rc, err = run(main, [str(junk), str(tmp_path / "out.pt")], capsys)
    assert rc == 2 and f"convert_norm: {junk}: not a readable checkpoint (UnpicklingError" in one_error_line(err)
    assert not (tmp_path / "out.pt").exists()


def test_painter_export_names_a_missing_net_or_cache_before_writing(tmp_path, capsys):
    from training.learnt_fill import main

    out = tmp_path / "painter.onnx"
    rc, err = run(main, ["export", "--net", str(tmp_path / "no.pt"), "--out", str(out)], capsys)
    assert rc == 2 and f"{tmp_path / 'no.pt'}: not a fill-net checkpoint" in one_error_line(err)
    assert not out.exists()


@pytest.mark.parametrize("more, says", [
    (["--eval-limit", "-1"], "--eval-limit: must be at least 0 (0: every held-out scene), got -1"),
    (["--threads", "0"], "--threads: must be at least 1, got 0"),
    (["--freestyle-share", "2"], "--freestyle-share: must be a share from 0 to 1, got 2.0"),
    # the train and pretraining configs: checked by the train / pretrain stage, after the dataset was made
    (["--set", "itterations=3"], "itterations: unknown key for TrainConfig"),
    (["--set", "lr=-1"], "lr: must be a positive number, got -1"),
    (["--pretrain-set", "lr=-1"], "pretrain_human.lr: must be a finite number > 0, got -1"),
    (["--pretrain-set", "loader_workers=-2"], "pretrain_human.loader_workers: must be >= 0, got -2"),
    # session 64: refused by the pretrain stage, after the dataset was made
    (["--train", "3", "--pretrain-set", "scenes_per_step=4"],
     "--train 3: fewer scenes than the pretraining's scenes_per_step 4 (each of its steps reads that many train "
     "scenes)"),
])
def test_pipeline_refuses_out_of_range_numbers_before_any_stage(tmp_path, capsys, monkeypatch, more, says):
    """These were used hours in (the eval limit, the export's threads) or raised a traceback from the dataset's
    config after the first stage began."""
    from training import pipeline

    def no_stage(cfg):
        raise AssertionError("the pipeline began its stages")  # (it would generate a 5000-scene dataset)

    monkeypatch.setattr(pipeline, "run", no_stage)
    main = pipeline.main
    argv = ["--out", str(tmp_path / "models"), "--data", str(tmp_path / "data"), "--until", "data", *more]
    rc, err = run(main, argv, capsys)
    assert rc == 2 and says in one_error_line(err)
    assert not (tmp_path / "data").exists() and not (tmp_path / "models").exists()


def test_the_pipeline_s_scene_count_check_is_only_of_a_pretraining_on_its_train_split(tmp_path):
    # --train counts the scenes the data stage makes: a pretraining on another dataset (--pretrain-set data=...)
    # was refused by it all the same (--train 1 under scenes_per_step 2)
    from training import pipeline

    cfg = pipeline.PipelineConfig(out=tmp_path / "models", data=tmp_path / "data", train=1)
    variant = next(v for v in cfg.variants if pipeline.pretrain_block(cfg, v))
    assert "--train 1: fewer scenes than the pretraining's scenes_per_step" in pipeline.pretrain_scene_problem(
        cfg, pipeline.pretrain_inputs(cfg, variant))
    cfg.pretrain_overrides = [f'data="{tmp_path / "elsewhere"}"']
    assert pipeline.pretrain_scene_problem(cfg, pipeline.pretrain_inputs(cfg, variant)) is None
    cfg.pretrain_overrides = ['split="val"']
    assert pipeline.pretrain_scene_problem(cfg, pipeline.pretrain_inputs(cfg, variant)) is None


def test_early_prior_names_a_job_file_it_cannot_read(tmp_path, capsys):
    from training.early_prior import main

    job = tmp_path / "job.json"
    job.write_text("{}")
    rc, err = run(main, [str(job)], capsys)
    assert rc == 2 and f"JOB {job}: not a readable job.json of the pipeline (KeyError" in one_error_line(err)


def test_generate_names_an_out_that_is_a_file(tmp_path, caplog):
    from training.data.generate import main

    afile = tmp_path / "afile"
    afile.write_text("x")
    assert main(["--out", str(afile), "--train", "1", "--val", "0", "--val-seen-motions", "0", "--res", "64",
                 "--workers", "1"]) == 2
    assert f"{afile}: is a file; --out names the dataset folder" in caplog.text
    assert afile.read_text() == "x"


@pytest.mark.parametrize("argv, says", [
    (["score", "--val-cache", "v.npz", "--net", "n.pt", "--device", "tpu"], "argument --device: invalid choice: 'tpu'"),
    (["train", "--train-cache", "t.npz", "--val-cache", "v.npz", "--out", "{tmp}/r", "--device", "tpu"],
     "argument --device: invalid choice: 'tpu'"),
    (["train", "--train-cache", "t.npz", "--val-cache", "v.npz", "--out", "{tmp}/r", "--set", "device=tpu"],
     "--set device: must be auto, cpu or cuda, got tpu"),
])
def test_the_fill_net_device_is_checked_before_anything_is_read(tmp_path, capsys, argv, says):
    """``--device tpu`` was torch's RuntimeError (a traceback) once the caches were loaded."""
    from training.learnt_fill import main

    rc, err = run(main, [a.format(tmp=tmp_path) for a in argv], capsys)
    assert rc == 2 and says in one_error_line(err)


def test_fill_net_device_cuda_without_a_gpu_is_a_usage_error(tmp_path, capsys, monkeypatch):
    import torch

    from training.learnt_fill import main

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    rc, err = run(main, ["score", "--val-cache", "v.npz", "--net", "n.pt", "--device", "cuda"], capsys)
    assert rc == 2 and "--device cuda: torch sees no GPU" in one_error_line(err)


def test_generate_without_a_scene_count_is_a_usage_error_that_writes_nothing(tmp_path, capsys):
    # every count is 0 by default: `--out DATA` alone wrote an empty dataset.json ("nan bytes/sample", exit 0), and
    # the trainer then said the folder had no 'train' split
    from training.data.generate import main

    with pytest.raises(SystemExit) as e:
        main(["--out", str(tmp_path / "data"), "--res", "64"])
    assert e.value.code == 2 and "nothing to generate: give a scene count, --train, --val or --val-seen-motions" \
        in capsys.readouterr().err
    assert not (tmp_path / "data").exists()


@pytest.mark.parametrize("text", ["\u0663", "\uff13", "1_000", "1\uff12"])
def test_a_training_tools_whole_number_is_in_ascii_digits(text, capsys):
    """``at_least`` read with int(), which takes Arabic-Indic '\u0663' and full-width '\uff13' as 3 and '1_000' as
    1000: ``--iterations \u0663`` pretrained three steps. It is refused as 'x' is, naming the option and the value."""
    from training.cli import at_least
    from training.cli.pretrain_human import parse_args

    with pytest.raises(argparse.ArgumentTypeError, match=f"expected an integer, got {text!r}"):
        at_least(0)(text)
    with pytest.raises(SystemExit) as stopped:
        parse_args(["--out", "run", "--iterations", text])
    assert stopped.value.code == 2
    assert f"argument --iterations: expected an integer, got {text!r}" in capsys.readouterr().err
