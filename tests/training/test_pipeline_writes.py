"""``make model``'s writes: whole stamps and cards, staged exports, stamps that follow the exporter's settings, and
a card stage that keeps the painter's section (no training, no real export: the stages' tools are stand-ins)."""
from __future__ import annotations

import json
import logging
from pathlib import Path
from types import SimpleNamespace

import pytest

import training.pipeline as pipeline
from training.model_card import add_painter_to_card, sha256, write_atomic, write_card
from training.pipeline import PipelineConfig, Stages


# ------------------------------------------------------------------------------------ atomic writes, stamps
def test_a_truncated_stamp_counts_as_not_done_and_is_named_in_the_log(tmp_path, caplog):
    out, calls = tmp_path / "thing.txt", []

    def make():
        calls.append(1)
        out.write_text("made")
        return [out], {}

    Stages(tmp_path, ()).run("export_ghnerf", {"a": 1}, make)
    stamp = tmp_path / ".stages" / "export_ghnerf.json"
    stamp.write_text(stamp.read_text()[:20])  # cut in half by a crash
    caplog.set_level(logging.WARNING, logger="training.pipeline")
    st = Stages(tmp_path, ())
    assert st.stamp("export_ghnerf") is None and st.done("export_ghnerf", {"a": 1}) is None
    assert sum(str(stamp) in r.getMessage() for r in caplog.records) == 1  # named, once for both reads
    assert "export_ghnerf" in caplog.text and "not done" in caplog.text
    st.run("export_ghnerf", {"a": 1}, make)  # runs again, and its new stamp reads
    assert len(calls) == 2 and json.loads(stamp.read_text())["outputs"] == {str(out): sha256(out)}
    stamp.write_text("[1, 2]")  # JSON, but no stamp
    assert Stages(tmp_path, ()).stamp("export_ghnerf") is None
    assert list((tmp_path / ".stages").glob(".*")) == []  # no temporary file left behind


def test_an_atomic_write_that_fails_leaves_the_old_file_whole(tmp_path, monkeypatch):
    import os

    path = tmp_path / "model_card.json"
    write_atomic(path, '{"old": 1}')
    assert oct(path.stat().st_mode & 0o777) == oct(0o666 & ~_umask())  # not mkstemp's 0600

    def no_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", no_replace)
    with pytest.raises(OSError, match="disk full"):
        write_card(tmp_path, {"name": "new"})
    assert path.read_text() == '{"old": 1}' and sorted(p.name for p in tmp_path.iterdir()) == ["model_card.json"]


def _umask() -> int:
    import os

    mask = os.umask(0)
    os.umask(mask)
    return mask


# ----------------------------------------------------------------------------------------- staged export
GRAPHS = ("encoder", "volume")


class _Model:
    config = SimpleNamespace(to_dict=lambda: {"preset": "tiny"}, heatmap_stride=4)

    def state_dict(self):
        return {}

    def contract(self):
        return SimpleNamespace(graph_names=GRAPHS)


def _old_folder(cfg: PipelineConfig) -> tuple[Path, dict[str, bytes]]:
    """The model folder of an earlier export: fp32 and int8 graphs, weights, a prior."""
    folder = cfg.out / "ghnerf"
    folder.mkdir(parents=True)
    old = {"ghnerf.pt": b"old weights", "encoder.onnx": b"old encoder", "encoder.int8.onnx": b"old encoder int8",
           "volume.onnx": b"volume", "volume.int8.onnx": b"volume int8", "skeleton_prior.onnx": b"prior"}
    for name, body in old.items():
        (folder / name).write_bytes(body)
    return folder, old


