"""Static int8 QDQ quantization of the exported graphs (onnxruntime.quantization).

Policy (MODEL.md measurements on a 2-core CPU): dynamic quantization is 5-7x
*slower* than fp32 for convolutions, 3D convolutions are 5x slower in int8, so

* ``encoder``: the 2D Convs (FeatureNet + ResNet18 trunk + projections) -> int8 (activations uint8
  per-tensor, weights int8 per-channel), except the FeatureNet's first full-resolution conv (3 input
  channels: slower in int8 than in fp32 here).
* ``render`` / ``render_heat`` / ``render_rgb`` / ``query``: the hidden head layers, which are 1x1 Convs
  (the model's per-point matrix products) -> int8; each head's output layer stays float so densities and
  logits are not rounded to 8 bits before softplus / sigmoid / softmax. The camera MatMuls (3x3, 3x4 geometry), GridSample,
  softmax / sigmoid, and the compositing (Exp, Log, CumSum) stay float: quantizing geometry would
  move points by whole pixels, and the compositing needs the dynamic range.
* ``volume``: stays float entirely (3D convs, plane sweep, softmax over planes).

Weights are quantized with ``reduce_range`` (7-bit) by default: on AVX2 CPUs without VNNI (this
machine, and typical edge x86) u8s8 products can saturate otherwise.

Calibration: a :class:`FeedsReader` replays input dicts collected by running the float pipeline on
calibration frames (:func:`calibration_feeds`).
"""
from __future__ import annotations

