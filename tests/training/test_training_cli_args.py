"""The training tools' arguments and Ctrl-C (ghnerf-eval, ghnerf-train, python -m training.export): usage errors exit 2
before the work, Ctrl-C exits 130 with a line, never a traceback."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")
from training import evaluate  # noqa: E402
from training.cli import evaluate as evaluate_cli  # noqa: E402
from training.cli.evaluate import ModelItem, split_model_item  # noqa: E402
from training.export.calibration import MIN_FRAMES  # noqa: E402


def test_threads_below_one_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", "m=x.pt", "--threads", "0"])
    assert e.value.code == 2  # was torch's RuntimeError traceback
    assert "--threads: must be at least 1, got 0" in capsys.readouterr().err


def test_threads_past_a_c_int_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", "m=x.pt", "--threads", str(2 ** 31)])
    assert e.value.code == 2  # was torch's "ValueError: Overflow when unpacking long" traceback
    assert f"--threads: must be at most 1024, got {2 ** 31}" in capsys.readouterr().err


def test_an_out_that_is_a_models_checkpoint_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """It was replaced by the scores' JSON once the evaluation had run."""
    monkeypatch.setattr(evaluate, "prepare", lambda *a: pytest.fail("the models were loaded"))
    ckpt = tmp_path / "last.pt"
    ckpt.write_bytes(b"weights")
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", f"a={ckpt}", "--out", str(ckpt)])
    assert e.value.code == 2
    assert f"--out {ckpt} is the file --model a={ckpt} reads" in capsys.readouterr().err
    assert ckpt.read_bytes() == b"weights"


def test_an_out_that_is_a_graph_of_a_model_folder_is_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """``--out m/encoder.int8.onnx`` beside ``--model m#int8`` replaced the graph with the scores (session 73)."""
    monkeypatch.setattr(evaluate, "prepare", lambda *a: pytest.fail("the models were loaded"))
    graph = tmp_path / "m" / "encoder.int8.onnx"
    graph.parent.mkdir()
    graph.write_bytes(b"graph")
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", f"{graph.parent}#int8", "--out", str(graph)])
    assert e.value.code == 2
    assert f"--out {graph} is a file of the model folder (--model {graph.parent}#int8)" in capsys.readouterr().err
    assert graph.read_bytes() == b"graph"


def test_a_model_spec_that_is_a_file_not_named_pt_is_named_as_a_file():
    """A checkpoint saved as ``.pth`` was "no such model folder", as if the file were not there."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        ckpt = Path(d) / "run.pth"
        ckpt.write_bytes(b"weights")
        with pytest.raises(evaluate.EvalInputError, match=rf"^{ckpt}: a file, not a model folder; a checkpoint is "
                                                          r"read by its name ending \.pt"):
            evaluate.make_renderer(str(ckpt))


@pytest.mark.parametrize(("make", "said"), [(lambda p: p.write_text("{}"), "a file, not a model folder"),
                                             (lambda p: None, "no such model folder")])
def test_a_model_spec_that_is_no_model_folder_is_named_by_its_model_item(tmp_path, make, said):
    """``ghnerf-eval --model x=m.json`` said "m.json: a file, not a model folder", naming no option."""
    spec = tmp_path / "m.json"
    make(spec)
    with pytest.raises(evaluate.EvalInputError, match=rf"^--model x={spec}: {spec}: {said}"):
        evaluate.prepare([split_model_item(f"x={spec}")], str(tmp_path), "val", 1)


def _prepared(monkeypatch, items: list[str]) -> list[tuple[str, str]]:
    """``(label, spec)`` that :func:`evaluate.prepare` gives each ``--model`` item, nothing loaded."""
    monkeypatch.setattr(evaluate, "make_renderer", lambda spec, threads: (spec, {}))
    monkeypatch.setattr(evaluate, "open_eval_dataset", lambda *a: None)
    parsed = [split_model_item(item) for item in items]
    return [(label, renderer) for label, renderer, _, _ in evaluate.prepare(parsed, "data", "val", 1)]


def test_a_model_path_holding_an_equals_sign_is_read_whole(tmp_path, monkeypatch):
    """``runs/lr=1e-3/x.pt`` was read as the label ``runs/lr`` and the checkpoint ``1e-3/x.pt``: a label is a name
    (no ``/``), and an item that names a file or folder is that path, whatever it holds."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lr=1e-3").mkdir()
    (tmp_path / "lr=1e-3" / "x.pt").write_bytes(b"weights")
    assert _prepared(monkeypatch, ["runs/lr=1e-3/x.pt", "lr=1e-3/x.pt", "lr=1e-3#int8", "a=b/c.pt",
                                   "y=runs/lr=1e-3/x.pt"]) == [
        ("x", "runs/lr=1e-3/x.pt"), ("x", "lr=1e-3/x.pt"), ("lr=1e-3#int8", "lr=1e-3#int8"), ("a", "b/c.pt"),
        ("y", "runs/lr=1e-3/x.pt")]


