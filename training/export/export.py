"""Export the model as the contract's ONNX graphs, each stamped with the contract metadata and the weights id
(one per set of weights, the same in every graph: the runtime refuses a folder whose graphs disagree).

Graph split (``ghnerf_runtime.contract`` has the exact input/output specs):

* ``encoder``: batch of source images -> multi-scale features + human features (2D convs: int8).
* ``human``: the same images -> the human encoder's joint heatmaps alone (models with encoder heatmaps):
  the keypoint path without a cost volume runs it and skips the image feature network.
* ``volume``: features + host camera matrices -> regularised cost volume and depth statistics of each
  target frustum (3D convs, sampling, softmax: float).
* ``render`` / ``render_heat`` / ``render_rgb``: per-sample heads + compositing along host-chosen rays
  (everything / heatmaps for the source views / colour for the novel view); head 1x1 convs int8;
  sampling, softmax, compositing float.
* ``query``: heads at arbitrary rig points (volumetric joint heatmaps).

Targets (``B``), rays (``R``) and points (``N``) are dynamic axes; everything else is fixed. The
TorchScript exporter is used (``dynamo=False``): it needs no onnxscript and handles these ops.
"""
from __future__ import annotations

import hashlib
import logging
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import onnx
import torch
from torch import Tensor, nn

from ghnerf_runtime.contract import FRAME_PADDINGS, GRAPH_NAMES, WEIGHTS_ID_KEY, ContractError, GraphSpec, \
    ModelContract, ray_grid
from ghnerf_runtime.session import check_graph_file
from training.export.opsets import DEFAULT_OPSET
from training.model.camera_inputs import box_corners, orbit_camera, scene_inputs, synthetic_rig
from training.model.ghnerf import GHNeRF
from training.model_card import write_atomic

log = logging.getLogger(__name__)


class _GraphModule(nn.Module):
    """Positional-args adapter: contract input order in, contract output order out."""

    def __init__(self, model: GHNeRF, spec: GraphSpec):
        super().__init__()
        self.model = model
        self.spec = spec

    def named(self, args: tuple[Tensor, ...]) -> dict[str, Tensor]:
        return dict(zip(self.spec.input_names, args))

    def enc(self, d: dict[str, Tensor]) -> dict[str, Tensor]:
        return {k: d[k] for k in ("images", "feat_s1", "feat_s2", "feat_s4", "human_feat") if k in d}


class EncoderGraph(_GraphModule):
    def forward(self, images: Tensor):
        enc = self.model.encode(images)
        return tuple(enc[n] for n in self.spec.output_names)


class HumanGraph(_GraphModule):
    def forward(self, images: Tensor):
        return (self.model.encode_human(images),)


class VolumeGraph(_GraphModule):
    def forward(self, *args: Tensor):
        d = self.named(args)
        last = self.model.volumes(self.enc(d), d["src_P"], d["tgt_K_inv"], d["tgt_c2w"], d["near_far"])[-1]
        return last["volume"], last["stats"]


class RenderGraph(_GraphModule):
    def forward(self, *args: Tensor):
        d = self.named(args)
        level = len(self.model.config.levels) - 1
        out = self.model.render(level, self.enc(d), d["volume"], d["depth_stats"], d["src_P"], d["tgt_K_inv"],
                                d["tgt_c2w"], d["ray_uv"], src_centers=d.get("src_centers"),
                                heat="heatmaps" in self.spec.output_names)
        return tuple(out[n] for n in self.spec.output_names)


class QueryGraph(_GraphModule):
    def forward(self, *args: Tensor):
        d = self.named(args)
        out = self.model.query(self.enc(d), d["volume"], d["depth_stats"], d["src_P"], d["tgt_P"], d["points"])
        return out["joint_heat"], out["density"]


GRAPH_MODULES = {"encoder": EncoderGraph, "human": HumanGraph, "volume": VolumeGraph, "render": RenderGraph,
                 "render_heat": RenderGraph, "render_rgb": RenderGraph, "query": QueryGraph}


@dataclass
class ExampleInputs:
    """Consistent example inputs for every graph (torch), from the model itself in eval mode."""

    tensors: dict[str, Tensor]

    def for_graph(self, spec: GraphSpec) -> tuple[Tensor, ...]:
        return tuple(self.tensors[n] for n in spec.input_names)

    def numpy(self, spec: GraphSpec) -> dict[str, np.ndarray]:
        return {n: self.tensors[n].detach().cpu().numpy() for n in spec.input_names}


