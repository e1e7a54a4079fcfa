"""MPJPE against the stereo pair's baseline (or angle), at the simulated rig's working distance or several, per lens.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_baseline.py [--model-dir models] [--sequences 4]
        [--frames 8] [--baselines 0.02,0.03,0.04,0.06,0.1,0.2,0.6 | --angles 0.5,1,2] [--distances 3]
        [--hfovs 80] [--rigs docs/examples/rig.json] [--tile-finds] [--rig-lift 1.2] [--tile-find-max-foot inf]
        [--good-find-mm 150] [--lifts 0,1,3,50]

The simulator's default rig (``drivers.sim.RigPlacement()``: 640x480, 80 degrees, 1.3 m high, both cameras aimed
at the subject ``--distances`` ahead) with the pair's centres moved to each baseline, filming the bench's held-out
people (``ghnerf-bench runtime``'s scenes, motions and first instants, placed in this rig's volume). ``--hfovs``
swaps the lens (the horizontal field of view; the image size stays); ``--angles`` asks for the angle at which the
pair's rays meet at the working volume's centre instead of a baseline, so that rows of other distances and lenses
compare the same pair angle (session 66: does ``load_rig``'s 1-degree bound, measured with one lens at 3 m, hold
for others?). Each (distance, lens, baseline, sequence) runs cold in its own estimator, the runtime's defaults
(``EstimatorConfig()``). It prints per row that angle (``rig_file.pair_angle_deg``: what ``load_rig``'s narrow-pair
warning reads, docs/rig-file.md), the depth one pixel of disparity moves a point at the working distance
(``depth_per_disparity_px``), how a person standing at the volume's centre is framed (``framing_cells``: the share
of their height in view, what ``load_rig``'s framing warning reads, and their height in image and model pixels), the
MPJPE of the joints found, the share of joints found and the share of pairs with no 3D joint at all; ``--rigs``
adds a row per rig file, its own pair filming the same people drawn in its own working volume; ``--tile-finds``
then a row per pair of theirs whose cold tile search found someone: where the person stood and the error then and
after (session 70); ``--rig-lift`` gives each rig file's estimator that rig :func:`lifted` (the same images: the
floor no longer at y = 0; session 71); ``--tile-finds`` ends with the judged feet of the finds good (their pair's
MPJPE under ``--good-find-mm``) and bad, and what each foot bound would refuse; ``--tile-find-max-foot`` runs the
rigs' estimators with that bound instead of ``tracking.cold_tiles_max_foot_m``'s default (``inf``: every find
kept, so each shows its own error; session 72). ``RigPlacement``
refuses baselines under 5 cm, so the cameras are placed here as it places them. Then, per ``--lifts`` (``""``:
none), the default rig (its own baseline, 1.2 m; the first distance, 80 degrees) with its frame moved that many
metres up (cameras and working volume alike, the same images): the floor no longer at y = 0, where the runtime
reads it (``load_rig``'s camera height warning). A tool, not a test.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.cli.numbers import finite_number, number_list, optional_number_list  # noqa: E402
from ghnerf_runtime.cli.simdata import HELD_OUT_MOTIONS, SEED_BASE, depth_per_disparity_px  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig, TrackingConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, look_at  # noqa: E402
from ghnerf_runtime.metrics import mpjpe  # noqa: E402
from ghnerf_runtime.preprocess import roi_from_volume  # noqa: E402
from ghnerf_runtime.rig_file import load_rig, pair_angle_deg, person_in_view_share, standing_person_px  # noqa: E402


def rig_with_baseline(baseline_m: float, distance_m: float, hfov_deg: float = 80.0) -> Rig:
    """The simulator's default rig at ``distance_m`` with an ``hfov_deg`` lens, its cameras ``baseline_m`` apart (any
    baseline: the placement's own 5 cm floor does not apply), aimed at the target as ``RigPlacement.build`` aims
    them."""
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    placement = sim.RigPlacement(distance_m=distance_m, hfov_deg=hfov_deg)
    base = placement.build(rig_id=f"baseline-{baseline_m:g}")
    cams = []
    for cam, sign in zip(base.pair, (-1.0, 1.0)):
        eye = np.array([sign * baseline_m / 2, -placement.camera_height_m, 0.0])
        R, t = look_at(eye, placement.target)
        cams.append(Camera(cam.name, cam.width, cam.height, cam.K, cam.dist, R, t))
    return Rig(tuple(cams), base.volume, base.rig_id)


def baseline_for_angle(angle_deg: float, distance_m: float, hfov_deg: float) -> float:
    """The baseline at which :func:`rig_with_baseline`'s pair sees its working volume's centre ``angle_deg`` apart:
    the centre lies on the pair's perpendicular bisector, so the angle is ``2 atan(b / 2 / d)``, ``d`` from the
    pair's midpoint (which the baseline does not move) to the centre."""
    rig = rig_with_baseline(1.0, distance_m, hfov_deg)
    reach = float(np.linalg.norm(rig.volume.center - 0.5 * (rig.pair[0].center + rig.pair[1].center)))
    return 2.0 * reach * float(np.tan(np.radians(angle_deg) / 2.0))


