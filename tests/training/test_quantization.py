"""int8 QDQ round trip on the tiny preset: what is quantized, what stays float, and bounded drift."""
from __future__ import annotations

import collections

import pytest

torch = pytest.importorskip("torch")
onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from ghnerf_runtime.contract import ModelContract  # noqa: E402
from training.configs import preset  # noqa: E402
from training.export.export import example_inputs, export_all  # noqa: E402
from training.export.parity import int8_vs_fp32  # noqa: E402
from training.export.quantize import calibration_feeds, quantize_all  # noqa: E402
from training.model import GHNeRF  # noqa: E402

GRAPHS = ("encoder", "volume", "render_heat", "render_rgb")


@pytest.fixture(scope="module")
def quantized(tmp_path_factory):
    torch.manual_seed(0)
    model = GHNeRF(preset("tiny")).eval()
    out = tmp_path_factory.mktemp("q")
    fp32 = export_all(model, out, graphs=GRAPHS, inputs=example_inputs(model))
    g = torch.Generator().manual_seed(5)
    frames = [torch.rand(2, 3, 64, 64, generator=g) for _ in range(3)]
    feeds = calibration_feeds(model, frames, GRAPHS)
    int8 = quantize_all(fp32, out, feeds)
    return model, fp32, int8


def ops(path):
    return collections.Counter(n.op_type for n in onnx.load(str(path)).graph.node)


def test_quantized_ops(quantized):
    _, fp32, int8 = quantized
    enc = ops(int8["encoder"])
    assert enc["QuantizeLinear"] > 0 and enc["DequantizeLinear"] >= enc["Conv"] > 0
    # the volume graph (3D convs, plane sweep) stays float
    vol = ops(int8["volume"])
    assert vol["QuantizeLinear"] == 0 and vol["Conv"] > 0
    m = onnx.load(str(int8["render_heat"]))
    producers = {o: n for n in m.graph.node for o in n.output}
    for n in m.graph.node:
        if n.op_type in ("MatMul", "GridSample", "CumSum", "Exp", "Log", "Softplus", "Sigmoid"):
            for i in n.input[:2]:
                p = producers.get(i)
                assert p is None or p.op_type != "DequantizeLinear", f"{n.op_type} {n.name} reads int8 data"
    for path in int8.values():
        props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
        ModelContract.from_metadata(props)
    assert {p.key: p.value for p in onnx.load(str(int8["encoder"])).metadata_props}["ghnerf.precision"] == "int8"


def test_int8_drift_is_bounded(quantized):
    model, fp32, int8 = quantized
    report = int8_vs_fp32(fp32, int8, model.contract(), example_inputs(model, seed=11))
    heat = report["pipeline"]["heatmaps"]
    assert heat["max_abs"] < 0.1, report
    assert report["pipeline"]["depth_mean_abs_m"] < 0.05, report
    for graph, outputs in report["graphs"].items():
        for name, st in outputs.items():
            if graph == "volume":
                assert st["max_abs"] == 0.0
            else:
                assert st["max_abs"] <= 0.15 * max(1.0, st["ref_max"]), (graph, name, st)
