"""The training-to-runtime model contract, written once (torch-free).

The exporter (``training/export``) builds a :class:`ModelContract` from the
model config, stamps it into every ONNX file's ``metadata_props`` with
:meth:`ModelContract.to_metadata`, and the runtime reads it back with
:meth:`ModelContract.from_metadata` and refuses a model whose contract does not
match what it was built for (the error names the metadata key or the tensor).

What the contract fixes
-----------------------
* **Images**: the ``encoder`` graph takes ``images`` ``(S, 3, H, W)`` float32,
  **RGB** channel order (OpenCV frames are BGR: flip them), values in
  ``[0, 1]`` (``uint8 / 255``), undistorted (ideal pinhole with the ``K`` passed
  to the other graphs), resized to the contract resolution. The ImageNet
  mean/std normalisation is applied *inside* the graph (so a torchvision
  ResNet18 state dict applies unchanged); the host must not apply it again.
* **Pixels**: pixel centres at integer coordinates (``Camera.resized`` follows
  it); every ``K`` and every ``ray_uv`` is expressed at the contract
  resolution ``H x W``.
* **Cameras**: the host computes every camera matrix (no matrix inverse runs in
  a graph): see :func:`source_projections`, :func:`target_inputs`,
  :func:`target_projections`, :func:`near_far_from_box`, :func:`ray_grid`.
  Extrinsics map rig points into the camera (``X_cam = R X + t``).
* **Joints**: 25 BODY_25 joints in :data:`ghnerf_runtime.body25.JOINT_NAMES`
  order; heatmaps are sigmoid values in ``[0, 1]`` volume-rendered with the
  colour weights (so a ray that hits nothing has heatmap 0).
* **Background**: rendered colour is composited over ``background`` (black).

Graphs (names are stable API; see ``docs/model.md``)
----------------------------------------------------
``encoder``: ``images`` -> multi-scale image features (+ human features).
``volume``: features + cameras -> regularised cost volume of the *target*
frustum and per-pixel depth statistics. ``render`` / ``render_heat``:
per-sample heads and compositing along host-chosen rays (``render_heat`` skips
colour: use it with the source cameras as targets to get the heatmaps of each
source view; ``render_rgb`` skips heatmaps and the human features: the novel
view). ``query``: the joint heatmap head at arbitrary 3D points
(volumetric heatmaps for 3D joints).

Symbolic dimensions: ``S`` sources (fixed, 2), ``B`` targets, ``R`` rays,
``N`` query points; the exporter leaves ``B``, ``R`` and ``N`` dynamic.
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field, replace
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from ghnerf_runtime.body25 import JOINT_NAMES
from ghnerf_runtime.errors import DepthRangeError, GeometryError, RuntimeErrorBase
from ghnerf_runtime.plain_values import whole_number_or_none

#: Contract format version. A different *major* is refused by :meth:`ModelContract.from_metadata`.
CONTRACT_VERSION = "1.3.0"
"""1.1.0: optional ``encoder_heatmaps`` output of the encoder graph (1.0.0 files read as without it).
1.2.0: optional ``human`` graph (images -> ``encoder_heatmaps`` only; older files read as without it).
1.3.0: optional ``frame_padding`` key (what the training crops showed past a camera's frame; older files read as
``"none"``)."""
#: Prefix of every metadata key the contract writes.
META_PREFIX = "ghnerf."
#: Graph names in pipeline order.
GRAPH_NAMES = ("encoder", "human", "volume", "render", "render_heat", "render_rgb", "query")
#: What a model's training crops showed past a camera's frame (``ModelContract.frame_padding``): ``"none"`` (the
#: crops never reached past it: the shipped model, and every export before contract 1.3.0) or ``"black"`` (zeros,
#: ``TrainConfig.frame_padding``). The runtime's default ``roi.pad_fill`` follows it (``RoiConfig.pad_fill``).
FRAME_PADDINGS = ("none", "black")
#: ImageNet statistics, applied in the encoder graph after ``images`` (RGB, [0, 1]).
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
#: Channels of the ``depth_stats`` tensor, in order.
DEPTH_STATS_CHANNELS = ("mean", "std", "lo", "hi")
#: The farthest a box handed to :func:`near_far_from_box` may reach from the camera (metres, along any of the
#: camera's axes). ``near_far`` is float32: at 1e200 m it overflowed to inf, and past 16384 m the float32 spacing
#: (2 mm) swallows the helper's 1 mm floor between near and far (they came out equal). The shipped graphs are
#: tested finite up to 2e4 m (tests/ghnerf_runtime/test_model_extremes.py); a rig's cameras are at most
#: ``MAX_BASELINE_M`` (10 m) apart, so nothing a rig can see is near this.
MAX_DEPTH_M = 1e4
#: The widest margin (metres) the runtime grows a box by before taking its near/far: the bound of the config's
#: ``tracking.near_far_margin_m``. The rig loader grows the working volume by it, so that a volume it accepts
#: reaches no farther than :data:`MAX_DEPTH_M` however the near/far margin is set.
MAX_NEAR_FAR_MARGIN_M = 2.0
#: The image feature maps a sweep level or the render heads may read (``human_feat`` is a stride's key too).
IMAGE_FEATURES = ("feat_s1", "feat_s2", "feat_s4")
#: Metadata key of the weights id: one value (a sha256, 64 hex digits) in every graph file, fp32 and int8, that
#: one export of one set of weights writes, so that graphs of two exports left in one folder (a move cut short
#: by a power cut, a file copied in by hand) are told apart at load (``ModelSession.load``). Kept out of the
#: contract (:meth:`ModelContract.to_metadata`, :meth:`ModelContract.same_model`): it says which weights, not
#: how to feed them. Files exported before it have none (:func:`weights_id_of`).
WEIGHTS_ID_KEY = META_PREFIX + "weights_id"
_WEIGHTS_ID = re.compile(r"[0-9a-f]{64}")
#: Metadata key of an int8 graph file (``<graph>.int8.onnx``): the sha256 of the bytes of the fp32 file it was
#: quantized from, which the quantizer records. The stale-int8 check (``ModelSession.load``) compares it with the
#: ``<graph>.onnx`` beside it before anything else: a rewritten fp32 file shows, whatever the files' times.
FP32_SHA256_KEY = META_PREFIX + "fp32_sha256"


class ContractError(RuntimeErrorBase, ValueError):
    """The model contract (or a model's metadata) is malformed or does not match.

    ``key`` names the metadata key or tensor that was wrong; the message repeats it.
    """

    def __init__(self, message: str, *, key: str | None = None):
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key


# --------------------------------------------------------------------------- specs
Dim = int | str


@dataclass(frozen=True)
class TensorSpec:
    """One graph input or output: name, shape (ints or symbolic names), dtype, meaning."""

    name: str
    shape: tuple[Dim, ...]
    dtype: str = "float32"
    doc: str = ""

    def to_json(self) -> dict:
        return {"name": self.name, "shape": list(self.shape), "dtype": self.dtype, "doc": self.doc}

    @staticmethod
    def from_json(obj: Any, key: str) -> "TensorSpec":
        try:
            shape = tuple(d if isinstance(d, str) else int(d) for d in obj["shape"])
            return TensorSpec(str(obj["name"]), shape, str(obj.get("dtype", "float32")), str(obj.get("doc", "")))
        except (KeyError, TypeError, ValueError, OverflowError) as e:  # int(inf): OverflowError
            raise ContractError(f"malformed tensor spec {obj!r} ({e})", key=key) from e


@dataclass(frozen=True)
class GraphSpec:
    """Inputs and outputs of one exported graph."""

    name: str
    inputs: tuple[TensorSpec, ...]
    outputs: tuple[TensorSpec, ...]

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.outputs)

    def tensor(self, name: str) -> TensorSpec:
        for t in self.inputs + self.outputs:
            if t.name == name:
                return t
        raise ContractError(f"graph {self.name!r} has no tensor {name!r}", key=name)

    def to_json(self) -> dict:
        return {"name": self.name, "inputs": [t.to_json() for t in self.inputs],
                "outputs": [t.to_json() for t in self.outputs]}

    @staticmethod
    def from_json(obj: Any, key: str) -> "GraphSpec":
        try:
            return GraphSpec(
                str(obj["name"]),
                tuple(TensorSpec.from_json(t, key) for t in obj["inputs"]),
                tuple(TensorSpec.from_json(t, key) for t in obj["outputs"]),
            )
        except (KeyError, TypeError) as e:
            raise ContractError(f"malformed graph spec ({e})", key=key) from e


@dataclass(frozen=True)
class LevelSpec:
    """One level of the coarse-to-fine cascade.

    Attributes:
        volume_stride: cost volume resolution is ``H / volume_stride`` x ``W / volume_stride``.
        planes: depth planes of the cost volume.
        samples: samples per ray when this level is rendered.
        spacing: ``"inverse"`` (planes uniform in 1/z between near and far; level 0) or
            ``"linear"`` (uniform in z between the per-pixel ``lo`` and ``hi`` maps).
        feature: which encoder output the cost volume is built from (``"feat_s4"``...).
        sampling: ``"interval"`` (samples in mean +- k std of the level's depth distribution) or
            ``"planes"`` (the ray samples are the level's planes, spanning ``lo..hi``).
    """

    volume_stride: int
    planes: int
    samples: int
    spacing: str
    feature: str
    sampling: str = "interval"

    def to_json(self) -> dict:
        return {"volume_stride": self.volume_stride, "planes": self.planes, "samples": self.samples,
                "spacing": self.spacing, "feature": self.feature, "sampling": self.sampling}


@dataclass(frozen=True)
class Normalisation:
    """How images enter the ``encoder`` graph."""

    channel_order: str = "RGB"
    value_range: tuple[float, float] = (0.0, 1.0)
    mean: tuple[float, float, float] = IMAGENET_MEAN
    std: tuple[float, float, float] = IMAGENET_STD
    mean_std_in_graph: bool = True

    def to_json(self) -> dict:
        return {"channel_order": self.channel_order, "value_range": list(self.value_range),
                "mean": list(self.mean), "std": list(self.std), "mean_std_in_graph": self.mean_std_in_graph}


# ------------------------------------------------------------------------ contract
@dataclass(frozen=True)
class ModelContract:
    """Everything the runtime must know to feed the graphs and read their outputs.

    Build it with :meth:`build` (the exporter does, from the model config).
    """

    height: int
    width: int
    variant: str  # "ghnerf" (with the human encoder) or "baseline" (ENeRF + heatmap)
    levels: tuple[LevelSpec, ...]
    channels: Mapping[str, int]  # feat_s1, feat_s2, feat_s4, human_feat, volume
    strides: Mapping[str, int]  # encoder output -> stride w.r.t. the input
    render_feature: str = "feat_s1"
    heatmap_stride: int = 4
    num_sources: int = 2
    joint_names: tuple[str, ...] = JOINT_NAMES
    normalisation: Normalisation = field(default_factory=Normalisation)
    background: float = 0.0
    opset: int = 17
    version: str = CONTRACT_VERSION
    model_version: str = "0.1.0"
    graphs: tuple[GraphSpec, ...] = ()
    encoder_heatmaps: bool = False
    """The encoder graph also outputs ``encoder_heatmaps`` ``(S, 25, H / s, W / s)`` (``s`` the
    ``human_feat`` stride): the human encoder's own 2D joint heatmaps of each source image (the
    training-time auxiliary head). A cheaper heatmap source than rendering (docs/runtime.md)."""
    human_graph: bool = False
    """The model has a ``human`` graph: ``images`` -> ``encoder_heatmaps`` alone, the human encoder
    without the image feature network. onnxruntime runs every node of a graph whatever outputs are
    asked for, so a keypoint-only pass that needs no cost volume runs this graph instead of
    ``encoder`` and skips the feature network (docs/runtime.md)."""
    frame_padding: str = "none"
    """What the training crops showed past a camera's frame (:data:`FRAME_PADDINGS`): ``"black"`` for a model
    trained with ``frame_padding`` (it learnt black bands, so the runtime pads its crops black by default),
    ``"none"`` for one whose crops never reached past the frame. Written as ``ghnerf.frame_padding``; a file
    without the key (contract < 1.3.0) reads as ``"none"``."""

    # ------------------------------------------------------------------ build
    @classmethod
    def build(cls, *, height: int, width: int, variant: str, levels: Sequence[LevelSpec],
              channels: Mapping[str, int], strides: Mapping[str, int], **kwargs) -> "ModelContract":
        """A contract with its graph specs derived from the sizes given."""
        contract = cls(height=int(height), width=int(width), variant=variant, levels=tuple(levels),
                       channels=dict(channels), strides=dict(strides), **kwargs)
        contract = replace(contract, graphs=contract._derive_graphs())
        contract.validate()
        return contract

    @property
    def has_human(self) -> bool:
        return self.variant == "ghnerf"

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def graph_names(self) -> tuple[str, ...]:
        """The graphs this model has (the exporter writes one file per graph and precision)."""
        return tuple(g.name for g in self.graphs)

    def graph(self, name: str) -> GraphSpec:
        for g in self.graphs:
            if g.name == name:
                return g
        raise ContractError(f"no graph {name!r}; graphs: {[g.name for g in self.graphs]}", key="graphs")

    def _size(self, key: str) -> tuple[int, int]:
        s = self.strides[key]
        return self.height // s, self.width // s

    def _derive_graphs(self) -> tuple[GraphSpec, ...]:
        S, H, W, J = self.num_sources, self.height, self.width, self.num_joints
        last = self.levels[-1]
        hv, wv = H // last.volume_stride, W // last.volume_stride
        feats = [TensorSpec(k, (S, self.channels[k], *self._size(k)), doc=f"image features at 1/{self.strides[k]}")
                 for k in IMAGE_FEATURES]
        human = ([TensorSpec("human_feat", (S, self.channels["human_feat"], *self._size("human_feat")),
                             doc="pixel-aligned human (ResNet18) features")] if self.has_human else [])
        images = TensorSpec("images", (S, 3, H, W), doc="source images, RGB, [0, 1], undistorted")
        src_P = TensorSpec("src_P", (S, 3, 4), doc="K [R|t] of each source at the contract resolution")
        tgt_K_inv = TensorSpec("tgt_K_inv", ("B", 3, 3), doc="inverse intrinsics of each target")
        tgt_c2w = TensorSpec("tgt_c2w", ("B", 3, 4), doc="[R^T | camera centre] of each target (camera -> rig)")
        near_far = TensorSpec("near_far", ("B", 2), doc="depth range (camera z, metres) of the subject box")
        volume = TensorSpec("volume", ("B", self.channels["volume"], last.planes, hv, wv),
                            doc="regularised feature volume of the last level, target frustum")
        stats = TensorSpec("depth_stats", ("B", 4, hv, wv),
                           doc="per-pixel depth mean, std and plane range lo, hi of the last level (metres)")
        used_feats = sorted({lv.feature for lv in self.levels})
        render_feat = next(f for f in feats if f.name == self.render_feature)
        per_sample_in = [images, render_feat, *human, volume, stats, src_P]
        src_centers = TensorSpec("src_centers", (S, 3), doc="source camera centres (rig)")
        rgb = TensorSpec("rgb", ("B", "R", 3), doc=f"colour, RGB [0, 1], over background {self.background}")
        ray_uv = TensorSpec("ray_uv", ("B", "R", 2), doc="pixel (u, v) of each ray in the target, contract resolution")
        heat = TensorSpec("heatmaps", ("B", "R", J), doc="volume-rendered joint heatmaps, BODY_25 order")
        depth = TensorSpec("depth", ("B", "R"), doc="expected camera depth of each ray (metres)")
        acc = TensorSpec("acc", ("B", "R"), doc="accumulated opacity of each ray")
        enc_heat = ([TensorSpec("encoder_heatmaps", (S, J, *self._size("human_feat")),
                                doc="the human encoder's 2D joint heatmaps of each source (sigmoid), BODY_25 order")]
                    if self.encoder_heatmaps and self.has_human else [])
        human_only = [GraphSpec("human", (images,), tuple(enc_heat))] if self.human_graph and enc_heat else []
        return (
            GraphSpec("encoder", (images,), (*feats, *human, *enc_heat)),
            *human_only,
            GraphSpec("volume", (*[f for f in feats if f.name in used_feats], src_P, tgt_K_inv, tgt_c2w, near_far),
                      (volume, stats)),
            GraphSpec("render", (*per_sample_in, src_centers, tgt_K_inv, tgt_c2w, ray_uv), (rgb, heat, depth, acc)),
            GraphSpec("render_heat", (*per_sample_in, tgt_K_inv, tgt_c2w, ray_uv), (heat, depth, acc)),
            GraphSpec("render_rgb", (images, render_feat, volume, stats, src_P, src_centers, tgt_K_inv, tgt_c2w,
                                     ray_uv), (rgb, depth, acc)),
            GraphSpec("query", (*per_sample_in, TensorSpec("tgt_P", ("B", 3, 4), doc="K [R|t] of the volume's target"),
                                TensorSpec("points", ("B", "N", 3), doc="rig-frame query points (metres)")),
                      (TensorSpec("joint_heat", ("B", "N", J), doc="joint heatmap head at each point (sigmoid)"),
                       TensorSpec("density", ("B", "N"), doc="density at each point (softplus)"))),
        )

    # --------------------------------------------------------------- validate
    def validate(self) -> None:
        """Raise :class:`ContractError` (naming the key) unless the contract is self-consistent."""
        def fail(key: str, msg: str) -> None:
            raise ContractError(msg, key=META_PREFIX + key)

        if self.version.split(".")[0] != CONTRACT_VERSION.split(".")[0]:
            fail("contract_version", f"contract version {self.version} is incompatible with {CONTRACT_VERSION}")
        if not (64 <= self.height <= 256 and 64 <= self.width <= 256):
            fail("resolution", f"resolution must be within 64..256, got {self.width}x{self.height}")
        if self.variant not in ("ghnerf", "baseline"):
            fail("variant", f"variant must be 'ghnerf' or 'baseline', got {self.variant!r}")
        if tuple(self.joint_names) != JOINT_NAMES:
            # the count first: a model of other joints fails here, at load, not in a sink's worker (the joint
            # stream carries at most 64 per packet) or in the BODY_25 post-processing
            fail("joint_names", f"the runtime takes BODY_25's {len(JOINT_NAMES)} joints, in OpenPose order "
                                f"{list(JOINT_NAMES)}; this model has {len(self.joint_names)}: "
                                f"{list(self.joint_names)}")
        if self.num_sources != 2:
            fail("num_sources", f"the runtime feeds exactly 2 source views, got {self.num_sources}")
        n = self.normalisation
        if (n.channel_order not in ("RGB", "BGR") or len(n.mean) != 3 or len(n.std) != 3 or min(n.std) <= 0
                or len(n.value_range) != 2 or not n.value_range[0] < n.value_range[1]
                or not all(math.isfinite(v) for v in (*n.value_range, *n.mean, *n.std))):
            fail("normalisation", f"bad normalisation {n.to_json()}")
        if not math.isfinite(self.background):
            fail("background", f"background must be a finite number, got {self.background}")
        if not self.levels:
            fail("levels", "at least one level is required")
        needed = {"feat_s1", "feat_s2", "feat_s4", "volume"} | ({"human_feat"} if self.has_human else set())
        if missing := needed - set(self.channels):
            fail("channels", f"missing channel counts {sorted(missing)}")
        if missing := (needed - {"volume"}) - set(self.strides):
            fail("strides", f"missing strides {sorted(missing)}")
        if bad := {k: v for k, v in self.strides.items() if v < 1 or self.height % v or self.width % v}:
            fail("strides", f"strides must be at least 1 and divide {self.width}x{self.height}, got {bad}")
        if bad := {k: v for k, v in self.channels.items() if v < 1}:
            fail("channels", f"channel counts must be at least 1, got {bad}")
        for i, lv in enumerate(self.levels):
            if (lv.spacing not in ("inverse", "linear") or lv.sampling not in ("interval", "planes")
                    or lv.planes < 2 or lv.samples < 1 or lv.volume_stride < 1):
                fail("levels", f"level {i} is invalid: {lv.to_json()}")
            if lv.feature not in IMAGE_FEATURES:
                fail("levels", f"level {i} uses feature {lv.feature!r}, not one of {list(IMAGE_FEATURES)}")
            if self.height % lv.volume_stride or self.width % lv.volume_stride:
                fail("levels", f"level {i} stride {lv.volume_stride} does not divide {self.width}x{self.height}")
        if self.render_feature not in IMAGE_FEATURES:  # a key of strides is not enough: human_feat is one
            fail("render_feature", f"render feature {self.render_feature!r} is not one of {list(IMAGE_FEATURES)}")
        if self.heatmap_stride < 1 or self.height % self.heatmap_stride or self.width % self.heatmap_stride:
            fail("heatmap_stride", f"heatmap stride {self.heatmap_stride} must divide {self.width}x{self.height}")
        if self.encoder_heatmaps and not self.has_human:
            fail("encoder_heatmaps", "encoder heatmaps need the human encoder (variant 'ghnerf')")
        if self.human_graph and not self.encoder_heatmaps:
            fail("human_graph", "the human graph outputs the encoder heatmaps; encoder_heatmaps must be true")
        if self.frame_padding not in FRAME_PADDINGS:
            fail("frame_padding", f"frame padding must be one of {list(FRAME_PADDINGS)}, got {self.frame_padding!r}")

    # --------------------------------------------------------------- metadata
    def to_metadata(self, graph: str | None = None, precision: str = "fp32") -> dict[str, str]:
        """The contract as flat ``metadata_props`` (all strings); ``graph`` names the file's graph."""
        p = META_PREFIX
        meta = {
            p + "contract_version": self.version,
            p + "model_version": self.model_version,
            p + "variant": self.variant,
            p + "resolution": f"{self.width}x{self.height}",
            p + "num_sources": str(self.num_sources),
            p + "joint_names": json.dumps(list(self.joint_names)),
            p + "normalisation": json.dumps(self.normalisation.to_json()),
            p + "levels": json.dumps([lv.to_json() for lv in self.levels]),
            p + "channels": json.dumps(dict(self.channels)),
            p + "strides": json.dumps(dict(self.strides)),
            p + "render_feature": self.render_feature,
            p + "heatmap_stride": str(self.heatmap_stride),
            p + "background": repr(float(self.background)),
            p + "opset": str(self.opset),
            p + "graphs": json.dumps([g.to_json() for g in self.graphs]),
            p + "precision": precision,
            p + "encoder_heatmaps": "true" if self.encoder_heatmaps else "false",
            p + "human_graph": "true" if self.human_graph else "false",
            p + "frame_padding": self.frame_padding,
        }
        if graph is not None:
            if graph not in GRAPH_NAMES:
                raise ContractError(f"unknown graph {graph!r}; expected one of {GRAPH_NAMES}", key=p + "graph")
            meta[p + "graph"] = graph
        return meta

    @classmethod
    def from_metadata(cls, props: Mapping[str, str]) -> "ModelContract":
        """Parse :meth:`to_metadata` output; every error names the offending key."""
        p = META_PREFIX

        def get(key: str) -> str:
            if p + key not in props:
                raise ContractError(_missing_why(props), key=p + key)
            return props[p + key]

        def parse(key: str, fn):
            raw = get(key)
            try:
                return fn(raw)
            except ContractError:
                raise
            except (ValueError, TypeError, KeyError, OverflowError, json.JSONDecodeError) as e:  # int(inf)
                raise ContractError(f"cannot parse {raw!r} ({e})", key=p + key) from e
            except RecursionError as e:  # JSON nested thousands deep
                raise ContractError(f"cannot parse {raw[:60]!r}... (nested too deeply)", key=p + key) from e

        version = get("contract_version")
        if version.split(".")[0] != CONTRACT_VERSION.split(".")[0]:
            raise ContractError(f"model contract version {version} is incompatible with this runtime's "
                                f"{CONTRACT_VERSION}", key=p + "contract_version")

        def resolution(raw: str) -> tuple[int, int]:
            w, h = raw.lower().split("x")
            return int(w), int(h)

        def levels(raw: str) -> tuple[LevelSpec, ...]:
            return tuple(LevelSpec(_whole(d["volume_stride"]), _whole(d["planes"]), _whole(d["samples"]),
                                   str(d["spacing"]), str(d["feature"]), str(d.get("sampling", "interval")))
                         for d in json.loads(raw))

        def normalisation(raw: str) -> Normalisation:
            d = json.loads(raw)
            return Normalisation(str(d["channel_order"]), tuple(map(float, d["value_range"])),
                                 tuple(map(float, d["mean"])), tuple(map(float, d["std"])),
                                 _json_boolean(d["mean_std_in_graph"]))

        def int_map(raw: str) -> dict[str, int]:
            d = json.loads(raw)
            if not isinstance(d, dict):
                raise ValueError("expected a JSON object")
            return {str(k): _whole(v) for k, v in d.items()}

        def graphs(raw: str) -> tuple[GraphSpec, ...]:
            return tuple(GraphSpec.from_json(g, p + "graphs") for g in json.loads(raw))

        width, height = parse("resolution", resolution)
        contract = cls(
            height=height, width=width,
            variant=get("variant"),
            levels=parse("levels", levels),
            channels=parse("channels", int_map),
            strides=parse("strides", int_map),
            render_feature=get("render_feature"),
            heatmap_stride=parse("heatmap_stride", int),
            num_sources=parse("num_sources", int),
            joint_names=parse("joint_names", lambda r: tuple(str(x) for x in json.loads(r))),
            normalisation=parse("normalisation", normalisation),
            background=parse("background", float),
            opset=parse("opset", int),
            version=version,
            model_version=get("model_version"),
            graphs=parse("graphs", graphs),
            # optional since 1.1.0; absent in 1.0.0 files
            encoder_heatmaps=parse("encoder_heatmaps", _boolean) if p + "encoder_heatmaps" in props else False,
            # optional since 1.2.0
            human_graph=parse("human_graph", _boolean) if p + "human_graph" in props else False,
            # optional since 1.3.0: older exports were all trained on crops inside the frame
            frame_padding=get("frame_padding") if p + "frame_padding" in props else "none",
        )
        contract.validate()
        expected = contract._derive_graphs()
        if tuple(g.to_json() for g in contract.graphs) != tuple(g.to_json() for g in expected):
            raise ContractError("graph specs disagree with the sizes in the other keys", key=p + "graphs")
        return contract

    @staticmethod
    def graph_of(props: Mapping[str, str]) -> str:
        """Which graph an ONNX file holds, from its metadata."""
        key = META_PREFIX + "graph"
        if key not in props:
            raise ContractError(_missing_why(props), key=key)
        if props[key] not in GRAPH_NAMES:
            raise ContractError(f"unknown graph {props[key]!r}; expected one of {GRAPH_NAMES}", key=key)
        return props[key]

    def same_model(self, other: "ModelContract") -> bool:
        """True when two files' contracts describe the same model (the graph key aside)."""
        return self.to_metadata() == other.to_metadata()

    def check_io(self, graph: str, inputs: Mapping[str, Sequence], outputs: Mapping[str, Sequence]) -> None:
        """Check a session's I/O (name -> shape, symbolic dims as str/None) against the graph spec.

        Raises:
            ContractError: naming the first missing, extra or mis-shaped tensor.
        """
        spec = self.graph(graph)
        for kind, expected, actual in (("input", spec.inputs, inputs), ("output", spec.outputs, outputs)):
            names = [t.name for t in expected]
            if extra := sorted(set(actual) - set(names)):
                raise ContractError(f"graph {graph!r} has unexpected {kind}s {extra}", key=extra[0])
            for t in expected:
                if t.name not in actual:
                    raise ContractError(f"graph {graph!r} lacks {kind} {t.name!r}", key=t.name)
                shape = tuple(actual[t.name])
                # An input dimension the contract fixes must be that number in the file too (a symbolic one
                # means the graph was exported for other shapes than the contract promises). Outputs may be
                # symbolic: the exporter's shape inference leaves some names where the value is fixed.
                strict = kind == "input"
                if len(shape) != len(t.shape) or any(
                    isinstance(e, int) and (strict or isinstance(a, int)) and a != e for e, a in zip(t.shape, shape)
                ):
                    raise ContractError(f"graph {graph!r} {kind} shape {list(shape)} != contract {list(t.shape)}",
                                        key=t.name)


def weights_id_of(props: Mapping[str, str]) -> str | None:
    """The weights id in a graph file's metadata (:data:`WEIGHTS_ID_KEY`); None in a file exported before
    there was one.

    Raises:
        ContractError: naming the key, when the value is not what the exporter writes (64 lowercase hex
            digits): a file edited or damaged there, which no comparison with the other files can vouch for.
    """
    value = props.get(WEIGHTS_ID_KEY)
    if value is None:
        return None
    if not _WEIGHTS_ID.fullmatch(value):
        raise ContractError(f"expected 64 lowercase hex digits (a sha256), got {value[:80]!r}", key=WEIGHTS_ID_KEY)
    return value


def _missing_why(props: Mapping[str, str]) -> str:
    """Why a required key is not in a file's metadata. Every 1.x export writes them all, and an ONNX file's
    metadata follow its graph, at the end of the file (protobuf writes fields in number order), so a file that
    has the contract's version but not one of its keys was most likely cut short there, where the old hint
    ("too old") sent the user to re-export: a copy that stopped early, a full disk."""
    if META_PREFIX + "contract_version" in props:
        return ("missing from the model metadata, which has the contract's other keys: the file may be cut short "
                "(its metadata come last in it); copy or export it again")
    return "missing from the model metadata (not a GHNeRF export, or too old)"


def _whole(value: Any) -> int:
    """A JSON integer: not a bool, not 8.7 (which ``int`` would truncate to 8 without a word). Not 8.0 either,
    as a size elsewhere may be: the exporter writes integers, so a float here is a wrong or hand-edited file."""
    whole = whole_number_or_none(value)
    if whole is None:
        raise ValueError(f"expected an integer, got {value!r}")
    return whole


def _json_boolean(value: Any) -> bool:
    """A JSON true/false (``bool("false")`` is True)."""
    if not isinstance(value, bool):
        raise ValueError(f"expected true or false, got {value!r}")
    return value


def _boolean(raw: str) -> bool:
    if raw not in ("true", "false"):
        raise ValueError("expected 'true' or 'false'")
    return raw == "true"


# ----------------------------------------------------------------- camera inputs
def _cam_arrays(camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    K = np.asarray(camera.K, dtype=np.float64)
    R = np.asarray(camera.R, dtype=np.float64)
    t = np.asarray(camera.t, dtype=np.float64).reshape(-1)
    if K.shape != (3, 3) or R.shape != (3, 3) or t.shape != (3,):
        raise ContractError(f"camera needs K (3,3), R (3,3), t (3,), got {K.shape}, {R.shape}, {t.shape}",
                            key="camera")
    return K, R, t


def _check_size(cameras: Iterable, height: int, width: int) -> list:
    cams = list(cameras)
    for c in cams:
        if (getattr(c, "width", width), getattr(c, "height", height)) != (width, height):
            raise ContractError(f"camera {getattr(c, 'name', '?')!r} is {c.width}x{c.height}; resize it to the "
                                f"contract resolution {width}x{height} (Camera.resized)", key="camera")
    return cams


def source_projections(cameras: Sequence, height: int, width: int) -> np.ndarray:
    """``src_P`` ``(S, 3, 4)`` float32: ``K [R | t]`` of each source at the contract resolution."""
    out = []
    for c in _check_size(cameras, height, width):
        K, R, t = _cam_arrays(c)
        out.append(K @ np.hstack([R, t[:, None]]))
    return np.stack(out).astype(np.float32)


def source_centers(cameras: Sequence) -> np.ndarray:
    """``src_centers`` ``(S, 3)`` float32: camera centres in the rig frame."""
    out = []
    for c in cameras:
        _, R, t = _cam_arrays(c)
        out.append(-R.T @ t)
    return np.stack(out).astype(np.float32)


def target_inputs(cameras: Sequence, height: int, width: int) -> dict[str, np.ndarray]:
    """``tgt_K_inv`` ``(B, 3, 3)`` and ``tgt_c2w`` ``(B, 3, 4)`` (``[R^T | centre]``) float32."""
    k_inv, c2w = [], []
    for c in _check_size(cameras, height, width):
        K, R, t = _cam_arrays(c)
        k_inv.append(np.linalg.inv(K))
        c2w.append(np.hstack([R.T, (-R.T @ t)[:, None]]))
    return {"tgt_K_inv": np.stack(k_inv).astype(np.float32), "tgt_c2w": np.stack(c2w).astype(np.float32)}


def target_projections(cameras: Sequence, height: int, width: int) -> np.ndarray:
    """``tgt_P`` ``(B, 3, 4)`` float32 for the ``query`` graph (same as :func:`source_projections`)."""
    return source_projections(cameras, height, width)


def near_far_from_box(camera, corners: np.ndarray, margin: float = 0.1, min_near: float = 0.05) -> np.ndarray:
    """Depth range ``(2,)`` float32 of a rig-frame box seen from ``camera``.

    ``corners`` ``(8, 3)`` are the box corners (``WorkingVolume.corners()`` or a box
    around the subject); the box is grown by ``margin`` metres before the camera
    depths of its corners are taken. ``near`` is clamped to ``min_near``.

    Raises:
        GeometryError: the corners (or margin) are not finite, or the (grown) box lies wholly at or behind
            the near plane (``min_near`` in front of the camera): nothing of it can be rendered,
            and a range clamped to the near plane would look like a real one.
        DepthRangeError: (a :class:`GeometryError`) the box reaches farther than :data:`MAX_DEPTH_M` from
            the camera along one of its axes: float32 holds no near/far of it (the message names the box
            and the distance).
    """
    lo, hi, in_cam = _grown_box_in_camera(camera, corners, margin)
    z = in_cam[:, 2]
    if np.isfinite(in_cam).all() and not float(z.max()) > min_near:  # an overflow is refused as too far, below
        raise GeometryError(f"the box is behind the camera's near plane ({min_near} m): camera depths "
                            f"{float(z.min()):.3f} to {float(z.max()):.3f} m")
    reach = float(np.max(np.abs(in_cam)))  # NaN, inf where it overflowed: refused too
    if not reach <= MAX_DEPTH_M:
        raise DepthRangeError(f"the box from {lo.tolist()} to {hi.tolist()} (rig frame, grown by {margin:g} m) "
                              f"reaches {reach:.6g} m from camera {getattr(camera, 'name', '?')!r}, farther "
                              f"than the {MAX_DEPTH_M:g} m (MAX_DEPTH_M) a float32 near/far resolves")
    near = max(float(z.min()), min_near)
    far = max(float(z.max()), near + 1e-3)
    return np.array([near, far], dtype=np.float32)


def box_reach(camera, corners: np.ndarray, margin: float = 0.0) -> float:
    """How far (metres) the box around ``corners`` ``(N, 3)`` (rig frame), grown by ``margin``, reaches from
    ``camera`` along any of its axes: the largest ``|coordinate|`` of a grown corner in the camera's frame, the
    distance :func:`near_far_from_box` holds to :data:`MAX_DEPTH_M` (inf where it overflows).

    Raises:
        GeometryError: the corners (or margin) are not finite.
    """
    return float(np.max(np.abs(_grown_box_in_camera(camera, corners, margin)[2])))


def _grown_box_in_camera(camera, corners: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(lo, hi, in_cam)``: the box around ``corners`` grown by ``margin`` (rig frame) and its 8 corners ``(8, 3)``
    in ``camera``'s frame (inf where they overflow)."""
    corners = np.asarray(corners, dtype=np.float64)
    if corners.ndim != 2 or corners.shape[1] != 3:
        raise ContractError(f"corners must have shape (8, 3), got {corners.shape}", key="corners")
    if not (np.all(np.isfinite(corners)) and math.isfinite(margin)):
        raise GeometryError(f"box corners and margin must be finite, got {corners.tolist()}, {margin!r}")
    lo, hi = corners.min(0) - margin, corners.max(0) + margin
    idx = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)])
    box = np.where(idx == 1, hi, lo)
    _, R, t = _cam_arrays(camera)
    with np.errstate(over="ignore", invalid="ignore"):  # corners of 1e308 overflow to inf: refused as too far
        in_cam = box @ R.T + t
    return lo, hi, in_cam


def ray_grid(height: int, width: int, stride: int = 1) -> np.ndarray:
    """``ray_uv`` ``(R, 2)`` float32: the centres of ``stride x stride`` pixel blocks, row-major.

    Rendering these rays gives an ``(H / stride, W / stride)`` image whose pixel
    centres follow the integer-centre convention (``cv2.resize`` of it back to
    ``H x W`` lines up with the full-resolution image).
    """
    if stride < 1 or height % stride or width % stride:
        raise ContractError(f"stride {stride} must divide {width}x{height}", key="stride")
    us = (np.arange(width // stride) + 0.5) * stride - 0.5
    vs = (np.arange(height // stride) + 0.5) * stride - 0.5
    u, v = np.meshgrid(us, vs)
    return np.stack([u.ravel(), v.ravel()], axis=-1).astype(np.float32)


__all__ = [
    "CONTRACT_VERSION", "FRAME_PADDINGS",
    "GRAPH_NAMES", "DEPTH_STATS_CHANNELS", "MAX_DEPTH_M", "MAX_NEAR_FAR_MARGIN_M", "IMAGE_FEATURES",
    "IMAGENET_MEAN", "IMAGENET_STD",
    "WEIGHTS_ID_KEY", "weights_id_of", "FP32_SHA256_KEY",
    "ContractError", "TensorSpec", "GraphSpec", "LevelSpec", "Normalisation", "ModelContract",
    "source_projections", "source_centers", "target_inputs", "target_projections", "near_far_from_box", "box_reach",
    "ray_grid",
]