def _fake_export(monkeypatch, max_abs: float, fail_after: str | None = None, checkpoint: dict | None = None,
                 padded: list | None = None):
    """``stage_export`` with torch's side faked: ``checkpoint`` is what the trained checkpoint holds beside its
    weights (the step alone by default); ``padded`` collects each export's contract ``frame_padding``."""
    import training.export.export as export
    import training.export.parity as parity
    import training.train as train

    def export_all(model, out_dir, inputs=None, frame_padding="none"):
        if padded is not None:
            padded.append(frame_padding)
        paths = {}
        for g in GRAPHS:
            if g == fail_after:
                raise RuntimeError("the exporter crashed")
            paths[g] = Path(out_dir) / f"{g}.onnx"
            paths[g].write_bytes(b"volume" if g == "volume" else b"new encoder")  # the volume graph as it was
        return paths

    monkeypatch.setattr(train, "load_model", lambda ckpt: (_Model(), {"step": 6, **(checkpoint or {})}))
    monkeypatch.setattr(export, "example_inputs", lambda model, **kw: None)
    monkeypatch.setattr(export, "export_all", export_all)
    monkeypatch.setattr(parity, "torch_vs_ort", lambda model, paths, inputs: {
        g: {"out": {"max_abs": max_abs, "ref_max": 1.0}} for g in paths})


def test_a_failed_export_parity_leaves_the_model_folder_as_it_was_and_keeps_the_rejected_files(tmp_path,
                                                                                              monkeypatch, caplog):
    pytest.importorskip("torch")
    from training.export.parity import ParityError

    cfg = PipelineConfig(out=tmp_path / "models")
    folder, old = _old_folder(cfg)
    staging = cfg.out / "ghnerf.staging"
    _fake_export(monkeypatch, max_abs=1.0)
    with pytest.raises(ParityError) as err:
        pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert f"{staging}/encoder.onnx" in str(err.value)
    assert f"{folder} is left as it was; the rejected files are kept in {staging}" in str(err.value)
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == old  # byte for byte
    assert (staging / "encoder.onnx").read_bytes() == b"new encoder" and (staging / "ghnerf.pt").is_file()

    # a crash mid-export: the same, said in the log
    _fake_export(monkeypatch, max_abs=0.0, fail_after="volume")
    with pytest.raises(RuntimeError, match="the exporter crashed"):
        pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == old
    assert f"the rejected files are kept in {staging}" in caplog.text
    assert sorted(p.name for p in staging.iterdir()) == ["encoder.onnx", "ghnerf.pt"]  # this attempt's, not the last

    # passed: moved in, the staging folder gone, the stamp lists the model folder's files
    _fake_export(monkeypatch, max_abs=0.0)
    outputs, info = pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert outputs == [folder / "ghnerf.pt", folder / "encoder.onnx", folder / "volume.onnx"]
    assert not staging.exists() and (folder / "encoder.onnx").read_bytes() == b"new encoder"
    assert info["ghnerf"]["fp32_parity_torch_vs_ort"]["encoder"]["out"]["max_abs"] == 0.0
    # the int8 encoder quantized from the replaced graph went; the unchanged volume graph's stays, as the prior
    assert not (folder / "encoder.int8.onnx").exists()
    assert (folder / "volume.int8.onnx").read_bytes() == b"volume int8"
    assert (folder / "skeleton_prior.onnx").read_bytes() == b"prior"


