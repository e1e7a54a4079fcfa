"""``ghnerf-eval`` (``python -m training.evaluate``): held-out metrics of a checkpoint or of ONNX graphs.

Example::

    python -m training.evaluate --data data/edge128 --split val \\
        --model ghnerf=runs/edge128/last.pt --model ghnerf_fp32=models/ghnerf \\
        --model ghnerf_int8=models/ghnerf#int8 --model baseline=runs/edge128_baseline/last.pt --out metrics.json

A model spec is a torch checkpoint (``*.pt``), a folder of exported graphs (``<graph>.onnx``, fp32) or
such a folder with ``#int8`` (``<graph>.int8.onnx``), run through onnxruntime with 2 threads.

Per held-out scene (one ``MultiViewDataset`` item), every metric from ``ghnerf_runtime.metrics``:

* **Source views** (targets = the two source cameras, what the device renders): heatmaps on the
  heatmap grid (``contract.ray_grid`` at ``heatmap_stride``; 32x32 at 128), graph ``render_heat``.
  - ``heatmap_mse`` against the dataset's Gaussian heatmaps (all 25 joints; invisible joints have
    all-zero truth);
  - 2D joints: ``keypoints.decode_keypoints`` (OpenPose style) -> heatmap pixels ->
    ``keypoints.heatmap_to_model_pixels`` (crop pixels, centres at integers); ``pck`` at alpha 0.2 of
    the neck--mid-hip distance (fallback: torso box diagonal; see ``metrics.pck``) against
    ``tgt_joints_2d``, truth valid where ``tgt_visible``; undecoded joints count as wrong;
  - 3D joints: ``geometry.triangulate_dlt`` of the decoded joints of both sources with the crop
    projection matrices ``src_P``; ``mpjpe`` (mm, rig frame) against ``joints_3d``; joints that
    cannot be triangulated (not decoded in both views) are excluded and counted (``mpjpe_pred_missing``,
    ``mpjpe_found``: the share of the joints with truth that the MPJPE covers).
* **Encoder heatmaps** (models with the human encoder's auxiliary head): its 2D heatmaps of the two
  sources (an ONNX folder's ``human`` graph where it has one, as the runtime runs it, else ``encoder``),
  decoded and triangulated exactly as above (``encoder_heatmaps_pck@0.2``,
  ``encoder_heatmaps_mpjpe_mm``, over the joints decoded in both views: ``*_mpjpe_found`` is their share of
  the joints with truth, ``*_mpjpe_pred_missing`` the rest): the cheap heatmap source of the runtime; and
  flip-tested, averaged
  with the heatmaps of the mirrored images mirrored back (``encoder_heatmaps_flip_*``, the runtime's
  ``heatmaps.flip_test``). PCK is also reported per source view (``*_by_view``), and MPJPE per
  visibility class of the joint in the two sources (``*_mpjpe_by_visibility``: both see it, one, none;
  every joint is in the MPJPE itself, since the synthetic truth knows the hidden ones too). Each
  source's MPJPE is also given **gated** (``*_mpjpe_gated_mm``, with the share of joints kept,
  ``*_mpjpe_gated_found``, and its split by visibility): the runtime's triangulation
  (``joints3d.triangulate_joints``, default ``Joints3DConfig``: a joint whose views disagree beyond
  the reprojection gate, whose rays are nearly parallel (``min_ray_angle_deg``), or whose peak is weak,
  is missing), so the card states what a device reports.
* **Skeleton prior** (an ONNX folder with ``skeleton_prior.onnx`` the runtime accepts): the prior run on
  the flip-tested encoder joints, as the runtime runs it (with its own flip test):
  ``skeleton_prior_mpjpe_mm`` over every true joint, and ``skeleton_prior_gated_mpjpe_mm`` /
  ``skeleton_prior_gated_found`` over the joints whose expected error is within the runtime's default
  gate (``skeleton_prior_gate_m``). A prior of another feature version is not scored (a warning).
* **Novel views** (targets 2..V-1): the full-resolution image (graph ``render_rgb``), ``masked_psnr`` and
  ``masked_ssim`` inside the subject mask against the target composited over the model background.
  The dataset's novel cameras circle the subject (any azimuth), so many see sides that neither
  source camera sees; ``psnr_masked_by_source_angle`` splits the PSNR by each view's angle from the
  nearest source camera (seen from the subject's centre). The device's novel view lies between its
  two cameras, in the first bin or two.

Scores pool every joint / image of the split (PCK: correct / evaluated; MPJPE: mean over joints;
PSNR/SSIM/heatmap MSE: mean over views).
"""
from __future__ import annotations

if __name__ == "__main__":  # python -m: the arguments are parsed before torch loads (training.cli)
    from training.cli.evaluate import main as _cli_main

    raise SystemExit(_cli_main())

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Protocol

import numpy as np
import torch
from torch import Tensor

from ghnerf_runtime.body25 import BODY_PARTS, MID_HIP, NECK
from ghnerf_runtime.cli.output_path import model_file_clash, output_clash, ready_output_arg
from ghnerf_runtime.cli.sigterm import exit_status, sigterm_as_interrupt, stop_words
from ghnerf_runtime.contract import ModelContract, ray_grid
from ghnerf_runtime.config import Joints3DConfig
from ghnerf_runtime.flip_test import flip_averaged, mirror_images
from ghnerf_runtime.geometry import triangulate_dlt
from ghnerf_runtime.joints3d import triangulate_joints
from ghnerf_runtime.keypoints import KeypointDecoderConfig, decode_keypoints, heatmap_to_model_pixels
from ghnerf_runtime.metrics import (capped_psnr, heatmap_mse, masked_psnr, masked_ssim, mpjpe, mpjpe_by_visibility,
                                    pck, scorable_images)
from ghnerf_runtime.novel_painter import angle_from_centres_deg
from training.cli.evaluate import ModelItem
from training.model_card import strict_json, write_atomic
from training.run_limits import threads_problem

PCK_ALPHA = 0.2


