"""Why ``ghcal synth``'s rig loses pairs: its people framed, found and lost, as it is, as it was and aimed otherwise.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_synth_framing.py [--model-dir models] [--sequences 6]
        [--frames 10] [--pitches 17,10] [--heights 1.4,1.8] [--near 0.5] [--per-sequence] [--floor-seeds 6]
        [--save DIR]

``calibration.render.synth_rig()``, ``ghcal synth``'s rig since session 68 (960x600, 75 degrees, a 0.6 m pair 1.8 m
up, aimed 23 degrees down at a point 2.5 m ahead, its working volume 2-5 m ahead), then ``example_rig()``, its rig
until then (1.4 m up, aimed 24 degrees down so that the floor board is seen near, ``calibration.level.LEVEL_VOLUME``
0.5-5 m ahead), and per ``--heights`` (default: the rig's own) and ``--pitches`` ``synth_rig``'s cameras (x, lenses,
the point 2.5 m ahead they converge on horizontally) moved to that height and pitched that many degrees down
(``--near``: their volume from that many metres ahead), each filming the bench's held-out people drawn in its own
working volume, as ``benchmarks/measure_baseline.py --rigs`` films them: each sequence cold, the runtime's defaults.
A row per rig: the cameras' height and pitch, where the floor comes into view (the image's bottom centre, the pair's
farther camera: ``ghcal synth`` lays the board there), the volume's depth range, ``measure_baseline.py``'s framing
cells (the standing person at the volume's centre) and scores. ``--per-sequence``: per rig and sequence, where the
person stands, the share of their joints inside both images, whether the nose and the ankles are, and the pairs with
no joint (session 67: heads cut, people too near, or the cold crop's scale?), the pairs answered by one camera's 2D
joints alone (``PairResult.single_view``) and how tall the person is in the cold crop (the working volume projected,
in the model's input pixels, the worse camera; session 69: a person 4.47 m ahead, 27 pixels, was seen by one camera
through a tile and lost by the other's whole-volume crop). ``--floor-seeds N``: per rig, in how
many of N seeds both cameras read the floor view ``calibration_views`` renders (the board lying on the floor, as
``ghcal synth`` lays it), of the default 80 mm board and of ``ghcal synth``'s 120 mm one
(``calibration.render.SYNTH_BOARD``); ``--sequences 0``: that table only. ``--save DIR`` writes each aimed rig as
``DIR/synth_pitch_P.json`` (``DIR/synth_height_H_pitch_P.json`` with ``--heights``; for ``ghcal synth --rig``). A
tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.cli.numbers import finite_number, optional_number_list  # noqa: E402
from benchmarks.measure_baseline import bench_scene_in, framing_cells, score_cells  # noqa: E402
from benchmarks.measure_baseline import in_cold_crop_px  # noqa: E402
from calibration.board import BoardSpec  # noqa: E402
from calibration.detect import BoardDetector  # noqa: E402
from calibration.render import CONVERGE_AHEAD_M, SYNTH_BOARD, calibration_views, example_rig, synth_rig  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.geometry import Camera, Rig, WorkingVolume, look_at  # noqa: E402
from ghnerf_runtime.rig_file import save_rig  # noqa: E402

#: BODY_25 joints told apart in ``--per-sequence``: the nose (the head cut or not) and the ankles (the feet).
NOSE, ANKLES = 0, (11, 14)


def pitch_deg(cam: Camera) -> float:
    """Degrees the camera's optical axis points below the horizontal (the rig frame's y is down)."""
    return float(np.degrees(np.arcsin(np.clip(cam.R[2, 1], -1.0, 1.0))))


def pitched(rig: Rig, pitch: float, height: float | None = None, near: float | None = None) -> Rig:
    """``rig``'s cameras from the same centres (or, given ``height``, the same x and z that many metres above the
    floor), each aimed ``pitch`` degrees down at the point straight below or above where it converged
    (:data:`CONVERGE_AHEAD_M` ahead, x 0); its volume, or given ``near`` that volume from ``near`` metres ahead."""
    cams = []
    for cam in rig.pair:
        eye = cam.center if height is None else np.array([cam.center[0], -height, cam.center[2]])
        target = np.array([0.0, eye[1] + (CONVERGE_AHEAD_M - eye[2]) * np.tan(np.radians(pitch)), CONVERGE_AHEAD_M])
        R, t = look_at(eye, target)
        cams.append(Camera(cam.name, cam.width, cam.height, cam.K, cam.dist, R, t))
    raised = "" if height is None else f"-height-{height:g}"
    volume, nearer = rig.volume, ""
    if near is not None:
        lo = rig.volume.min_corner.copy()
        lo[2] = near
        volume, nearer = WorkingVolume(lo, rig.volume.max_corner.copy()), f"-near-{near:g}"
    return Rig(tuple(cams), volume, rig_id=f"{rig.rig_id}{raised}-pitch-{pitch:g}{nearer}")


def floor_in_view_from_m(cam: Camera) -> float:
    """How far ahead (horizontally, metres) the floor (y = 0) comes into ``cam``'s view at its image's bottom
    centre, lens model included; inf where that pixel looks above the horizon."""
    origin, ray = cam.rays(np.array([cam.K[0, 2], cam.height - 1.0]))
    origin, ray = np.asarray(origin, float).reshape(3), np.asarray(ray, float).reshape(3)
    if ray[1] <= 0.0:
        return float("inf")
    hit = origin + (-origin[1] / ray[1]) * ray
    return float(np.hypot(*(hit - origin)[[0, 2]]))


def pair_floor_in_view_from_m(rig: Rig) -> float:
    """:func:`floor_in_view_from_m` of the pair's farther camera (where ``ghcal synth`` lays the floor board)."""
    return max(floor_in_view_from_m(cam) for cam in rig.pair)