def test_a_failed_int8_parity_leaves_the_int8_graphs_as_they_were(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    import training.data.torch_dataset as torch_dataset
    import training.export.parity as parity
    import training.export.quantize as quantize
    import training.train as train
    from training.export.parity import ParityError

    cfg = PipelineConfig(out=tmp_path / "models", calib_scenes=1)
    folder, old = _old_folder(cfg)
    staging = cfg.out / "ghnerf.staging"
    got = {}

    def quantize_all(fp32, out_dir, feeds):
        got["fp32"], got["feeds"] = fp32, feeds
        paths = {g: Path(out_dir) / f"{g}.int8.onnx" for g in fp32}
        for g, p in paths.items():
            p.write_bytes(b"new " + g.encode())
        return paths

    def int8_vs_fp32(fp32, int8, contract, inputs):
        return {"graphs": {g: {"out": {"max_abs": 0.0, "mean_abs": 0.0, "ref_max": 1.0}} for g in int8},
                "pipeline": {"heatmaps": {"max_abs": got["heat"]}, "depth_mean_abs_m": 0.0}}

    monkeypatch.setattr(train, "load_model", lambda ckpt: (_Model(), {"step": 6}))
    monkeypatch.setattr(torch_dataset, "MultiViewDataset", lambda *a: [{"scene": 0}])
    monkeypatch.setattr(pipeline, "_scene_inputs", lambda model, item, ray_stride, **kw: ray_stride)
    monkeypatch.setattr(quantize, "calibration_feeds", lambda model, calib, graphs, rays_per_target: rays_per_target)
    monkeypatch.setattr(quantize, "quantize_all", quantize_all)
    monkeypatch.setattr(parity, "int8_vs_fp32", int8_vs_fp32)
    got["heat"] = 1e9
    with pytest.raises(ParityError, match=f"kept in {staging}"):
        pipeline.stage_quantize(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == old
    assert (staging / "encoder.int8.onnx").read_bytes() == b"new encoder"
    assert got["fp32"] == {g: folder / f"{g}.onnx" for g in GRAPHS}  # from the model folder's fp32 graphs
    assert got["feeds"] == pipeline.CALIB_RAYS_PER_TARGET
    got["heat"] = 0.0
    outputs, _ = pipeline.stage_quantize(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert outputs == [folder / "encoder.int8.onnx", folder / "volume.int8.onnx"] and not staging.exists()
    assert (folder / "volume.int8.onnx").read_bytes() == b"new volume"


# --------------------------------------------------------------------------- stamps follow the tools' settings
def test_the_export_and_quantize_stamps_follow_the_exporters_and_quantizers_settings(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    import training.export.export as export
    import training.export.quantize as quantize

    ran = []

    def stage(name):
        def fn(cfg, *a):
            ran.append(name)
            out = cfg.out / f"{name}.out"
            out.write_text(name)  # the same bytes each time: only the stage's own inputs make it run
            return [out], {}
        return fn

    for name in ("data", "train", "export", "quantize", "eval"):
        monkeypatch.setattr(pipeline, f"stage_{name}", stage(name))
    monkeypatch.setattr(pipeline, "_run_finished", lambda cfg, v: True)
    monkeypatch.setattr(pipeline, "train_inputs", lambda cfg, preset: {"preset": preset})
    monkeypatch.setattr(pipeline, "expected_model", lambda cfg, v: {})
    monkeypatch.setattr(pipeline, "pretrain_block", lambda cfg, v: {})
    cfg = PipelineConfig(out=tmp_path / "m", variants=("baseline",))

    def run() -> list[str]:
        ran.clear()
        assert pipeline.run(cfg) is None  # (the card waits for ghnerf)
        return list(ran)

    assert run() == ["data", "train", "export", "quantize", "eval"]
    assert run() == []
    before = pipeline.quantize_settings()
    monkeypatch.setitem(quantize.POLICIES, "render",
                        quantize.QuantPolicy(exclude_name_contains=quantize.HEAD_OUTPUT_LAYERS[:-1]))
    assert pipeline.quantize_settings() != before
    assert run() == ["quantize"]  # (the same int8 bytes: nothing after it)
    monkeypatch.setattr(pipeline, "CALIB_RAYS_PER_TARGET", 1024)
    assert run() == ["quantize"]
    monkeypatch.setattr(export, "DEFAULT_OPSET", export.DEFAULT_OPSET + 1)
    assert run() == ["export"]
    monkeypatch.setattr("ghnerf_runtime.contract.CONTRACT_VERSION", "99.0.0")
    assert run() == ["export"]
    assert run() == []


# ----------------------------------------------------------------------------------- the painter's section
def _card_inputs(cfg: PipelineConfig) -> None:
    """What the card stage reads besides the stamps: each variant's metrics and the dataset's manifest."""
    cfg.data.mkdir(parents=True)
    (cfg.data / "dataset.json").write_text(json.dumps({"resolution": 128, "splits": {"val": {"count": 2}}}))
    for v in pipeline.VARIANTS:
        (cfg.out / v).mkdir(parents=True, exist_ok=True)
        (cfg.out / v / "encoder.onnx").write_bytes(v.encode())
        (cfg.out / f"metrics_{v}.json").write_text(json.dumps({
            "models": {f"{v}_int8": {"kind": "onnx-int8", "scenes": 2, "pck@0.2": 0.5}}, "data": str(cfg.data),
            "split": "val", "pck_alpha": 0.2, "pck_reference": "bbox"}))


def test_the_card_stage_keeps_the_painters_section_while_its_files_are_unchanged(tmp_path, caplog):
    pytest.importorskip("torch")
    cfg = PipelineConfig(out=tmp_path / "models", data=tmp_path / "data", quick=True)
    _card_inputs(cfg)
    st = Stages(cfg.out, ())
    pipeline.stage_card(cfg, st)  # the pipeline's card
    painter = cfg.out / "ghnerf" / "novel_painter.onnx"
    painter.write_bytes(b"painter")
    painter.with_suffix(".int8.onnx").write_bytes(b"painter int8")
    section = {"steps": 100, "held_out": {"all": {"n": 3, "shown": 20.0, "fill:learnt": 21.5}}}
    painter.with_suffix(".json").write_text(json.dumps(section))
    add_painter_to_card(cfg.out, painter, [painter.with_suffix(".int8.onnx")])  # learnt_fill export --card-dir

    pipeline.stage_card(cfg, st)  # the card stage again (it always runs)
    card = json.loads((cfg.out / "model_card.json").read_text())
    assert card["novel_painter"] == {"ghnerf": section}
    assert card["files"]["ghnerf/novel_painter.int8.onnx"]["sha256"] == sha256(painter.with_suffix(".int8.onnx"))
    assert "Novel-view painter (`ghnerf/novel_painter.onnx`)" in (cfg.out / "MODEL_CARD.md").read_text()
    pipeline.stage_card(cfg, st)  # and again: still there
    assert json.loads((cfg.out / "model_card.json").read_text())["novel_painter"] == {"ghnerf": section}

    painter.with_suffix(".int8.onnx").write_bytes(b"another painter int8")  # not the file the figures describe
    caplog.set_level(logging.WARNING, logger="training.pipeline")
    pipeline.stage_card(cfg, st)
    assert "novel_painter" not in json.loads((cfg.out / "model_card.json").read_text())
    assert "Novel-view painter" not in (cfg.out / "MODEL_CARD.md").read_text()
    assert f"{painter.with_suffix('.int8.onnx')} changed or went" in caplog.text


def test_new_graphs_moving_in_set_the_card_aside_until_the_card_stage_writes_it_again(tmp_path, monkeypatch,
                                                                                     caplog):
    pytest.importorskip("torch")
    from training.export.parity import ParityError

    cfg = PipelineConfig(out=tmp_path / "models", data=tmp_path / "data", quick=True)
    folder, old = _old_folder(cfg)
    (folder / "novel_painter.onnx").write_bytes(b"painter")  # learnt_fill's section: kept through the set-aside card
    painter = {"steps": 100}
    recorded = [*old, "novel_painter.onnx"]
    write_card(cfg.out, {"name": "old", "novel_painter": {"ghnerf": painter},
                         "files": {f"ghnerf/{n}": {"sha256": sha256(folder / n)} for n in recorded}})
    (cfg.out / "metrics.json").write_text('{"models": "old"}')
    card, stale = cfg.out / "model_card.json", cfg.out / "model_card.stale.json"
    _fake_export(monkeypatch, max_abs=1.0)
    with pytest.raises(ParityError):
        pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})
    assert card.is_file() and not stale.exists()  # nothing moved in: the card still describes the folder

    _fake_export(monkeypatch, max_abs=0.0)
    caplog.set_level(logging.WARNING)
    pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})  # a later stage may fail: no card may lie meanwhile
    assert not card.exists() and not (cfg.out / "metrics.json").exists() and not (cfg.out / "MODEL_CARD.md").exists()
    assert json.loads(stale.read_text())["name"] == "old" and (cfg.out / "metrics.stale.json").is_file()
    assert f"{card}: set aside as model_card.stale.json" in caplog.text and "ghnerf/encoder.onnx" in caplog.text

    _card_inputs(cfg)
    pipeline.stage_card(cfg, Stages(cfg.out, ()))
    new_card = json.loads(card.read_text())
    assert new_card["files"]["ghnerf/encoder.onnx"]["sha256"] == sha256(folder / "encoder.onnx")
    assert new_card["novel_painter"] == {"ghnerf": painter}
    assert sorted(p.name for p in cfg.out.glob("*.stale*")) == []