@torch.no_grad()
def example_inputs(model: GHNeRF, images: Tensor | None = None, targets: int = 2, ray_stride: int | None = None,
                   points: int = 64, seed: int = 0) -> ExampleInputs:
    """Inputs for every graph: a synthetic rig (two sources + novel targets), images, rays, points.

    ``targets`` targets: the two sources first, then novel cameras around the subject.
    """
    cfg = model.config
    H, W = cfg.height, cfg.width
    g = torch.Generator().manual_seed(seed)
    src = synthetic_rig(H, W)
    tgts = (src + [orbit_camera(H, W, 25.0 * (i + 1), name=f"novel{i}") for i in range(max(0, targets - 2))])
    tgts = tgts[:targets]
    cams = {k: torch.from_numpy(v) for k, v in scene_inputs(src, tgts, box_corners(), H, W).items()}
    if images is None:
        images = torch.rand(2, 3, H, W, generator=g)
    stride = ray_stride or cfg.heatmap_stride
    uv = torch.from_numpy(ray_grid(H, W, stride))
    t = {**cams, "images": images, "ray_uv": uv.unsqueeze(0).expand(len(tgts), -1, -1).contiguous()}
    was_training = model.training
    model.eval()
    enc = model.encode(images)
    t.update(enc)
    last = model.volumes(enc, cams["src_P"], cams["tgt_K_inv"], cams["tgt_c2w"], cams["near_far"])[-1]
    t["volume"], t["depth_stats"] = last["volume"], last["stats"]
    centre = torch.tensor([0.0, -0.95, 3.0])
    t["points"] = (centre + torch.rand(len(tgts), points, 3, generator=g) * torch.tensor([0.8, 1.8, 0.8])
                   - torch.tensor([0.4, 0.9, 0.4]))
    model.train(was_training)
    return ExampleInputs(t)


def _dynamic_axes(spec: GraphSpec) -> dict[str, dict[int, str]]:
    axes: dict[str, dict[int, str]] = {}
    for t in spec.inputs + spec.outputs:
        dyn = {i: d for i, d in enumerate(t.shape) if isinstance(d, str)}
        if dyn:
            axes[t.name] = dyn
    return axes


def weights_id(model: nn.Module) -> str:
    """The weights id of ``model`` (``ghnerf_runtime.contract.WEIGHTS_ID_KEY``): the sha256 of its state dict
    (each tensor's name, dtype, shape and bytes, by name), so every graph exported from these weights, in this
    export or a later one, carries the same id, and graphs of other weights another."""
    h = hashlib.sha256()
    for name, tensor in sorted(model.state_dict().items()):
        t = tensor.detach().cpu().contiguous()
        h.update(f"{name}\0{t.dtype}\0{list(t.shape)}\0".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())  # the bytes of any dtype (bf16 has no numpy)
    return h.hexdigest()


def trained_frame_padding(checkpoint: Mapping[str, Any]) -> str:
    """What the model of ``checkpoint`` was shown past a camera's frame in training, as the contract records it
    (``ModelContract.frame_padding``): ``"black"`` when its train config set ``frame_padding`` (a trainer
    checkpoint's ``config``), or as a weights file ``make model`` ships says (its ``frame_padding`` key);
    ``"none"`` for a checkpoint that says neither (trained before the option, or a bare state dict).

    Raises:
        ContractError: naming the key, when the checkpoint holds a value that is not one of these.
    """
    if "frame_padding" in checkpoint:  # the weights file's own record, written by the export stage
        value = checkpoint["frame_padding"]
        if value not in FRAME_PADDINGS:
            raise ContractError(f"expected one of {list(FRAME_PADDINGS)}, got {value!r}", key="frame_padding")
        return value
    config = checkpoint.get("config")
    padded = config.get("frame_padding", False) if isinstance(config, Mapping) else False
    if not isinstance(padded, bool):
        raise ContractError(f"expected true or false, got {padded!r}", key="config.frame_padding")
    return "black" if padded else "none"