def test_an_empty_label_is_a_usage_error_naming_the_item(tmp_path, capsys, monkeypatch):
    """``--model =x.pt`` was scored under the label "" (a JSON key of nothing); a file named ``=x.pt`` there is
    still that file, read whole."""
    from training.cli.evaluate import build_parser, main as cli_main

    monkeypatch.setattr(evaluate, "main", lambda argv: pytest.fail("the evaluation ran"))
    with pytest.raises(SystemExit) as e:
        cli_main(["--data", str(tmp_path), "--model", "=x.pt"])
    assert e.value.code == 2
    assert "argument --model: =x.pt: the LABEL before '=' is empty" in capsys.readouterr().err
    monkeypatch.chdir(tmp_path)
    (tmp_path / "=x.pt").write_bytes(b"weights")
    assert build_parser().parse_args(["--model", "=x.pt"]).model == [ModelItem("=x.pt", None, "=x.pt")]
    assert _prepared(monkeypatch, ["=x.pt"]) == [("=x", "=x.pt")]


def test_an_out_that_is_a_checkpoint_whose_path_holds_an_equals_sign_is_refused(tmp_path, capsys, monkeypatch):
    """The clash check read such a path from its ``=`` on, as the loader did, and let ``--out`` replace it."""
    monkeypatch.setattr(evaluate, "prepare", lambda *a: pytest.fail("the models were loaded"))
    ckpt = tmp_path / "lr=1e-3" / "last.pt"
    ckpt.parent.mkdir()
    ckpt.write_bytes(b"weights")
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", str(ckpt), "--out", str(ckpt)])
    assert e.value.code == 2
    assert f"--out {ckpt} is the file --model {ckpt} reads" in capsys.readouterr().err
    assert ckpt.read_bytes() == b"weights"


def test_each_model_item_is_split_once_from_the_command_line_to_its_renderer(tmp_path, monkeypatch):
    """The parser's check, the labels, the --out clash check and the loading each split the item again (five
    looks at the disk for one ``--model``), any of which could read it otherwise than the parser checked it."""
    looked = []
    monkeypatch.setattr(evaluate_cli, "_names_a_file", lambda item: looked.append(item) or False)
    monkeypatch.setattr(evaluate, "make_renderer", lambda spec, threads: (spec, {"kind": "stand-in"}))
    monkeypatch.setattr(evaluate, "open_eval_dataset", lambda *a: [])
    monkeypatch.setattr(evaluate, "evaluate", lambda *a: {})
    assert evaluate.main(["--data", str(tmp_path), "--model", "a=runs/a.pt", "--out", str(tmp_path / "s.json")]) == 0
    assert looked == ["a=runs/a.pt"]
    assert list(json.loads((tmp_path / "s.json").read_text())["models"]) == ["a"]


def test_two_models_with_one_label_are_refused_before_the_work(tmp_path, capsys, monkeypatch):
    """Two runs' ``last.pt`` are both labelled "last": the second's scores replaced the first's in the JSON."""
    monkeypatch.setattr(evaluate, "prepare", lambda *a: pytest.fail("the models were loaded"))
    with pytest.raises(SystemExit) as e:
        evaluate.main(["--data", str(tmp_path), "--model", "runs/a/last.pt", "--model", "runs/b/last.pt"])
    assert e.value.code == 2
    assert "the label last is given twice" in capsys.readouterr().err


