"""How far a body proxy built from the 3D joints carries the novel views (``training.body_proxy``).

    .venv/bin/python -m training.device_joints --data out/s26/data --split val --limit 256 \
        --out out/s34/joints_val.npz
    .venv/bin/python benchmarks/measure_body_proxy.py --data out/s26/data --limit 256 \
        --model models/ghnerf/ghnerf.pt --joints out/s34/joints_val.npz

Per novel view of each held-out scene, by its angle from the nearest source (``ghnerf-eval``'s bins):

* ``depth_mm`` columns: the median absolute depth error on the subject pixels each geometry covers:
  the model's (its opacity above 0.5), the proxy from the true joints (``proxy:truth``, scale fitted to
  the sources' true masks; what the template can do) and from the device's joints (``proxy``: the
  ``--joints`` cache at the template's girth, or ``--scale fit``: fitted to the model's own masks in the
  sources; nothing from the truth);
  ``cover`` is the share of the subject the device proxy covers.
* PSNR columns (masked, ``ghnerf-eval``'s): ``shown``, the model's picture as the runtime shows it
  (``psnr@opaque_at``); ``blend@proxy``, the two-camera blend at the device proxy's depth with its own
  visibility (3 cm); ``relit@proxy``, that blend with the pixels no source sees repainted by
  ``training.unseen_fill.relit_fill`` (light fitted on the proxy's seen surface); ``shown+relit``, the
  model's picture with only the proxy's unseen pixels repainted so; ``seen:blend``, the blend on the
  pixels of the proxy some source sees and the model's picture on every other. Subject pixels the
  proxy misses keep the model's picture in every column but ``proxy only``: the blend on the proxy's
  pixels and the background elsewhere, no network rendering at all.
* ``runtime``: what the runtime shows by default, the model's picture recoloured by
  ``ghnerf_runtime.proxy_blend`` with the device proxy and the runtime's defaults (angular weights,
  only where the picture shows the subject and a source sees the point within
  ``novel_view.proxy_max_angle_deg`` of the view's ray).
* ``--painter novel_painter.onnx``: ``painter``, the model's picture repainted by the runtime's learnt
  painter (``ghnerf_runtime.novel_painter``, on the device proxy and joints, where the proxy or the
  picture shows the subject); ``painter+blend``, that picture then recoloured as ``runtime`` does;
  ``device``, what the runtime shows by default with the painter: ``painter+blend`` on views at least
  ``novel_view.painter_min_angle_deg`` from a source camera (by the device's joints), ``runtime`` nearer.
* ``--matte``: the runtime's fog matte (``ghnerf_runtime.proxy_matte``, the runtime's defaults) after
  ``runtime`` (``runtime+matte``) and, with ``--painter``, after ``device`` (``device+matte``); and the
  PSNR over the whole view (the truth over the background) of ``shown``, ``runtime`` and those
  (``whole:...`` columns), which sees the fog around the subject that the masked PSNR does not.
* ``ceiling`` and ``fill:relit``: the same blend and fill on the true geometry (session 27's columns).
* ``--guided``: the network itself given the better depth, without retraining: its fine level's
  planes placed around a guide depth (``guide_std`` wide) instead of around its coarse level's
  depth, in the cells the guide covers (:func:`guided_render`); ``guided:proxy`` is its picture
  (``psnr@opaque_at``) with the device proxy's depth, ``guided:truth`` with the true depth.

Not a test; CPU, about 1 s per scene with a model.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.numbers import number_or  # noqa: E402
from ghnerf_runtime.config import NovelViewConfig  # noqa: E402
from ghnerf_runtime.metrics import masked_psnr  # noqa: E402
from ghnerf_runtime.novel_view import opaque_colour  # noqa: E402
from training.blend_ceiling import blend_sources  # noqa: E402
from ghnerf_runtime.body_proxy import proxy_body, proxy_depth  # noqa: E402
from ghnerf_runtime.proxy_blend import proxy_blend, subject_region  # noqa: E402
from ghnerf_runtime.proxy_matte import proxy_matte  # noqa: E402
from training.body_proxy import proxy_scene, view_camera  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402
from training.evaluate import angle_bins  # noqa: E402
from training.unseen_fill import fit_lighting, relit_fill, seen_surface  # noqa: E402


def psnr(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float:
    return float(np.ravel(masked_psnr(np.clip(pred, 0, 1)[None], truth[None], mask[None]).per_image)[0])


def median_mm(depth: np.ndarray, truth: np.ndarray, region: np.ndarray) -> float:
    return 1000 * float(np.median(np.abs(depth - truth)[region])) if region.any() else np.nan


def guided_render(model, scene, targets: np.ndarray, guide: np.ndarray | None, guide_std: float = 0.03):
    """The model's last level at every pixel of ``targets``, its planes placed around ``guide``
    ``(V, H, W)`` (metres, 0 = none) wherever a coarse cell is at least a quarter covered: the coarse
    level's depth mean and spread replaced by the guide's mean and ``guide_std`` there, then the fine
    level built as ``GHNeRF.volumes`` builds it. Returns ``rgb`` ``(T, H*W, 3)``, ``acc``, ``depth``."""
    import torch
    from torch.nn import functional as F

    from ghnerf_runtime.contract import ray_grid
    from training.evaluate import _cams
    from training.model.cost_volume import build_cost_volume
    from training.model.sampling import linear_planes, refine_interval

    cfg = model.config
    H, W = cfg.height, cfg.width
    d = {k: torch.from_numpy(np.asarray(v)) for k, v in _cams(scene, targets, ray_grid(H, W, 1)).items()}
    with torch.no_grad():
        enc = model.encode(d["images"])
        stats = model.volumes(enc, d["src_P"], d["tgt_K_inv"], d["tgt_c2w"], d["near_far"], upto=0)[0]["stats"]
        if guide is not None:
            g = torch.from_numpy(np.asarray(guide[targets], np.float32))[:, None]
            k = H // stats.shape[-2]
            cover = F.avg_pool2d((g > 0).float(), k)
            mean = F.avg_pool2d(g, k) / cover.clamp(min=1e-6)
            use = cover > 0.25
            stats = stats.clone()
            stats[:, 0:1] = torch.where(use, mean, stats[:, 0:1])
            stats[:, 1:2] = torch.where(use, torch.full_like(mean, guide_std), stats[:, 1:2])
        last = len(cfg.levels) - 1
        B = stats.shape[0]
        near, far = d["near_far"][:, 0].reshape(B, 1, 1, 1), d["near_far"][:, 1].reshape(B, 1, 1, 1)
        for i in range(1, len(cfg.levels)):  # the levels after the coarse one, as GHNeRF.volumes builds them
            lv = cfg.levels[i]
            h, w = H // lv.volume_stride, W // lv.volume_stride
            prev = F.interpolate(stats[:, :2], size=(h, w), mode="bilinear", align_corners=False)
            lo, hi = refine_interval(prev[:, :1], prev[:, 1:2], near, far, cfg.levels[i - 1].range_scale,
                                     cfg.min_depth_range)
            cost = build_cost_volume(enc[lv.feature], d["src_P"], d["tgt_K_inv"], d["tgt_c2w"],
                                     linear_planes(lo, hi, lv.planes), lv.volume_stride, H, W, cfg.cost_volume.groups)
            volume, logits = model.regularizers[i](cost)
            if logits is not None:
                raise ValueError("guided_render takes models whose later levels sample their planes")
            stats = torch.cat([prev, lo, hi], dim=1)
        o = model.render(last, enc, volume, stats, d["src_P"], d["tgt_K_inv"], d["tgt_c2w"], d["ray_uv"],
                         src_centers=d["src_centers"], heat=False)
    return o["rgb"].numpy(), o["acc"].numpy(), o["depth"].numpy()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--split", default="val")
    ap.add_argument("--limit", type=non_negative_count, default=256)
    ap.add_argument("--model", required=True, help="the GHNeRF torch checkpoint whose picture and masks are used")
    ap.add_argument("--joints", required=True, help="the device's joints (python -m training.device_joints)")
    ap.add_argument("--scale", type=number_or("fit"), default=1.0,
                    help="the device proxy's girth scale, or 'fit' to fit it to the model's masks (default: 1)")
    ap.add_argument("--guided", action="store_true", help="add the guided:proxy and guided:truth columns")
    ap.add_argument("--painter", default=None, metavar="ONNX",
                    help="add the runtime painter's columns (ghnerf_runtime.novel_painter): painter, painter+blend")
    ap.add_argument("--matte", action="store_true", help="add the fog matte's columns and the whole-view PSNRs")
    ap.add_argument("--threads", type=positive_count, default=1)
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, args.split)  # before the checkpoint loads

    import torch

    from training.data.torch_dataset import MultiViewDataset
    from training.device_joints import load_joints
    from training.evaluate import TorchRenderer, source_angles_deg
    from training.fill_features import render_views
    from training.train import load_model
    from training.model.config import ConfigError

    torch.set_num_threads(args.threads)
    try:
        renderer = TorchRenderer(load_model(Path(args.model))[0])
    except ConfigError as e:  # a missing, damaged or foreign file, named (was a traceback)
        ap.error(f"argument --model: {e}")
    ds = MultiViewDataset(args.data, split=args.split)
    n = min(args.limit, len(ds)) if args.limit else len(ds)
    device_joints = load_joints(args.joints, n)
    nvc = NovelViewConfig()  # the runtime's defaults
    painter = None
    if args.painter:
        from ghnerf_runtime.novel_painter import NovelPainter, angle_from_sources_deg

        painter = NovelPainter.load(args.painter, threads=args.threads)
    at = nvc.opaque_at
    rows: list[dict] = []
    for i in range(n):
        scene = {k: v.numpy() for k, v in ds[i].items()}
        V = len(scene["tgt_is_source"])
        src = [v for v in range(V) if scene["tgt_is_source"][v]]
        angles = source_angles_deg(scene, np.arange(V))
        rgb, depth, acc = render_views(renderer, scene)
        oracle, _ = proxy_scene(scene, scene["joints_3d"], scene["joints_3d_valid"], scale=None)
        valid = np.ones(25, bool)
        dev, scale = proxy_scene({**scene, "joints_3d": device_joints[i], "joints_3d_valid": valid},
                                 device_joints[i], valid, args.scale, [acc[v] > 0.5 for v in src])
        body = proxy_body(device_joints[i], valid, scale=scale)
        src_cams = [view_camera(scene, v) for v in src]
        src_rgb = np.ascontiguousarray(np.asarray(scene["images"]).transpose(0, 2, 3, 1))
        true_light = fit_lighting(seen_surface(scene))
        dev_light = fit_lighting(seen_surface(dev))
        guided = {}
        if args.guided:
            nov = np.flatnonzero(~np.asarray(scene["tgt_is_source"], bool))
            truth_depth = np.where(scene["tgt_masks"], scene["tgt_depth"], 0.0)
            for name, guide in (("proxy", dev["tgt_depth"]), ("truth", truth_depth)):
                g_rgb, g_acc, _ = guided_render(renderer.model, scene, nov, guide)
                guided.update({(name, int(t)): (g_rgb[k], g_acc[k]) for k, t in enumerate(nov)})
        for t in range(V):
            mask = np.asarray(scene["tgt_masks"][t], bool)
            if scene["tgt_is_source"][t] or not mask.any():
                continue
            truth = scene["tgt_images"][t].transpose(1, 2, 0) * mask[..., None]
            true_depth = scene["tgt_depth"][t]
            shown = opaque_colour(rgb[t].reshape(-1, 3), acc[t].ravel(), renderer.background, at).reshape(rgb[t].shape)
            ceiling, seen = blend_sources(scene, t, true_depth)
            fill = relit_fill(ceiling, scene, t, true_depth, mask & ~seen, mask=mask, lighting=true_light)
            pm, pd = dev["tgt_masks"][t], dev["tgt_depth"][t]
            blend, pseen = blend_sources(dev, t, pd)
            unseen = pm & ~pseen
            relit = relit_fill(blend, dev, t, pd, unseen, mask=pm, lighting=dev_light)
            repainted = relit_fill(shown, dev, t, pd, unseen, mask=pm, lighting=dev_light)
            keep = pm[..., None]
            extra = {}
            shown_u8 = np.round(np.clip(shown, 0, 1)[..., ::-1] * 255).astype(np.uint8)  # BGR, as the runtime's
            region = subject_region(shown_u8, renderer.background, nvc.silhouette_min_diff)
            runtime = proxy_blend(shown_u8, view_camera(scene, t), body, src_cams, src_rgb, nvc.proxy_tolerance_m,
                                  region=region, max_angle_deg=nvc.proxy_max_angle_deg)
            extra["runtime"] = psnr(runtime.image[..., ::-1] / 255.0, truth, mask)
            if painter is not None:
                painted, _ = painter.repaint(shown_u8, view_camera(scene, t), body, src_cams, src_rgb, device_joints[i],
                                             valid, nvc.proxy_tolerance_m, region=region)
                extra["painter"] = psnr(painted[..., ::-1] / 255.0, truth, mask)
                both = proxy_blend(painted, view_camera(scene, t), body, src_cams, src_rgb, nvc.proxy_tolerance_m,
                                   region=region, max_angle_deg=nvc.proxy_max_angle_deg)
                extra["painter+blend"] = psnr(both.image[..., ::-1] / 255.0, truth, mask)
                near = angle_from_sources_deg(view_camera(scene, t), src_cams, device_joints[i], valid) \
                    < nvc.painter_min_angle_deg  # the runtime's gate, on the device's joints
                extra["device"] = extra["runtime"] if near else extra["painter+blend"]
            if args.matte:
                cam = view_camera(scene, t)
                whole = np.ones_like(mask)
                view_depth = proxy_depth(body, cam)
                pictures = {"shown": shown_u8, "runtime": runtime.image}
                if painter is not None:
                    pictures["device"] = runtime.image if near else both.image
                for name, picture in list(pictures.items())[1:]:
                    pictures[f"{name}+matte"] = proxy_matte(picture, cam, view_depth, region, renderer.background,
                                                            nvc.matte_margin_m, nvc.matte_feather_m,
                                                            joints=device_joints[i], valid=valid).image
                    extra[f"{name}+matte"] = psnr(pictures[f"{name}+matte"][..., ::-1] / 255.0, truth, mask)
                for name, picture in pictures.items():
                    extra[f"whole:{name}"] = psnr(picture[..., ::-1] / 255.0, truth, whole)
            for name in ("proxy", "truth") if args.guided else ():
                g_rgb, g_acc = guided[(name, t)]
                g = opaque_colour(g_rgb, g_acc, renderer.background, at).reshape(rgb[t].shape)
                extra[f"guided:{name}"] = psnr(g, truth, mask)
            rows.append({**extra,
                "angle": float(angles[t]), "scale": scale,
                "model:depth_mm": median_mm(depth[t], true_depth, mask & (acc[t] > 0.5)),
                "proxy:truth:depth_mm": median_mm(oracle["tgt_depth"][t], true_depth, mask & oracle["tgt_masks"][t]),
                "proxy:depth_mm": median_mm(pd, true_depth, mask & pm),
                "cover": float(pm[mask].mean()),
                "ceiling": psnr(ceiling, truth, mask), "fill:relit": psnr(fill, truth, mask),
                "shown": psnr(shown, truth, mask),
                "blend@proxy": psnr(np.where(keep, blend, shown), truth, mask),
                "relit@proxy": psnr(np.where(keep, relit, shown), truth, mask),
                "shown+relit": psnr(np.where(keep, repainted, shown), truth, mask),
                "seen:blend": psnr(np.where((pm & pseen)[..., None], blend, shown), truth, mask),
                "proxy only": psnr(np.where(keep, blend, renderer.background), truth, mask),
            })
        if (i + 1) % 32 == 0:
            print(f"  {i + 1}/{n} scenes", file=sys.stderr, flush=True)

    cols = ["model:depth_mm", "proxy:truth:depth_mm", "proxy:depth_mm", "cover", "ceiling", "fill:relit", "shown",
            "blend@proxy", "relit@proxy", "shown+relit",
            "seen:blend", "proxy only", "runtime"] + (["guided:proxy", "guided:truth"] if args.guided else [])
    cols += ["painter", "painter+blend", "device"] if painter is not None else []
    if args.matte:
        cols += ["runtime+matte"] + (["device+matte"] if painter is not None else [])
        cols += ["whole:shown", "whole:runtime", "whole:runtime+matte"]
        cols += ["whole:device", "whole:device+matte"] if painter is not None else []
    # ghnerf-eval's bins (the last includes 180 degrees)
    groups = [(f"novel {lo:.0f}-{hi:.0f} deg", inside) for lo, hi, inside in angle_bins([r["angle"] for r in rows])]
    groups += [("novel, all", np.ones(len(rows), bool))]
    print(f"{n} scenes of {args.data} ({args.split}); depth errors: median mm, mean over views; PSNR dB; "
          f"proxy scale median {np.median([r['scale'] for r in rows]):.2f}")
    print("| views | n | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 2) + "|")
    for label, keep in groups:
        sel = [r for r, k in zip(rows, keep) if k]
        if sel:
            means = (f"{np.nanmean([r[c] for r in sel]):.2f}" for c in cols)
            print(f"| {label} | {len(sel)} | " + " | ".join(means) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
