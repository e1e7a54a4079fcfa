"""Shared pieces of the runtime benchmarks and tests: the *oracle* session, the session taps
(:class:`SessionTap`, :class:`RenderTap`: what the estimator ran, lanes included), and re-exports of the
simulator sequences (``ghnerf_runtime.cli.simdata``).

Not part of the runtime; used by ``benchmarks/compare_3d_methods.py``,
``benchmarks/bench_runtime_regions.py`` and the runtime tests.

Oracle session
    :class:`OracleSession` has the :class:`~ghnerf_runtime.session.ModelSession` interface and
    answers every graph with what a perfectly trained model is trained to produce, computed
    from the ground truth: Gaussian joint heatmaps (sigma 1.5 heatmap cells, as the training
    targets) at the true joints' projections (0 for joints the truth marks occluded), a
    heatmap-weighted joint depth, and a 3D Gaussian response for the ``query`` graph. Running
    the estimator on it measures the error of everything *around* the model (crops, decoding,
    coordinate mapping, the 3D methods) and checks the geometry end to end, whatever the state
    of training. It is a reference, not a stand-in for the model's accuracy.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Mapping

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.simdata import (  # noqa: E402,F401  (re-exported)
    Accuracy,
    Sequence,
    default_cache_dir,
    load_sequences,
    percentiles,
)
from ghnerf_runtime.body25 import FLIP_INDEX  # noqa: E402
from ghnerf_runtime.contract import LevelSpec, ModelContract  # noqa: E402


def edge128_contract() -> ModelContract:
    """The ``edge128`` preset's contract, built without torch (for oracle runs without a model)."""
    return ModelContract.build(
        height=128, width=128, variant="ghnerf",
        levels=(LevelSpec(8, 16, 8, "inverse", "feat_s4", "interval"),
                LevelSpec(4, 4, 4, "linear", "feat_s2", "planes")),
        channels={"feat_s1": 8, "feat_s2": 16, "feat_s4": 16, "volume": 8, "human_feat": 32},
        strides={"feat_s1": 1, "feat_s2": 2, "feat_s4": 4, "human_feat": 4},
        encoder_heatmaps=True,
    )