def test_ctrl_c_exits_130_and_keeps_the_models_finished(tmp_path, capsys, monkeypatch):
    runs = [(label, object(), {"kind": "stub"}, None) for label in ("a", "b")]
    monkeypatch.setattr(evaluate, "prepare", lambda *a: runs)
    calls = []

    def scores(renderer, ds, limit, novel):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return {"pck@0.2": 0.5}

    monkeypatch.setattr(evaluate, "evaluate", scores)
    out = tmp_path / "m.json"
    try:
        rc = evaluate.main(["--data", str(tmp_path), "--model", "a=x.pt", "--model", "b=y.pt", "--out", str(out)])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghnerf-eval: the user saw a traceback")
    assert rc == 130
    assert f"stopped (Ctrl-C); models finished: a; {out} holds them" in capsys.readouterr().err
    assert list(json.loads(out.read_text())["models"]) == ["a"]


def test_a_sigterm_stops_eval_with_143_and_a_line_naming_what_out_holds(tmp_path, capsys, monkeypatch):
    """``timeout`` or ``kill``: a real SIGTERM mid-model stops ghnerf-eval as Ctrl-C does (it killed the process
    silently, exit 143 with no word of what --out held)."""
    import signal

    from ghnerf_runtime.cli.sigterm import sigterm_raises
    from tests.sigterm_here import sigterm_here

    runs = [(label, object(), {"kind": "stub"}, None) for label in ("a", "b")]
    monkeypatch.setattr(evaluate, "prepare", lambda *a: runs)
    calls = []

    def scores(renderer, ds, limit, novel):
        calls.append(1)
        if len(calls) == 2:
            sigterm_here("ghnerf-eval runs its models")
        return {"pck@0.2": 0.5}

    monkeypatch.setattr(evaluate, "evaluate", scores)
    out = tmp_path / "m.json"
    rc = evaluate.main(["--data", str(tmp_path), "--model", "a=x.pt", "--model", "b=y.pt", "--out", str(out)])
    assert rc == 143
    assert f"ghnerf-eval: stopped (SIGTERM); models finished: a; {out} holds them" in capsys.readouterr().err
    assert list(json.loads(out.read_text())["models"]) == ["a"]
    assert [p.name for p in tmp_path.iterdir()] == ["m.json"]  # no write_atomic temporary left
    assert signal.getsignal(signal.SIGTERM) is not None and not sigterm_raises()  # the handler before is back


def test_a_stop_inside_the_write_of_out_names_only_the_models_the_file_holds(tmp_path, capsys, monkeypatch):
    """The stop lands in the write of the second model's scores: the file keeps the first model alone, whole, and
    the line says so (it said the file held both)."""
    runs = [(label, object(), {"kind": "stub"}, None) for label in ("a", "b")]
    monkeypatch.setattr(evaluate, "prepare", lambda *a: runs)
    monkeypatch.setattr(evaluate, "evaluate", lambda *a: {"pck@0.2": 0.5})
    real, writes = evaluate.write_atomic, []

    def write_atomic(path, data):
        writes.append(1)
        if len(writes) == 2:
            raise KeyboardInterrupt
        return real(path, data)

    monkeypatch.setattr(evaluate, "write_atomic", write_atomic)
    out = tmp_path / "m.json"
    assert evaluate.main(["--data", str(tmp_path), "--model", "a=x.pt", "--model", "b=y.pt", "--out", str(out)]) == 130
    assert f"stopped (Ctrl-C); models finished: a, b; {out} holds a" in capsys.readouterr().err
    assert list(json.loads(out.read_text())["models"]) == ["a"]


# ------------------------------------------------------------------ ghnerf-train (same kind of checks)
def test_train_refuses_a_file_for_its_run_folder_and_a_missing_init_before_writing(tmp_path, capsys):
    from training.train import main

    (tmp_path / "afile").write_text("")
    assert main(["--preset", "tiny", "--data", str(tmp_path / "data"), "--out", str(tmp_path / "afile")]) == 2
    assert f"{tmp_path / 'afile'}: is a file; --out names the run folder" in capsys.readouterr().err  # was mkdir's
    run = tmp_path / "run"
    assert main(["--preset", "tiny", "--data", str(tmp_path / "data"), "--out", str(run),
                 "--init", str(tmp_path / "resnet18.pth")]) == 2
    assert f"init: {tmp_path / 'resnet18.pth'}: no such file" in capsys.readouterr().err
    assert not run.exists()  # was a FileNotFoundError traceback after run/config.json was written


