"""Export round trip on the tiny preset: every contract graph, torch vs onnxruntime fp32 parity,
dynamic targets/rays/points, contract metadata, and the ONNX-friendliness rules."""
from __future__ import annotations

import re

import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from ghnerf_runtime.contract import GRAPH_NAMES, ModelContract  # noqa: E402
from training.export.export import example_inputs, export_all  # noqa: E402
from training.export.parity import make_session, torch_vs_ort  # noqa: E402
from training.model import GHNeRF  # noqa: E402

FORBIDDEN_OPS = {"Inverse", "Det", "NonZero", "Loop", "If", "Scan", "SequenceConstruct"}


@pytest.fixture(scope="module")
def exported(tmp_path_factory, tiny_each_norm):
    torch.manual_seed(0)
    model = GHNeRF(tiny_each_norm).eval()
    out = tmp_path_factory.mktemp("onnx")
    paths = export_all(model, out, inputs=example_inputs(model, targets=2))
    return model, paths


def test_every_graph_exported_with_contract(exported):
    model, paths = exported
    assert set(paths) == set(GRAPH_NAMES)
    expected = model.contract()
    for graph, path in paths.items():
        m = onnx.load(str(path))
        props = {p.key: p.value for p in m.metadata_props}
        contract = ModelContract.from_metadata(props)
        assert contract.same_model(expected)
        assert ModelContract.graph_of(props) == graph
        assert props["ghnerf.precision"] == "fp32"
        ops = {n.op_type for n in m.graph.node}
        assert not ops & FORBIDDEN_OPS, f"{graph} uses {ops & FORBIDDEN_OPS}"
        for n in m.graph.node:  # only 4-D GridSample (5-D would need opset >= 20)
            assert n.op_type != "CumProd"
        spec = contract.graph(graph)
        sess = make_session(path)
        contract.check_io(graph, {i.name: i.shape for i in sess.get_inputs()},
                          {o.name: o.shape for o in sess.get_outputs()})


def test_torch_vs_ort_fp32_parity(exported):
    model, paths = exported
    for ex in (example_inputs(model, targets=2), example_inputs(model, targets=3, ray_stride=2, points=33, seed=3)):
        report = torch_vs_ort(model, paths, ex)
        for graph, outputs in report.items():
            for name, st in outputs.items():
                assert st["max_abs"] <= 1e-4 * max(1.0, st["ref_max"]), (graph, name, st)
        # depth is compared on the rays that hit something only (a full make model failed on a ray of
        # opacity ~0, whose depth is a ratio of two roundings). The tiny random model's rays all reach
        # opacity 0.1 on these inputs: a mask that kept none (or few) would compare nothing and pass.
        rays = ex.tensors["ray_uv"].shape[0] * ex.tensors["ray_uv"].shape[1]
        with_depth = [g for g, outputs in report.items() if "depth" in outputs]
        assert {"render", "render_heat", "render_rgb"} <= set(with_depth), report.keys()
        for graph in with_depth:
            st = report[graph]["depth"]
            assert st["min_acc"] == 0.1 and rays // 2 <= st["rays"] <= rays, (graph, st, rays)
            assert st["ref_max"] > 0, (graph, st)  # the compared depths are real ones, not the empty stand-in


def test_the_parity_check_passes_a_good_export_and_stops_a_wrong_one(exported):
    import copy

    from training.export.parity import ParityError, check_fp32_parity

    model, paths = exported
    ex = example_inputs(model, targets=2)
    check_fp32_parity(torch_vs_ort(model, paths, ex))  # the export as made
    wrong = copy.deepcopy(model)
    with torch.no_grad():
        for p in wrong.parameters():
            p.mul_(3.0)  # torch no longer computes what the files hold
    with pytest.raises(ParityError, match=r"\.onnx output '.*': onnxruntime differs from torch"):
        check_fp32_parity(torch_vs_ort(wrong, paths, ex), "m/")


def test_no_inverse_and_static_channel_dims(exported):
    _, paths = exported
    sess = make_session(paths["volume"])
    dims = {i.name: i.shape for i in sess.get_inputs()}
    assert dims["tgt_K_inv"][1:] == [3, 3] and isinstance(dims["tgt_K_inv"][0], str)
    assert dims["src_P"] == [2, 3, 4]


@pytest.mark.parametrize("fault", ["channels", "dynamic_sources"])
def test_an_export_that_differs_from_its_contract_is_refused_at_export(tmp_path, monkeypatch, fault):
    """A graph the runtime would refuse at load (ModelSession's I/O check) is refused by the exporter, naming the
    file and the tensor: a channel count the contract states wrongly, a fixed axis exported symbolic."""
    import training.export.export as export_mod
    from ghnerf_runtime.errors import ModelContractError
    from training.configs import preset

    torch.manual_seed(0)
    model = GHNeRF(preset("tiny")).eval()
    if fault == "channels":  # the contract says 1 more feat_s1 channel than the network makes
        channels = model.channels
        monkeypatch.setattr(model, "channels", lambda: {**channels(), "feat_s1": channels()["feat_s1"] + 1})
        key, what = "feat_s1", r"output shape \[2, 4, 64, 64\] != contract \[2, 5, 64, 64\]"
    else:  # the sources axis (fixed at 2 by the contract) left dynamic
        dynamic = export_mod._dynamic_axes
        monkeypatch.setattr(export_mod, "_dynamic_axes", lambda spec: {**dynamic(spec), "images": {0: "S"}})
        key, what = "images", r"input shape \['S', 3, 64, 64\] != contract \[2, 3, 64, 64\]"
    path = tmp_path / "encoder.onnx"
    with pytest.raises(ModelContractError, match=rf"^{re.escape(str(path))}: {key}: graph 'encoder' {what}") as e:
        export_mod.export_graph(model, "encoder", path)
    assert e.value.key == key and e.value.path == str(path)


def test_the_lowest_opset_the_cli_takes_exports_and_the_one_below_does_not(tmp_path):
    """``training.export.opsets.MIN_OPSET``: the feature sampling is GridSample, in ONNX since opset 16."""
    from training.configs import tiny
    from training.export.export import export_graph
    from training.export.opsets import MIN_OPSET

    torch.manual_seed(0)
    model = GHNeRF(tiny()).eval()
    ex = example_inputs(model, targets=2)
    path = export_graph(model, "volume", tmp_path / "volume.onnx", ex, opset=MIN_OPSET)
    assert {o.domain: o.version for o in onnx.load(str(path)).opset_import}[""] == MIN_OPSET
    with pytest.raises(Exception, match="grid_sampler"):
        export_graph(model, "volume", tmp_path / "below.onnx", ex, opset=MIN_OPSET - 1)


def test_the_export_is_byte_identical_for_the_same_weights(exported, tmp_path):
    """The same model exports to the same bytes (node names, initializers, the contract metadata: no time or path
    stamped), so a stage stamp's sha256 or drop_stale_int8's comparison tells a changed graph from a re-export."""
    model, paths = exported
    again = export_all(model, tmp_path, graphs=("encoder", "render_heat"), inputs=example_inputs(model, targets=2))
    for graph, path in again.items():
        assert path.read_bytes() == paths[graph].read_bytes(), graph
