"""The novel view's PSNR against what blending the two source images can reach at all.

    .venv/bin/python benchmarks/measure_novel_ceiling.py --data data/edge128 [--limit 256]
        [--model NAME=runs/edge128/last.pt ...]

For every view of each held-out scene (the two sources and the novel cameras ``ghnerf-eval``
scores), by the view's angle from the nearest source camera (``ghnerf-eval``'s bins):

* ``ceiling``: the masked PSNR of ``training.blend_ceiling.blend_sources`` fed the *true* depth: each
  pixel's surface point coloured by the source cameras that see it (true visibility). A GHNeRF or
  ENeRF colour is such a blend, so this is that family's ceiling; ``seen`` is the share of the
  subject's pixels some source camera sees.
* per ``--model`` (a torch checkpoint): its rendered colour's masked PSNR (the last cascade level,
  as ``ghnerf-eval`` renders it), the same with the colour divided by the ray's accumulated opacity
  (``psnr/acc``: what the dimming costs; ``acc`` is the mean opacity on the subject), the picture the
  runtime shows (``psnr@opaque_at``: ``ghnerf_runtime.novel_view.opaque_colour`` with the runtime's
  ``novel_view.opaque_at``, which counts a ray as opaque from that opacity on), the median
  absolute error of its rendered depth on the subject (``depth_mm``), and ``blend@depth``: the same
  visible blend fed the model's depth instead of the truth. The gap from ``blend@depth`` to the
  model's PSNR is its blending and opacity; from ``ceiling`` to ``blend@depth`` its geometry.
* ``--oracles``: what a renderer that also *invents* the surfaces no source sees could gain, bounded
  with the truth (oracles, not renderers): ``ceil:seen`` / ``ceil:unseen`` split the ceiling's PSNR
  into the subject's pixels some source sees and the rest; ``fill:affine`` is the ceiling with its
  unseen pixels (the plain average of the sources there) passed through the per-view, per-channel
  gain and offset that fit the truth best (least squares on those pixels): the most that any global
  colour or shading correction of the borrowed colours can give; ``fill:exact`` is the ceiling with
  the unseen pixels replaced by the truth (a perfect inventor; what is left is the seen pixels' error).
  Beside them two renderers that are not oracles (``training.unseen_fill``: they read the sources,
  the true geometry and the 3D joints, not the view): ``fill:part`` paints each unseen pixel the mean
  colour the sources see on its bone, in the same bin along it; ``fill:relit`` takes those colours as
  albedos under a light fitted to the seen pixels and shades the unseen surface with it;
  ``part:unseen`` and ``relit:unseen`` are their PSNR on the unseen pixels alone (against
  ``ceil:unseen``). With ``--model`` it adds ``relit@depth``: the picture the runtime shows with the
  pixels the model's *own* geometry calls unseen repainted by ``fill:relit``'s method, everything
  from the model (its depth at every view, its opacity above 0.5 as the subject, visibility within
  ``--fill-tolerance``) but the 3D joints: what the fill would give on a device.

Masked PSNR inside the subject mask, the truth over the model's black background (``ghnerf-eval``'s).
Not a test; CPU, about 20 s per 64 scenes and model.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.config import NovelViewConfig  # noqa: E402
from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from ghnerf_runtime.novel_view import opaque_colour  # noqa: E402
from training.blend_ceiling import VISIBILITY_TOLERANCE_M, affine_fill, blend_sources  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402
from training.fill_features import modelled_scene, render_views  # noqa: E402
from training.unseen_fill import fit_lighting, part_fill, relit_fill, seen_surface  # noqa: E402



def psnr(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    return float(np.ravel(masked_psnr(np.clip(pred, 0, 1)[None], truth[None], mask[None]).per_image)[0])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data/edge128")
    ap.add_argument("--split", default="val")
    ap.add_argument("--limit", type=non_negative_count, default=256, help="first N scenes (0: all)")
    ap.add_argument("--model", action="append", default=[], metavar="NAME=CKPT",
                    help="a torch checkpoint (last.pt) to score beside the ceiling; repeatable")
    ap.add_argument("--threads", type=positive_count, default=2)
    ap.add_argument("--oracles", action="store_true",
                    help="add the oracle columns (ceil:seen, ceil:unseen, fill:affine, fill:exact) and the "
                         "fills (fill:part, fill:relit; with --model, relit@depth)")
    ap.add_argument("--fill-tolerance", type=float, default=VISIBILITY_TOLERANCE_M, metavar="M",
                    help="visibility tolerance (metres) of the relit@depth column (default: %(default)s)")
    ap.add_argument("--opaque-at", type=float, default=NovelViewConfig().opaque_at,
                    help="the runtime's novel_view.opaque_at for the psnr@opaque_at column (default: the runtime's)")
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, args.split)  # before the --model checkpoints load
    opaque_at = args.opaque_at

    import torch

    from training.data.torch_dataset import MultiViewDataset
    from training.evaluate import TorchRenderer, angle_bins, source_angles_deg
    from training.train import load_model
    from training.model.config import ConfigError

    torch.set_num_threads(args.threads)
    models = []
    for spec in args.model:
        name, _, path = spec.rpartition("=")
        try:
            model, _ = load_model(Path(path))
        except ConfigError as e:  # a missing, damaged or foreign file, named (was a traceback)
            ap.error(f"argument --model: {e}")
        models.append((name or Path(path).parent.name, TorchRenderer(model)))
    background = models[0][1].background if models else 0.0
    ds = MultiViewDataset(args.data, split=args.split)
    n = min(args.limit, len(ds)) if args.limit else len(ds)
    rows: list[dict] = []
    for i in range(n):
        scene = {k: v.numpy() for k, v in ds[i].items()}
        if not scene["tgt_has_depth"].all():
            continue  # no true depth (ZJU-MoCap): no ceiling
        V = len(scene["tgt_is_source"])
        angles = source_angles_deg(scene, np.arange(V))
        rendered = [render_views(m, scene) for _, m in models]
        surface = seen_surface(scene) if args.oracles else None  # gathered once per scene
        lighting = fit_lighting(surface) if args.oracles else None
        as_modelled = [modelled_scene(scene, depth, acc) for _, depth, acc in rendered] if args.oracles else []
        model_lighting = [fit_lighting(seen_surface(m)) for m in as_modelled]
        for t in range(V):
            mask = np.asarray(scene["tgt_masks"][t], bool)
            if not mask.any():
                continue
            truth = scene["tgt_images"][t].transpose(1, 2, 0) * mask[..., None]
            rgb, seen = blend_sources(scene, t, scene["tgt_depth"][t])
            row = {"source": bool(scene["tgt_is_source"][t]), "angle": float(angles[t]),
                   "ceiling": psnr(rgb, truth, mask), "seen": float(seen[mask].mean())}
            if args.oracles:
                unseen = mask & ~seen
                row["ceil:seen"] = psnr(rgb, truth, mask & seen) if (mask & seen).any() else np.nan
                row["ceil:unseen"] = psnr(rgb, truth, unseen) if unseen.any() else np.nan
                row["fill:affine"] = psnr(affine_fill(rgb, truth, unseen), truth, mask)
                row["fill:exact"] = psnr(np.where(unseen[..., None], truth, rgb), truth, mask) if (mask & seen).any() else np.nan
                painted = part_fill(rgb, scene, t, scene["tgt_depth"][t], unseen, surface=surface)
                relit = relit_fill(rgb, scene, t, scene["tgt_depth"][t], unseen, mask=mask, lighting=lighting)
                row["fill:part"], row["fill:relit"] = psnr(painted, truth, mask), psnr(relit, truth, mask)
                row["part:unseen"] = psnr(painted, truth, unseen) if unseen.any() else np.nan
                row["relit:unseen"] = psnr(relit, truth, unseen) if unseen.any() else np.nan
            for k, ((name, _), (m_rgb, m_depth, m_acc)) in enumerate(zip(models, rendered)):
                row[f"{name}:psnr"] = psnr(m_rgb[t], truth, mask)
                row[f"{name}:psnr/acc"] = psnr(m_rgb[t] / np.maximum(m_acc[t], 1e-3)[..., None], truth, mask)
                shown = opaque_colour(m_rgb[t].reshape(-1, 3), m_acc[t].ravel(), background, opaque_at)
                row[f"{name}:psnr@opaque_at"] = psnr(shown.reshape(m_rgb[t].shape), truth, mask)
                if args.oracles:
                    own, own_mask = as_modelled[k], as_modelled[k]["tgt_masks"][t]
                    _, own_seen = blend_sources(own, t, own["tgt_depth"][t], tolerance_m=args.fill_tolerance)
                    repainted = relit_fill(shown.reshape(m_rgb[t].shape), own, t, own["tgt_depth"][t],
                                           own_mask & ~own_seen, mask=own_mask, lighting=model_lighting[k])
                    row[f"{name}:relit@depth"] = psnr(repainted, truth, mask)
                row[f"{name}:acc"] = float(m_acc[t][mask].mean())
                row[f"{name}:blend@depth"] = psnr(blend_sources(scene, t, m_depth[t])[0], truth, mask)
                row[f"{name}:depth_mm"] = 1000 * float(np.median(np.abs(m_depth[t] - scene["tgt_depth"][t])[mask]))
            rows.append(row)
        if (i + 1) % 32 == 0:
            print(f"  {i + 1}/{n} scenes", file=sys.stderr, flush=True)

    per_model = ("psnr", "psnr/acc", "psnr@opaque_at", "acc", "blend@depth", "depth_mm")
    oracle_cols = (["ceil:seen", "ceil:unseen", "fill:affine", "fill:exact", "fill:part", "fill:relit",
                    "part:unseen", "relit:unseen"] if args.oracles else [])
    if args.oracles:
        per_model += ("relit@depth",)
    cols = ["ceiling", "seen"] + oracle_cols + [f"{name}:{k}" for name, _ in models for k in per_model]
    novel = np.array([not r["source"] for r in rows], bool)
    groups = [("sources", ~novel)]
    groups += [(f"novel {lo:g}-{hi:g} deg", novel & inside)  # ghnerf-eval's bins: the last includes 180
               for lo, hi, inside in angle_bins([r["angle"] for r in rows])]
    groups += [("novel, all", novel)]
    print(f"{n} scenes of {args.data} ({args.split}); PSNR in dB (mean over views), depth error median mm")
    print("| views | n | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 2) + "|")
    for label, keep in groups:
        sel = [r for r, k in zip(rows, keep) if k]
        if sel:
            print(f"| {label} | {len(sel)} | " + " | ".join(f"{np.nanmean([r[c] for r in sel]):.2f}" for c in cols) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