def _a_training_checkpoint(path):
    """A file shaped as a run's last.pt: weights beside numpy RNG state, which torch's weights-only load refuses."""
    import numpy as np
    import torch

    torch.save({"model": {"w": torch.zeros(2)}, "rng": {"numpy": np.random.get_state()}}, path)
    return path


def _resnet18_file(path, change):
    """torchvision's resnet18 state dict (random, named as torchvision names it), each ``(key, tensor)`` through
    ``change``, saved at ``path``."""
    import torch

    from tests.training.test_resnet18_names import fake_state_dict

    torch.save(dict(change(k, v) for k, v in fake_state_dict().items()), path)
    return path


def _a_list_file(path):
    """A file torch loads that holds no mapping."""
    import torch

    torch.save([1, 2], path)
    return path


@pytest.mark.parametrize(("key", "make", "words"), [
    # a traceback (torch's zip reader) after run/config.json was written
    ("init", lambda p: p.write_bytes(b"PK\x03\x04 cut short") and p,
     "init: {f}: not torchvision resnet18 weights this encoder takes (RuntimeError: "),
    # a traceback: a page of torch's advice on trusting the file, in ANSI bold
    ("init", _a_training_checkpoint,
     "init: {f}: holds more than weights (a training run's last.pt or ckpt_*.pt?); init takes torchvision's"),
    # torch's advice on weights_only, which says nothing of the file, and after run/config.json was written
    ("human_init", lambda p: p.write_text("x") and p,
     "human_init: cannot read {f}: UnpicklingError: not a file torch.save wrote, or a damaged one"),
    ("init", lambda p: p.write_bytes(b"") or p, "init: {f}: not torchvision resnet18 weights this encoder takes "
                                                "(EOFError: the file ends before its first record (empty?))"),
    # torch's strict-load message, cut at 200 characters before the shapes ("torch.Size([64, 3,)") or the key
    ("init", lambda p: _resnet18_file(p, lambda k, v: (k, v[:, :1] if k == "conv1.weight" else v)),
     "init: {f}: not torchvision resnet18 weights this encoder takes ('conv1.weight' has shape [64, 1, 7, 7], "
     "resnet18 [64, 3, 7, 7]); give torchvision's"),
    ("init", lambda p: _resnet18_file(p, lambda k, v: (f"backbone.{k}", v)),
     "init: {f}: not torchvision resnet18 weights this encoder takes (no key 'conv1.weight' and 59 more; "
     "unexpected key 'backbone.conv1.weight' and 121 more)"),
    ("init", _a_list_file,
     "init: {f}: not torchvision resnet18 weights this encoder takes (holds a list, not a state dict)"),
    # one line, but torch's page of advice cut to its first line, and after run/config.json was written
    ("human_init", _a_training_checkpoint,
     "human_init: {f} is not a human-encoder checkpoint (it holds more than weights: a training run's last.pt"),
])
def test_train_refuses_start_weights_that_are_not_such_weights_before_writing(data64, tmp_path, capsys, key, make,
                                                                             words):
    from training.train import main

    weights = make(tmp_path / "weights.pth")
    run = tmp_path / "run"
    assert main(["--preset", "tiny", "--data", str(data64), "--out", str(run), "--iterations", "1",
                 "--set", f"{key}={json.dumps(str(weights))}"]) == 2
    assert words.format(f=weights) in capsys.readouterr().err
    assert not run.exists()


