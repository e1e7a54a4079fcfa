"""One weights id across a model folder's graphs (``ghnerf.weights_id``): every graph of one export carries the
same, fp32 and int8 alike, and the runtime refuses a folder whose graphs come from two exports (a move into it
cut short by a power cut, a file copied in), which share the contract and used to load as one model."""
from __future__ import annotations

import logging
import re
import shutil

import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from ghnerf_runtime.config import SessionConfig  # noqa: E402
from ghnerf_runtime.contract import WEIGHTS_ID_KEY  # noqa: E402
from ghnerf_runtime.errors import ModelContractError  # noqa: E402
from ghnerf_runtime.session import ModelSession, check_graph_file  # noqa: E402
from training.configs import preset  # noqa: E402
from training.export.export import example_inputs, export_all, weights_id  # noqa: E402
from training.model import GHNeRF  # noqa: E402

GRAPHS = ("encoder", "volume", "render_heat")


def _export(folder, seed):
    torch.manual_seed(seed)
    model = GHNeRF(preset("tiny")).eval()
    export_all(model, folder, graphs=GRAPHS, inputs=example_inputs(model))
    return model


@pytest.fixture(scope="module")
def two_exports(tmp_path_factory):
    """The tiny model exported twice, with other weights (seed 0, seed 1): (folder, model) each."""
    base = tmp_path_factory.mktemp("weights_id")
    return [(base / f"seed{seed}", _export(base / f"seed{seed}", seed)) for seed in (0, 1)]


def _props(path):
    return {p.key: p.value for p in onnx.load(str(path)).metadata_props}


def _set_props(path, edit):
    model = onnx.load(str(path))
    props = edit(_props(path))
    del model.metadata_props[:]
    onnx.helper.set_model_props(model, props)
    onnx.save(model, str(path))


def _load(folder, **kw):
    return ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False, **kw), GRAPHS)


def test_every_graph_of_one_export_carries_its_weights_id_and_another_export_another(two_exports):
    (first, model), (second, other) = two_exports
    ids = [{_props(folder / f"{g}.onnx")[WEIGHTS_ID_KEY] for g in GRAPHS} for folder in (first, second)]
    assert ids == [{weights_id(model)}, {weights_id(other)}] and weights_id(model) != weights_id(other)
    assert re.fullmatch(r"[0-9a-f]{64}", weights_id(model))
    assert _load(first).weights_id == weights_id(model)  # a whole folder loads, its id said
    assert _load(first).describe()["weights_id"] == weights_id(model)


def test_a_folder_holding_a_graph_of_another_export_is_refused_naming_both_files(two_exports, tmp_path):
    """What a power cut in the middle of the move leaves: volume.onnx new, the others old. Same contract, so it
    loaded as one model and gave wrong but plausible joints."""
    (first, model), (second, other) = two_exports
    mixed = shutil.copytree(first, tmp_path / "mixed")
    shutil.copy(second / "volume.onnx", mixed / "volume.onnx")
    with pytest.raises(ModelContractError) as e:
        _load(mixed)
    said = str(e.value)
    assert e.value.key == WEIGHTS_ID_KEY and e.value.path == str(mixed / "volume.onnx")
    assert "volume.onnx" in said and "encoder.onnx" in said and "export the model again" in said
    assert weights_id(other)[:16] in said and weights_id(model)[:16] in said


def test_an_int8_graph_carries_the_id_of_the_fp32_graph_it_was_quantized_from(two_exports, tmp_path):
    from training.export.quantize import POLICIES, calibration_feeds, quantize_graph

    (first, model), (second, other) = two_exports
    feeds = calibration_feeds(model, [torch.rand(2, 3, 64, 64)], ("encoder",))["encoder"]
    folder = shutil.copytree(first, tmp_path / "int8")
    quantize_graph(first / "encoder.onnx", folder / "encoder.int8.onnx", feeds, POLICIES["encoder"], "encoder")
    assert _props(folder / "encoder.int8.onnx")[WEIGHTS_ID_KEY] == weights_id(model)
    s = _load(folder, precision="int8")  # int8 encoder beside the fp32 volume and render_heat: one export
    assert s.precision("encoder") == "int8" and s.weights_id == weights_id(model)
    # quantized from the other export's encoder: not run beside this one's encoder.onnx, which runs instead (session
    # 74: a folder exported before session 73 keeps such files), and refused beside its other graphs without it
    quantize_graph(second / "encoder.onnx", folder / "encoder.int8.onnx", feeds, POLICIES["encoder"], "encoder")
    s = _load(folder, precision="int8")
    assert s.files["encoder"].path.name == "encoder.onnx" and s.weights_id == weights_id(model)
    (folder / "encoder.onnx").unlink()
    with pytest.raises(ModelContractError, match=r"volume\.onnx has weights id .* and encoder\.int8\.onnx "):
        _load(folder, precision="int8")


