"""Train the skeleton prior (``ghnerf_runtime.skeleton_prior``) on a model's own 2D errors, export it.

    python -m training.skeleton_prior --model-dir models/ghnerf --data data/edge128_fs50

1. **Collect**: the model's human encoder (its ``human`` graph, else ``encoder``; int8 when present,
   as the runtime loads it) runs on every scene of the training split, with the flip test (the
   runtime's default), and its decoded 2D peaks are kept with the scene's cameras and true joints.
   The encoder was trained on those scenes, but its 3D error there is the held-out one's (78.7 vs
   73.4 mm gated MPJPE, session 16), so its errors on them are a fair sample of the device's.
2. **Train**: an MLP (``--hidden`` wide, three hidden layers) from :func:`prior_inputs`' features
   to the canonical-frame skeleton (a residual on the triangulated points) and the log of each
   joint's expected error. Loss: the mean joint distance (MPJPE itself) plus a Laplace likelihood
   of the detached distance for the error head. Augmented by mirroring and by hiding joints in
   one view (as the reprojection gate and occlusion do). ``--members K`` trains K such networks
   (seeds ``seed..seed+K-1``; side by side, one process each, as far as ``--threads`` goes) and exports
   their mean as one file. A NaN or infinite loss or gradient stops the run before that update, in one
   line naming the seed and the step (``training.step_guard``; exit 1, nothing written).
3. **Export** ``skeleton_prior.onnx`` (fp32; 1.6 M weights per network: int8 would save nothing that
   matters) with ``ghnerf_skeleton.*`` metadata, and **evaluate** on the held-out split:
   ``skeleton_prior.json`` beside it (MPJPE over all joints, and gated by the expected error).

torch for training and export only; the device runs the ONNX file.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ghnerf_runtime.body25 import FLIP_INDEX, NUM_JOINTS
from ghnerf_runtime.cli.output_path import ready_output_arg
from ghnerf_runtime.skeleton_prior import (
    CONTEXT_FEATURES,
    FEATURE_VERSION,
    FILE_NAME,
    INPUTS,
    JOINT_FEATURES,
    META_PREFIX,
    OUTPUTS,
    PriorInputs,
    mirror_inputs,
    prior_inputs,
)
from training.cli import at_least
from training.model_card import strict_json, write_atomic
from training.run_limits import seed_problem

#: What a tilted training copy turns (``PriorTrainConfig.tilt_mode``).
TILT_MODES = ("scene", "body")
#: Expected-error gates the evaluation reports (m); the runtime's default is one of them.
GATES_M = (0.03, 0.05, 0.075, 0.1, 0.15, math.inf)


@dataclass(frozen=True)
class PriorTrainConfig:
    """How the prior is trained (recorded in the file's metadata and the metrics)."""

    steps: int = 15000
    hidden: int = 768
    batch: int = 256
    lr: float = 1e-3
    weight_decay: float = 1e-4
    hide_joint_prob: float = 0.1
    seed: int = 0
    members: int = 1
    """Networks averaged in the exported file, trained alike but from seeds ``seed .. seed + members - 1``
    (their errors are partly independent: the mean of two is better than either)."""
    tilt_share: float = 0.0
    """Tilted copies of this share of the training scenes are added: bodies at any angle to the rig's up, so
    that a lying person is not answered as an upright one."""
    tilt_mode: str = "scene"
    """How a copy is tilted: ``scene``, the whole scene, cameras too (:func:`tilt_scenes`: the peaks stay
    exact), or ``body``, the body alone before the same cameras (:func:`turn_bodies`: the peaks carry the
    encoder's errors over)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.tilt_share <= 1.0:  # also refuses nan
            raise ValueError(f"PriorTrainConfig.tilt_share must be a share from 0 to 1, not {self.tilt_share!r}")
        if self.tilt_mode not in TILT_MODES:
            raise ValueError(f"PriorTrainConfig.tilt_mode must be one of {TILT_MODES}, not {self.tilt_mode!r}")


# ---------------------------------------------------------------------------------------------- collect
#: The graphs a model decodes its 2D joints from, in order of preference (the first the folder has).
KEYPOINT_GRAPHS = ("human", "encoder")


def _heatmap_session(model_dir: Path, threads: int):
    """The model's keypoint graph as the runtime loads it (``human`` when the folder has one, else ``encoder``;
    ``auto`` precision: int8), checked against the model contract."""
    from ghnerf_runtime.config import SessionConfig
    from ghnerf_runtime.session import ModelSession

    config = SessionConfig(model_dir=str(model_dir), threads=threads, warmup=False)
    graph = next((g for g in KEYPOINT_GRAPHS if ModelSession.has_graph_file(config, g)), KEYPOINT_GRAPHS[-1])
    return ModelSession.load(config, (graph,)), graph


def collect(model_dir: str | Path, data: str | Path, split: str, limit: int = 0, flip_test: bool = True,
            threads: int = 2, progress: bool = True,
            per_scene: Callable[[np.ndarray, dict], dict] | None = None) -> dict[str, np.ndarray]:
    """The model's decoded 2D peaks on ``split`` with the cameras and true joints (arrays over scenes).

    ``per_scene(heatmaps, record)``, if given, is called with each scene's heatmaps ``(2, J, h, w)`` (those the
    peaks were decoded from) and its record (``uv``, ``confidence``, ``valid``, ``P``, ...); the arrays it
    returns are kept too, by their names (what a measurement wants of the heatmaps besides the peaks)."""
    from ghnerf_runtime.flip_test import flip_averaged, mirror_images
    from training.data.torch_dataset import MultiViewDataset
    from training.evaluate import _decode

    if limit < 0:
        raise ValueError(f"limit must be 0 (all scenes) or more, not {limit}")
    sess, graph = _heatmap_session(Path(model_dir), threads)
    ds = MultiViewDataset(data, split)
    n = min(limit, len(ds)) if limit else len(ds)
    keys = ("uv", "confidence", "valid", "P", "joints_3d", "joints_3d_valid")
    out: dict[str, list] = {k: [] for k in keys}
    t0 = time.monotonic()
    for i in range(n):
        scene = ds[i]
        images = np.ascontiguousarray(scene["images"].numpy(), np.float32)
        heat = sess.run(graph, {"images": images})["encoder_heatmaps"]
        if flip_test:
            heat = flip_averaged(heat, sess.run(graph, {"images": mirror_images(images)})["encoder_heatmaps"])
        uv, conf = _decode(heat, images.shape[-1], None)
        out["uv"].append(np.nan_to_num(uv))
        out["confidence"].append(conf)
        out["valid"].append(np.isfinite(uv).all(-1))
        out["P"].append(scene["src_P"].numpy())
        out["joints_3d"].append(scene["joints_3d"].numpy())
        out["joints_3d_valid"].append(scene["joints_3d_valid"].numpy())
        if per_scene is not None:
            for k, v in per_scene(heat, {k: out[k][-1] for k in keys}).items():
                out.setdefault(k, []).append(v)
        if progress and (i + 1) % 1000 == 0:
            print(f"  collect {split} {i + 1}/{n} {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
    arrays = {k: np.stack(v) for k, v in out.items()}
    arrays["encoder_file"] = np.array(sess.files[graph].path.name)
    return arrays


def scene_tilt(joints: np.ndarray, joints_valid: np.ndarray, axis_deg: float, angle_deg: float) -> np.ndarray:
    """The ``(4, 4)`` rigid motion that turns a scene by ``angle_deg`` about a horizontal axis (at ``axis_deg``
    from rig +x towards +z) through the mean of the valid true joints ``(J, 3)``, then moves it up or down so
    that its lowest valid joint is as high as before (the body still rests on the floor it stood on)."""
    X = np.asarray(joints, np.float64)[np.asarray(joints_valid, bool)]
    if not len(X) or not np.isfinite(X).all():
        raise ValueError("a scene to tilt needs finite valid true joints; it has none")
    a, t = np.radians(axis_deg), np.radians(angle_deg)
    u = np.array([np.cos(a), 0.0, np.sin(a)])
    ux = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    R = np.cos(t) * np.eye(3) + np.sin(t) * ux + (1.0 - np.cos(t)) * np.outer(u, u)  # Rodrigues
    c = X.mean(0)
    Y = (X - c) @ R.T + c
    G = np.eye(4)
    G[:3, :3] = R
    G[:3, 3] = c - R @ c + [0.0, X[:, 1].max() - Y[:, 1].max(), 0.0]  # y points down: max y is the lowest
    return G


def tilt_scenes(arrays: dict[str, np.ndarray], share: float, seed: int) -> dict[str, np.ndarray]:
    """``arrays`` (:func:`collect`'s) with tilted copies of ``share`` of their scenes appended.

    Each copy is the same scene turned as a whole, the true joints and both cameras together
    (:func:`scene_tilt`: a random horizontal axis, an angle uniform in 0-180 degrees): the cameras see
    exactly what they saw, so the decoded 2D peaks, their values and the decoded flags are the collected
    ones (no rendering, no encoder run), while the rig's up, which :func:`prior_inputs`' canonical frame
    keeps, now meets the body at that angle. The tilted cameras are not where a device's stand (a lying
    body is then seen from above, below or the side), and the peaks are the encoder's errors on an upright
    person's images, not on a lying one's: the copies teach that a body may lie at any angle, not how the
    encoder errs on it. Scenes with no valid true joint are not chosen (nothing to learn from them).
    """
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"tilt share must be from 0 to 1, not {share!r}")
    valid = np.asarray(arrays["joints_3d_valid"], bool)
    usable = np.flatnonzero(valid.any(1))
    rng = np.random.default_rng([seed, 0x7117])  # its own stream: the training's draws do not move
    chosen = np.sort(rng.choice(usable, size=int(round(share * len(usable))), replace=False))
    if not len(chosen):
        return arrays
    G = np.stack([scene_tilt(arrays["joints_3d"][i], valid[i], rng.uniform(0.0, 360.0), rng.uniform(0.0, 180.0))
                  for i in chosen])
    P = np.asarray(arrays["P"], np.float64)[chosen] @ np.linalg.inv(G)[:, None]  # P' X' = P X for X' = G X
    J = np.asarray(arrays["joints_3d"], np.float64)[chosen]
    J = np.einsum("nij,nkj->nki", G[:, :3, :3], J) + G[:, None, :3, 3]
    tilted = {k: (np.asarray(v)[chosen] if k != "encoder_file" else v) for k, v in arrays.items()}
    tilted["P"] = P.astype(np.asarray(arrays["P"]).dtype)
    tilted["joints_3d"] = J.astype(np.asarray(arrays["joints_3d"]).dtype)
    return {k: (v if k == "encoder_file" else np.concatenate([v, tilted[k]])) for k, v in arrays.items()}


def _project(P: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``(J, 2)`` of points ``(J, 3)`` through ``P`` ``(3, 4)``, and whether each lies in front."""
    h = np.c_[X, np.ones(len(X))] @ P.T
    depth = h[:, 2] * np.sign(np.linalg.det(P[:, :3]))
    return h[:, :2] / np.where(np.abs(h[:, 2:]) > 1e-12, h[:, 2:], 1e-12), depth > 1e-6


