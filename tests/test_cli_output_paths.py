"""Tools that work for minutes before writing refuse an output path they could not write, before the work.

Each is given a folder where its file goes (or a file where its folder goes) and must stop at once with
exit status 2 and the flag named, not after the work with a traceback (``ready_output``)."""
from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _bench_script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


#: (how to load the tool's main, its arguments with OUT where the bad path goes, the flag named)
TOOLS = [
    (lambda: importlib.import_module("training.evaluate").main, ["--data", "nowhere", "--model", "m.pt", "--out", "OUT"],
     "--out"),
    (lambda: importlib.import_module("training.export.cli").main, ["--preset", "tiny", "--out", "x", "--report", "OUT"],
     "--report"),
    (lambda: importlib.import_module("training.device_joints").main, ["--data", "nowhere", "--out", "OUT"], "--out"),
    (lambda: importlib.import_module("training.learnt_fill").main,
     ["cache", "--data", "nowhere", "--split", "val", "--out", "OUT"], "--out"),
    (lambda: importlib.import_module("training.skeleton_prior").main,
     ["--model-dir", "nowhere", "--data", "nowhere", "--out", "OUT"], "--out"),
    (lambda: _bench_script("compare_3d_methods").main, ["--json", "OUT"], "--json"),
    (lambda: _bench_script("measure_prior_peak_shape").main, ["--data", "nowhere", "--cache", "OUT"], "--cache"),
]


@pytest.mark.parametrize("load, argv, flag", TOOLS, ids=lambda v: v[0] if isinstance(v, list) else None)
def test_a_folder_given_for_the_output_file_is_refused_before_the_work(tmp_path, capsys, load, argv, flag):
    pytest.importorskip("torch")
    bad = tmp_path / "a_folder.npz"  # a folder, named as the file would be (so a .npz suffix changes nothing)
    bad.mkdir()
    with pytest.raises(SystemExit) as e:
        load()([str(bad) if a == "OUT" else a for a in argv])
    assert e.value.code == 2
    assert f"{flag} {bad}: is a folder" in capsys.readouterr().err


def test_learnt_fill_train_refuses_a_file_for_its_folder_before_training(tmp_path, capsys):
    pytest.importorskip("torch")
    from training.learnt_fill import main

    (tmp_path / "f").write_text("")
    with pytest.raises(SystemExit) as e:
        main(["train", "--train-cache", "a.npz", "--val-cache", "b.npz", "--out", str(tmp_path / "f")])
    assert e.value.code == 2 and f"--out {tmp_path / 'f'}: is a file" in capsys.readouterr().err


def test_ghnerf_bench_refuses_its_json_path_before_the_bench(tmp_path, capsys):
    from ghnerf_runtime.cli.bench import main

    (tmp_path / "plain").write_text("")
    bad = tmp_path / "plain" / "r.json"  # its folder would be inside a file
    assert main(["runtime", "--model-dir", str(tmp_path / "no_model"), "--json", str(bad)]) == 2
    err = capsys.readouterr()
    assert f"--json {bad}: cannot make the folder" in err.err and "load average" not in err.out  # nothing ran


def test_a_cache_named_without_npz_is_written_and_found_under_the_name_savez_gives(tmp_path):
    """``--out joints`` used to write ``joints.npz`` and then look for ``joints``."""
    pytest.importorskip("torch")
    from training.data.generate import main as generate
    from training.device_joints import load_joints, main

    data = tmp_path / "d"
    generate(["--out", str(data), "--train", "0", "--val", "2", "--val-seen-motions", "0", "--res", "64",
              "--novel-views", "0", "--workers", "1"])
    assert main(["--data", str(data), "--split", "val", "--truth", "--out", str(tmp_path / "joints")]) == 0
    assert load_joints(tmp_path / "joints.npz").shape == (2, 25, 3)


@pytest.mark.parametrize("tool", ["skeleton_prior", "learnt_fill export"])
def test_a_card_folder_without_a_card_or_not_holding_the_output_is_refused_before_the_work(tmp_path, capsys, tool):
    pytest.importorskip("torch")
    from training import learnt_fill, skeleton_prior

    card = tmp_path / "models"
    card.mkdir()
    if tool == "skeleton_prior":
        run, flag = skeleton_prior.main, "--card"
        argv = ["--model-dir", "nowhere", "--data", "nowhere", "--card", str(card), "--out"]
    else:
        run, flag = learnt_fill.main, "--card-dir"
        argv = ["export", "--net", "nowhere.pt", "--card-dir", str(card), "--out"]
    with pytest.raises(SystemExit):
        run([*argv, str(card / "ghnerf" / "x.onnx")])
    assert f"{flag} {card}: no model_card.json there" in capsys.readouterr().err
    (card / "model_card.json").write_text("{}")
    with pytest.raises(SystemExit):
        run([*argv, str(tmp_path / "elsewhere" / "x.onnx")])
    assert f"{flag} {card}: the output {tmp_path / 'elsewhere' / 'x.onnx'} is not inside" in capsys.readouterr().err


def _model_folder(root: Path) -> Path:
    """A model folder's file names (contents never read here): a graph, and the skeleton prior's graph and settings."""
    root.mkdir(parents=True)
    for name in ("encoder.onnx", "skeleton_prior.onnx", "skeleton_prior.json"):
        (root / name).write_text(f"{name} itself")
    return root


def test_ghnerf_bench_refuses_a_json_report_over_a_model_graph(tmp_path, capsys):
    """``--json models/ghnerf/encoder.onnx`` replaced the graph with the report (session 73's review)."""
    from ghnerf_runtime.cli.bench import main

    models = _model_folder(tmp_path / "m")
    assert main(["runtime", "--model-dir", str(models), "--json", str(models / "encoder.onnx")]) == 2
    err = capsys.readouterr()
    assert f"--json {models / 'encoder.onnx'} is a file of the model folder (--model-dir {models})" in err.err
    assert "load average" not in err.out and (models / "encoder.onnx").read_text() == "encoder.onnx itself"


def test_ghnerf_run_refuses_joints_over_the_model_folder_s_settings(tmp_path, capsys):
    """``--out`` over the skeleton prior's settings (a ``.json`` beside its graph), the folder named by its parent
    (``models`` reads ``models/ghnerf``), was replaced by the joints before the model load failed on it."""
    import cv2
    import numpy as np

    from ghnerf_runtime.cli.run import main

    models = _model_folder(tmp_path / "models" / "ghnerf").parent
    prior = models / "ghnerf" / "skeleton_prior.json"
    images = [str(tmp_path / f"{side}.png") for side in ("l", "r")]
    for path in images:
        cv2.imwrite(path, np.zeros((8, 8, 3), np.uint8))
    rig = Path(__file__).resolve().parents[1] / "docs" / "examples" / "rig.json"
    argv = ["--rig", str(rig), "--images", *images, "--model-dir", str(models), "--out", str(prior)]
    assert main(argv) == 2
    assert f"--out {prior} is a file of the model folder (--model-dir {models})" in capsys.readouterr().err
    assert prior.read_text() == "skeleton_prior.json itself"


def test_a_report_of_the_user_s_own_in_the_model_folder_is_no_model_file(tmp_path):
    from ghnerf_runtime.cli.output_path import is_model_file

    models = _model_folder(tmp_path / "m")
    (models / "bench.json").write_text("{}")
    assert is_model_file(models / "skeleton_prior.json", models) and is_model_file(models / "encoder.onnx", models)
    assert not is_model_file(models / "bench.json", models) and not is_model_file(models / "new.onnx", models)