def in_both_images(rig: Rig, points: np.ndarray) -> np.ndarray:
    """Per point, whether it lies in front of both cameras of the pair and inside both images."""
    inside = np.ones(len(points), bool)
    for cam in rig.pair:
        uv, depth = cam.project(points)
        with np.errstate(invalid="ignore"):
            inside &= (depth > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= cam.width - 0.5) \
                & (uv[:, 1] >= -0.5) & (uv[:, 1] <= cam.height - 0.5)
    return inside


def cold_crop_px(rig: Rig, joints: np.ndarray, model_px: int) -> float:
    """How tall ``joints`` ``(J, 3)`` (rig frame) are in the model's input through the cold-start crop (the working
    volume projected, ``roi_from_volume``, resized to ``model_px``), the pair's worse camera, pinhole: as
    ``framing_cells`` measures the standing person at the volume's centre, for this person where they stand (their
    vertical extent in the image, where ``framing_cells`` reads the feet-to-head length)."""
    tall = [float(np.ptp(cam.project(joints, distort=False)[0][:, 1])) for cam in rig.pair]
    return in_cold_crop_px(rig, tall, model_px)


def sequence_row(session, cfg, rig: Rig, k: int, frames: int, fps: float = 30.0):
    """Bench sequence ``k`` filmed by ``rig``, one cold estimator: the predictions and truth for
    :func:`score_cells`, and the sequence's ``--per-sequence`` cells."""
    scene, t0 = bench_scene_in(rig, k)
    est = Estimator(session, rig, cfg)
    pred, found, truth, in_view, lost, one_view = [], [], [], [], 0, 0
    for i in range(frames):
        t = t0 + i / fps
        r = est.estimate([scene.render(cam, t, with_truth=False)[0] for cam in rig.pair], sequence=i)
        joints = scene.joints_3d(t)
        pred.append(r.joints_3d)
        found.append(~r.missing)
        truth.append(joints)
        in_view.append(in_both_images(rig, joints))
        lost += int(r.missing.all())
        one_view += r.single_view is not None
    est.close()
    in_view = np.array(in_view)
    mid = 0.5 * (rig.pair[0].center + rig.pair[1].center)
    ahead = float(np.hypot(*(truth[0][8] - mid)[[0, 2]]))  # the mid hip at the first instant
    cells = (f"{k} | {truth[0][8][0]:+.2f} | {ahead:.2f} | {scene.config.motion} | {in_view.mean():.2f} | "
             f"{in_view[:, NOSE].mean():.1f} | {in_view[:, list(ANKLES)].all(axis=1).mean():.1f} | {lost} of {frames}"
             f" | {one_view} of {frames} | {cold_crop_px(rig, truth[0], session.contract.width):.0f}")
    return (np.array(pred), np.array(found), np.array(truth)), cells


def floor_view_read(rig: Rig, board: BoardSpec, seed: int) -> tuple[int, int]:
    """How many markers ``calibration.detect.BoardDetector`` finds in each camera's floor view that
    ``calibration_views`` renders of ``board`` for ``rig`` and ``seed`` (``ghcal synth``'s floor view; 0: not found).
    One shared view and no corner views drawn first, so the floor's pose is not ``ghcal synth``'s own for that seed:
    a sample of where the board lies, not a replay."""
    detector = BoardDetector(board)
    views = calibration_views(rig, board, count=1, edge_count=0, seed=seed)
    found = [detector.detect(views[cam.name]["floor"]) for cam in rig.pair]
    return tuple(0 if view is None else len(view.ids) for view in found)


