"""What a crop padded at the frame's edge costs the shipped model (the runtime's padding policy,
``ghnerf_runtime/preprocess.py``: the square crop is kept where it leaves the frame, those pixels show
``roi.pad_fill``: 0 under "black", the frame's edge fading into the crop's mean under "fade", the default for a
model trained without frame padding).

    .venv/bin/python benchmarks/measure_edge_padding.py [--model-dir models] [--sequences 10] [--frames 30]
                                                        [--outside 0,0.1,0.25,0.5] [--training-samples 300]
                                                        [--edge-crop clip,centre,shift]
                                                        [--pad-fill black|edge|fade] [--pad-fade 0.1]
                                                        [--blacken black|grey|replicate|reflect]

The comparison: the held-out-like bench sequences (``ghnerf-bench runtime``'s) are run as rendered (640x480,
the person in full view: the reference, no padding), and again with camera 0's frame cut on its left side,
so that a share ``p`` of the person's box (the true 2D joints' box in camera 0, its median left edge and width
over the sequence) lies outside the cut frame. The cut frame is the rendered one's columns ``m..639`` and its
camera ``Camera.cropped(m, 0, ...)``: the same pixels, the same lens, the same person, only less frame, so the
runtime's crop reaches past the edge and is padded exactly as a camera with that field of view would give
it. Everything else is the runtime's defaults (``EstimatorConfig()``), one estimator per run.

Printed per run: the share of camera 0's model-input pixels that are padding (from the crop window used,
``PairResult.rois``, against the cut frame), the 3D MPJPE over the joints found and the share found, and
camera 0's 2D error (median, pixels of the rendered frame) and share found of its visible joints, split between
those inside the cut frame (the model sees them in both runs: a change there is the cost of the black band
itself) and those cut off (no training can bring back what the frame does not show; they are what a wider
camera would have seen). With ``--training-samples N`` it first counts how the synthetic ``train`` split's
source crops cross their frame (what ``TargetConfig.frame_padding`` alone shows the model). ``--edge-crop``
runs the whole table once per tracked-crop policy (``roi.edge_crop``: ``clip`` the box to the frame and square
what is left, ``centre`` the square on the whole box with the part past the frame black, ``shift`` the whole
box's square inside the frame); the reference run is each policy's own. ``--pad-fill`` sets ``roi.pad_fill``
(``black``: zeros; ``edge``: the frame's edge repeated past it; ``fade``: that edge fading into the crop's mean
over ``--pad-fade`` crop sides, ``roi.pad_fade``). ``--blacken FILL`` keeps camera 0's frame whole and
fills its columns left of the cut instead (``fill_columns``): the crops are then the uncut run's, so the table
shows what the lost pixels alone cost, and with a fill other than ``black`` what another padding would. A tool,
not a test.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.numbers import number_list  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.geometry import Rig  # noqa: E402
from ghnerf_runtime.preprocess import PAD_FILLS  # noqa: E402


def cut_rig(rig: Rig, m: int) -> Rig:
    """``rig`` with camera 0's frame cut to its columns ``m..W-1`` (the same lens and pose)."""
    cam = rig.cameras[0]
    return replace(rig, cameras=(cam.cropped(m, 0, cam.width - m, cam.height),) + tuple(rig.cameras[1:]))


def cut_for(seq, share: float) -> int:
    """Columns to cut from camera 0's left so that ``share`` of the person's median joint box lies outside."""
    xs = np.asarray(seq.joints_2d[:, 0, :, 0])
    left, width = np.median(xs.min(axis=1)), np.median(xs.max(axis=1) - xs.min(axis=1))
    return int(round(left + share * width))


def padded_share(roi, width: int, height: int) -> float:
    """Share of a square crop window (undistorted pixels) outside ``[0, width) x [0, height)``; the lens'
    footprint is ignored (the bench rigs have no lens distortion: `RigPlacement.random`)."""
    inside_x = max(0, min(roi.x0 + roi.size, width) - max(roi.x0, 0))
    inside_y = max(0, min(roi.y0 + roi.size, height) - max(roi.y0, 0))
    return 1.0 - inside_x * inside_y / roi.size ** 2