def lifted(rig: Rig, lift_m: float) -> Rig:
    """``rig`` with its frame's origin moved ``lift_m`` metres down (y down): cameras and volume ``lift_m`` higher
    above the floor the runtime reads at y = 0, the geometry between them unchanged."""
    shift = np.array([0.0, -lift_m, 0.0])
    cams = tuple(Camera(c.name, c.width, c.height, c.K, c.dist, c.R, c.t - c.R @ shift) for c in rig.cameras)
    volume = WorkingVolume(rig.volume.min_corner + shift, rig.volume.max_corner + shift)
    return Rig(cams, volume, f"{rig.rig_id}-lifted-{lift_m:g}")


def bench_scene_in(rig: Rig, k: int, people: WorkingVolume | None = None):
    """Bench sequence ``k``'s scene seed (its person, clothes, motion and room) drawn in ``people`` (default
    ``rig``'s volume), and its first instant (seconds, from that seed alone, not the bench sequence's): what
    ``--rigs`` films, and ``benchmarks/measure_cold_tiles.py`` and ``measure_volume_near_edge.py`` too."""
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    seed = SEED_BASE + k
    scene = sim.random_scene(seed, volume=rig.volume if people is None else people, motions=HELD_OUT_MOTIONS)
    return scene, float(np.random.default_rng([seed, 7]).uniform(0.0, scene.period_s))


def run_sequence(session, cfg, rig: Rig, k: int, frames: int, fps: float = 30.0, lift_m: float = 0.0,
                 people: WorkingVolume | None = None, tile_finds: list | None = None):
    """Predicted joints, found mask and truth of bench sequence ``k``'s scene (:func:`bench_scene_in`, its person
    drawn in ``people``, default ``rig``'s volume) filmed by ``rig``, one cold estimator given ``rig`` :func:`lifted`
    by ``lift_m`` (truth in ``rig``'s frame). ``tile_finds``: gets ``(pair, kept, foot)`` for each pair whose cold
    tile search found someone, kept or refused for floating feet, and that find's lower foot as the refusal judged
    it (``Estimator.tile_find_foot_m``; ``--tile-finds``)."""
    scene, t0 = bench_scene_in(rig, k, people)
    est = Estimator(session, lifted(rig, lift_m) if lift_m else rig, cfg)
    pred, found, truth = [], [], []
    for i in range(frames):
        t = t0 + i / fps
        before = (est.cold_tiles_found, est.tile_finds_floating)
        r = est.estimate([scene.render(cam, t, with_truth=False)[0] for cam in rig.pair], sequence=i)
        if tile_finds is not None and (est.cold_tiles_found, est.tile_finds_floating) != before:
            tile_finds.append((i, est.cold_tiles_found > before[0], est.tile_find_foot_m))
        pred.append(r.joints_3d + [0.0, lift_m, 0.0])
        found.append(~r.missing)
        truth.append(scene.joints_3d(t))
    est.close()
    return np.array(pred), np.array(found), np.array(truth)


def default_baseline_m() -> float:
    """The simulator's default rig's baseline (``drivers.sim.RigPlacement``'s, 1.2 m), the one ``--lifts`` moves."""
    import drivers.sim as sim

    return sim.RigPlacement().baseline_m


def score_cells(runs) -> str:
    """The table's last three cells over :func:`run_sequence`'s ``runs``: MPJPE mm ("-" with no joint found), the
    share of joints found and the share of pairs with no joint at all."""
    pred, found, truth = (np.concatenate(a) for a in zip(*runs))
    value = f"{mpjpe(pred, truth, np.ones(found.shape, bool), pred_valid=found).value:.0f}" if found.any() else "-"
    return f"{value} | {found.mean():.3f} | {float((~found.any(axis=1)).mean()):.3f}"