def turn_bodies(arrays: dict[str, np.ndarray], share: float, seed: int, size: int) -> dict[str, np.ndarray]:
    """``arrays`` with copies of ``share`` of their scenes appended whose *body alone* is turned
    (:func:`scene_tilt`), before the same cameras: each view's crop is refitted to the turned body (a
    pixel scale and shift of the crop camera, as the runtime's ROI follows a person), and each joint's
    peak is its exact image there plus the encoder's error on it in the collected scene (peak minus the
    true joint's image, model pixels). Peak values and decoded flags stay; a joint whose peak falls outside
    the ``size``-pixel crop, or with no true joint, is not decoded. Scenes where a turned joint would lie
    behind a camera are left out. The encoder's errors on a lying person's images are not these (they
    come from the upright images), and a part hidden by the turned body is not hidden here."""
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"tilt share must be from 0 to 1, not {share!r}")
    valid = np.asarray(arrays["joints_3d_valid"], bool)
    usable = np.flatnonzero(valid.sum(1) >= 2)  # a crop needs an extent
    rng = np.random.default_rng([seed, 0x7117])
    chosen = np.sort(rng.choice(usable, size=int(round(share * len(usable))), replace=False))
    keep, new = [], {k: [] for k in ("uv", "valid", "P", "joints_3d")}
    for i in chosen:
        X, tv = np.asarray(arrays["joints_3d"][i], np.float64), valid[i]
        G = scene_tilt(X, tv, rng.uniform(0.0, 360.0), rng.uniform(0.0, 180.0))
        Y = np.where(tv[:, None], X @ G[:3, :3].T + G[:3, 3], X)
        uv, dec = np.array(arrays["uv"][i], np.float64), np.array(arrays["valid"][i], bool) & tv
        Ps, ok = [], True
        for v in range(2):
            P = np.asarray(arrays["P"][i, v], np.float64)
            (q, front), (q2, front2) = _project(P, X), _project(P, Y)
            if not (front2[tv].all() and front[tv].all()):
                ok = False
                break
            lo, hi, lo2, hi2 = q[tv].min(0), q[tv].max(0), q2[tv].min(0), q2[tv].max(0)
            scale = max(hi - lo) / max(max(hi2 - lo2), 1e-6)  # the body fills the crop as much as before
            A = np.eye(3)
            A[:2, :2] *= scale
            A[:2, 2] = 0.5 * (lo + hi) - scale * 0.5 * (lo2 + hi2)
            Ps.append(A @ P)
            uv[v] = q2 * scale + A[:2, 2] + (uv[v] - q)
            dec[v] &= np.isfinite(uv[v]).all(-1) & (uv[v] >= 0).all(-1) & (uv[v] <= size - 1).all(-1)
        if not ok:
            continue
        keep.append(i)
        for k, val in (("uv", np.where(dec[..., None], uv, 0.0)), ("valid", dec), ("P", np.stack(Ps)),
                       ("joints_3d", Y)):
            new[k].append(val)
    if not keep:
        return arrays
    turned = {k: (np.asarray(v)[keep] if k != "encoder_file" else v) for k, v in arrays.items()}
    for k, v in new.items():
        turned[k] = np.stack(v).astype(np.asarray(arrays[k]).dtype)
    return {k: (v if k == "encoder_file" else np.concatenate([v, turned[k]])) for k, v in arrays.items()}