class EvalInputError(ValueError):
    """A model spec, its files or the dataset cannot be evaluated; the message names the file and what is wrong."""


#: Bin edges (degrees) of a novel view's angle from the nearest source camera, for the PSNR split.
SOURCE_ANGLE_BINS_DEG = (0.0, 15.0, 30.0, 60.0, 90.0, 180.0)


# ------------------------------------------------------------------------------------------ renderers
class Renderer(Protocol):
    """Renders one scene: heatmaps of targets on rays, colour of targets on rays."""

    height: int
    width: int
    heatmap_stride: int
    background: float

    def heatmaps(self, scene: Mapping[str, np.ndarray], targets: np.ndarray, ray_uv: np.ndarray) -> np.ndarray:
        """``(T, R, J)`` heatmaps of the views ``targets`` at ``ray_uv`` ``(R, 2)``."""

    def colour(self, scene: Mapping[str, np.ndarray], targets: np.ndarray, ray_uv: np.ndarray) -> np.ndarray:
        """``(T, R, 3)`` colour."""

    def encoder_heatmaps(self, scene: Mapping[str, np.ndarray]) -> np.ndarray | None:
        """``(S, J, h, w)`` the human encoder's own 2D heatmaps of the sources, or None (no such head)."""


def _cams(scene: Mapping[str, np.ndarray], targets: np.ndarray, ray_uv: np.ndarray) -> dict[str, np.ndarray]:
    T = len(targets)
    return {"images": scene["images"], "src_P": scene["src_P"], "src_centers": scene["src_centers"],
            "tgt_K_inv": scene["tgt_K_inv"][targets], "tgt_c2w": scene["tgt_c2w"][targets],
            "near_far": scene["near_far"][targets],
            "ray_uv": np.ascontiguousarray(np.broadcast_to(ray_uv, (T, *ray_uv.shape)), dtype=np.float32)}


class TorchRenderer:
    """The torch model (eval mode, no grad), same graph split as the export (last cascade level)."""

    def __init__(self, model, device: str | torch.device = "cpu", chunk: int = 8192):
        self.model = model.eval()
        cfg = model.config
        self.height, self.width, self.heatmap_stride = cfg.height, cfg.width, cfg.heatmap_stride
        self.background = cfg.background
        self.device = torch.device(device)
        self.chunk = chunk

    @torch.no_grad()
    def render(self, scene, targets, ray_uv, heat: bool) -> dict[str, np.ndarray]:
        """Rays ``ray_uv`` of ``targets`` at the last level, in chunks: ``heatmaps`` (``heat``) or ``rgb``,
        and ``depth``, ``acc`` (numpy, ``(T, R, ...)``)."""
        d = {k: torch.from_numpy(np.asarray(v)).to(self.device) for k, v in _cams(scene, targets, ray_uv).items()}
        m = self.model
        enc = m.encode(d["images"])
        vols = m.volumes(enc, d["src_P"], d["tgt_K_inv"], d["tgt_c2w"], d["near_far"])
        v, lvl = vols[-1], len(vols) - 1
        keys = ("heatmaps" if heat else "rgb", "depth", "acc")
        outs: dict[str, list[Tensor]] = {k: [] for k in keys}
        for i in range(0, d["ray_uv"].shape[1], self.chunk):
            o = m.render(lvl, enc, v["volume"], v["stats"], d["src_P"], d["tgt_K_inv"], d["tgt_c2w"],
                         d["ray_uv"][:, i:i + self.chunk], src_centers=None if heat else d["src_centers"],
                         heat=heat)
            for k in keys:
                outs[k].append(o[k])
        return {k: torch.cat(v, 1).cpu().numpy() for k, v in outs.items()}

    def heatmaps(self, scene, targets, ray_uv):
        return self.render(scene, targets, ray_uv, heat=True)["heatmaps"]

    def colour(self, scene, targets, ray_uv):
        return self.render(scene, targets, ray_uv, heat=False)["rgb"]

    @torch.no_grad()
    def encoder_heatmaps(self, scene):
        enc = self.model.encode(torch.from_numpy(np.asarray(scene["images"])).to(self.device))
        return enc["encoder_heatmaps"].cpu().numpy() if "encoder_heatmaps" in enc else None


def _folder_prior(folder: Path, threads: int):
    """The folder's skeleton prior (the runtime's), or None: none there, or one this runtime refuses (the
    model's own metrics do not need it; a warning says why it is not scored): another feature version, or
    trained on another encoder file than the folder's (``SkeletonPrior.check_encoder``, as
    ``ModelSession.load`` checks it)."""
    from ghnerf_runtime.errors import ModelError
    from ghnerf_runtime.skeleton_prior import FILE_NAME, SkeletonPrior

    if not (folder / FILE_NAME).is_file():
        return None
    try:
        prior = SkeletonPrior.load(folder / FILE_NAME, threads)
        prior.check_encoder(folder)
        return prior
    except ModelError as e:
        print(f"warning: the skeleton prior is not scored: {e}", file=sys.stderr)
        return None