@pytest.mark.parametrize("checkpoint, padding", [
    ({"config": {"frame_padding": True, "edge_cut": 0.05}}, "black"),  # edge128.json's recipe: black bands
    ({"config": {"frame_padding": False}}, "none"),
    ({}, "none"),  # a checkpoint of before the option (or a bare state dict): the shipped model's
    ({"frame_padding": "black"}, "black"),  # a weights file the export stage wrote, exported again
])
def test_the_export_stage_records_the_training_padding_in_the_contract_and_the_weights_file(
        tmp_path, monkeypatch, checkpoint, padding):
    """A model trained on black bands past the frame (``TrainConfig.frame_padding``) is exported with
    ``frame_padding "black"`` in its contract, which the runtime's default ``roi.pad_fill`` follows, and its
    weights file keeps it for a later export (``python -m training.export --checkpoint models/ghnerf/ghnerf.pt``)."""
    torch = pytest.importorskip("torch")
    from training.export.export import trained_frame_padding

    cfg = PipelineConfig(out=tmp_path / "models")
    _old_folder(cfg)
    padded: list = []
    _fake_export(monkeypatch, max_abs=0.0, checkpoint=checkpoint, padded=padded)
    pipeline.stage_export(cfg, {"ghnerf": tmp_path / "last.pt"})
    weights = torch.load(cfg.out / "ghnerf" / "ghnerf.pt", weights_only=True)
    assert padded == [padding] and weights["frame_padding"] == padding
    assert trained_frame_padding(weights) == padding