def fill_columns(frame: np.ndarray, m: int, fill: str) -> np.ndarray:
    """``frame`` with its columns ``0..m-1`` replaced: ``black`` 0, ``grey`` the rest's mean colour, ``replicate``
    column ``m`` repeated, ``reflect`` the columns after ``m`` mirrored (what a padding other than black would
    show the model)."""
    if m <= 0:
        return frame
    if fill == "black":
        frame[:, :m] = 0
    elif fill == "grey":
        frame[:, :m] = frame[:, m:].reshape(-1, frame.shape[-1]).mean(axis=0).round().astype(frame.dtype)
    elif fill == "replicate":
        frame[:, :m] = frame[:, m:m + 1]
    elif fill == "reflect":
        idx = m + np.abs(np.arange(m) - m + 1) % (2 * (frame.shape[1] - m) - 1)
        frame[:, :m] = frame[:, np.minimum(idx, frame.shape[1] - 1)]
    else:
        raise ValueError(f"--fill must be black, grey, replicate or reflect, got {fill!r}")
    return frame


def run(session, cfg, sequences, share: float | None, blacken: str | None = None) -> dict:
    """One estimator per sequence over every pair; camera 0's frame cut for ``share`` (``None``: uncut), or with
    ``blacken`` (a ``fill_columns`` fill) kept whole with those columns filled (the runtime crops as it would
    uncut).
    Per pair: camera 0's 2D error (rendered frame's pixels) and found flags, the 3D error and found flags."""
    e2, f2, e3, f3, pads, cuts = [], [], [], [], [], []
    for seq in sequences:
        m = 0 if share is None else max(0, cut_for(seq, share))
        cuts.append(m)
        rig = seq.rig if m == 0 or blacken else cut_rig(seq.rig, m)
        est = Estimator(session, rig, cfg)
        name = rig.cameras[0].name
        for i in range(len(seq)):
            if blacken:  # the whole frame, its columns 0..m-1 filled: the crops as uncut, only the pixels lost
                frame = fill_columns(np.array(seq.images[i, 0]), m, blacken)
            else:
                frame = np.ascontiguousarray(seq.images[i, 0, :, m:])
            r = est.estimate([frame, np.array(seq.images[i, 1])], sequence=i)
            e3.append(np.linalg.norm(r.joints_3d - seq.joints_3d[i], axis=-1) * 1000)
            f3.append(~r.missing)
            roi = r.rois.get(name)
            if roi is not None:  # (blackened: the share of the crop on the black columns)
                pads.append(padded_share(roi if not blacken else replace(roi, x0=roi.x0 - m),
                                         rig.cameras[0].width - (m if blacken else 0), rig.cameras[0].height))
            pred = r.joints_2d[name] + [0 if blacken else m, 0]  # back to the rendered frame's pixels
            e2.append(np.linalg.norm(pred - seq.joints_2d[i, 0], axis=-1))
            f2.append(~r.missing_2d[name])
        est.close()
    return {"e2": np.array(e2), "f2": np.array(f2), "e3": np.array(e3), "f3": np.array(f3),
            "pad": float(np.mean(pads)) if pads else float("nan"), "cuts": cuts}


def in_frame(sequences, cuts) -> np.ndarray:
    """``(pairs, 25)``: camera 0's true joint lies inside the frame cut at ``cuts`` (one per sequence)."""
    return np.concatenate([np.asarray(seq.joints_2d[:, 0, :, 0]) >= m - 0.5 for seq, m in zip(sequences, cuts)])


def stats(run_: dict, sel: np.ndarray) -> tuple[float, float, int]:
    """Median 2D error over the selected joints found, the share of them found, and how many there are."""
    found = run_["f2"][sel]
    err = run_["e2"][sel][found]
    return (float(np.median(err)) if err.size else float("nan")), (float(found.mean()) if found.size else
                                                                    float("nan")), int(sel.sum())


def training_crops(samples: int, resolution: int = 128) -> None:
    """How the synthetic ``train`` split's source crops (the default ``SyntheticConfig``'s boxes, rendered at
    32 px here: the boxes do not depend on it) cross their frame: the share that does, and their padded share
    at ``resolution`` with ``TargetConfig.frame_padding`` (``training.data.frame_padding``)."""
    from training.data.frame_padding import frame_coverage
    from training.data.splits import split_spec
    from training.data.synthetic import SyntheticConfig, make_sample

    config = SyntheticConfig(resolution=32, supersample=1, novel_views=0)
    spec = split_spec("train")
    padded = []
    for i in range(samples):
        for v in make_sample(spec, 0, i, config).views:
            share = frame_coverage(v.full_K, v.full_size, v.roi, resolution)
            padded.append(0.0 if share is None else float((share < 1).mean()))
    padded = np.array(padded)
    print(f"train split, {samples} samples' source crops ({len(padded)}) at {resolution} px: {np.mean(padded > 0):.1%} "
          f"cross the frame, {np.mean(padded > 0.01):.1%} by more than 1 % of their pixels, "
          f"{np.mean(padded > 0.1):.1%} by more than 10 %; the most padded {padded.max():.1%}")