def inputs_of(arrays: dict[str, np.ndarray]) -> tuple[PriorInputs, np.ndarray]:
    """The prior's inputs and the canonical-frame truth of collected arrays."""
    inp = prior_inputs(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"])
    return inp, inp.frame.to_canonical(np.asarray(arrays["joints_3d"], np.float64))


# ---------------------------------------------------------------------------------------------- model
def make_network(hidden: int, joint_features: int = JOINT_FEATURES):
    """``joint_features``: the width of each joint's features (:data:`JOINT_FEATURES`; a measurement of other
    features passes its own)."""
    import torch
    from torch import nn

    class SkeletonPriorNet(nn.Module):
        """Features of all joints and the pair -> canonical joints (residual on the triangulated ones)
        and the log of their expected error (m)."""

        def __init__(self) -> None:
            super().__init__()
            self.trunk = nn.Sequential(nn.Linear(NUM_JOINTS * joint_features + CONTEXT_FEATURES, hidden), nn.GELU(),
                                       nn.Linear(hidden, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU())
            self.joints = nn.Linear(hidden, NUM_JOINTS * 3)
            self.log_error = nn.Linear(hidden, NUM_JOINTS)
            nn.init.zeros_(self.joints.weight)
            nn.init.zeros_(self.joints.bias)
            nn.init.zeros_(self.log_error.weight)
            nn.init.constant_(self.log_error.bias, math.log(0.1))

        def forward(self, joint_features, context):
            h = self.trunk(torch.cat([joint_features.flatten(1), context], 1))
            joints = joint_features[..., :3] + self.joints(h).view(-1, NUM_JOINTS, 3)
            return joints, self.log_error(h)

    return SkeletonPriorNet()


def make_ensemble(nets):
    """One network answering the mean of ``nets``' joints and the log of the mean of their expected
    errors (so one file, one run, the same I/O as a single network)."""
    import torch
    from torch import nn

    class SkeletonPriorEnsemble(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.members = nn.ModuleList(nets)

        def forward(self, joint_features, context):
            outs = [m(joint_features, context) for m in self.members]
            joints = torch.stack([o[0] for o in outs]).mean(0)
            log_error = torch.logsumexp(torch.stack([o[1] for o in outs]), 0) - math.log(len(outs))
            return joints, log_error

    return SkeletonPriorEnsemble().eval()


def _hide_in_one_view(f, prob: float, gen):
    """Some joints lose one view (as occlusion and the gates do): each joint with probability ``prob``, in a
    view drawn at random (:func:`_hide_joints`)."""
    import torch

    N, J, _ = f.shape
    hide = torch.rand(N, J, generator=gen) < prob
    view = torch.randint(0, 2, (N, J), generator=gen)
    return _hide_joints(f, hide, view)


def _hide_joints(f, hide, view):
    """``f`` with the joints ``hide`` ``(N, J)`` bool undecoded in their view ``view`` ``(N, J)`` (0 or 1), as
    :func:`prior_inputs` builds such a joint: no triangulated point, ray angle nor reprojection error (in
    either view: the device has none without a DLT point), no peak value, ray or decoded flag in that view;
    the other view's peak value, ray and flag stay. The pair is not rebuilt: on the device, losing a joint
    that helped place the body's centre also moves the canonical frame a little (the other view's ray and
    the other joints' features with it), which rebuilding every batch through :func:`prior_inputs` (a DLT
    per pair) would cost too much to follow. Columns past :data:`JOINT_FEATURES` (a measurement's extra
    features) are per view, view 0's half first."""
    import torch

    width = f.shape[-1]
    f = f.clone()
    f[..., 0:4] = torch.where(hide[..., None], 0.0, f[..., 0:4])
    f[..., 6:9] = torch.where(hide[..., None], 0.0, f[..., 6:9])
    for v in (0, 1):
        h = hide & (view == v)
        for col in (4 + v, 15 + v):
            f[..., col] = torch.where(h, 0.0, f[..., col])
        f[..., 9 + 3 * v:12 + 3 * v] = torch.where(h[..., None], 0.0, f[..., 9 + 3 * v:12 + 3 * v])
        k = (width - JOINT_FEATURES) // 2
        if k:
            cols = slice(JOINT_FEATURES + k * v, JOINT_FEATURES + k * (v + 1))
            f[..., cols] = torch.where(h[..., None], 0.0, f[..., cols])
    return f


def train(inputs: PriorInputs, truth: np.ndarray, truth_valid: np.ndarray, config: PriorTrainConfig,
          progress: bool = True, threads: int | None = None):
    """The trained network (torch, eval mode): one, or the ensemble of ``config.members``.

    ``threads`` (None: torch's current setting, one member after the other): with several members and
    ``threads`` >= 2 the members train side by side, in processes of ``threads // processes`` threads each
    (:func:`member_lanes`). This small network gains little from a second thread, so the recipe's two networks
    at one thread each took 900 s against 1422 s one after the other at two (docs/training.md, "Lanes that
    share the cores"). The thread counts follow from ``members`` and
    ``threads`` alone, so a rerun on the same machine trains the same weights.
    """
    import torch

    seeds = [config.seed + k for k in range(config.members)]
    processes, each = member_lanes(config.members, threads) if threads else (1, torch.get_num_threads())
    if processes == 1:
        before = torch.get_num_threads()
        torch.set_num_threads(each)
        try:
            nets = [_train_one(inputs.joint_features, inputs.context, truth, truth_valid, config, s, progress)
                    for s in seeds]
        finally:
            torch.set_num_threads(before)
        return nets[0] if config.members == 1 else make_ensemble(nets)
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    arrays = (inputs.joint_features, inputs.context, np.asarray(truth), np.asarray(truth_valid))
    # spawn, not fork: a forked child of a process whose OpenMP pool has run can hang in its first parallel region
    with ProcessPoolExecutor(processes, mp.get_context("spawn")) as pool:
        states = list(pool.map(_train_member, [(arrays, config, s, progress, each) for s in seeds]))
    nets = []
    for state in states:
        net = make_network(config.hidden, inputs.joint_features.shape[-1])
        net.load_state_dict({k: torch.from_numpy(v) for k, v in state.items()})
        nets.append(net.eval())
    return make_ensemble(nets)


def member_lanes(members: int, threads: int) -> tuple[int, int]:
    """``(processes, threads each)`` for training ``members`` networks with ``threads`` threads in all."""
    processes = max(1, min(members, threads))
    return processes, max(1, threads // processes)


def _train_member(job) -> dict[str, np.ndarray]:
    """One member in a worker process: its weights as arrays (plain pickles, no shared-memory handles)."""
    import torch

    (features, context, truth, truth_valid), config, seed, progress, threads = job
    torch.set_num_threads(threads)
    net = _train_one(features, context, truth, truth_valid, config, seed, progress)
    return {k: v.detach().numpy().copy() for k, v in net.state_dict().items()}


def _train_one(joint_features: np.ndarray, context: np.ndarray, truth: np.ndarray, truth_valid: np.ndarray,
               config: PriorTrainConfig, seed: int, progress: bool):
    """One network, trained on the arrays; :class:`~training.step_guard.TrainingDiverged` (naming the seed and
    the step) where a step's loss or gradients are NaN or infinite, before that update."""
    import torch

    from training.step_guard import TrainingDiverged, finite_step

    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    f_all = torch.from_numpy(joint_features)
    c_all = torch.from_numpy(context)
    y_all = torch.from_numpy(np.nan_to_num(truth).astype(np.float32))  # invalid joints weigh 0
    w_all = torch.from_numpy(np.asarray(truth_valid, np.float32))
    net = make_network(config.hidden, f_all.shape[-1])
    opt = torch.optim.AdamW(net.parameters(), config.lr, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, config.lr, total_steps=max(config.steps, 2))
    t0 = time.monotonic()
    for step in range(config.steps):
        idx = torch.randint(0, len(f_all), (config.batch,), generator=gen)
        f, c, y, w = f_all[idx], c_all[idx], y_all[idx], w_all[idx]
        mir = torch.rand(len(idx), generator=gen) < 0.5
        if mir.any():
            fm, cm, ym = mirror_inputs(f[mir], c[mir], y[mir])
            f, c, y, w = f.clone(), c.clone(), y.clone(), w.clone()
            f[mir], c[mir], y[mir] = fm, cm, ym
            w[mir] = w[mir][:, list(FLIP_INDEX)]
        f = _hide_in_one_view(f, config.hide_joint_prob, gen)
        joints, log_err = net(f, c)
        dist = torch.where(w > 0, (joints - y).norm(dim=-1), 0.0)
        # the error head: a Laplace likelihood of the (detached) distance; log b kept to 1 mm..20 m so that
        # a confident early guess cannot blow dist / b up
        log_b = log_err.clamp(-7.0, 3.0)
        loss_joints = dist.sum() / w.sum().clamp(min=1)
        loss_error = torch.where(w > 0, dist.detach() / log_b.exp() + log_b, 0.0).sum() / w.sum().clamp(min=1)
        loss = loss_joints + 0.01 * loss_error
        opt.zero_grad()
        loss.backward()
        try:  # before the update: AdamW would spread a NaN to every weight, and the file would answer NaN
            finite_step(loss, net, step + 1)
        except TrainingDiverged as e:
            raise TrainingDiverged(f"seed {seed}, {e}") from None
        opt.step()
        sched.step()
        if progress and (step % 1000 == 0 or step == config.steps - 1):
            print(f"  prior (seed {seed}) step {step}/{config.steps} MPJPE {1e3 * loss_joints.item():.1f} mm "
                  f"{time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)
    return net.eval()


# ---------------------------------------------------------------------------------------------- export
def export(net, path: str | Path, metadata: dict[str, str]) -> Path:
    """``net`` as an ONNX file with a dynamic batch and the ``ghnerf_skeleton.*`` metadata.

    Built in memory and written whole (a temporary file in the same folder, then ``os.replace``): an
    interrupted export leaves the old file or the new one, never one without the metadata, which the
    runtime refuses (and with it the whole model folder's prior)."""
    import io

    import onnx
    import torch

    path = Path(path)
    f = torch.zeros(1, NUM_JOINTS, JOINT_FEATURES)
    c = torch.zeros(1, CONTEXT_FEATURES)
    buf = io.BytesIO()
    torch.onnx.export(net, (f, c), buf, input_names=list(INPUTS), output_names=list(OUTPUTS),
                      opset_version=17, dynamo=False, dynamic_axes={n: {0: "N"} for n in (*INPUTS, *OUTPUTS)})
    model = onnx.load_from_string(buf.getvalue())
    meta = {"feature_version": str(FEATURE_VERSION), "num_joints": str(NUM_JOINTS), **metadata}
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = META_PREFIX + k, str(v)
    write_atomic(path, model.SerializeToString())
    return path


# ---------------------------------------------------------------------------------------------- evaluate
def error_stats(errors_mm: np.ndarray) -> dict:
    """Mean, median, p90 (mm; None when there is no joint) and count of joint errors."""
    e = np.asarray(errors_mm, np.float64)
    return {"mean_mm": float(e.mean()) if e.size else None, "median_mm": float(np.median(e)) if e.size else None,
            "p90_mm": float(np.percentile(e, 90)) if e.size else None, "joints": int(e.size)}


def score(points: np.ndarray, expected_error: np.ndarray, truth: np.ndarray, truth_valid: np.ndarray,
          triangulated: np.ndarray) -> dict:
    """MPJPE (mm) of the prior's joints over all true joints, over the triangulated / filled ones, and
    gated by the expected error (:data:`GATES_M`: share of true joints kept, mean, median)."""
    err = 1e3 * np.linalg.norm(points - truth, axis=-1)
    valid = np.asarray(truth_valid, bool)

    def stats(mask):
        return error_stats(err[mask])

    out = {"all": stats(valid), "triangulated": stats(valid & triangulated), "filled": stats(valid & ~triangulated)}
    out["gated"] = {("inf" if math.isinf(g) else f"{g:g}"): {**stats(valid & (expected_error <= g)),
                                                              "found": float((valid & (expected_error <= g)).sum()
                                                                             / max(valid.sum(), 1))}
                    for g in GATES_M}
    return out


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def card_summary(folder: str | Path) -> dict | None:
    """The prior's held-out figures (``skeleton_prior.json`` in ``folder``) as the model card keeps them."""
    path = (Path(folder) / FILE_NAME).with_suffix(".json")
    if not path.is_file():
        return None
    r = json.loads(path.read_text())
    return {k: r.get(k) for k in ("command", "split", "scenes", "train_scenes", "trained_on", "encoder_file",
                                  "flip_test", "config", "collect_s", "train_s", "metrics", "trained_beside",
                                  "tilted_scenes")
            if k in r or k not in ("trained_beside", "tilted_scenes")}  # newer keys: absent from older files


def add_to_card(card_dir: str | Path, out: Path) -> Path:
    """Record the prior ``out`` (figures, size, hash) in the model card of ``card_dir`` and re-render it.

    ``out`` must be named :data:`FILE_NAME`: the card keeps one prior per model folder, the file the runtime
    loads (its figures are read from ``skeleton_prior.json`` beside it; another name's would be recorded
    under this one's)."""
    from training.model_card import write_card

    out = Path(out)
    if out.name != FILE_NAME:
        raise ValueError(f"{out}: the model card records the prior the runtime loads, {FILE_NAME}")
    card_dir = Path(card_dir)
    card = json.loads((card_dir / "model_card.json").read_text())
    variant = out.parent.name
    card.setdefault("skeleton_prior", {})[variant] = card_summary(out.parent)
    card.setdefault("files", {})[str(out.resolve().relative_to(card_dir.resolve()))] = {"bytes": out.stat().st_size,
                                                                     "sha256": _sha256(out)}
    write_card(card_dir, card)
    return card_dir / "model_card.json"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m training.skeleton_prior", description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model-dir", required=True, help="the exported model folder (models/ghnerf)")
    ap.add_argument("--data", required=True, help="the cached dataset (training split: train, held out: val)")
    ap.add_argument("--out", default=None, help=f"the ONNX file (default: <model-dir>/{FILE_NAME})")
    ap.add_argument("--train-split", default="train")
    ap.add_argument("--extra-data", action="append", default=[],
                    help="another dataset folder whose training split the prior also learns from (repeatable; "
                         "made by python -m training.data.generate with another --seed; --novel-views 0 suffices)")
    ap.add_argument("--val-split", default="val")
    ap.add_argument("--limit", type=int, default=0, help="scenes per split (0: all)")
    ap.add_argument("--steps", type=at_least(1), default=PriorTrainConfig.steps)
    ap.add_argument("--hidden", type=at_least(1), default=PriorTrainConfig.hidden)
    ap.add_argument("--lr", type=float, default=PriorTrainConfig.lr)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--members", type=int, default=1,
                    help="networks averaged in the file (seeds seed..seed+members-1), trained side by side "
                         "when --threads allows (one thread each at two members and two threads)")
    ap.add_argument("--tilt-share", type=float, default=PriorTrainConfig.tilt_share,
                    help="add tilted copies of this share (0-1) of the training scenes, turned about a random "
                         "horizontal axis (--tilt-mode says what turns), so the prior learns bodies lying at any "
                         "angle")
    ap.add_argument("--tilt-mode", choices=TILT_MODES, default=PriorTrainConfig.tilt_mode,
                    help="scene: the copies turn the whole scene, cameras too (the peaks stay exact); body: the "
                         "body alone, before the same cameras (crop refitted, the encoder's 2D errors carried over)")
    ap.add_argument("--no-flip-test", action="store_true", help="collect without the flip test")
    ap.add_argument("--threads", type=at_least(1), default=2)
    ap.add_argument("--card", help="a model card folder (models) to record the prior in (model_card.json, "
                                   "MODEL_CARD.md); the pipeline's card stage does it for new models")
    args = ap.parse_args(argv)
    command = " ".join(["python -m training.skeleton_prior", *(argv if argv is not None else sys.argv[1:])])

    import torch

    torch.set_num_threads(args.threads)
    from ghnerf_runtime.session import resolve_model_dir

    # read as the runtime and collect() read it (models -> models/ghnerf): for the default --out and the
    # encoder's hash too
    model_dir = resolve_model_dir(args.model_dir)
    out = Path(args.out) if args.out else model_dir / FILE_NAME
    if args.members < 1:
        ap.error(f"--members must be at least 1, not {args.members}")
    if problem := seed_problem(args.seed):  # torch's or numpy's traceback once the scenes were collected
        ap.error(f"--seed: {problem}")
    if problem := seed_problem(args.seed + args.members - 1):  # the members train from seed .. seed + members - 1
        ap.error(f"--seed {args.seed} with --members {args.members}: the last member's seed {problem}")
    if args.limit < 0:
        ap.error(f"--limit must be 0 (all scenes) or more, not {args.limit}")
    # the held-out figures must be of scenes the prior did not learn from
    if args.train_split == args.val_split:
        ap.error(f"--train-split and --val-split are both {args.train_split!r}: the held-out figures would be "
                 "training figures")
    seen = {Path(args.data).resolve(): "--data"}
    for extra in args.extra_data:
        if Path(extra).resolve() in seen:
            ap.error(f"--extra-data {extra} is the folder {seen[Path(extra).resolve()]} already gives: its "
                     f"{args.train_split!r} scenes would count twice")
        seen[Path(extra).resolve()] = "--extra-data"
    out = ready_output_arg(ap, out, "--out")  # written after minutes of collecting and training: settled first
    if args.card:
        from training.model_card import CardError, check_card_dir

        try:
            check_card_dir(args.card, out, "--card")
        except CardError as e:
            ap.error(str(e))
        if out.name != FILE_NAME:  # the card records the file the runtime loads, under that name
            ap.error(f"--card records the prior the runtime loads, {FILE_NAME}; --out {out} has another name "
                     f"(drop --card, or write {FILE_NAME})")
    if not 0.0 <= args.tilt_share <= 1.0:  # before minutes of collecting
        ap.error(f"--tilt-share must be a share from 0 to 1, not {args.tilt_share!r}")
    if not (math.isfinite(args.lr) and args.lr > 0):  # (a NaN or negative rate trained minutes for nothing)
        ap.error(f"--lr must be a finite number above 0, not {args.lr!r}")
    from training.data.cache import ShardedSplit
    from training.data.errors import DataError

    try:  # every split read, opened first (manifest, shards, array headers): the val split is read only after
        # minutes of collecting the training ones, and a damaged one was a traceback
        for data in [args.data, *args.extra_data]:
            ShardedSplit(data, args.train_split)
        ShardedSplit(args.data, args.val_split)
    except DataError as e:
        ap.error(str(e))
    from ghnerf_runtime.errors import RuntimeErrorBase

    try:  # the keypoint graph, loaded as collect() loads it: a folder without it was a traceback (ModelLoadError)
        _heatmap_session(model_dir, args.threads)
    except RuntimeErrorBase as e:  # a ModelLoadError, or the graph against the model contract
        ap.error(f"--model-dir: {e}")  # (the message names the folder)
    config = PriorTrainConfig(steps=args.steps, hidden=args.hidden, lr=args.lr, seed=args.seed,
                              members=args.members, tilt_share=args.tilt_share, tilt_mode=args.tilt_mode)
    t0 = time.monotonic()
    tr = collect(model_dir, args.data, args.train_split, args.limit, not args.no_flip_test, args.threads)
    for extra in args.extra_data:
        more = collect(model_dir, extra, args.train_split, args.limit, not args.no_flip_test, args.threads)
        tr = {k: (v if k == "encoder_file" else np.concatenate([v, more[k]])) for k, v in tr.items()}
    va = collect(model_dir, args.data, args.val_split, args.limit, not args.no_flip_test, args.threads)
    collect_s = time.monotonic() - t0
    collected = len(tr["uv"])
    if config.tilt_mode == "body":
        from training.data.torch_dataset import MultiViewDataset

        size = MultiViewDataset(args.data, args.train_split).resolution  # the crops' side, model pixels
        tr = turn_bodies(tr, config.tilt_share, config.seed, size)
    else:
        tr = tilt_scenes(tr, config.tilt_share, config.seed)
    tr_in, tr_truth = inputs_of(tr)
    from training.step_guard import TrainingDiverged

    try:
        net = train(tr_in, tr_truth, tr["joints_3d_valid"], config, threads=args.threads)
    except TrainingDiverged as e:  # one line; nothing written: the old file and its figures stay as they were
        print(f"error: training diverged: {e}", file=sys.stderr)
        return 1
    train_s = time.monotonic() - t0 - collect_s
    encoder_file = str(tr["encoder_file"])
    trained_on = ",".join(f"{d}:{args.train_split}" for d in [args.data, *args.extra_data])
    # the old figures describe the old file: gone before the new file takes its place, written anew at the end
    out.with_suffix(".json").unlink(missing_ok=True)
    export(net, out, {"trained_on": trained_on, "scenes": str(collected),
                      "tilted_scenes": str(len(tr["uv"]) - collected),
                      "encoder_file": encoder_file,
                      "encoder_sha256": _sha256(model_dir / encoder_file),
                      "flip_test": str(not args.no_flip_test).lower(), "config": json.dumps(asdict(config))})

    from ghnerf_runtime.config import Joints3DConfig
    from ghnerf_runtime.joints3d import triangulate_joints
    from ghnerf_runtime.skeleton_prior import SkeletonPrior

    prior = SkeletonPrior.load(out, args.threads)
    est = prior.estimate(va["uv"], va["confidence"], va["valid"], va["P"])
    metrics = score(est.points, est.expected_error_m, va["joints_3d"], va["joints_3d_valid"], est.triangulated)
    # the runtime runs the prior with its flip test (joints3d.prior_flip_test); what it adds, over every joint
    plain = prior.estimate(va["uv"], va["confidence"], va["valid"], va["P"], flip_test=False)
    metrics["all_without_flip_test"] = score(plain.points, plain.expected_error_m, va["joints_3d"],
                                             va["joints_3d_valid"], plain.triangulated)["all"]
    # the runtime without the prior, same peaks: the gated triangulation
    tri_err, known = [], 0
    for i in range(len(va["uv"])):
        g = triangulate_joints(va["uv"][i], va["confidence"][i], va["valid"][i], list(va["P"][i]), Joints3DConfig())
        keep = g.valid & va["joints_3d_valid"][i]
        tri_err.append(1e3 * np.linalg.norm(g.points[keep] - va["joints_3d"][i][keep], axis=-1))
        known += int(va["joints_3d_valid"][i].sum())
    e = np.concatenate(tri_err)
    metrics["triangulation_gated"] = {**error_stats(e), "found": e.size / max(known, 1)}
    result = {"command": command, "file": str(out), "sha256": _sha256(out), "split": args.val_split,
              "scenes": len(va["uv"]), "train_scenes": collected, "tilted_scenes": len(tr["uv"]) - collected,
              "trained_on": trained_on,
              "encoder_file": encoder_file, "flip_test": not args.no_flip_test, "config": asdict(config),
              "collect_s": round(collect_s, 1), "train_s": round(train_s, 1), "metrics": metrics}
    write_atomic(out.with_suffix(".json"), strict_json(result) + "\n")  # a NaN error (NaN joints) as null
    m, tg = metrics, metrics["triangulation_gated"]

    def mm(v):
        return "n/a" if v is None else f"{v:.1f}"

    print(f"{out}: held out ({args.val_split}, {len(va['uv'])} scenes) all joints MPJPE {mm(m['all']['mean_mm'])} "
          f"mean / {mm(m['all']['median_mm'])} median mm; gated triangulation {mm(tg['mean_mm'])} / "
          f"{mm(tg['median_mm'])} mm over {tg['found']:.0%} of joints; without the prior's flip test "
          f"{mm(m['all_without_flip_test']['mean_mm'])} mean over every joint; {collect_s:.0f} s collect, "
          f"{train_s:.0f} s train")
    for g, s in m["gated"].items():
        print(f"  expected error <= {g} m: {s['found']:.0%} of joints, MPJPE {mm(s['mean_mm'])} mean"
              f" / {mm(s['median_mm'])} median mm")
    if args.card:
        print(f"recorded in {add_to_card(args.card, out)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