def test_a_checkpoint_padding_of_another_kind_is_refused_by_key():
    pytest.importorskip("torch")
    from ghnerf_runtime.contract import ContractError
    from training.export.export import trained_frame_padding

    for checkpoint, key, shown in (({"frame_padding": "grey"}, "frame_padding", "'grey'"),
                                   ({"config": {"frame_padding": "yes"}}, "config.frame_padding", "'yes'")):
        with pytest.raises(ContractError) as e:
            trained_frame_padding(checkpoint)
        assert e.value.key == key and shown in str(e.value), str(e.value)


# ------------------------------------------------------------------------------------- python -m training.export
def test_the_export_cli_stages_its_graphs_and_moves_them_in_only_after_the_parity_check(tmp_path, monkeypatch,
                                                                                        capsys, caplog):
    pytest.importorskip("torch")
    import training.export.cli as cli

    cfg = PipelineConfig(out=tmp_path / "models")
    folder, old = _old_folder(cfg)  # a live model folder, its card beside it (the shipped layout)
    write_card(cfg.out, {"name": "old", "files": {f"ghnerf/{n}": {"sha256": sha256(folder / n)} for n in old}})
    staging = cfg.out / "ghnerf.staging"
    got = {}

    def export_all(model, out_dir, graphs, opset, inputs, frame_padding):
        assert frame_padding == "none"  # random weights (no --checkpoint): trained on nothing
        paths = {g: Path(out_dir) / f"{g}.onnx" for g in graphs}
        for g, p in paths.items():
            p.write_bytes(b"volume" if g == "volume" else b"new encoder")  # the volume graph as it was
        return paths

    # the CLI imports the torch side after its arguments (fast --help): patched where it is read from
    import training.export.export as export
    import training.export.parity as parity

    monkeypatch.setattr(export, "export_all", export_all)
    monkeypatch.setattr(export, "example_inputs", lambda model, **kw: None)
    monkeypatch.setattr(parity, "torch_vs_ort", lambda model, paths, inputs: {
        g: {"out": {"max_abs": got["max_abs"], "ref_max": 1.0}} for g in paths})
    argv = ["--preset", "tiny", "--graphs", "encoder,volume", "--out", str(folder)]

    got["max_abs"] = 1.0  # onnxruntime strays from torch: rejected
    assert cli.main(argv) == 1
    err = capsys.readouterr().err
    assert f"{staging}/encoder.onnx output 'out'" in err and f"{folder} is left as it was" in err
    assert {p.name: p.read_bytes() for p in folder.iterdir()} == old  # byte for byte
    assert (staging / "encoder.onnx").read_bytes() == b"new encoder" and (cfg.out / "model_card.json").is_file()

    got["max_abs"] = 0.0  # an fp32-only export over a folder with int8 twins
    caplog.set_level(logging.INFO)
    assert cli.main(argv) == 0
    assert (folder / "encoder.onnx").read_bytes() == b"new encoder" and not staging.exists()
    assert not (folder / "encoder.int8.onnx").exists()  # quantized from the replaced graph: "auto" would mix them
    assert (folder / "volume.int8.onnx").read_bytes() == b"volume int8"  # its fp32 graph is unchanged
    assert not (cfg.out / "model_card.json").exists() and (cfg.out / "model_card.stale.json").is_file()
    assert "set aside as model_card.stale.json" in caplog.text