class OnnxRenderer:
    """Exported graphs through onnxruntime (``training.export.parity.run_pipeline``)."""

    def __init__(self, folder: str | Path, precision: str = "fp32", threads: int = 2):
        import onnx

        folder = Path(folder)
        suffix = ".int8.onnx" if precision == "int8" else ".onnx"
        self.paths = {g: folder / f"{g}{suffix}" for g in ("encoder", "volume", "render_heat", "render_rgb")}
        missing = [p.name for p in self.paths.values() if not p.exists()]
        if missing:
            raise EvalInputError(f"{folder}: missing ONNX graphs {', '.join(missing)} (export the model there, or "
                                 f"give another folder{'; without #int8 for fp32' if precision == 'int8' else ''})")
        try:
            props = {p.key: p.value
                     for p in onnx.load(str(self.paths["encoder"]), load_external_data=False).metadata_props}
            self.contract = ModelContract.from_metadata(props)
        except Exception as e:  # protobuf's DecodeError, the contract's own errors
            raise EvalInputError(f"{self.paths['encoder']}: not a readable GHNeRF graph ({_short(e)})") from e
        # the 2D joints' graph, as the runtime (and the prior's collection) runs it: ``human`` where the folder
        # has it (at int8 it differs from ``encoder``, whose first convolution the quantizer keeps in float)
        human = folder / f"human{suffix}"
        self.keypoint_graph = "human" if human.exists() else "encoder"
        self.sessions = {g: _session(p, threads) for g, p in self.paths.items()}
        if self.keypoint_graph == "human":
            self.sessions["human"] = _session(human, threads)
        _check_one_export({self.paths.get(g, human): sess for g, sess in self.sessions.items()})
        self.height, self.width = self.contract.height, self.contract.width
        self.heatmap_stride = self.contract.heatmap_stride
        self.background = self.contract.background
        self.skeleton_prior = _folder_prior(folder, threads)

    def _run(self, scene, targets, ray_uv, graph: str) -> dict[str, np.ndarray]:
        from training.export.parity import run_pipeline

        feeds = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in _cams(scene, targets, ray_uv).items()}
        return run_pipeline(self.sessions, self.contract, feeds, render_graph=graph)

    def heatmaps(self, scene, targets, ray_uv):
        return self._run(scene, targets, ray_uv, "render_heat")["heatmaps"]

    def encoder_heatmaps(self, scene):
        if not self.contract.encoder_heatmaps:
            return None
        images = np.ascontiguousarray(scene["images"], dtype=np.float32)
        return self.sessions[self.keypoint_graph].run(["encoder_heatmaps"], {"images": images})[0]

    def colour(self, scene, targets, ray_uv):
        return self._run(scene, targets, ray_uv, "render_rgb")["rgb"]


def _check_one_export(sessions: Mapping[Path, object]) -> None:
    """The graph files' weights ids (``ghnerf.weights_id``) agree, as the runtime's load checks: a folder holding
    graphs of two exports (a move into it cut short) was scored as one model. Files without an id are taken."""
    from ghnerf_runtime.contract import ContractError, weights_id_of

    first: tuple[Path, str] | None = None
    for path, sess in sessions.items():
        try:
            weights = weights_id_of(dict(sess.get_modelmeta().custom_metadata_map))
        except ContractError as e:
            raise EvalInputError(f"{path}: {e}") from e
        if weights is not None and first is not None and weights != first[1]:
            raise EvalInputError(f"{path}: weights id {weights[:16]}..., and {first[0].name} {first[1][:16]}...: the "
                                 "graph files come from two different exports; export the model again into "
                                 f"{path.parent}")
        first = first or ((path, weights) if weights is not None else None)


def _session(path: Path, threads: int):
    """An onnxruntime session of ``path``; a damaged file is an :class:`EvalInputError` naming it."""
    from training.export.parity import make_session

    try:
        return make_session(path, threads)
    except Exception as e:  # onnxruntime's InvalidProtobuf / Fail
        raise EvalInputError(f"{path}: onnxruntime cannot load it ({_short(e)})") from e


def _short(e: BaseException) -> str:
    from training.train import error_words  # (as load_model: train imports this module)

    return f"{type(e).__name__}: {error_words(e)}"