def stamp_metadata(path: str | Path, contract: ModelContract, graph: str, precision: str, *,
                   weights_id: str | None, extra: Mapping[str, str] | None = None) -> None:
    """Write the contract and ``weights_id`` (:func:`weights_id`; None: a graph of unknown weights, say a
    quantization of a file exported before there were ids) into ``metadata_props`` of the ONNX file at ``path``
    (in place), with ``extra`` keys (the quantizer's version)."""
    m = onnx.load(str(path))
    # the id first: a copy cut short in the metadata (they end the file) then loses a contract key, which the
    # runtime refuses as a file cut short, before it could lose the id alone and pass for an older export
    props = {**({WEIGHTS_ID_KEY: weights_id} if weights_id is not None else {}),
             **contract.to_metadata(graph=graph, precision=precision), **(extra or {})}
    # an id already in the file (a copied source's) never outlives a restamp, whatever replaces it
    keep = [p for p in m.metadata_props if p.key not in props and p.key != WEIGHTS_ID_KEY]
    del m.metadata_props[:]
    m.metadata_props.extend(keep)
    onnx.helper.set_model_props(m, {**{p.key: p.value for p in keep}, **props})
    m.producer_name = "ghnerf-training"
    m.doc_string = f"GHNeRF graph {graph!r} ({contract.variant}, {contract.width}x{contract.height}, {precision})"
    write_atomic(path, m.SerializeToString())  # a crash here leaves the whole old file, not half a graph


def export_graph(model: GHNeRF, graph: str, path: str | Path, inputs: ExampleInputs | None = None,
                 opset: int = DEFAULT_OPSET, weights: str | None = None, frame_padding: str = "none") -> Path:
    """Export one graph (fp32) to ``path`` with the contract and the weights id stamped in (``weights``: the
    model's :func:`weights_id`, computed here when not given; ``frame_padding``: the contract's, what the
    training crops showed past the frame, :func:`trained_frame_padding`).

    Raises:
        ModelContractError: the file written is one the runtime would refuse (its inputs or outputs differ from
            the contract); the message names the file and the tensor.
    """
    if graph not in GRAPH_NAMES:
        raise ValueError(f"unknown graph {graph!r}; graphs: {GRAPH_NAMES}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    contract = model.contract(opset=opset, frame_padding=frame_padding)
    spec = contract.graph(graph)
    inputs = inputs or example_inputs(model)
    wrapper = GRAPH_MODULES[graph](model, spec).eval()
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # Python branches on shapes (two views, square maps, sample count, map sizes) only read axes that
            # the contract fixes, so the tracer's "might not generalize" warning does not apply; the dynamic
            # axes (targets, rays, points) never reach a Python branch (tested with other B/R/N).
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            warnings.filterwarnings("ignore", message=".*legacy TorchScript-based ONNX export.*")
            warnings.filterwarnings("ignore", message="The feature will be removed.*")
            torch.onnx.export(
                wrapper, inputs.for_graph(spec), str(path), dynamo=False, opset_version=opset,
                input_names=list(spec.input_names), output_names=list(spec.output_names),
                dynamic_axes=_dynamic_axes(spec), do_constant_folding=True,
            )
    finally:
        model.train(was_training)
    stamp_metadata(path, contract, graph, "fp32", weights_id=weights or weights_id(model))
    onnx.checker.check_model(str(path))
    # the runtime's own load checks, here: a graph whose inputs or outputs differ from the contract (a channel
    # count the config states wrongly, a fixed axis the tracer left symbolic) is refused now, naming the file and
    # the tensor, not when a device loads it
    check_graph_file(path, graph, "fp32")
    log.info("exported %s -> %s", graph, path)
    return path


def export_all(model: GHNeRF, out_dir: str | Path, graphs: tuple[str, ...] | None = None,
               opset: int = DEFAULT_OPSET, inputs: ExampleInputs | None = None,
               frame_padding: str = "none") -> dict[str, Path]:
    """Export ``graphs`` (default: every graph of the model's contract) as ``<out_dir>/<graph>.onnx`` (fp32), each
    with the model's :func:`weights_id` and ``frame_padding`` in its contract (:func:`trained_frame_padding`).
    Returns graph -> path."""
    out_dir = Path(out_dir)
    graphs = model.contract(opset=opset).graph_names if graphs is None else graphs
    inputs = inputs or example_inputs(model)
    weights = weights_id(model)
    return {g: export_graph(model, g, out_dir / f"{g}.onnx", inputs, opset, weights, frame_padding) for g in graphs}


__all__ = ["export_all", "export_graph", "example_inputs", "ExampleInputs", "stamp_metadata", "weights_id",
           "trained_frame_padding",
           "GRAPH_MODULES", "DEFAULT_OPSET"]
