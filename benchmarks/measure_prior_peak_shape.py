"""Would the shape of each heatmap around its peak help the skeleton prior? Trains it with and without.

    .venv/bin/python benchmarks/measure_prior_peak_shape.py --model-dir models/ghnerf --data data/edge128_fs50 \
        --extra-data data/prior_extra_s1 [--variants base,shape,mass] [--seed 0] [--steps 30000] \
        [--cache out/peak_shape.npz] [--threads 2]

The prior (``ghnerf_runtime.skeleton_prior``) sees each peak as a point and a value. A heatmap says more:
how far it spreads and in which direction, and whether a second blob (the other arm) holds part of its mass.
This collects the model's flip-tested 2D peaks as ``training.skeleton_prior`` does, and per view and joint
(:func:`peak_shape`):

* the heatmap's spread (log of the standard deviation, model pixels) along the epipolar line through the
  peak, where the other view cannot correct it, and across it;
* the share of the map's mass within :data:`WINDOW` cells of the peak;
* the runner-up region's peak over this peak (``Keypoints2D.runner_up``).

Variants, each the prior's recipe (one network, ``--steps``, the same seed) on other inputs: ``base`` (the
runtime's features), ``shape`` (+ all four per view), ``mass`` (+ the last two per view). Prints held-out
MPJPE over every joint with the prior's flip test, without it, and within the default gate. The collected
arrays go to ``--cache`` (reused when it exists). A measurement, not a test: the runtime does not build
these features (docs/training.md, "Heatmap shape as prior evidence").
"""
from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.body25 import FLIP_INDEX  # noqa: E402
from ghnerf_runtime.cli.output_path import ready_output_arg  # noqa: E402
from ghnerf_runtime.config import Joints3DConfig  # noqa: E402
from ghnerf_runtime.keypoints import decode_keypoints, model_to_heatmap_pixels  # noqa: E402
from ghnerf_runtime.skeleton_prior import PriorInputs, _centres, mirror_inputs  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402
from training.model_card import write_atomic  # noqa: E402
from training.run_limits import seed_problem  # noqa: E402

WINDOW = 3
"""Half-width (heatmap cells) of the window described: the training Gaussian (sigma 1.5 cells) lies inside."""
SPREAD_FLOOR_PX = 0.25  # keeps the log finite for a one-cell peak
VARIANTS = {"base": (), "shape": (0, 1, 2, 3), "mass": (2, 3)}
"""Which of :func:`peak_shape`'s four columns each variant adds per view."""


def peak_shape(heatmaps: np.ndarray, uv_model: np.ndarray, valid: np.ndarray, P: np.ndarray,
               model_size: int) -> np.ndarray:
    """``(2, J, 3)``: log spread along / across the epipolar line (model px), mass share near the peak (0 where
    the joint was not decoded).

    Args:
        heatmaps: ``(2, J, h, w)``; uv_model: ``(2, J, 2)`` peaks in model pixels; valid: ``(2, J)``;
        P: ``(2, 3, 4)`` crop cameras (rig frame -> model pixels); model_size: crop side (pixels).
    """
    V, J, H, W = heatmaps.shape
    stride = model_size / W
    h = np.clip(np.nan_to_num(np.asarray(heatmaps, np.float64)), 0.0, None)
    pad = np.pad(h, ((0, 0), (0, 0), (WINDOW, WINDOW), (WINDOW, WINDOW)))
    uv = np.where(valid[..., None], uv_model, 0.0)
    cell = model_to_heatmap_pixels(uv, (W, H), model_size)
    ix = np.clip(np.rint(cell[..., 0]).astype(int), 0, W - 1)
    iy = np.clip(np.rint(cell[..., 1]).astype(int), 0, H - 1)
    oy, ox = np.mgrid[-WINDOW:WINDOW + 1, -WINDOW:WINDOW + 1]
    vi, ji = np.meshgrid(np.arange(V), np.arange(J), indexing="ij")
    win = pad[vi[..., None, None], ji[..., None, None], iy[..., None, None] + WINDOW + oy,
              ix[..., None, None] + WINDOW + ox]
    mass = win.sum((-1, -2))
    share = mass / np.maximum(h.sum((-1, -2)), 1e-9)
    wn = win / np.maximum(mass, 1e-9)[..., None, None]
    dx = (ix[..., None, None] + ox - cell[..., 0][..., None, None]) * stride
    dy = (iy[..., None, None] + oy - cell[..., 1][..., None, None]) * stride
    cxx, cyy, cxy = ((wn * a * b).sum((-1, -2)) for a, b in ((dx, dx), (dy, dy), (dx, dy)))
    C = _centres(P)
    out = np.zeros((V, J, 3))
    for v in range(V):
        e = P[v] @ np.append(C[1 - v], 1.0)  # the other camera's centre seen from this one: the epipole
        d = e[:2][None] - uv[v] * e[2]  # along the epipolar line through the peak (works for an epipole at infinity)
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        d = np.where(n > 1e-9, d / np.maximum(n, 1e-12), [1.0, 0.0])
        along = d[:, 0] ** 2 * cxx[v] + 2 * d[:, 0] * d[:, 1] * cxy[v] + d[:, 1] ** 2 * cyy[v]
        across = d[:, 1] ** 2 * cxx[v] - 2 * d[:, 0] * d[:, 1] * cxy[v] + d[:, 0] ** 2 * cyy[v]
        out[v, :, 0] = np.log(np.sqrt(np.maximum(along, 0.0)) + SPREAD_FLOOR_PX)
        out[v, :, 1] = np.log(np.sqrt(np.maximum(across, 0.0)) + SPREAD_FLOOR_PX)
        out[v, :, 2] = share[v]
    return np.where(valid[..., None], out, 0.0)


