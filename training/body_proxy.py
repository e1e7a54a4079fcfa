"""The body proxy (``ghnerf_runtime.body_proxy``) on dataset scenes: its depth at every view, the
per-person girth fitted to silhouettes, and the tuning of its template on the truth.

The novel-view measurements (docs/training.md, "A learnt painter of the unseen side") rank the
geometry first: a painter of the unseen side reaches 24.5 dB with the true depth and about 20.6 dB
with the depth GHNeRF's cost volume gives today (57 mm median error on the novel views). The proxy
builds the surface from the 3D joints instead; docs/training.md, "A body proxy from the joints", has
what it gives.

The template (``ProxyTemplate``) holds proportions of an average adult; its defaults were tuned on
the *training* split's true joints and depth (``python -m training.body_proxy tune --data ...``;
``--joints`` tunes on a device's joints instead). The simulated bodies are made of the same kinds of
primitives (``drivers.sim.body``), so the proxy fits them better than it would fit clothed people:
what it measures is how far a joint-driven shape prior carries the novel views, not how well it
would fit a real person. numpy; no torch.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, replace
from collections.abc import Mapping

import numpy as np

from ghnerf_runtime.body_proxy import ProxyTemplate, proxy_body, proxy_depth
from ghnerf_runtime.geometry.camera import Camera
from training.cli import at_least

__all__ = ["ProxyTemplate", "proxy_body", "proxy_depth", "view_camera", "iou", "fit_scale", "proxy_scene", "tune"]


def view_camera(scene: Mapping[str, np.ndarray], view: int) -> Camera:
    """The dataset item's target ``view`` as a pinhole camera (rig frame to camera)."""
    c2w = np.asarray(scene["tgt_c2w"][view], np.float64)
    R = c2w[:, :3].T
    H, W = np.asarray(scene["tgt_masks"]).shape[-2:]
    return Camera(f"view{view}", int(W), int(H), np.asarray(scene["tgt_K"][view], np.float64), np.zeros(5), R,
                  -R @ c2w[:, 3])


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def fit_scale(joints: np.ndarray, valid: np.ndarray, cameras: list[Camera], masks: list[np.ndarray],
              template: ProxyTemplate = ProxyTemplate(), scales=np.linspace(0.7, 1.5, 17)) -> float:
    """The girth scale whose proxy silhouettes best overlap ``masks`` (mean IoU over the cameras)."""
    best, best_s = -1.0, 1.0
    for s in scales:
        body = proxy_body(joints, valid, template, s)
        score = np.mean([iou(proxy_depth(body, c) > 0, m) for c, m in zip(cameras, masks)])
        if score > best:
            best, best_s = score, float(s)
    return best_s


def proxy_scene(scene: Mapping[str, np.ndarray], joints: np.ndarray, valid: np.ndarray,
                scale: float | None = 1.0, source_masks: list[np.ndarray] | None = None,
                template: ProxyTemplate = ProxyTemplate()) -> tuple[dict, float]:
    """``scene`` with the proxy's geometry at every view (``tgt_depth``, ``tgt_masks``), like
    ``training.fill_features.modelled_scene``. ``scale``: the girth scale, or None to fit it to
    ``source_masks`` (default: the true masks of the source views). Returns the scene and the scale.

    GHNeRF's own masks (opacity above 0.5) are too fat to fit the scale to (fitted to them the scale
    runs to the top of its range): the template's mean body (1.0) does better on the device's joints
    (docs/training.md, "A body proxy from the joints")."""
    V = len(scene["tgt_is_source"])
    cams = [view_camera(scene, v) for v in range(V)]
    if scale is None:
        src = [v for v in range(V) if scene["tgt_is_source"][v]]
        masks = source_masks if source_masks is not None else [np.asarray(scene["tgt_masks"][v], bool) for v in src]
        scale = fit_scale(joints, valid, [cams[v] for v in src], masks, template)
    body = proxy_body(joints, valid, template, scale)
    depth = np.stack([proxy_depth(body, c) for c in cams]).astype(np.float32)
    return {**scene, "tgt_depth": depth, "tgt_masks": depth > 0}, float(scale)