def test_train_refuses_a_human_pt_of_another_encoder_before_writing(data64, tmp_path, capsys):
    import torch

    from training.configs import preset
    from training.model import GHNeRF
    from training.train import main

    other = preset("tiny")
    other.human.num_layers = 3
    human = tmp_path / "human.pt"
    torch.save({"human": GHNeRF(other).human.state_dict(), "model_config": other.to_dict(), "step": 5}, human)
    run = tmp_path / "run"
    assert main(["--preset", "tiny", "--data", str(data64), "--out", str(run), "--iterations", "1",
                 "--set", f"human_init={json.dumps(str(human))}"]) == 2
    assert f"human_init: {human} was pretrained with human.num_layers=3, this model has 2" in capsys.readouterr().err
    assert not run.exists()  # its config.json was written first


@pytest.mark.parametrize("tool", ["training.train", "training.pretrain_human"])
@pytest.mark.parametrize(("make", "words"), [
    (lambda p: p, "model.human.init: {f}: no such file"),
    (lambda p: _resnet18_file(p, lambda k, v: (k, v[:, :1] if k == "conv1.weight" else v)),
     "model.human.init: {f}: not torchvision resnet18 weights this encoder takes ('conv1.weight' has shape "
     "[64, 1, 7, 7], resnet18 [64, 3, 7, 7]); give torchvision's"),
])
def test_a_model_human_init_that_is_not_resnet18_weights_is_named_before_writing(data64, tmp_path, capsys, tool,
                                                                                  make, words):
    """``model.human.init`` (the pretraining's way to start from ImageNet weights) is read as the model is built:
    a missing or foreign file was a traceback (FileNotFoundError, torch's cut load message) after config.json."""
    import importlib

    weights = make(tmp_path / "resnet18.pth")
    run = tmp_path / "run"
    main = importlib.import_module(tool).main
    args = ["--data", str(data64), "--out", str(run), "--iterations", "1", "--set",
            f"model.human.init={json.dumps(str(weights))}"]
    args += ["--preset", "tiny"] if tool == "training.train" else ["--set", 'preset="tiny"', "--set", "eval_every=0"]
    assert main(args) == 2
    assert words.format(f=weights) in capsys.readouterr().err
    assert not run.exists()


def test_train_ctrl_c_exits_130_and_says_how_to_resume(tmp_path, capsys, monkeypatch):
    import training.train as tr

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(tr, "train", interrupted)
    try:
        rc = tr.main(["--preset", "tiny", "--data", str(tmp_path), "--out", str(tmp_path / "run")])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghnerf-train: the user saw a traceback")
    assert rc == 130 and f"`--resume --out {tmp_path / 'run'}` continues" in capsys.readouterr().err