def table(session, cfg, sequences, visible, args) -> None:
    """One table: the uncut reference and each share of ``args.outside``, at ``cfg``."""
    ref = run(session, cfg, sequences, None)
    # as the estimator runs them: an unset fill is the model's, an unset turn search on where it has encoder
    # heatmaps (since session 57: the tables before it were measured with the search off)
    roi = cfg.beside_model(session.contract.frame_padding, session.contract.encoder_heatmaps).roi
    print(f"\nroi.edge_crop {cfg.roi.edge_crop!r}, roi.pad_fill {roi.pad_fill!r} (pad_fade {cfg.roi.pad_fade}), "
          f"roi.turn_search {'on' if roi.turn_search else 'off'}: {args.sequences} held-out-like "
          f"sequences x {args.frames} pairs, "
          "runtime defaults otherwise; camera 0's frame cut on the left so that a share of the person's box lies "
          f"outside it{f' (kept whole, those columns filled {args.blacken})' if args.blacken else ''}; [uncut]: the "
          "same joints in the uncut reference run")
    print("| box outside cam 0 | cam 0 crop padded | 3D MPJPE mm [uncut] | 3D found [uncut] | cam 0 2D err px, "
          "joints in the cut frame [uncut] | found [uncut] | cut-off joints: 2D err px [uncut] | found (n) |")
    print("|---|---|---|---|---|---|---|---|")
    e3_ref = float(ref["e3"][ref["f3"]].mean())
    print(f"| uncut (reference) | {ref['pad']:.1%} | {e3_ref:.1f} | {ref['f3'].mean():.3f} | "
          f"{stats(ref, visible)[0]:.1f} | {stats(ref, visible)[1]:.3f} | - | - |", flush=True)
    for share in args.outside:
        s = run(session, cfg, sequences, share, args.blacken)
        inside = in_frame(sequences, s["cuts"])
        e_in, f_in, _ = stats(s, visible & inside)
        r_in, rf_in, _ = stats(ref, visible & inside)
        e_out, f_out, n_out = stats(s, visible & ~inside)
        r_out = stats(ref, visible & ~inside)[0]
        print(f"| {share:.0%} | {s['pad']:.1%} | {s['e3'][s['f3']].mean():.1f} [{e3_ref:.1f}] | "
              f"{s['f3'].mean():.3f} [{ref['f3'].mean():.3f}] | {e_in:.1f} [{r_in:.1f}] | {f_in:.3f} [{rf_in:.3f}] | "
              f"{e_out:.1f} [{r_out:.1f}] | {f_out:.3f} ({n_out}) |", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--outside", default="0,0.1,0.25,0.5", type=number_list,
                    help="shares of the person's box outside camera 0's cut frame")
    ap.add_argument("--edge-crop", default=None, type=lambda s: [v for v in s.split(",") if v],
                    help="roi.edge_crop policies to run, comma-separated (default: the runtime's default only)")
    ap.add_argument("--pad-fill", default=None, choices=PAD_FILLS,
                    help="roi.pad_fill (default: the model's, fade for one trained without frame padding)")
    ap.add_argument("--pad-fade", default=None, type=float,
                    help="roi.pad_fade, crop sides (default: the runtime's default)")
    ap.add_argument("--blacken", default=None, choices=("black", "grey", "replicate", "reflect"),
                    help="instead of cutting camera 0's frame, fill its cut columns so (the crops stay as uncut)")
    ap.add_argument("--training-samples", type=non_negative_count, default=0,
                    help="also count how the synthetic train split's source crops cross their frame (0: skip)")
    args = ap.parse_args(argv)
    if args.training_samples:
        training_crops(args.training_samples)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    if args.pad_fill:
        cfg = replace(cfg, roi=replace(cfg.roi, pad_fill=args.pad_fill))
    if args.pad_fade is not None:
        cfg = replace(cfg, roi=replace(cfg.roi, pad_fade=args.pad_fade))
    session = load_session(cfg)
    sequences = load_sequences(args.sequences, args.frames)
    visible = np.concatenate([np.asarray(seq.visible[:, 0]) for seq in sequences])
    start = time.perf_counter()
    for policy in args.edge_crop or [cfg.roi.edge_crop]:
        table(session, replace(cfg, roi=replace(cfg.roi, edge_crop=policy)), sequences, visible, args)
    print(f"({time.perf_counter() - start:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