def framing_cells(rig: Rig, model_px: int) -> str:
    """The framing cells of a row, each the pair's worse camera: the share of a standing person's height at the working
    volume's centre inside the image (``rig_file.person_in_view_share``: what ``load_rig``'s warning reads), that
    person's height in image pixels (pinhole) and in the model's input pixels through the cold-start crop (the volume
    projected, ``roi_from_volume``, resized to the model's ``model_px``: what a pair with no track sees)."""
    share = min(person_in_view_share(cam, rig.volume) for cam in rig.pair)
    heights = [standing_person_px(cam, rig.volume) for cam in rig.pair]
    return f"{share:.2f} | {min(heights):.0f} | {in_cold_crop_px(rig, heights, model_px):.0f}"


def in_cold_crop_px(rig: Rig, image_px: Sequence[float], model_px: int) -> float:
    """``image_px`` (a height per camera of the pair, image pixels) in the model's input through the cold-start crop
    (the working volume projected, ``roi_from_volume``, resized to ``model_px``), the pair's worse camera: what a pair
    with no track sees of a person that tall (:func:`framing_cells`, ``measure_synth_framing.cold_crop_px``)."""
    if len(image_px) != len(rig.pair):
        raise ValueError(f"image_px: one height per camera of the pair ({len(rig.pair)}), got {len(image_px)}")
    return min(h * model_px / roi_from_volume(cam, rig.volume).size for cam, h in zip(rig.pair, image_px))


def finite_float(text: str) -> float:
    """``--rig-lift``: a finite number of metres."""
    try:
        return finite_number(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"a finite number of metres, got {text!r}") from None