# ------------------------------------------------------------------ oracle
class OracleSession:
    """The :class:`ModelSession` interface answered from the ground truth (module docstring).

    Set the truth of the pair before each ``estimate``: :meth:`set_truth`.

    Args:
        contract: the contract to mimic (from any exported model of the wanted resolution).
        heat_sigma_cells: heatmap Gaussian sigma in heatmap cells (training targets: 1.5).
        query_sigma_m: 3D Gaussian sigma of the ``query`` response.
    """

    def __init__(self, contract: ModelContract, heat_sigma_cells: float = 1.5, query_sigma_m: float = 0.05) -> None:
        self.contract = contract
        self.sigma_px = heat_sigma_cells * contract.heatmap_stride
        self.query_sigma = query_sigma_m
        self.graphs = tuple(g.name for g in contract.graphs)
        self.run_counts = {g: 0 for g in self.graphs}
        self.truth: np.ndarray | None = None
        self.visible: np.ndarray | None = None

    def set_truth(self, joints_3d: np.ndarray | None, visible: np.ndarray | None = None) -> None:
        """``(25, 3)`` true joints (``None``: nobody), optional ``(2, 25)`` visibility per source."""
        self.truth = None if joints_3d is None else np.asarray(joints_3d, np.float64)
        self.visible = None if visible is None else np.asarray(visible, bool)

    def has(self, graph: str) -> bool:
        return graph in self.graphs

    def _source_heatmaps(self, src_P: np.ndarray) -> np.ndarray:
        """``(S, J, g, g)`` Gaussians at the true joints' projections on the heatmap grid of each source."""
        c = self.contract
        stride, g = c.heatmap_stride, c.height // c.heatmap_stride
        centres = stride * np.arange(g) + 0.5 * (stride - 1)  # model pixels of the grid cells (contract.ray_grid)
        homog = np.concatenate([self.truth, np.ones((len(self.truth), 1))], axis=1)
        maps = np.zeros((len(src_P), c.num_joints, g, g), np.float32)
        for s, P in enumerate(src_P):
            p = homog @ P.T
            z = p[:, 2]
            uv = p[:, :2] / np.where(z > 1e-6, z, 1.0)[:, None]
            gx = np.exp(-(centres[None, :] - uv[:, :1]) ** 2 / (2 * self.sigma_px ** 2))  # (J, g)
            gy = np.exp(-(centres[None, :] - uv[:, 1:]) ** 2 / (2 * self.sigma_px ** 2))
            seen = (z > 1e-6) & (self.visible[s] if self.visible is not None else True)
            maps[s] = gy[:, :, None] * gx[:, None, :] * seen[:, None, None]
            if np.linalg.det(P[:, :3]) < 0:  # a mirrored camera (the flip test) sees the mirror person:
                maps[s] = maps[s][list(FLIP_INDEX)]  # its right wrist is the person's left one
        return maps

    def _zeros(self, spec, **dims) -> np.ndarray:
        return np.zeros([dims[d] if isinstance(d, str) else d for d in spec.shape], np.float32)

    def run(self, graph: str, feeds: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        self.run_counts[graph] += 1
        spec = self.contract.graph(graph)
        J = self.contract.num_joints
        # "human" too: the turn search scores a turn's crops through the human graph where there is one, and
        # reads only its encoder heatmaps (which the oracle draws from the crops' projections, as for "encoder")
        if graph in ("encoder", "human"):
            out = {t.name: self._zeros(t) for t in spec.outputs}
            if "encoder_heatmaps" in out and self.truth is not None:
                out["encoder_heatmaps"] = self._source_heatmaps(np.asarray(feeds["src_P"], np.float64))
            return out
        if graph == "volume":
            B = len(feeds["tgt_K_inv"])
            return {t.name: self._zeros(t, B=B) for t in spec.outputs}
        if graph == "query":
            pts = np.asarray(feeds["points"], np.float64)  # (B, N, 3)
            if self.truth is None:
                heat = np.zeros(pts.shape[:2] + (J,), np.float32)
            else:
                d2 = ((pts[:, :, None, :] - self.truth[None, None]) ** 2).sum(-1)
                heat = np.exp(-d2 / (2 * self.query_sigma ** 2)).astype(np.float32)
            return {"joint_heat": heat, "density": np.ones(pts.shape[:2], np.float32)}
        # render graphs
        k_inv = np.asarray(feeds["tgt_K_inv"], np.float64)
        c2w = np.asarray(feeds["tgt_c2w"], np.float64)
        rays = np.asarray(feeds["ray_uv"], np.float64)  # (B, R, 2)
        B, R = rays.shape[:2]
        heat = np.zeros((B, R, J), np.float32)
        depth = np.zeros((B, R), np.float32)
        if self.truth is not None:
            for b in range(B):
                K = np.linalg.inv(k_inv[b])
                Rm, centre = c2w[b, :, :3].T, c2w[b, :, 3]
                pc = (self.truth - centre) @ Rm.T
                z = pc[:, 2]
                uv = (pc @ K.T)[:, :2] / np.where(z > 1e-6, z, 1.0)[:, None]
                d2 = ((rays[b, :, None, :] - uv[None]) ** 2).sum(-1)  # (R, J)
                h = np.exp(-d2 / (2 * self.sigma_px ** 2)) * (z > 1e-6)[None]
                if self.visible is not None and B == 2 and graph == "render_heat":
                    h = h * self.visible[b][None]
                heat[b] = h
                w = h.sum(-1)
                depth[b] = np.where(w > 1e-6, (h * z[None]).sum(-1) / np.maximum(w, 1e-6), 0.0)
        acc = np.clip(heat.max(-1) * 2, 0, 1).astype(np.float32)
        out = {"heatmaps": heat, "depth": depth, "acc": acc}
        if graph in ("render", "render_rgb"):
            out["rgb"] = np.repeat(acc[..., None], 3, axis=-1) * 0.8
        return {t.name: out[t.name] for t in spec.outputs}


class SessionTap:
    """A session wrapper that hands :meth:`record` every graph run it passes on; everything else passes through.

    The estimator runs graphs by four doors, not only ``run``: a tracked pair's novel view renders on the
    one-thread lanes (``on_lanes()``, whose ``run`` is ``run_on_lane``) and the flip test's second ``human`` run
    goes beside it (``run_on_lane``) or beside the first (``run_both``). A tap that overrode ``run`` alone let
    those through to the wrapped session unseen (``__getattr__``), so the novel-view scripts recorded only the
    untracked pairs' renders. The lanes stay on: what is timed is the runtime's own path."""

    def __init__(self, session):
        self._session = session

    def __getattr__(self, name):
        return getattr(self._session, name)

    def record(self, graph: str, feeds: Mapping[str, np.ndarray], out: Mapping[str, np.ndarray]) -> None:
        """Called after every run (from the lane worker's thread too); a subclass keeps what it needs."""

    def run(self, graph, feeds):
        out = self._session.run(graph, feeds)
        self.record(graph, feeds, out)
        return out

    def run_on_lane(self, graph, feeds):
        out = self._session.run_on_lane(graph, feeds)
        self.record(graph, feeds, out)
        return out

    def on_lanes(self):
        from ghnerf_runtime.session import LaneRunner

        return LaneRunner(self)  # its run is this tap's run_on_lane

    def run_both(self, graph, first, second):
        out, out2 = self._session.run_both(graph, first, second)
        self.record(graph, first, out)
        self.record(graph, second, out2)
        return out, out2


class RenderTap(SessionTap):
    """A session wrapper recording ``(ray_uv, acc)`` of every colour render (``render_rgb`` / ``render``) it runs,
    for the novel-view scripts (opacity statistics); everything else passes through."""

    def __init__(self, session):
        super().__init__(session)
        self.runs: list[tuple[np.ndarray, np.ndarray]] = []

    def record(self, graph, feeds, out):
        if graph in ("render_rgb", "render"):
            self.runs.append((np.asarray(feeds["ray_uv"][0]), np.asarray(out["acc"][0])))


#: Render factor of :func:`truth_view` before its area reduction (the novel-view scripts' reference picture).
TRUTH_SUPERSAMPLE = 4


def truth_view(scene, camera, t: float, background: float) -> tuple[np.ndarray, np.ndarray]:
    """The simulator's picture of ``camera`` at time ``t`` (rendered at ``TRUTH_SUPERSAMPLE`` x, area-averaged): ``(S, S, 3)`` RGB in [0, 1] composited over
    ``background`` outside the subject, and the ``(S, S)`` subject mask (area share >= 0.5)."""
    big = camera.resized(camera.width * TRUTH_SUPERSAMPLE, camera.height * TRUTH_SUPERSAMPLE)
    image, truth = scene.render(big, t)
    size = (camera.width, camera.height)
    rgb = cv2.resize(image[..., ::-1].astype(np.float32) / 255.0, size, interpolation=cv2.INTER_AREA)
    mask = cv2.resize(truth.mask.astype(np.float32), size, interpolation=cv2.INTER_AREA) >= 0.5
    return np.where(mask[..., None], rgb, np.float32(background)), mask


def contract_of(model_dir: str | os.PathLike) -> ModelContract:
    """The contract stamped in a model folder's encoder (used to build an :class:`OracleSession`)."""
    import onnxruntime as ort

    from ghnerf_runtime.session import resolve_model_dir

    files = sorted(resolve_model_dir(model_dir).glob("encoder*.onnx"))
    if not files:
        raise FileNotFoundError(f"{model_dir}: no encoder*.onnx")
    sess = ort.InferenceSession(str(files[0]), providers=["CPUExecutionProvider"])
    return ModelContract.from_metadata(sess.get_modelmeta().custom_metadata_map)