def test_a_folder_exported_before_weights_ids_loads_as_before(two_exports, tmp_path, caplog):
    """The shipped models/ were exported before the id: their graphs have none and must load unchanged; a folder
    where only some graphs have one loads too (nothing to compare the others with), with a warning naming them."""
    (first, _), (second, _) = two_exports
    legacy = shutil.copytree(first, tmp_path / "legacy")
    for g in GRAPHS:
        _set_props(legacy / f"{g}.onnx", lambda p: {k: v for k, v in p.items() if k != WEIGHTS_ID_KEY})
    assert _load(legacy).weights_id is None
    shutil.copy(second / "volume.onnx", legacy / "volume.onnx")  # one stamped graph among older ones
    with caplog.at_level(logging.WARNING, logger="ghnerf_runtime.session"):
        assert _load(legacy).weights_id is not None
    assert "encoder.onnx, render_heat.onnx carry no weights id" in caplog.text


def test_a_malformed_weights_id_is_refused_naming_the_file_and_key(two_exports, tmp_path):
    (first, _), _ = two_exports
    folder = shutil.copytree(first, tmp_path / "bad")
    _set_props(folder / "volume.onnx", lambda p: {**p, WEIGHTS_ID_KEY: "not-an-id"})
    for load in (lambda: _load(folder), lambda: check_graph_file(folder / "volume.onnx", "volume")):
        with pytest.raises(ModelContractError, match=r"volume\.onnx: ghnerf\.weights_id: expected 64 lowercase hex"):
            load()


def test_the_painter_is_not_part_of_the_check(two_exports, tmp_path):
    """The novel-view painter is another network, exported on its own (training.learnt_fill export): a folder of
    stamped graphs with any painter loads it, by its own metadata."""
    pytest.importorskip("drivers.sim")
    from tests.ghnerf_runtime.test_novel_painter import blend_painter

    (first, model), _ = two_exports
    folder = shutil.copytree(first, tmp_path / "painted")
    blend_painter(folder / "novel_painter.onnx")
    s = ModelSession.load(SessionConfig(model_dir=str(folder), warmup=False), GRAPHS, novel_painter=True)
    assert s.novel_painter is not None and s.weights_id == weights_id(model)


def test_the_graph_hash_leaves_the_weights_id_and_fp32_sha256_out_and_the_adopted_prior_names_the_encoder(tmp_path):
    # the early prior's keypoint graph and the finished export's are one frozen encoder under two weights ids, so
    # int8 files quantized from two fp32 files (ghnerf.fp32_sha256): the pipeline compares them without either, and
    # the prior it adopts must pass the runtime's encoder check
    import onnx
    from onnx import TensorProto, helper

    from ghnerf_runtime.contract import FP32_SHA256_KEY, WEIGHTS_ID_KEY
    from ghnerf_runtime.skeleton_prior import META_PREFIX
    from training.model_card import graph_sha256, sha256
    from training.pipeline import prior_for_folder

    def graph(path, weights, scale=1.0):
        x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
        y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
        k = helper.make_tensor("k", TensorProto.FLOAT, [1], [scale])
        m = helper.make_model(helper.make_graph([helper.make_node("Mul", ["x", "k"], ["y"])], "g", [x], [y], [k]))
        helper.set_model_props(m, {WEIGHTS_ID_KEY: weights, FP32_SHA256_KEY: weights[::-1], "other": "kept"})
        onnx.save(m, str(path))
        return path

    early = graph(tmp_path / "early.onnx", "a" * 64)
    final = graph(tmp_path / "human.int8.onnx", "b" * 64)
    other = graph(tmp_path / "other.onnx", "a" * 64, scale=2.0)
    assert sha256(early) != sha256(final) and graph_sha256(early) == graph_sha256(final)
    assert graph_sha256(other) != graph_sha256(early)  # other weights, same id: still another graph
    (tmp_path / "junk.onnx").write_bytes(b"not a graph")
    assert graph_sha256(tmp_path / "junk.onnx") == sha256(tmp_path / "junk.onnx")

    prior = tmp_path / "prior.onnx"
    graph(prior, "c" * 64)
    m = onnx.load(str(prior))
    helper.set_model_props(m, {META_PREFIX + "encoder_file": "human.int8.onnx",
                               META_PREFIX + "encoder_sha256": sha256(early), "kept": "yes"})
    onnx.save(m, str(prior))
    adopted = onnx.load_from_string(prior_for_folder(prior, tmp_path))
    props = {p.key: p.value for p in adopted.metadata_props}
    assert props[META_PREFIX + "encoder_sha256"] == sha256(final) and props["kept"] == "yes"
    assert props[META_PREFIX + "encoder_file"] == "human.int8.onnx"