def test_the_export_cli_writes_a_nan_parity_figure_as_null(tmp_path, monkeypatch, capsys):
    """A broken model's NaN parity figure: the report (stdout and --report) is strict JSON, null for NaN; it was
    a bare NaN, which ``jq`` and ``JSON.parse`` refuse."""
    pytest.importorskip("torch")
    import training.export.cli as cli
    import training.export.export as export
    import training.export.parity as parity

    def export_all(model, out_dir, graphs, opset, inputs, frame_padding):
        paths = {g: Path(out_dir) / f"{g}.onnx" for g in graphs}
        for p in paths.values():
            p.write_bytes(b"graph")
        return paths

    monkeypatch.setattr(export, "export_all", export_all)
    monkeypatch.setattr(export, "example_inputs", lambda model, **kw: None)
    monkeypatch.setattr(parity, "torch_vs_ort", lambda model, paths, inputs: {
        g: {"out": {"max_abs": float("nan"), "ref_max": 1.0}} for g in paths})
    report = tmp_path / "report.json"
    assert cli.main(["--preset", "tiny", "--graphs", "encoder", "--out", str(tmp_path / "m"), "--report", str(report),
                     "--no-parity-check"]) == 0

    def refuse(name):
        raise ValueError(f"not strict JSON: {name}")

    for text in (capsys.readouterr().out, report.read_text()):
        assert json.loads(text, parse_constant=refuse)["fp32_parity"]["encoder"]["out"]["max_abs"] is None


def test_the_export_cli_writes_the_checkpoints_training_padding_into_the_contract(tmp_path, capsys):
    """``python -m training.export --checkpoint``: a checkpoint whose train config set ``frame_padding`` gives
    graphs whose contract says "black" (the runtime's unset ``roi.pad_fill`` follows it); a padding record of
    another kind is a usage error naming the file and the key (tiny preset, one graph: real export)."""
    torch = pytest.importorskip("torch")
    import training.export.cli as cli
    from ghnerf_runtime.session import check_graph_file
    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    ckpt = tmp_path / "last.pt"
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "step": 1,
                "config": {"frame_padding": True, "edge_cut": 0.05}}, ckpt)
    out = tmp_path / "m"
    argv = ["--preset", "tiny", "--checkpoint", str(ckpt), "--graphs", "encoder", "--out", str(out)]
    assert cli.main(argv) == 0
    assert check_graph_file(out / "encoder.onnx", "encoder", "fp32").frame_padding == "black"
    assert json.loads(capsys.readouterr().out)["contract"]["frame_padding"] == "black"
    torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "frame_padding": "grey"}, ckpt)
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"{ckpt}: frame_padding:" in err and "'grey'" in err, err


def test_the_export_cli_warns_of_a_checkpoint_whose_run_has_not_finished(tmp_path, capsys, caplog):
    """A checkpoint of a run stopped at step 1 of 6 (Ctrl-C, ``max_minutes``) was exported without a word, its
    graphs in the model folder as if the run had ended; a finished run's and a weights file's are not named."""
    torch = pytest.importorskip("torch")
    import training.export.cli as cli
    from training.configs import preset
    from training.model import GHNeRF

    model = GHNeRF(preset("tiny"))
    ckpt = tmp_path / "last.pt"
    argv = ["--preset", "tiny", "--checkpoint", str(ckpt), "--graphs", "encoder", "--out", str(tmp_path / "m")]
    for step, warned in ((1, True), (6, False)):
        torch.save({"model": model.state_dict(), "model_config": model.config.to_dict(), "step": step,
                    "config": {"iterations": 6}}, ckpt)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="training.export"):
            assert cli.main(argv) == 0
        said = f"{ckpt}: step 1 of its run's 6 iterations: the run has not finished" in caplog.text
        assert said == warned, caplog.text
    assert cli.unfinished_run_words("w.pt", {"model": {}, "step": 3}) is None  # no run recorded: nothing to say
    capsys.readouterr()


