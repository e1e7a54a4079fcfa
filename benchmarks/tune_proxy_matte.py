"""What the fog matte (``ghnerf_runtime.proxy_matte``) gives and costs at each margin and feather.

    .venv/bin/python -m training.device_joints --data out/s26/data --split val_seen_motions --limit 128 \
        --out out/s36/joints_seen.npz
    .venv/bin/python benchmarks/tune_proxy_matte.py --data out/s26/data --split val_seen_motions --limit 128 \
        --model models/ghnerf/ghnerf.pt --joints out/s36/joints_seen.npz

For every view of each scene (the rig's two cameras and ``ghnerf-eval``'s circling novel views) the
model's picture as the runtime shows it (``novel_view.opaque_at``) is matted with the body proxy of the
device's joints (``--joints``, ``training.device_joints``; those the runtime reports, their expected error
within ``joints3d.max_prior_error_m``, the rest missing as there) at each ``--margins`` x ``--feathers`` (metres),
and scored against the dataset's view over the background: the masked PSNR (inside the true subject,
``ghnerf-eval``'s), the PSNR over the whole view (the fog counts) and the share of the subject's pixels
the matte dims or the clearing turns to background (``cut``). ``--clear-below`` adds an axis: the
picture with each opacity floor (:func:`cleared`: rays at most that opaque show the background), with
and without the matte. Tune on ``val_seen_motions`` (the defaults were), report on ``val``.

Not a test; CPU, about 0.3 s per scene.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.numbers import number_list  # noqa: E402
from ghnerf_runtime.body_proxy import proxy_body, proxy_depth  # noqa: E402
from ghnerf_runtime.config import NovelViewConfig  # noqa: E402
from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from ghnerf_runtime.novel_view import opaque_colour  # noqa: E402
from ghnerf_runtime.proxy_blend import subject_region  # noqa: E402
from ghnerf_runtime.proxy_matte import proxy_matte  # noqa: E402
from training.body_proxy import view_camera  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402


def cleared(rgb: np.ndarray, acc: np.ndarray, background: float, opaque_at: float, clear_below: float) -> np.ndarray:
    """The runtime's picture (``opaque_colour``) with an opacity floor the runtime does not have: a ray at
    most ``clear_below`` opaque shows the background, and its colour fades in linearly up to ``opaque_at``
    (0: the runtime's picture exactly). docs/novel-view.md, "Matting out the fog", has why it is not there."""
    if clear_below <= 0.0:
        return opaque_colour(rgb, acc, background, opaque_at)
    acc = np.clip(np.nan_to_num(acc, nan=0.0), 0.0, 1.0)[:, None]
    shown = np.clip((acc - clear_below) / (opaque_at - clear_below), 0.0, 1.0)
    return (rgb - (1.0 - acc) * background) * (shown / np.maximum(acc, clear_below)) + (1.0 - shown) * background


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--split", default="val_seen_motions")
    ap.add_argument("--limit", type=non_negative_count, default=128)
    ap.add_argument("--model", required=True, help="the GHNeRF torch checkpoint whose picture is matted")
    ap.add_argument("--joints", required=True,
                    help="the device's joints of the split (python -m training.device_joints)")
    ap.add_argument("--margins", type=number_list, default=[0.04, 0.06, 0.08, 0.10, 0.12])
    ap.add_argument("--feathers", type=number_list, default=[0.0, 0.10, 0.15, 0.20])
    ap.add_argument("--clear-below", type=number_list, default=[0.0],
                    help="comma list of opacity floors (cleared); 0: the runtime's picture")
    ap.add_argument("--threads", type=positive_count, default=1)
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, args.split)  # before the checkpoint loads

    import torch

    from training.data.torch_dataset import MultiViewDataset
    from training.device_joints import load_found, load_joints
    from training.fill_features import render_views
    from training.evaluate import TorchRenderer
    from training.train import load_model
    from training.model.config import ConfigError

    torch.set_num_threads(args.threads)
    try:
        renderer = TorchRenderer(load_model(Path(args.model))[0])
    except ConfigError as e:  # a missing, damaged or foreign file, named (was a traceback)
        ap.error(f"argument --model: {e}")
    ds = MultiViewDataset(args.data, split=args.split)
    n = min(args.limit, len(ds)) if args.limit else len(ds)
    joints, found = load_joints(args.joints, n), load_found(args.joints, n)
    nvc = NovelViewConfig()
    mattes = [None, *[(m, f) for m in args.margins for f in args.feathers]]
    settings = [(c, m) for c in args.clear_below for m in mattes]
    scores: dict[str, dict] = {kind: {s: [] for s in settings} for kind in ("source", "novel")}
    for i in range(n):
        scene = {k: v.numpy() for k, v in ds[i].items()}
        rgb, _, acc = render_views(renderer, scene)
        valid = found[i]  # the runtime's joints: those whose expected error passes its gate
        body = proxy_body(joints[i], valid)
        for t in range(len(scene["tgt_is_source"])):
            mask = np.asarray(scene["tgt_masks"][t], bool)
            if not mask.any():
                continue
            truth = scene["tgt_images"][t].transpose(1, 2, 0) * mask[..., None]
            camera = view_camera(scene, t)
            depth = proxy_depth(body, camera)
            kind = "source" if scene["tgt_is_source"][t] else "novel"
            everywhere = np.ones_like(mask)
            for clear in args.clear_below:
                shown = cleared(rgb[t].reshape(-1, 3), acc[t].ravel(), renderer.background, nvc.opaque_at, clear)
                picture = np.round(np.clip(shown.reshape(rgb[t].shape), 0, 1)[..., ::-1] * 255).astype(np.uint8)
                region = subject_region(picture, renderer.background, nvc.silhouette_min_diff)
                for s in mattes:
                    if s is None:
                        out, weight = picture, np.ones(mask.shape)
                    else:
                        m = proxy_matte(picture, camera, depth, region, renderer.background, s[0], s[1],
                                        joints=joints[i], valid=valid)
                        out, weight = m.image, m.weight
                    x = out[..., ::-1] / 255.0
                    # cut: the subject's pixels the matte dims or the clearing turns to background
                    dimmed = (weight < 1) | (acc[t] <= clear) if clear > 0 else weight < 1
                    scores[kind][(clear, s)].append((masked_psnr(x, truth, mask).value,
                                                     masked_psnr(x, truth, everywhere).value,
                                                     float(dimmed[mask].mean())))
        if (i + 1) % 32 == 0:
            print(f"  {i + 1}/{n} scenes", file=sys.stderr, flush=True)

    print(f"{n} scenes of {args.data} ({args.split}); mean over views; PSNR dB; the runtime's picture "
          f"(opaque_at {nvc.opaque_at}) matted with the proxy of the device's joints")
    print("| clear_below | margin m | feather m | source: masked | whole | cut | novel: masked | whole | cut |")
    print("|---|---|---|---|---|---|---|---|---|")
    for s in settings:
        cells = []
        for kind in ("source", "novel"):
            v = np.array(scores[kind][s])
            cells += [f"{v[:, 0].mean():.2f}", f"{v[:, 1].mean():.2f}", f"{v[:, 2].mean():.4f}"]
        label = f"{s[0]:g} | " + ("no matte | –" if s[1] is None else f"{s[1][0]:g} | {s[1][1]:g}")
        print(f"| {label} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