def bound_m(text: str) -> float:
    """``--good-find-mm``: a number, inf allowed, not nan."""
    if text.strip() == "inf":
        return float("inf")
    try:
        return finite_number(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(f"a number (inf allowed), got {text!r}") from None


def max_foot_m(text: str) -> float:
    """``--tile-find-max-foot``: a bound ``tracking.cold_tiles_max_foot_m`` takes (0-10 m), or inf (none)."""
    value = bound_m(text)
    if value != float("inf") and not 0.0 <= value <= 10.0:
        raise argparse.ArgumentTypeError(f"metres from 0 to 10 (tracking.cold_tiles_max_foot_m), or inf, got {text!r}")
    return value


def rig_paths(text: str) -> list[str]:
    """``--rigs``: a comma-separated list of rig files ("" is none), as ``benchmarks/measure_cold_tiles.py`` reads
    it too."""
    return [p for p in text.split(",") if p.strip()]


def baseline_rows(args) -> list[tuple[float, float, float]]:
    """(distance m, lens hfov degrees, baseline m) per row of the first table: every ``--distances`` x ``--hfovs`` x
    ``--baselines``, or x ``--angles`` (each turned into the baseline giving that angle there) where given."""
    rows = []
    for distance in args.distances:
        for hfov in args.hfovs:
            if args.angles:
                rows.extend((distance, hfov, baseline_for_angle(a, distance, hfov)) for a in args.angles)
            else:
                rows.extend((distance, hfov, b) for b in args.baselines)
    return rows


def tile_find_rows(path: str, k: int, run, finds: list) -> list[str]:
    """``--tile-finds``' rows of sequence ``k``'s ``run`` (:func:`run_sequence`'s) in rig file ``path``: per pair
    whose tile search found someone (``finds``), whether the find was kept, where the person stood (their true
    joints' mean, m, and the nearest joint's depth: the example rig's volume starts 1 m ahead), the find's lower foot
    above the floor (``Estimator.tile_find_foot_m``, what the estimator refuses a tile find on; "-": no figure), the
    pair's MPJPE and joints found, and the MPJPE of the sequence's pairs from it on (what the track then followed)."""
    pred, found, truth = run
    rows = []
    for i, kept, foot in finds:
        mean = ", ".join(f"{v:.2f}" for v in truth[i].mean(axis=0))
        rows.append(f"| {path} | {k} | {i} | {'kept' if kept else 'refused'} | {mean} | {truth[i][:, 2].min():.2f} | "
                    f"{'-' if foot is None else f'{foot:.2f}'} | "
                    f"{score_cells([(pred[i:i + 1], found[i:i + 1], truth[i:i + 1])]).rsplit(' | ', 1)[0]} | "
                    f"{score_cells([(pred[i:], found[i:], truth[i:])]).split(' | ')[0]} |")
    return rows


def find_outcomes(run, finds: list) -> list[tuple[bool, float | None, float | None]]:
    """Per tile find of ``run`` (``finds``, as :func:`tile_find_rows` reads them): kept or not, the judged foot (m)
    and the pair's MPJPE (mm; None where no joint was found, as on a refused find's pair)."""
    pred, found, truth = run
    return [(kept, foot, pair_mpjpe_mm(pred[i], found[i], truth[i])) for i, kept, foot in finds]


def pair_mpjpe_mm(pred: np.ndarray, found: np.ndarray, truth: np.ndarray) -> float | None:
    """One pair's MPJPE (mm) over its joints found, as the rows' cell; None with none found."""
    if not found.any():
        return None
    return mpjpe(pred, truth, np.ones(found.shape, bool), pred_valid=found).value


def feet_span(feet: list[float]) -> str:
    """"N, feet A to B m" (N alone with none)."""
    return f"{len(feet)}" + (f", feet {min(feet):.2f} to {max(feet):.2f} m" if feet else "")


def tile_find_summary(outcomes: list, good_mm: float, bounds: Sequence[float] = (0.3, 0.4, 0.5)) -> list[str]:
    """``--tile-finds``' closing lines over :func:`find_outcomes`' ``outcomes``: the kept finds good (their pair's
    MPJPE under ``good_mm``) and bad with their judged feet, those with no foot figure (good and bad: no bound judges
    them) and with no joint found, the refused ones (their error unseen: the pair answered nobody); then what each
    foot bound in ``bounds`` would refuse of the kept ones."""
    scored = [(foot, mm) for kept, foot, mm in outcomes if kept and mm is not None]
    good = [foot for foot, mm in scored if foot is not None and mm < good_mm]
    bad = [foot for foot, mm in scored if foot is not None and mm >= good_mm]
    footless = [mm for foot, mm in scored if foot is None]
    refused = [foot for kept, foot, _ in outcomes if not kept]
    lines = [f"tile finds kept and judged: good (pair MPJPE < {good_mm:g} mm) {feet_span(good)}; bad "
             f"{feet_span(bad)}; with no foot figure good {sum(mm < good_mm for mm in footless)}, bad "
             f"{sum(mm >= good_mm for mm in footless)}; kept with no joint found "
             f"{sum(kept and mm is None for kept, _, mm in outcomes)}; refused "
             f"{feet_span([f for f in refused if f is not None])} (error unseen)"]
    lines += [f"a {b:g} m bound would refuse of those kept: good {sum(f > b for f in good)}, bad "
              f"{sum(f > b for f in bad)}" for b in bounds]
    return lines


def print_tile_finds(rows: list[str], summary: list[str]) -> None:
    """``--tile-finds``' table (:func:`tile_find_rows`) and closing lines (:func:`tile_find_summary`)."""
    print("\n| rig file | sequence | pair | tile find | person's joints' mean x, y, z, m | nearest joint ahead, m | "
          "lower foot above the floor, m | MPJPE mm | joints found | MPJPE mm from this pair on |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows) if rows else "| (none) |")
    print("\n" + "\n".join(summary), flush=True)


def rig_label(path: str, lift_m: float) -> str:
    """A ``--rigs`` row's first cell: the rig file, and ``--rig-lift`` where its frame is moved."""
    return path if not lift_m else f"{path}, frame {lift_m:g} m up"


def with_max_foot(cfg: EstimatorConfig, max_foot_m: float) -> EstimatorConfig:
    """``cfg`` with ``tracking.cold_tiles_max_foot_m`` set to ``max_foot_m`` (``inf``: None, every find kept)."""
    bound = None if max_foot_m == float("inf") else float(max_foot_m)
    return replace(cfg, tracking=replace(cfg.tracking, cold_tiles_max_foot_m=bound))


def print_rig_files(args, session, cfg) -> None:
    """The table of ``--rigs``: each rig file's own pair, framing and scores on the same people (its estimator given
    the rig :func:`lifted` by ``--rig-lift``); with ``--tile-finds``, then each pair whose cold tile search found
    someone (:func:`tile_find_rows`)."""
    paths = rig_paths(args.rigs)
    if not paths:
        return
    rig_cfg = with_max_foot(cfg, args.tile_find_max_foot)
    print("\n| rig file | standing person in view, share | person tall, image px | person tall in the cold crop, "
          "model px | MPJPE mm | joints found | pairs with no joint |")
    print("|---|---|---|---|---|---|---|")
    rows, outcomes = [], []
    for path in paths:
        rig = load_rig(path)
        runs = []
        for k in range(args.sequences):
            finds: list = []  # (filled with --tile-finds only)
            runs.append(run_sequence(session, rig_cfg, rig, k, args.frames, lift_m=args.rig_lift,
                                     tile_finds=finds if args.tile_finds else None))
            rows += tile_find_rows(rig_label(path, args.rig_lift), k, runs[-1], finds)
            outcomes += find_outcomes(runs[-1], finds)
        print(f"| {rig_label(path, args.rig_lift)} | {framing_cells(rig, session.contract.width)} | "
              f"{score_cells(runs)} |", flush=True)
    if args.tile_finds:
        print_tile_finds(rows, tile_find_summary(outcomes, args.good_find_mm))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=4)
    ap.add_argument("--frames", type=positive_count, default=8)
    ap.add_argument("--distances", type=number_list, default="3",
                    help="the subject's distance ahead, metres, comma-separated (1.5-8); the first is the --lifts "
                         "rig's")
    ap.add_argument("--hfovs", type=number_list, default="80",
                    help="the lens's horizontal field of view, degrees, comma-separated (20-150; the simulator's "
                         "default 80)")
    ap.add_argument("--baselines", type=optional_number_list, default="0.02,0.03,0.04,0.06,0.1,0.2,0.6",
                    help="metres, comma-separated (\"\": none)")
    ap.add_argument("--angles", type=optional_number_list, default="",
                    help="instead of --baselines: the pair's angle at the working volume's centre, degrees, "
                         "comma-separated (each distance and lens its own baselines)")
    ap.add_argument("--rigs", default="", help="rig files whose own pair films the same people (drawn in each file's "
                                               "working volume), comma-separated: one row each (\"\": none)")
    ap.add_argument("--lifts", type=optional_number_list, default="0,1,3,50",
                    help="metres the default rig's frame is moved up, comma-separated (\"\": no such table)")
    ap.add_argument("--tile-finds", action="store_true", help="after the --rigs table, a row per pair whose cold "
                                                               "tile search found someone (kept or refused)")
    ap.add_argument("--rig-lift", type=finite_float, default=0.0,
                    help="metres each --rigs file's frame is moved up for its estimator (the same images; a "
                         "negative one moves it down): where the runtime reads the floor at y = 0")
    ap.add_argument("--tile-find-max-foot", type=max_foot_m, default=TrackingConfig().cold_tiles_max_foot_m,
                    help="metres: the --rigs estimators refuse a tile find whose lower foot stands higher (default "
                         "the runtime's tracking.cold_tiles_max_foot_m; inf: every find kept, each showing its own "
                         "error)")
    ap.add_argument("--good-find-mm", type=bound_m, default=150.0,
                    help="--tile-finds' closing lines count a kept find good where its pair's MPJPE is under this")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision))
    session = load_session(cfg)
    print(f"{args.sequences} held-out-like sequences x {args.frames} frames, {args.precision}, the simulator's "
          "default rig (640x480), each sequence cold")
    print("| subject ahead, m | lens hfov, degrees | focal, px | baseline m | rays' angle at the volume's centre, "
          "degrees | depth per px of disparity at the subject, m | standing person in view, share | person tall, "
          "image px | person tall in the cold crop, model px | MPJPE mm | joints found | pairs with no joint |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for distance, hfov, baseline in baseline_rows(args):
        rig = rig_with_baseline(baseline, distance, hfov)
        runs = [run_sequence(session, cfg, rig, k, args.frames) for k in range(args.sequences)]
        print(f"| {distance:g} | {hfov:g} | {rig.pair[0].K[0, 0]:.0f} | {baseline:.3g} | "
              f"{pair_angle_deg(rig, rig.volume.center):.2f} | {depth_per_disparity_px(rig, distance):.3f} | "
              f"{framing_cells(rig, session.contract.width)} | {score_cells(runs)} |", flush=True)
    print_rig_files(args, session, cfg)
    if not args.lifts:
        return 0
    print("\n| frame moved up, m | cameras above the floor y = 0, m | MPJPE mm | joints found | pairs with no joint |")
    print("|---|---|---|---|---|")
    rig = rig_with_baseline(default_baseline_m(), args.distances[0])
    for lift in args.lifts:
        runs = [run_sequence(session, cfg, rig, k, args.frames, lift_m=lift) for k in range(args.sequences)]
        print(f"| {lift:g} | {-lifted(rig, lift).cameras[0].center[1]:.2f} | {score_cells(runs)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