def test_the_export_cli_refuses_to_leave_graphs_of_other_weights_beside_its_own(tmp_path, capsys):
    """``--graphs encoder`` of other weights into a folder holding a whole model replaced its encoder and left the
    rest: a folder of two models, which the runtime refuses, its working encoder gone. Refused before anything is
    written, naming the files left; the same weights' encoder goes in."""
    torch = pytest.importorskip("torch")
    import training.export.cli as cli
    from training.configs import preset
    from training.export.export import example_inputs, export_all
    from training.model import GHNeRF

    torch.manual_seed(0)
    shipped = GHNeRF(preset("tiny")).eval()
    out = tmp_path / "m"
    export_all(shipped, out, graphs=("encoder", "volume"), inputs=example_inputs(shipped))
    before = {f.name: sha256(f) for f in out.iterdir()}
    torch.manual_seed(1)
    other = GHNeRF(preset("tiny"))
    for model, status in ((other, 2), (shipped, 0)):
        ckpt = tmp_path / "w.pt"
        torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, ckpt)
        argv = ["--preset", "tiny", "--checkpoint", str(ckpt), "--graphs", "encoder", "--out", str(out)]
        assert cli.main(argv) == status
        if status == 2:
            err = capsys.readouterr().err
            assert f"--out {out}: volume.onnx (weights id " in err and "would hold two models" in err, err
            assert {f.name: sha256(f) for f in out.iterdir()} == before
            assert not (tmp_path / "m.staging").exists()
    assert {f.name: sha256(f) for f in out.iterdir()} == before  # the same weights: the same files
    capsys.readouterr()


def test_the_export_cli_warns_when_it_replaces_another_models_graphs(tmp_path, capsys, caplog):
    """A whole export of other weights into a model's folder replaced that model with one INFO line (``moved 1
    graph(s)``); it is now a warning naming the replaced files and both weights ids. The same weights: no word."""
    torch = pytest.importorskip("torch")
    import training.export.cli as cli
    from training.configs import preset
    from training.export.export import example_inputs, export_all, weights_id
    from training.model import GHNeRF

    torch.manual_seed(0)
    shipped = GHNeRF(preset("tiny")).eval()
    out = tmp_path / "m"
    export_all(shipped, out, graphs=("encoder",), inputs=example_inputs(shipped))
    torch.manual_seed(1)
    other = GHNeRF(preset("tiny"))
    for model, warned in ((shipped, False), (other, True)):
        ckpt = tmp_path / "w.pt"
        torch.save({"model": model.state_dict(), "model_config": model.config.to_dict()}, ckpt)
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="training.export"):
            assert cli.main(["--preset", "tiny", "--checkpoint", str(ckpt), "--graphs", "encoder",
                             "--out", str(out)]) == 0
        said = (f"{out} held another model: its encoder.onnx (weights id {weights_id(shipped)[:16]}...) were "
                f"replaced by this export's (weights id {weights_id(other)[:16]}...)") in caplog.text
        assert said == warned, caplog.text
    capsys.readouterr()


# ----------------------------------------------------------------------------------------- strict JSON
def _strict(text: str):
    """``json.loads`` that refuses the bare NaN / Infinity Python writes and other readers refuse."""
    def refuse(word):
        raise ValueError(f"not JSON: {word}")

    return json.loads(text, parse_constant=refuse)