@pytest.mark.parametrize("module", ["training.train", "training.pretrain_human"])
def test_a_sigterm_stops_training_as_ctrl_c_does_with_143_and_how_to_resume(tmp_path, capsys, monkeypatch, module):
    """``timeout``, ``kill`` or a job scheduler's stop: SIGTERM (raised as ``Terminated`` under the command line's
    ``sigterm_as_interrupt``) is named as such and exits 143, the shell's figure; it was reported as a Ctrl-C, and
    outside a test it killed the process silently, leaving its ``.tmp`` checkpoint and ``train.pid``."""
    import importlib

    from ghnerf_runtime.cli.sigterm import Terminated

    tool = importlib.import_module(module)

    def terminated(*a, **k):
        raise Terminated("SIGTERM")

    monkeypatch.setattr(tool, "train" if module == "training.train" else "pretrain", terminated)
    rc = tool.main(["--data", str(tmp_path), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert rc == 143 and "stopped (SIGTERM); `--resume --out" in err and "Ctrl-C" not in err


# ------------------------------------------------------------------ python -m training.export
@pytest.mark.parametrize(("extra", "words"), [
    (["--threads", "0"], "--threads: must be at least 1, got 0"),  # was torch's RuntimeError
    (["--int8", "--calib-frames", "0"], f"--calib-frames: must be at least {MIN_FRAMES}"),  # was after the fp32 export
    # review 51: one random frame passed where --calib-npz wants MIN_FRAMES pairs
    *[(["--int8", "--calib-frames", str(n)], f"--calib-frames: must be at least {MIN_FRAMES} (calibration.MIN_FRAMES, "
                                             f"as for --calib-npz), got {n}") for n in (1, MIN_FRAMES - 1)],
    # MIN_FRAMES itself passes that check and reaches the next one
    (["--calib-frames", str(MIN_FRAMES), "--calib-npz", "x.npz"], "--calib-npz calibrates the int8 graphs"),
    # session 64: a file of 4 frame pairs calibrated on 4 where 16 were asked, without a word; and fp32 alone
    # ignored the count
    (["--int8", "--calib-frames", "16", "--calib-npz", "x.npz"],
     "--calib-frames 16 counts random calibration frames, which --calib-npz replaces with every frame pair of its "
     "file: give one of them"),
    (["--calib-frames", "16"], "--calib-frames counts the int8 graphs' random calibration frames: give --int8"),
    (["--out", "AFILE"], "is a file; give the model folder"),  # was mkdir's FileExistsError
    # was "Unsupported onnx_opset_version: 3" (or grid_sampler unsupported below 16) after loading the model
    (["--opset", "3"], "--opset: must be 16 to 20 (GridSample needs 16; torch's exporter stops at 20), got 3"),
    (["--opset", "15"], "--opset: must be 16 to 20"),
    (["--opset", "24"], "got 24"),
])
def test_export_refuses_bad_values_before_the_export(tmp_path, capsys, extra, words):
    from training.export.cli import main

    (tmp_path / "afile").write_text("")
    extra = [str(tmp_path / "afile") if a == "AFILE" else a for a in extra]
    out = [] if "--out" in extra else ["--out", str(tmp_path / "m")]
    with pytest.raises(SystemExit) as e:
        main(["--preset", "tiny", *out, *extra])
    assert e.value.code == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "m.staging").exists()


@pytest.mark.parametrize("where", ["under a file", "on /proc"])
def test_export_refuses_an_out_whose_folder_cannot_take_it_before_the_export(tmp_path, capsys, where):
    """Was a traceback after the model was built: under a file, one that blamed "a cut-short move" (the staging
    folder's moving.json could not be read), on /proc a FileNotFoundError of OUT.staging."""
    from training.export.cli import main

    if where == "on /proc" and not Path("/proc/self").exists():
        pytest.skip("no /proc here")
    (tmp_path / "afile").write_text("")
    out = tmp_path / "afile" / "m" if where == "under a file" else Path("/proc/ghnerf-no-such-model")
    words = (f"--out {out}: {tmp_path / 'afile'} is a file, not a folder" if where == "under a file" else
             f"--out {out}: the folder /proc is not writable (")
    with pytest.raises(SystemExit) as e:
        main(["--preset", "tiny", "--out", str(out)])
    assert e.value.code == 2 and words in capsys.readouterr().err


@pytest.mark.parametrize("tool", ["export", "eval"])
def test_a_pretraining_s_human_pt_given_as_a_model_is_named_as_such(data64, tmp_path, capsys, tool):
    """The pretraining's human.pt (or its last.pt) given to export or ghnerf-eval was "its weights do not fit its
    model config" and a list of missing tensors."""
    import torch

    from training.configs import preset
    from training.model import GHNeRF

    cfg = preset("tiny")
    human = tmp_path / "human.pt"
    torch.save({"human": GHNeRF(cfg).human.state_dict(), "model_config": cfg.to_dict(), "step": 3}, human)
    words = f"{human}: a human-encoder pretraining checkpoint (the encoder's weights alone, the start of a joint run's"
    if tool == "export":
        from training.export.cli import main

        rc = main(["--checkpoint", str(human), "--out", str(tmp_path / "m")])
    else:
        rc = evaluate.main(["--data", str(data64), "--model", str(human), "--limit", "1", "--no-novel"])
    assert rc == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "m").exists()