# ------------------------------------------------------------------ tuning the template on the truth
def _depth_error(scene: Mapping[str, np.ndarray], template: ProxyTemplate, scale: float | None,
                 views: list[int]) -> tuple[float, float]:
    """Mean over ``views`` of (median |depth error| on the true mask where both hit, IoU); ``scale`` as
    :func:`proxy_scene` takes it."""
    joints, valid = np.asarray(scene["joints_3d"], np.float64), np.asarray(scene["joints_3d_valid"], bool)
    proxy, _ = proxy_scene(scene, joints, valid, scale, template=template)
    errs, ious = [], []
    for v in views:
        d = proxy["tgt_depth"][v]
        m = np.asarray(scene["tgt_masks"][v], bool)
        both = m & (d > 0)
        # a view where the proxy misses the subject altogether counts as half a metre off
        errs.append(float(np.median(np.abs(d - scene["tgt_depth"][v])[both])) if both.any() else 0.5)
        ious.append(iou(d > 0, m))
    return float(np.mean(errs)), float(np.mean(ious))


def tune(scenes: list[Mapping[str, np.ndarray]], rounds: int = 2, start: ProxyTemplate = ProxyTemplate(),
         log=print) -> ProxyTemplate:
    """Coordinate descent on the template's fields: mean over scenes and views of the median depth
    error plus 0.1 m times (1 - IoU) of the silhouettes; the per-person scale is held at 1. The
    scenes' ``joints_3d`` are the joints it is built from (the truth, or a device's)."""
    t = start

    def cost(tt: ProxyTemplate) -> float:
        r = [_depth_error(s, tt, 1.0, list(range(len(s["tgt_is_source"])))) for s in scenes]
        return float(np.mean([e + 0.1 * (1 - i) for e, i in r]))

    best = cost(t)
    log(f"start {best * 1000:.1f}")  # mm
    for _ in range(rounds):
        for name, value in asdict(t).items():
            for f in (0.8, 0.9, 1.1, 1.25):
                v = tuple(x * f for x in value) if isinstance(value, tuple) else value * f
                cand = replace(t, **{name: v})
                c = cost(cand)
                if c < best:
                    best, t = c, cand
                    log(f"  {name} x{f}: {best * 1000:.1f}")
    return t


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("command", choices=["tune", "score"])
    ap.add_argument("--data", required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--limit", type=at_least(1), default=32)
    ap.add_argument("--joints", default=None, help="build from these joints (training.device_joints) instead of "
                                                   "the true ones")
    ap.add_argument("--rounds", type=at_least(1), default=2)
    args = ap.parse_args(argv)
    from training.data.errors import DataError  # noqa: PLC0415
    from training.data.torch_dataset import MultiViewDataset  # noqa: PLC0415
    from training.device_joints import JointsCacheError, load_joints  # noqa: PLC0415

    try:  # a missing dataset, split or joints cache: one line naming it (were tracebacks)
        ds = MultiViewDataset(args.data, split=args.split)
        scenes = [{k: v.numpy() for k, v in ds[i].items()} for i in range(min(args.limit, len(ds)))]
        joints = load_joints(args.joints, len(scenes)) if args.joints else None
    except (DataError, JointsCacheError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if joints is not None:
        scenes = [{**s, "joints_3d": joints[i], "joints_3d_valid": np.ones(25, bool)} for i, s in enumerate(scenes)]
    t0 = time.monotonic()
    if args.command == "tune":
        t = tune(scenes, args.rounds)
        print(json.dumps(asdict(t)))
    else:
        scale = 1.0 if args.joints else None  # device joints: the template's girth (proxy_scene's docstring)
        rows = [_depth_error(s, ProxyTemplate(), scale, [v for v in range(len(s["tgt_is_source"]))
                                                        if not s["tgt_is_source"][v]]) for s in scenes]
        print(f"novel views: depth error {1000 * np.mean([r[0] for r in rows]):.1f} mm, "
              f"IoU {np.mean([r[1] for r in rows]):.3f}")
    print(f"{time.monotonic() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