def floor_cells(rig: Rig, boards: list[BoardSpec], seeds: int) -> str:
    """Per board: the seeds (of ``seeds``) whose floor view both cameras read, and the fewest markers either found."""
    cells = []
    for board in boards:
        reads = [floor_view_read(rig, board, seed) for seed in range(seeds)]
        cells.append(f"{sum(min(r) > 0 for r in reads)} of {seeds} | {min(min(r) for r in reads)}")
    return " | ".join(cells)


def rigs_to_measure(pitches: list[float], heights: list[float] | None = None, near: float | None = None) -> list[Rig]:
    """``ghcal synth``'s rig as it is and as it was (``example_rig``), then at each of ``heights`` (None: its own)
    pitched to each of ``pitches``, its volume from ``near`` metres ahead (None: its own)."""
    synth = synth_rig()
    return [synth, example_rig()] + [pitched(synth, p, h, near) for h in heights or [None] for p in pitches]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=non_negative_count, default=6, help="0: the --floor-seeds table only")
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--pitches", type=optional_number_list, default="17,10",
                    help="degrees below the horizontal, comma-separated (\"\": the rig as it is only)")
    ap.add_argument("--heights", type=optional_number_list, default="",
                    help="camera heights above the floor, metres, comma-separated, each crossed with --pitches "
                         "(\"\": the rig's own)")
    ap.add_argument("--near", type=finite_number,
                    help="the aimed rigs' volume from this many metres ahead (default: the rig's own, 2)")
    ap.add_argument("--per-sequence", action="store_true", help="a row per rig and sequence too")
    ap.add_argument("--floor-seeds", type=non_negative_count, default=0,
                    help="a row per rig too: of this many seeds, the floor "
                                                               "views both cameras read, the default 80 mm board and "
                                                               "ghcal synth's 120 mm one (--sequences 0: this only)")
    ap.add_argument("--save", type=Path, help="write each pitched rig to this folder as synth_pitch_P.json "
                                                "(synth_height_H_pitch_P.json with --heights)")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision))
    session = load_session(cfg)
    rigs = rigs_to_measure(args.pitches, args.heights, args.near)
    if args.save:
        args.save.mkdir(parents=True, exist_ok=True)
        for rig in rigs[2:]:
            save_rig(rig, args.save / f"synth_{rig.rig_id.removeprefix('ghcal-synth-').replace('-', '_')}.json")
    print(f"{args.sequences} held-out-like sequences x {args.frames} frames, {args.precision}, ghcal synth's rig "
          "(calibration.render.synth_rig) and its rig until session 68 (example_rig), each sequence cold")
    if args.sequences > 0:
        scores_table(session, cfg, rigs, args)
    if args.floor_seeds > 0:
        print("\n| rig | floor in view from, m | 80 mm board: floor views read by both | fewest markers | 120 mm "
              "board: floor views read by both | fewest markers |")
        print("|---|---|---|---|---|---|")
        for rig in rigs:
            floor = pair_floor_in_view_from_m(rig)
            print(f"| {rig.rig_id} | {floor:.2f} | {floor_cells(rig, [BoardSpec(), SYNTH_BOARD], args.floor_seeds)} |",
                  flush=True)
    return 0


def scores_table(session, cfg, rigs: list[Rig], args: argparse.Namespace) -> None:
    """The rows of the module's docstring (and with ``--per-sequence``, a row per rig and sequence)."""
    print("| rig | camera height, m | pitch, degrees down | floor in view from, m | volume ahead, m | standing person "
          "in view, share | person tall, image px | person tall in the cold crop, model px | MPJPE mm | joints found "
          "| pairs with no joint |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    per_sequence = []
    for rig in rigs:
        results = [sequence_row(session, cfg, rig, k, args.frames) for k in range(args.sequences)]
        per_sequence += [f"| {rig.rig_id} | {cells} |" for _, cells in results]
        floor = pair_floor_in_view_from_m(rig)
        height = -float(np.mean([cam.center[1] for cam in rig.pair]))
        ahead = f"{rig.volume.min_corner[2]:.1f}-{rig.volume.max_corner[2]:.1f}"
        print(f"| {rig.rig_id} | {height:.2f} | {pitch_deg(rig.pair[0]):.1f} | {floor:.2f} | {ahead} | "
              f"{framing_cells(rig, session.contract.width)} | {score_cells([r for r, _ in results])} |", flush=True)
    if args.per_sequence:
        print("\n| rig | sequence | person at x, m | ahead of the pair, m | motion | joints in both images | nose in "
              "both | ankles in both | pairs with no joint | pairs with one camera's 2D joints only | person tall in "
              "the cold crop, model px |")
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        print("\n".join(per_sequence))


if __name__ == "__main__":
    sys.exit(main())