@pytest.mark.parametrize("tool", ["export", "eval"])
@pytest.mark.parametrize("bad", [float("nan"), float("inf")])
def test_a_checkpoint_holding_non_finite_weights_is_named_before_the_export(data64, tmp_path, capsys, tool, bad):
    """A diverged run's weights (one NaN) were exported, then quantized into onnxruntime's bare "AssertionError:
    scale issue" (--int8), or refused as "onnxruntime differs from torch by nan: the export is wrong"; ghnerf-eval
    scored them as a model that finds no one."""
    import torch

    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    state = model.state_dict()
    name = next(k for k, v in state.items() if v.is_floating_point() and k.endswith("weight"))
    state[name].view(-1)[0] = bad
    ckpt = tmp_path / "last.pt"
    torch.save({"model": state, "model_config": model.config.to_dict(), "step": 3}, ckpt)
    words = f"{ckpt}: tensor {name!r} holds 1 NaN or infinite value(s) of {state[name].numel()}"
    if tool == "export":
        from training.export.cli import main

        rc = main(["--checkpoint", str(ckpt), "--out", str(tmp_path / "m"), "--int8"])
    else:
        rc = evaluate.main(["--data", str(data64), "--model", str(ckpt), "--limit", "1", "--no-novel"])
    assert rc == 2 and words in capsys.readouterr().err
    assert not (tmp_path / "m").exists() and not (tmp_path / "m.staging").exists()


@pytest.mark.parametrize("precision", ["", "#int8"])
def test_a_model_folder_of_two_exports_is_named_not_scored_as_one_model(tmp_path, precision):
    """A folder whose graphs carry two weights ids (a move into it cut short; the runtime refuses to load it) was
    scored by ghnerf-eval as one model."""
    import onnx
    import torch

    from ghnerf_runtime.contract import WEIGHTS_ID_KEY
    from training.configs import preset
    from training.export.export import example_inputs, export_all
    from training.export.quantize import calibration_feeds, quantize_all
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny")).eval()
    fp32 = export_all(model, tmp_path, graphs=("encoder", "human", "volume", "render_heat", "render_rgb"),
                      inputs=example_inputs(model))
    if precision:
        frames = np.random.default_rng(0).random((4, 2, 3, 64, 64), dtype=np.float32)
        calib = [example_inputs(model, images=torch.from_numpy(f), targets=1, ray_stride=4, seed=i)
                 for i, f in enumerate(frames)]
        quantize_all(fp32, tmp_path, calibration_feeds(model, calib, tuple(fp32), rays_per_target=64))
    evaluate.make_renderer(f"{tmp_path}{precision}")  # one export: taken
    other = tmp_path / ("render_rgb.int8.onnx" if precision else "render_rgb.onnx")
    graph = onnx.load(str(other))
    next(p for p in graph.metadata_props if p.key == WEIGHTS_ID_KEY).value = "0" * 64
    onnx.save(graph, str(other))
    with pytest.raises(evaluate.EvalInputError, match=rf"^{other}: weights id 0{{16}}\.\.\., and \S+ [0-9a-f]{{16}}"
                                                      r"\.\.\.: the graph files come from two different exports"):
        evaluate.make_renderer(f"{tmp_path}{precision}")


def test_the_opset_range_is_what_torch_exports():
    """``training.export.opsets``: 16 needs GridSample (ONNX 16), 20 is the TorchScript exporter's newest here."""
    from torch.onnx import _constants

    from training.export.opsets import DEFAULT_OPSET, MAX_OPSET, MIN_OPSET

    assert MIN_OPSET <= DEFAULT_OPSET <= MAX_OPSET
    assert _constants.ONNX_MIN_OPSET <= MIN_OPSET and MAX_OPSET <= _constants.ONNX_TORCHSCRIPT_EXPORTER_MAX_OPSET


@pytest.mark.parametrize("module", ["training.train", "training.pretrain_human"])
def test_device_cuda_without_a_gpu_is_a_config_error_before_the_run_folder(data64, tmp_path, capsys, monkeypatch,
                                                                           module):
    # was torch's RuntimeError traceback (exit 1): the trainer's from torch.cuda.set_device, the pretraining's
    # when the model moved to the GPU, after its config.json was written
    import importlib

    torch = pytest.importorskip("torch")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    tool = importlib.import_module(module)
    out = tmp_path / "run"
    rc = tool.main(["--data", str(data64), "--out", str(out), "--set", 'preset="tiny"', "--set", 'device="cuda"',
                    "--iterations", "1", "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and "device: 'cuda', but torch sees no CUDA GPU here" in err and "Traceback" not in err, err
    assert not out.exists()