def scene_shape(model_size: int):
    """``collect``'s ``per_scene``: the four shape columns of one scene, ``(2, J, 4)``."""
    def per_scene(heat: np.ndarray, rec: dict) -> dict:
        kp = decode_keypoints(np.asarray(heat, np.float32))
        ratio = np.where(rec["valid"], kp.runner_up / np.maximum(kp.confidence, 1e-6), 0.0)
        spread = peak_shape(heat, rec["uv"], rec["valid"], np.asarray(rec["P"], np.float64), model_size)
        return {"shape": np.concatenate([spread, ratio[..., None]], -1)}

    return per_scene


def with_columns(inputs: PriorInputs, shape: np.ndarray, columns: tuple[int, ...]) -> PriorInputs:
    """``inputs`` with ``columns`` of ``shape`` ``(N, 2, J, 4)`` appended to each joint, view 0's first (the
    layout ``training.skeleton_prior`` hides per view)."""
    if not columns:
        return inputs
    s = shape[..., list(columns)]
    extra = np.concatenate([s[:, 0], s[:, 1]], -1).astype(np.float32)
    return PriorInputs(np.concatenate([inputs.joint_features, extra], -1), inputs.context, inputs.frame,
                       inputs.triangulated)


def answers(net, inputs: PriorInputs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rig-frame joints with the runtime's flip test, expected errors, and the joints without it (the
    network in torch: the runtime's ONNX path builds only its own features)."""
    import torch

    f, c = torch.from_numpy(inputs.joint_features), torch.from_numpy(inputs.context)
    with torch.no_grad():
        joints, log_err = net(f, c)
        mj, mlog = net(*mirror_inputs(f, c))  # the new columns do not change in a mirror: no sign to flip
    back = np.argsort(FLIP_INDEX)
    mirrored = mj.numpy()[:, back] * np.array([-1.0, 1.0, 1.0])
    err = 0.5 * (np.exp(log_err.numpy()) + np.exp(mlog.numpy()[:, back]))
    return (inputs.frame.to_rig(0.5 * (joints.numpy() + mirrored)), err,
            inputs.frame.to_rig(joints.numpy().astype(np.float64)))


def collect_all(args) -> tuple[dict, dict]:
    from training.skeleton_prior import collect

    from training.data.torch_dataset import MultiViewDataset

    size = int(MultiViewDataset(args.data, args.val_split)[0]["images"].shape[-1])
    per_scene = scene_shape(size)
    t0 = time.monotonic()
    tr = collect(args.model_dir, args.data, "train", args.limit, threads=args.threads, per_scene=per_scene,
                 progress=False)
    for extra in args.extra_data:
        more = collect(args.model_dir, extra, "train", args.limit, threads=args.threads, per_scene=per_scene,
                       progress=False)
        tr = {k: (v if k == "encoder_file" else np.concatenate([v, more[k]])) for k, v in tr.items()}
    va = collect(args.model_dir, args.data, args.val_split, args.limit, threads=args.threads,
                 per_scene=per_scene, progress=False)
    print(f"collected {len(tr['uv'])} training and {len(va['uv'])} held-out scenes in {time.monotonic() - t0:.0f} s",
          flush=True)
    return tr, va


def save_collection(path: Path, tr: dict, va: dict) -> None:
    """The collected arrays saved to ``path`` whole or not at all (``write_atomic``): ``np.savez`` to the path
    itself, stopped halfway (Ctrl-C, a full disk), closed its zip on the arrays written so far, a file the next
    run read as the collection, with the held-out split missing."""
    buf = io.BytesIO()
    np.savez(buf, **{f"tr_{k}": v for k, v in tr.items()}, **{f"va_{k}": v for k, v in va.items()})
    write_atomic(path, buf.getvalue())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models/ghnerf")
    ap.add_argument("--data", required=True)
    ap.add_argument("--extra-data", action="append", default=[])
    ap.add_argument("--val-split", default="val", help="the held-out split scored (not train, which the prior "
                                                       "is fitted on)")
    ap.add_argument("--limit", type=non_negative_count, default=0, help="scenes per split (0: all)")
    ap.add_argument("--variants", default="base,shape,mass")
    ap.add_argument("--steps", type=positive_count, default=30000)
    ap.add_argument("--hidden", type=positive_count, default=768)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=positive_count, default=2)
    ap.add_argument("--cache", help="npz of the collected arrays (written once, then read)")
    args = ap.parse_args(argv)
    if problem := seed_problem(args.seed):  # torch's overflow traceback once the scenes were collected
        ap.error(f"argument --seed: {problem}")
    if args.val_split == "train":  # as training.skeleton_prior refuses it: the prior is fitted on train's scenes
        ap.error("argument --val-split: 'train' is the split the prior is fitted on: the held-out figures would be "
                 "training figures (val or val_seen_motions)")
    variants = args.variants.split(",")
    if unknown := [v for v in variants if v not in VARIANTS]:
        ap.error(f"unknown variants {unknown}; known: {', '.join(VARIANTS)}")
    if args.cache:  # the collection takes minutes: its file's place is settled first, with the name savez writes
        args.cache = ready_output_arg(ap, args.cache, "--cache", suffix=".npz")
    if not (args.cache and Path(args.cache).is_file()):  # the splits collect_all reads, before minutes of it
        for data, split, option in [(args.data, "train", "--data"),
                                    *((extra, "train", "--extra-data") for extra in args.extra_data),
                                    (args.data, args.val_split, "--data")]:
            check_dataset_split(ap, data, split, option)

    import torch

    from training.model_card import strict_json
    from training.skeleton_prior import PriorTrainConfig, _train_one, inputs_of, score

    torch.set_num_threads(args.threads)
    if args.cache and Path(args.cache).is_file():
        z = np.load(args.cache)
        tr, va = ({k[3:]: z[k] for k in z.files if k.startswith(p)} for p in ("tr_", "va_"))
    else:
        tr, va = collect_all(args)
        if args.cache:
            save_collection(args.cache, tr, va)
    tr_in, tr_truth = inputs_of(tr)
    va_in, _ = inputs_of(va)
    gate = f"{Joints3DConfig().max_prior_error_m:g}"  # the runtime's default gate, one of GATES_M
    results = {}
    for name in variants:
        cols = VARIANTS[name]
        t0 = time.monotonic()
        features = with_columns(tr_in, tr["shape"], cols)
        net = _train_one(features.joint_features, features.context, tr_truth, tr["joints_3d_valid"],
                         PriorTrainConfig(steps=args.steps, hidden=args.hidden), args.seed, progress=False)
        train_s = time.monotonic() - t0
        vin = with_columns(va_in, va["shape"], cols)
        points, err, plain = answers(net, vin)
        m = score(points, err, va["joints_3d"], va["joints_3d_valid"], vin.triangulated)
        p = score(plain, err, va["joints_3d"], va["joints_3d_valid"], vin.triangulated)["all"]
        g = m["gated"][gate]
        results[name] = {"mean_mm": m["all"]["mean_mm"], "median_mm": m["all"]["median_mm"],
                         "no_flip_mean_mm": p["mean_mm"], "gated_mean_mm": g["mean_mm"], "gated_found": g["found"],
                         "train_s": round(train_s)}
        print(f"{name} (+{len(cols)} per view, seed {args.seed}): every joint {m['all']['mean_mm']:.1f} mean / "
              f"{m['all']['median_mm']:.1f} median mm, without the flip test {p['mean_mm']:.1f}; within "
              f"{gate} m {g['mean_mm']:.1f} mm over {g['found']:.1%}; {train_s:.0f} s", flush=True)
    print(strict_json(results, indent=None))  # a NaN error (a diverged network) as null
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