def test_the_card_and_metrics_json_are_strict_json(tmp_path):
    """``write_card`` wrote a NaN or infinite metric as bare ``NaN`` / ``Infinity`` (``jq`` and browsers refuse the
    file) and a numpy float32 as a string (``default=str``); the card stage's ``metrics.json`` the same."""
    import numpy as np

    pytest.importorskip("torch")
    card = {"metrics": {"m": {"psnr_masked": float("nan"), "best_psnr": float("inf"), "ssim_masked": np.float32(0.5),
                              "pck@0.2": np.float32("nan"), "scenes": np.int64(2), "by_view": np.array([0.5, np.nan]),
                              "kind": "onnx-int8"}},
            "novel_painter": {"ghnerf": {"held_out": {"all": {"n": 3, "shown": float("-inf"), "fill:learnt": 21.5}}}}}
    j, m = write_card(tmp_path, card)
    got = _strict(j.read_text())["metrics"]["m"]
    assert got == {"psnr_masked": None, "best_psnr": None, "ssim_masked": 0.5, "pck@0.2": None, "scenes": 2,
                   "by_view": [0.5, None], "kind": "onnx-int8"}
    # the markdown: n/a, numpy floats too (a float32 NaN printed "nan", 0.5 "0.5")
    assert "| m | onnx-int8 | n/a | n/a | n/a | n/a | 0.500 |" in m.read_text()

    cfg = PipelineConfig(out=tmp_path / "models", data=tmp_path / "data", quick=True)
    _card_inputs(cfg)
    # a variant's metrics file written by an older ghnerf-eval (json.dumps' default: bare NaN)
    (cfg.out / "metrics_baseline.json").write_text(json.dumps({
        "models": {"baseline_int8": {"kind": "onnx-int8", "scenes": 2, "pck@0.2": 0.5, "psnr_masked": float("nan")}},
        "data": str(cfg.data), "split": "val", "pck_alpha": 0.2, "pck_reference": "bbox"}))
    pipeline.stage_card(cfg, Stages(cfg.out, ()))
    assert _strict((cfg.out / "metrics.json").read_text())["models"]["baseline_int8"]["psnr_masked"] is None
    assert _strict((cfg.out / "model_card.json").read_text())["metrics"]["baseline_int8"]["psnr_masked"] is None


def test_the_card_names_the_pck_fallback_reference_and_the_psnr_unit():
    """The card said PCK@0.2 "of the neck--mid-hip distance" only; ``metrics.pck`` takes the torso box's diagonal
    where either is hidden (docs/metrics.md; the design notes ask to write down which)."""
    from training.model_card import render_markdown

    md = render_markdown({"metrics": {"m": {"kind": "onnx-int8", "pck@0.2": 0.5}}})
    assert "(the diagonal of the torso joints' box where the neck or the mid-hip is hidden)" in md
    assert "masked PSNR (dB) / SSIM" in md


def test_the_card_says_which_split_calibrated_the_int8_graphs():
    """The card's int8 rows did not say whether the held-out scenes they are scored on also fixed their activation
    ranges (they do not: the quantize stage calibrates on training scenes)."""
    from training.model_card import render_markdown

    md = render_markdown({"parity": {"ghnerf": {"pipeline": {}}},
                          "calibration": {"ghnerf": {"split": "train", "scenes": 16}, "baseline": None}})
    assert ("int8 calibration (static QDQ activation ranges): ghnerf on 16 scenes of the `train` split (evenly "
            "spaced, `training.pipeline.calibration_items`), none of the held-out scenes scored above.") in md
    assert "baseline on" not in md


def test_int8_calibration_on_a_split_of_fewer_scenes_than_asked_takes_them_all_and_warns(data64, caplog):
    # `--train 8` with the default 16 calib_scenes indexed past the split's end: an IndexError traceback at the
    # quantize stage (and in training.early_prior), after the training had run
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset

    train = MultiViewDataset(data64, "train", TargetConfig())
    with caplog.at_level(logging.WARNING, logger="training.pipeline"):
        items = pipeline.calibration_items(train, 16)
    assert [i for i, _ in items] == [0, 1, 2]
    assert f"{data64}/train holds 3 scene(s), fewer than the 16 asked (calib_scenes)" in caplog.text
    caplog.clear()
    assert [i for i, _ in pipeline.calibration_items(train, 2)] == [0, 1]  # enough scenes: as before, no warning
    assert not caplog.text