@torch.no_grad()
def render_heatmap_grids(model, item: dict, targets: Tensor) -> Tensor:
    """Heatmaps ``(T, J, h, w)`` of the views ``targets`` of ``item`` (torch tensors) on the heatmap grid."""
    cfg = model.config
    H, W, s = cfg.height, cfg.width, cfg.heatmap_stride
    dev = item["images"].device
    r = TorchRenderer(model, dev)
    scene = {k: v.cpu().numpy() for k, v in item.items() if k in ("images", "src_P", "src_centers", "tgt_K_inv",
                                                                   "tgt_c2w", "near_far")}
    hm = r.heatmaps(scene, targets.cpu().numpy(), ray_grid(H, W, s))
    return torch.from_numpy(hm).transpose(1, 2).reshape(len(targets), -1, H // s, W // s)


# ------------------------------------------------------------------------------------------- metrics
def keypoints_from_heatmaps(heatmaps: np.ndarray, model_size: int,
                            config: KeypointDecoderConfig | None = None) -> np.ndarray:
    """Decoded joints ``(..., J, 2)`` in model (crop) pixels from ``(..., J, h, w)`` heatmaps; NaN where none."""
    return _decode(heatmaps, model_size, config)[0]


def _decode(heatmaps: np.ndarray, model_size: int,
            config: KeypointDecoderConfig | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`keypoints_from_heatmaps` and the peaks' confidence ``(..., J)`` (0 where none)."""
    heatmaps = np.asarray(heatmaps, np.float32)
    kp = decode_keypoints(heatmaps, config)
    h, w = heatmaps.shape[-2:]
    uv = heatmap_to_model_pixels(kp.uv, (w, h), model_size)
    return np.where(kp.valid[..., None], uv, np.nan), np.where(kp.valid, kp.confidence, 0.0)


@dataclass
class HeatmapScores:
    """Pooled PCK@0.2 and MPJPE of one heatmap source (rendered, or the encoder's plain or flip-tested)."""

    pck_correct: int = 0
    pck_evaluated: int = 0
    mpjpe_sum_mm: float = 0.0
    mpjpe_joints: int = 0
    # joints with truth that the plain (ungated) triangulation could not place (not decoded in both views):
    # out of the MPJPE, so reported beside it, or the encoder's MPJPE looks like one over every joint
    mpjpe_pred_missing: int = 0
    # per body part (body25.BODY_PARTS) and per source view: [correct, evaluated]
    parts: dict[str, list[int]] = field(default_factory=dict)
    views: list[list[int]] = field(default_factory=list)
    # MPJPE per visibility class of the joint in the sources (metrics.VISIBILITY_CLASSES): [sum mm, joints]
    visibility: dict[str, list[float]] = field(default_factory=dict)
    # the runtime's gated triangulation: errors (mm) of the joints it keeps (mean and median: the mean has a
    # long tail), joints with truth, and the split per visibility class
    gated_errors: list[np.ndarray] = field(default_factory=list)
    gated_known: int = 0
    gated_visibility: dict[str, list[float]] = field(default_factory=dict)

    def add(self, p, e, visible: np.ndarray | None = None, gated=None) -> None:
        self.pck_correct += p.num_correct
        self.pck_evaluated += p.num_evaluated
        _add_parts(self.parts, p)
        _add_views(self.views, p)
        self.mpjpe_sum_mm += float(e.errors[e.evaluated].sum())
        self.mpjpe_joints += e.num_evaluated
        self.mpjpe_pred_missing += e.num_pred_missing
        if visible is not None:
            _add_visibility(self.visibility, e, visible)
        if gated is not None:
            self.gated_errors.append(np.asarray(gated.errors[gated.evaluated], np.float64))
            self.gated_known += gated.num_evaluated + gated.num_pred_missing
            if visible is not None:
                _add_visibility(self.gated_visibility, gated, visible)

    @property
    def pck(self) -> float | None:
        return self.pck_correct / self.pck_evaluated if self.pck_evaluated else None

    @property
    def mpjpe_mm(self) -> float | None:
        return self.mpjpe_sum_mm / self.mpjpe_joints if self.mpjpe_joints else None

    @property
    def mpjpe_found(self) -> float | None:
        """Share of the joints with truth that the plain MPJPE scores (the rest were not triangulated)."""
        known = self.mpjpe_joints + self.mpjpe_pred_missing
        return self.mpjpe_joints / known if known else None

    def result(self, prefix: str) -> dict:
        return {f"{prefix}_pck@0.2": self.pck, f"{prefix}_mpjpe_mm": self.mpjpe_mm,
                f"{prefix}_mpjpe_evaluated_joints": self.mpjpe_joints,
                f"{prefix}_mpjpe_pred_missing": self.mpjpe_pred_missing,
                f"{prefix}_mpjpe_found": self.mpjpe_found,
                f"{prefix}_pck@0.2_by_part": _part_scores(self.parts) if self.parts else None,
                f"{prefix}_pck@0.2_by_view": _view_scores(self.views) if self.views else None,
                f"{prefix}_mpjpe_by_visibility": _visibility_scores(self.visibility) if self.visibility else None,
                **self.gated_result(f"{prefix}_")}

    def gated_result(self, prefix: str) -> dict:
        errors = np.concatenate(self.gated_errors) if self.gated_errors else np.zeros(0)
        return {f"{prefix}mpjpe_gated_mm": float(errors.mean()) if errors.size else None,
                f"{prefix}mpjpe_gated_median_mm": float(np.median(errors)) if errors.size else None,
                f"{prefix}mpjpe_gated_found": errors.size / self.gated_known if self.gated_known else None,
                f"{prefix}mpjpe_gated_by_visibility":
                    _visibility_scores(self.gated_visibility) if self.gated_visibility else None}


@dataclass
class Accumulator:
    """Pools per-scene results into split scores."""

    rendered: HeatmapScores = field(default_factory=HeatmapScores)
    pck_missing: int = 0
    pck_pred_missing: int = 0
    mpjpe_missing: int = 0
    mpjpe_pred_missing: int = 0
    encoder: HeatmapScores = field(default_factory=HeatmapScores)
    encoder_flip: HeatmapScores = field(default_factory=HeatmapScores)
    heat_mse: list[float] = field(default_factory=list)
    psnr: list[float] = field(default_factory=list)
    psnr_angle_deg: list[float] = field(default_factory=list)  # per entry of psnr (NaN: unknown)
    ssim: list[float] = field(default_factory=list)
    scenes: int = 0
    pck_unreferenced: int = 0  # visible joints of views with no reference length (excluded, counted)
    pck_views: int = 0  # source views with a reference length
    pck_fallback_views: int = 0  # ... of which took the torso box's diagonal (neck or mid-hip hidden)
    nonfinite_scenes: int = 0  # a non-finite heatmap prediction: excluded from heatmap_mse, counted
    nonfinite_views: int = 0  # a non-finite novel view (not an empty mask): excluded from PSNR/SSIM, counted
    # the skeleton prior on the flip-tested encoder joints: every true joint's error (mm), its expected error (m)
    prior_errors_mm: list[np.ndarray] = field(default_factory=list)
    prior_expected_m: list[np.ndarray] = field(default_factory=list)

    def add(self, m: dict) -> None:
        self.scenes += 1
        p, e, hm = m["pck"], m["mpjpe"], m["heatmap_mse"]
        vis = m.get("source_visible")
        self.rendered.add(p, e, vis, m.get("mpjpe_gated"))
        self.pck_missing += p.num_missing
        self.pck_pred_missing += p.num_pred_missing
        self.mpjpe_missing += e.num_missing
        self.mpjpe_pred_missing += e.num_pred_missing
        self.pck_unreferenced += p.num_unreferenced
        ref = np.asarray(p.reference) > 0
        torso = np.asarray(p.evaluated)[..., NECK] & np.asarray(p.evaluated)[..., MID_HIP]
        self.pck_views += int(ref.sum())
        self.pck_fallback_views += int((ref & ~torso).sum())
        if np.isfinite(hm.value):
            self.heat_mse.append(hm.value)
        else:  # a broken prediction must not vanish from the score silently
            self.nonfinite_scenes += 1
        if m.get("encoder_pck") is not None:
            self.encoder.add(m["encoder_pck"], m["encoder_mpjpe"], vis, m.get("encoder_mpjpe_gated"))
        if m.get("encoder_flip_pck") is not None:
            self.encoder_flip.add(m["encoder_flip_pck"], m["encoder_flip_mpjpe"], vis,
                                  m.get("encoder_flip_mpjpe_gated"))
        if m.get("prior_mpjpe") is not None:
            e = m["prior_mpjpe"]
            self.prior_errors_mm.append(np.asarray(e.errors[e.evaluated], np.float64))
            self.prior_expected_m.append(np.asarray(m["prior_expected_error_m"], np.float64)[e.evaluated])
        if m.get("psnr") is not None:
            # An empty mask is not scored; a non-finite render is excluded too, but counted; identical
            # images (+inf) are capped at metrics.PSNR_CAP_DB so one such view cannot make the mean infinite.
            per_image = np.ravel(m["psnr"].per_image)
            scored = np.ravel(m["psnr"].num_pixels) > 0
            ssim = np.ravel(m["ssim"].per_image)
            angles = np.ravel(m.get("novel_source_angle_deg", np.full(per_image.shape, np.nan)))
            for v, q, a, ok in zip(per_image, ssim, angles, scored):
                if not ok:
                    continue
                if np.isnan(v) or not np.isfinite(q):
                    self.nonfinite_views += 1
                    continue
                self.psnr.append(float(capped_psnr(v)))
                self.psnr_angle_deg.append(float(a))
                self.ssim.append(float(q))

    def result(self) -> dict:
        def mean(v):
            v = [x for x in v if not np.isnan(x)]
            return float(np.mean(v)) if v else float("nan")

        r = self.rendered
        return {
            "scenes": self.scenes,
            "pck@0.2": r.pck if r.pck is not None else float("nan"),
            "pck_evaluated_joints": r.pck_evaluated, "pck_missing_truth": self.pck_missing,
            "pck_undecoded": self.pck_pred_missing, "pck_unreferenced": self.pck_unreferenced,
            "pck_fallback_views": self.pck_fallback_views, "pck_views": self.pck_views,
            "mpjpe_mm": r.mpjpe_mm if r.mpjpe_mm is not None else float("nan"),
            "mpjpe_evaluated_joints": r.mpjpe_joints, "mpjpe_missing_truth": self.mpjpe_missing,
            "mpjpe_pred_missing": self.mpjpe_pred_missing, "mpjpe_found": r.mpjpe_found,
            "heatmap_mse": mean(self.heat_mse),
            "psnr_masked": mean(self.psnr), "ssim_masked": mean(self.ssim), "novel_views": len(self.psnr),
            "nonfinite_scenes": self.nonfinite_scenes, "nonfinite_views": self.nonfinite_views,
            "psnr_masked_by_source_angle": psnr_by_angle(self.psnr, self.psnr_angle_deg),
            "pck@0.2_by_part": _part_scores(r.parts),
            # a PCK target applies to each source view
            "pck@0.2_by_view": _view_scores(r.views),
            # the MPJPE of joints both sources see, one sees, neither sees (all are scored above)
            "mpjpe_by_visibility": _visibility_scores(r.visibility),
            # the runtime's triangulation (reprojection gate, minimum view confidence): what a device reports
            **r.gated_result(""),
            # the human encoder's own 2D heatmaps (no rendering), decoded and triangulated the same way;
            # "flip": averaged with those of the mirrored images (the runtime's heatmaps.flip_test)
            **self.encoder.result("encoder_heatmaps"),
            **self.encoder_flip.result("encoder_heatmaps_flip"),
            **self.prior_result(),
        }

    def prior_result(self) -> dict:
        """The skeleton prior's MPJPE over every joint, and over those its expected error keeps under the
        runtime's default gate (``joints3d.max_prior_error_m``); all None without a prior."""
        from ghnerf_runtime.config import Joints3DConfig

        keys = ("skeleton_prior_mpjpe_mm", "skeleton_prior_mpjpe_median_mm", "skeleton_prior_gated_mpjpe_mm",
                "skeleton_prior_gated_found", "skeleton_prior_gate_m")
        if not self.prior_errors_mm:
            return dict.fromkeys(keys)
        e, x = np.concatenate(self.prior_errors_mm), np.concatenate(self.prior_expected_m)
        gate = Joints3DConfig().max_prior_error_m
        kept = e[x <= gate]
        return dict(zip(keys, (float(e.mean()), float(np.median(e)), float(kept.mean()) if kept.size else None,
                               kept.size / e.size, gate)))


def angle_bins(angles_deg, edges: tuple[float, ...] = SOURCE_ANGLE_BINS_DEG) -> list[tuple[float, float, np.ndarray]]:
    """``(lo, hi, inside)`` for each bin of ``edges``: ``inside`` marks the angles in ``[lo, hi)``, in the last
    bin ``[lo, hi]`` (a view straight behind a source, 180 degrees, is in it); a NaN angle (unknown) is in none.
    One binning for ``ghnerf-eval`` (:func:`psnr_by_angle`) and the painter's table (``learnt_fill.score_rows``).

    Example:
        >>> [(lo, hi, m.tolist()) for lo, hi, m in angle_bins([15.0, 180.0, float("nan")], (0.0, 15.0, 180.0))]
        [(0.0, 15.0, [False, False, False]), (15.0, 180.0, [True, True, False])]
    """
    a = np.asarray(angles_deg, np.float64)
    last = len(edges) - 2
    return [(lo, hi, (a >= lo) & ((a <= hi) if k == last else (a < hi)))
            for k, (lo, hi) in enumerate(zip(edges[:-1], edges[1:]))]


def psnr_by_angle(psnr: list[float], angles_deg: list[float],
                  edges: tuple[float, ...] = SOURCE_ANGLE_BINS_DEG) -> list[dict]:
    """Mean PSNR of the views in each angle bin (:func:`angle_bins`: ``[lo, hi)``, the last includes ``hi``)."""
    p = np.asarray(psnr, np.float64)
    return [{"range_deg": [lo, hi], "views": int(inside.sum()),
             "psnr": float(np.mean(p[inside])) if inside.any() else None}
            for lo, hi, inside in angle_bins(angles_deg, edges)]


def source_angles_deg(scene: Mapping[str, np.ndarray], targets: np.ndarray) -> np.ndarray:
    """Angle (degrees) at the subject's centre between each target camera and the nearest source camera.

    The device's rule, :func:`ghnerf_runtime.novel_painter.angle_from_centres_deg` (one implementation, so the
    painter's gate and these bins agree): the centre is the mean of the scene's valid, finite 3D joints; camera
    centres are ``tgt_c2w[:, :, 3]``. 0 for a source itself and for a camera exactly at the centre (a source
    there is left out); NaN when the scene has no valid joint.
    """
    eyes = np.asarray(scene["tgt_c2w"], np.float64)[:, :, 3]
    sources = list(eyes[np.asarray(scene["tgt_is_source"], bool)])
    joints, valid = scene["joints_3d"], scene["joints_3d_valid"]
    return np.array([angle_from_centres_deg(eyes[t], sources, joints, valid) for t in np.asarray(targets, int)],
                    np.float64)


def _add_parts(totals: dict[str, list[int]], result) -> None:
    """Add a :class:`~ghnerf_runtime.metrics.PckResult`'s correct / evaluated joints per body part."""
    for part, joints in BODY_PARTS.items():
        t = totals.setdefault(part, [0, 0])
        t[0] += int(result.correct[..., joints].sum())
        t[1] += int(result.evaluated[..., joints].sum())


def _add_views(totals: list[list[int]], result) -> None:
    """Add a :class:`~ghnerf_runtime.metrics.PckResult`'s correct / evaluated joints per source view."""
    correct = np.asarray(result.correct).reshape(-1, np.shape(result.correct)[-1])
    evaluated = np.asarray(result.evaluated).reshape(correct.shape)
    while len(totals) < len(correct):
        totals.append([0, 0])
    for v in range(len(correct)):
        totals[v][0] += int(correct[v].sum())
        totals[v][1] += int(evaluated[v].sum())


def _view_scores(totals: list[list[int]]) -> list[float | None]:
    return [(c / n if n else None) for c, n in totals]


def _add_visibility(totals: dict[str, list[float]], e, visible: np.ndarray) -> None:
    """Add an MPJPE result's error sums and joint counts per visibility class."""
    for name, (total, n) in mpjpe_by_visibility(e, visible).items():
        t = totals.setdefault(name, [0.0, 0])
        t[0] += total
        t[1] += n


def _visibility_scores(totals: Mapping[str, list[float]]) -> dict[str, dict]:
    """``{class: {"mpjpe_mm", "joints"}}`` (metrics.VISIBILITY_CLASSES; mpjpe None when no joint)."""
    return {name: {"mpjpe_mm": (t / n if n else None), "joints": int(n)} for name, (t, n) in totals.items()}


def _part_scores(totals: Mapping[str, list[int]]) -> dict[str, float | None]:
    return {part: (c / n if n else None) for part, (c, n) in totals.items()}


#: The runtime's triangulation (``joints3d.triangulate_joints`` with the default ``Joints3DConfig``:
#: reprojection gate, minimum view confidence, minimum ray angle), applied to the eval's crops for the gated MPJPE.
RUNTIME_TRIANGULATION = Joints3DConfig()


def _joint_scores(prefix: str, uv: np.ndarray, conf: np.ndarray, scene: Mapping[str, np.ndarray]) -> dict:
    """PCK of decoded joints ``uv`` ``(S, J, 2)`` (NaN = none) and the MPJPE of their triangulation, ungated
    (``<prefix>mpjpe``: DLT of every joint decoded in both views) and gated as the runtime does
    (``<prefix>mpjpe_gated``: a joint whose views disagree by more than the reprojection gate, or whose
    peak is too weak, is missing)."""
    S = len(uv)
    decoded = np.isfinite(uv).all(-1)
    P = np.asarray(scene["src_P"], np.float64)
    out = {f"{prefix}pck": pck(np.nan_to_num(uv), scene["tgt_joints_2d"][:S], scene["tgt_visible"][:S],
                               alpha=PCK_ALPHA, pred_valid=decoded)}
    tri = triangulate_dlt(uv, P)
    out[f"{prefix}mpjpe"] = mpjpe(tri.points, scene["joints_3d"], scene["joints_3d_valid"], pred_valid=tri.valid)
    gated = triangulate_joints(np.nan_to_num(uv), conf, decoded, list(P), RUNTIME_TRIANGULATION)
    out[f"{prefix}mpjpe_gated"] = mpjpe(gated.points, scene["joints_3d"], scene["joints_3d_valid"],
                                        pred_valid=gated.valid)
    out[f"{prefix}joints_3d"] = np.where(tri.valid[:, None], tri.points, np.nan)
    return out


def scene_metrics(scene: Mapping[str, np.ndarray], source_heatmaps: np.ndarray, novel_rgb: np.ndarray | None,
                  novel_targets: np.ndarray, background: float = 0.0,
                  decoder: KeypointDecoderConfig | None = None, encoder_heatmaps: np.ndarray | None = None,
                  encoder_heatmaps_flip: np.ndarray | None = None, skeleton_prior=None) -> dict:
    """Metrics of one scene from rendered outputs (pure; the tests feed it known answers).

    Args:
        scene: numpy ``MultiViewDataset`` item.
        source_heatmaps: ``(2, J, h, w)`` heatmaps rendered in the two source views (targets 0, 1).
        novel_rgb: ``(T, 3, H, W)`` colour rendered in the views ``novel_targets`` (or None).
        encoder_heatmaps: ``(2, J, h, w)`` the human encoder's 2D heatmaps of the sources (or None): scored
            like the rendered ones (``encoder_pck``, ``encoder_mpjpe``).
        encoder_heatmaps_flip: the same averaged with those of the mirrored images (or None):
            ``encoder_flip_pck``, ``encoder_flip_mpjpe``.
        skeleton_prior: a :class:`~ghnerf_runtime.skeleton_prior.SkeletonPrior` (or None): its joints from
            the flip-tested encoder joints, as the runtime makes them (``prior_mpjpe``: every joint;
            ``prior_expected_error_m``: its own estimate, which the runtime's gate reads).
    """
    S = source_heatmaps.shape[0]
    H = scene["tgt_images"].shape[-1]
    hm_true = scene["tgt_heatmaps"][:S]
    out = {"heatmap_mse": heatmap_mse(source_heatmaps, hm_true)}
    uv, conf = _decode(source_heatmaps, H, decoder)  # (S, J, 2) crop pixels, NaN = none
    out.update(_joint_scores("", uv, conf, scene))
    out["source_visible"] = np.asarray(scene["tgt_visible"][:S], bool)
    out["keypoints_2d"] = uv
    for key, maps in (("encoder", encoder_heatmaps), ("encoder_flip", encoder_heatmaps_flip)):
        out[f"{key}_pck"] = out[f"{key}_mpjpe"] = out[f"{key}_mpjpe_gated"] = None
        if maps is not None:
            out.update(_joint_scores(f"{key}_", *_decode(maps, H, decoder), scene))
    out["prior_mpjpe"] = out["prior_expected_error_m"] = None
    if skeleton_prior is not None and encoder_heatmaps_flip is not None:
        est = prior_estimate(skeleton_prior, encoder_heatmaps_flip, scene["src_P"], H, decoder)
        out["prior_mpjpe"] = mpjpe(est.points, scene["joints_3d"], scene["joints_3d_valid"])
        out["prior_expected_error_m"] = est.expected_error_m
    out["psnr"] = out["ssim"] = None
    if novel_rgb is not None and len(novel_targets):
        img = scene["tgt_images"][novel_targets]
        m = scene["tgt_masks"][novel_targets]
        truth = img * m[:, None] + background * (1 - m[:, None])
        # a view with any non-finite pixel is a broken render: NaN throughout, so it is counted (nonfinite_views),
        # not scored
        pred, _ = scorable_images(novel_rgb)
        # metrics take channels-last images (..., H, W, C) or (..., H, W)
        out["psnr"] = masked_psnr(pred.transpose(0, 2, 3, 1), truth.transpose(0, 2, 3, 1), m)
        out["ssim"] = masked_ssim(pred.transpose(0, 2, 3, 1), truth.transpose(0, 2, 3, 1), m)
        out["novel_source_angle_deg"] = source_angles_deg(scene, novel_targets)
    return out


def flip_tested(renderer: Renderer, scene: Mapping[str, np.ndarray], heatmaps: np.ndarray) -> np.ndarray:
    """The flip test: the encoder's ``heatmaps`` of the sources averaged with those of the mirrored sources."""
    return flip_averaged(heatmaps, renderer.encoder_heatmaps({"images": mirror_images(scene["images"])}))


def prior_estimate(skeleton_prior, heatmaps: np.ndarray, src_P: np.ndarray, model_size: int,
                   decoder: KeypointDecoderConfig | None = None):
    """The skeleton prior's estimate from the sources' (flip-tested) encoder heatmaps, decoded as the runtime
    decodes them: a :class:`~ghnerf_runtime.skeleton_prior.SkeletonPrior` estimate (``points``,
    ``expected_error_m``)."""
    uv, conf = _decode(heatmaps, model_size, decoder)
    return skeleton_prior.estimate(np.nan_to_num(uv), conf, np.isfinite(uv).all(-1), np.asarray(src_P, np.float64))


def evaluate(renderer: Renderer, dataset, limit: int = 0, novel: bool = True, progress: bool = True) -> dict:
    """Pooled metrics of ``renderer`` over ``dataset`` (``MultiViewDataset``); an empty dataset is an
    :class:`EvalInputError` (its metrics would all be nan)."""
    H, W, s = renderer.height, renderer.width, renderer.heatmap_stride
    grid_h, grid_1 = ray_grid(H, W, s), ray_grid(H, W, 1)
    acc = Accumulator()
    if limit < 0:  # min(-1, len) would evaluate nothing and report empty metrics
        raise ValueError(f"limit must be >= 0 (0: every scene), got {limit}")
    n = min(limit, len(dataset)) if limit else len(dataset)
    if n == 0:  # every metric would be nan (null in the JSON): an empty split is an input error, not a score
        raise EvalInputError("the dataset holds no scenes: nothing to evaluate")
    t0 = time.monotonic()
    for i in range(n):
        scene = {k: v.numpy() for k, v in dataset[i].items()}
        src = np.flatnonzero(scene["tgt_is_source"])
        nov = np.flatnonzero(~scene["tgt_is_source"])
        hm = renderer.heatmaps(scene, src, grid_h)  # (2, R, J)
        hm = hm.transpose(0, 2, 1).reshape(len(src), -1, H // s, W // s)
        rgb = None
        if novel and len(nov):
            rgb = renderer.colour(scene, nov, grid_1).reshape(len(nov), H, W, 3).transpose(0, 3, 1, 2)
        enc_hm = renderer.encoder_heatmaps(scene) if hasattr(renderer, "encoder_heatmaps") else None
        enc_flip = None if enc_hm is None else flip_tested(renderer, scene, enc_hm)
        acc.add(scene_metrics(scene, hm, rgb, nov, renderer.background, encoder_heatmaps=enc_hm,
                              encoder_heatmaps_flip=enc_flip, skeleton_prior=getattr(renderer, "skeleton_prior", None)))
        if progress and (i + 1) % 32 == 0:
            print(f"  eval {i + 1}/{n} {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
    res = acc.result()
    res["wall_s"] = round(time.monotonic() - t0, 1)
    return res


def make_renderer(spec: str, threads: int = 2) -> tuple[Renderer, dict]:
    """A renderer and a description from a model spec (``x.pt``, ``folder`` or ``folder#int8``); a spec that
    cannot be loaded is an :class:`EvalInputError` (or the trainer's ``ConfigError``) naming the file."""
    path, _, precision = spec.partition("#")
    p = Path(path)
    if p.suffix == ".pt":
        from training.train import load_model

        if not p.is_file():
            raise EvalInputError(f"{p}: no such checkpoint")
        model, ck = load_model(p)
        return TorchRenderer(model), {"kind": "torch", "path": str(p), "step": ck.get("step"),
                                      "variant": "ghnerf" if model.human is not None else "baseline"}
    precision = precision or "fp32"
    if precision not in ("fp32", "int8"):
        raise EvalInputError(f"{spec}: precision must be fp32 or int8, got {precision!r}")
    if p.is_file():  # a checkpoint saved as .pth, say: "no such model folder" said it was not there
        raise EvalInputError(f"{p}: a file, not a model folder; a checkpoint is read by its name ending .pt "
                             "(a spec is x.pt, a folder of graphs, or folder#int8)")
    if not p.is_dir():
        raise EvalInputError(f"{p}: no such model folder (a spec is x.pt, a folder of graphs, or folder#int8)")
    r = OnnxRenderer(p, precision, threads)
    return r, {"kind": f"onnx-{precision}", "path": str(p), "variant": r.contract.variant}


def open_eval_dataset(data: str, split: str, renderer: Renderer, label: str):
    """The split as ``renderer`` reads it, refused up front when it holds no scene or its resolution is not the
    model's (it would render a scene first and then fail)."""
    from training.data.targets import TargetConfig
    from training.data.torch_dataset import MultiViewDataset

    ds = MultiViewDataset(data, split, TargetConfig(heatmap_stride=renderer.heatmap_stride))
    if len(ds) == 0:  # scored nothing and wrote "scenes": 0 with every metric null, exit 0
        raise EvalInputError(f"{data}: split {split!r} holds no scenes: nothing to evaluate")
    if (ds.resolution, ds.resolution) != (renderer.height, renderer.width):
        raise EvalInputError(f"{data}: holds {ds.resolution} px scenes, model {label} takes "
                             f"{renderer.width}x{renderer.height}: evaluate it on a dataset of its resolution")
    return ds


def prepare(items: list[ModelItem], data: str, split: str, threads: int) -> list[tuple[str, Renderer, dict, object]]:
    """``(label, renderer, description, dataset)`` of every ``--model`` (as the parser split it): all loaded and
    checked before the first scene is rendered, so a bad spec fails in seconds, not after the models before it were
    scored."""
    out = []
    for item in items:
        try:
            renderer, desc = make_renderer(item.spec, threads)
        except EvalInputError as e:  # "m.json: a file, not a model folder" said no option: which --model gave it
            raise EvalInputError(f"--model {item.text}: {e}") from None
        out.append((item.name, renderer, desc, open_eval_dataset(data, split, renderer, item.name)))
    return out


def _kept_words(finished: list[str], saved: list[str], out: str | None) -> str:
    """What a stopped ``ghnerf-eval`` kept: the models it finished and, with ``--out``, the ones that file holds
    (the last finished one is not in it when the stop came during its write). A rerun evaluates every model again."""
    words = f"models finished: {', '.join(finished) or 'none'}"
    if out and saved:
        words += "; " + (f"{out} holds them" if saved == finished else f"{out} holds {', '.join(saved)}")
    return words


def main(argv: list[str] | None = None) -> int:
    from training.cli.evaluate import build_parser  # noqa: PLC0415

    ap = build_parser()
    args = ap.parse_args(argv)
    if args.limit < 0:
        ap.error(f"--limit: must be >= 0 (0: every scene), got {args.limit}")
    if problem := threads_problem(args.threads, 1):  # torch.set_num_threads: a traceback for 0 and past a C int
        ap.error(f"--threads: {problem}")
    labels = [item.name for item in args.model]
    if dup := sorted({label for label in labels if labels.count(label) > 1}):
        # two runs' last.pt are both "last": the second model's scores replaced the first's in the JSON
        ap.error(f"--model: the label {', '.join(dup)} is given twice; name each model, e.g. --model a=runs/a/last.pt")
    if args.out:  # written after minutes of evaluation: its place is settled first
        # --out x.pt beside --model x.pt replaced the checkpoint with the scores, after the evaluation
        clash = output_clash({"--out": args.out}, {f"--model {item.text}": item.path for item in args.model})
        # --out m/encoder.onnx beside --model m (a graph folder) replaced the graph the same way
        clash = clash or next(filter(None, (model_file_clash({"--out": args.out}, item.path, f"--model {item.text}")
                                            for item in args.model if Path(item.path).is_dir())), None)
        if clash:
            ap.error(clash)
        args.out = ready_output_arg(ap, args.out, "--out")
    torch.set_num_threads(args.threads)
    from training.data.errors import DataError
    from training.model.config import ConfigError

    try:
        runs = prepare(args.model, args.data, args.split, args.threads)
    except (EvalInputError, ConfigError, DataError) as e:
        print(f"ghnerf-eval: error: {e}", file=sys.stderr)
        return 2
    results: dict = {"data": args.data, "split": args.split, "pck_alpha": PCK_ALPHA,
                     "pck_reference": "neck--mid-hip distance (fallback: torso box diagonal)", "models": {}}
    saved: list[str] = []  # the models --out holds: a stop inside a write leaves the file before it (write_atomic)
    try:
        with sigterm_as_interrupt():  # `timeout`, `kill`, a job scheduler: stopped as Ctrl-C stops it
            for label, renderer, desc, ds in runs:
                print(f"evaluating {label} ({desc['kind']}) on {args.split}", file=sys.stderr, flush=True)
                results["models"][label] = {**desc, **evaluate(renderer, ds, args.limit, not args.no_novel)}
                if args.out:  # each finished model kept, whole, whatever happens to the next
                    write_atomic(args.out, strict_json(results))
                    saved = list(results["models"])
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: a line saying what was kept, not a traceback
        print(f"ghnerf-eval: stopped ({stop_words(e)}); {_kept_words(list(results['models']), saved, args.out)}",
              file=sys.stderr)
        return exit_status(e)
    print(strict_json(results))
    return 0