import logging
import re
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
import onnx
from google.protobuf.message import DecodeError
from onnxruntime.quantization import (
    CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process

from ghnerf_runtime.contract import FP32_SHA256_KEY, weights_id_of
from ghnerf_runtime.session import check_graph_file
from training.model_card import sha256

log = logging.getLogger(__name__)


class FeedsReader(CalibrationDataReader):
    """A CalibrationDataReader over a list of ``{input name: array}`` dicts."""

    def __init__(self, feeds: Sequence[dict[str, np.ndarray]]):
        if not feeds:
            raise ValueError("calibration needs at least one feed dict")
        self.feeds = list(feeds)
        self._it = iter(self.feeds)

    def get_next(self) -> dict[str, np.ndarray] | None:
        return next(self._it, None)

    def rewind(self) -> None:
        self._it = iter(self.feeds)


@dataclass
class QuantPolicy:
    """How one graph is quantized (``None`` policy: left float)."""

    op_types: tuple[str, ...] = ("Conv",)
    """Op types given QDQ pairs; everything else stays float."""
    per_channel: bool = True
    reduce_range: bool = True
    """7-bit weights: avoids u8s8 saturation on AVX2 without VNNI."""
    calibrate_method: str = "MinMax"
    """``MinMax``, ``Percentile`` or ``Entropy``."""
    exclude_name_contains: tuple[str, ...] = ()
    """Nodes whose name contains any of these stay float."""
    extra_options: dict = field(default_factory=dict)


#: Last layer of each head: left float so densities, heatmap logits and blend logits reach the
#: softplus / sigmoid / softmax and the compositing at full precision (and they are tiny).
HEAD_OUTPUT_LAYERS = ("/g_sigma/", "/g_h_out/", "/g_c_out/", "/g_co/g_co.2/")

#: Encoder convs left float: the first full-resolution conv reads 3 channels, where int8 QLinearConv
#: measured ~2.5x slower than fp32 on this CPU (0.75 vs 0.29 ms at 128^2 x 2).
ENCODER_FLOAT_LAYERS = ("/feature_net/stage0/stage0.0/",)

#: Raised whenever what the quantizer makes changes in a way :data:`POLICIES` does not show (a pipeline stamp
#: input: 2 since the filter takes a module's later calls, :func:`_name_matcher`).
QUANTIZER_VERSION = 2

#: Metadata key of the :data:`QUANTIZER_VERSION` that made an int8 file (written since version 2; older files
#: are read by their graph, :func:`quantizer_version_of_file`).
QUANTIZER_VERSION_KEY = "ghnerf.quantizer_version"

#: Default policy per graph; ``None`` = stays float.
POLICIES: dict[str, QuantPolicy | None] = {
    "encoder": QuantPolicy(exclude_name_contains=ENCODER_FLOAT_LAYERS),
    "human": QuantPolicy(),
    "volume": None,
    "render": QuantPolicy(exclude_name_contains=HEAD_OUTPUT_LAYERS),
    "render_heat": QuantPolicy(exclude_name_contains=HEAD_OUTPUT_LAYERS),
    "render_rgb": QuantPolicy(exclude_name_contains=HEAD_OUTPUT_LAYERS),
    "query": QuantPolicy(exclude_name_contains=HEAD_OUTPUT_LAYERS),
}


def _name_matcher(parts: Sequence[str]) -> re.Pattern:
    """Node names containing any of ``parts``; a module path ``/m/`` also matches ``/m_1/``, ``/m_2/``..., the
    names the exporter gives the module's later calls (the colour head runs twice in ``render``)."""
    alternatives = [re.escape(p[:-1]) + r"(?:_\d+)?/" if p.startswith("/") and p.endswith("/") else re.escape(p)
                    for p in parts]
    return re.compile("|".join(alternatives) if alternatives else r"(?!)")


def _nodes_to_exclude(model: onnx.ModelProto, policy: QuantPolicy) -> list[str]:
    """Named by the policy, plus every conv whose output a normalisation reduces (``_feeds_a_reduction``)."""
    matcher = _name_matcher(policy.exclude_name_contains)
    named = {n.name for n in model.graph.node if matcher.search(n.name)}
    return [n.name for n in model.graph.node if n.name in named or _feeds_a_reduction(model, n)]


def _feeds_a_reduction(model: onnx.ModelProto, node: onnx.NodeProto) -> bool:
    """A Conv whose output goes into a ReduceMean: the scene normalisation (``SceneNorm2d``) that follows
    it divides by each channel's spread, which would magnify the per-tensor uint8 rounding of its
    quieter channels (the tiny model's ``feat_s4`` drifted 0.55 on a 2.4 range that way); such convs stay float.
    """
    if node.op_type != "Conv":
        return False
    out = set(node.output)
    return any(m.op_type == "ReduceMean" and out & set(m.input) for m in model.graph.node)


def quantize_qdq(fp32_path: str | Path, out_path: str | Path, feeds: Sequence[dict[str, np.ndarray]],
                 policy: QuantPolicy, name: str) -> Path:
    """Static QDQ int8 of one fp32 ONNX file by ``policy``, calibrated on ``feeds``; ``name`` is for the log.
    The metadata is onnxruntime's: the caller stamps its own."""
    fp32_path, out_path = Path(fp32_path), Path(out_path)
    with tempfile.TemporaryDirectory() as tmp:
        pre = Path(tmp) / "pre.onnx"
        try:
            quant_pre_process(str(fp32_path), str(pre), skip_symbolic_shape=False)
        except Exception as e:  # symbolic shape inference can fail on exotic graphs; quantize unprepared
            log.warning("quant_pre_process failed for %s (%s); quantizing the raw graph", name, e)
            shutil.copyfile(fp32_path, pre)
        model = onnx.load(str(pre))
        quantize_static(
            str(pre), str(out_path), FeedsReader(feeds),
            quant_format=QuantFormat.QDQ,
            op_types_to_quantize=list(policy.op_types),
            nodes_to_exclude=_nodes_to_exclude(model, policy),
            per_channel=policy.per_channel,
            reduce_range=policy.reduce_range,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
            calibrate_method=getattr(CalibrationMethod, policy.calibrate_method),
            extra_options=dict(policy.extra_options),
        )
    return out_path


def quantize_graph(fp32_path: str | Path, out_path: str | Path, feeds: Sequence[dict[str, np.ndarray]],
                   policy: QuantPolicy | None, graph: str) -> Path:
    """Quantize one fp32 graph to QDQ int8 (or copy it when ``policy`` is None) and restamp the contract, the
    source's weights id (``ghnerf_runtime.contract.WEIGHTS_ID_KEY``: the int8 file is of the same weights) and the
    source file's sha256 (``ghnerf_runtime.contract.FP32_SHA256_KEY``).

    Raises:
        ModelLoadError, ModelContractError: the source (or the file written) is not a ``graph`` file the runtime
            would load as fp32 (int8); the message names the file (``ghnerf_runtime.session.check_graph_file``).
    """
    from training.export.export import stamp_metadata

    fp32_path, out_path = Path(fp32_path), Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    # the source as the runtime would load it: a truncated file, one without a contract, another graph's or an
    # int8 one is refused naming the file (not a bare protobuf DecodeError, nor an int8 file stamped as this graph)
    contract = check_graph_file(fp32_path, graph, "fp32")
    # (a malformed id was refused by check_graph_file just now)
    weights = weights_id_of({p.key: p.value for p in onnx.load(str(fp32_path)).metadata_props})
    precision = "fp32" if policy is None else "int8"
    if policy is None:
        shutil.copyfile(fp32_path, out_path)
    else:
        quantize_qdq(fp32_path, out_path, feeds, policy, graph)
    # a copied float graph is not the quantizer's making: only int8 files name its version. Both record the bytes
    # they were made from: the runtime's stale-int8 check compares them with the fp32 file beside them.
    made_by = {FP32_SHA256_KEY: sha256(fp32_path)}
    if policy is not None:
        made_by[QUANTIZER_VERSION_KEY] = str(QUANTIZER_VERSION)
    stamp_metadata(out_path, contract, graph, precision, weights_id=weights, extra=made_by)
    check_graph_file(out_path, graph, precision)
    log.info("quantized %s -> %s (%s)", graph, out_path, precision)
    return out_path


def quantizer_version_of_file(path: str | Path) -> int | None:
    """The :data:`QUANTIZER_VERSION` that made the int8 graph at ``path``: its :data:`QUANTIZER_VERSION_KEY`, else
    (a file made before the key) read from the graph, the one thing versions 1 and 2 make differently: version 1
    quantized a head output layer's later calls (``/g_c_out_1/``), version 2 leaves every call float. None: no
    stamp and no later call of a head output layer (both versions make that graph alike), or a float file.

    Raises:
        ValueError: the file is no ONNX model, or its stamp is not a positive integer (the message names the file
            and the value).
    """
    model = _onnx_model(path)
    props = {p.key: p.value for p in model.metadata_props}
    if QUANTIZER_VERSION_KEY in props:
        return _stamped_version(path, props[QUANTIZER_VERSION_KEY])
    later_calls = [n for n in model.graph.node if _LATER_HEAD_CALL.search(n.name)]
    if not later_calls or not any(n.op_type == "DequantizeLinear" for n in model.graph.node):
        return None
    return 1 if any(_reads_int8(model, n) for n in later_calls) else 2


#: A head output layer's second or later call (``/g_c_out_1/Conv``): the nodes version 1 quantized.
_LATER_HEAD_CALL = re.compile("|".join(re.escape(p[:-1]) + r"_\d+/" for p in HEAD_OUTPUT_LAYERS))


def _reads_int8(model: onnx.ModelProto, node: onnx.NodeProto) -> bool:
    """Whether an input of ``node`` is a DequantizeLinear's output (a quantized activation or weight)."""
    dequantized = {o for n in model.graph.node if n.op_type == "DequantizeLinear" for o in n.output}
    return any(i in dequantized for i in node.input)


def _onnx_model(path: str | Path) -> onnx.ModelProto:
    try:
        return onnx.load(str(path), load_external_data=False)
    except DecodeError as e:  # a bare protobuf error would not say which file
        raise ValueError(f"{path}: not an ONNX model ({e})") from e


def _stamped_version(path: str | Path, raw: str) -> int:
    if not (raw.isascii() and raw.isdigit()) or int(raw) < 1:  # "²" is a digit to isdigit, not to int
        raise ValueError(f"{path}: {QUANTIZER_VERSION_KEY} is {raw!r}, not a positive integer")
    return int(raw)


def quantize_all(fp32_paths: dict[str, Path], out_dir: str | Path, feeds: dict[str, list[dict[str, np.ndarray]]],
                 policies: dict[str, QuantPolicy | None] | None = None, suffix: str = ".int8") -> dict[str, Path]:
    """Quantize every graph in ``fp32_paths`` to ``<out_dir>/<graph><suffix>.onnx``."""
    policies = {**POLICIES, **(policies or {})}
    out_dir = Path(out_dir)
    return {g: quantize_graph(p, out_dir / f"{g}{suffix}.onnx", feeds[g], policies.get(g), g)
            for g, p in fp32_paths.items()}


def calibration_feeds(model, frames: Iterable, graphs: Sequence[str], rays_per_target: int | None = None
                      ) -> dict[str, list[dict[str, np.ndarray]]]:
    """Inputs of every graph for each calibration frame, from the float torch model.

    Args:
        model: the :class:`~training.model.ghnerf.GHNeRF` (eval mode is set temporarily).
        frames: items accepted by :func:`training.export.export.example_inputs` as ``images``
            (``(2, 3, H, W)`` RGB [0, 1] tensors), or ready :class:`ExampleInputs`.
        rays_per_target: subsample the rays (calibration cost), default all.
    """
    from training.export.export import ExampleInputs, example_inputs

    contract = model.contract()
    feeds: dict[str, list[dict[str, np.ndarray]]] = {g: [] for g in graphs}
    for i, frame in enumerate(frames):
        ex = frame if isinstance(frame, ExampleInputs) else example_inputs(model, images=frame, seed=i)
        for g in graphs:
            d = ex.numpy(contract.graph(g))
            if rays_per_target and "ray_uv" in d and d["ray_uv"].shape[1] > rays_per_target:
                idx = np.linspace(0, d["ray_uv"].shape[1] - 1, rays_per_target).astype(int)
                d["ray_uv"] = np.ascontiguousarray(d["ray_uv"][:, idx])
            feeds[g].append(d)
    return feeds


__all__ = ["FeedsReader", "QuantPolicy", "POLICIES", "HEAD_OUTPUT_LAYERS", "ENCODER_FLOAT_LAYERS", "quantize_graph",
           "quantize_all", "calibration_feeds", "QUANTIZER_VERSION", "QUANTIZER_VERSION_KEY",
           "quantizer_version_of_file"]
