"""The two cameras' inputs exchanged on a symmetric rig: what the runtime reports, how soon the daemon's checks say so.

    PYTHONPATH=$PWD /work/main/.venv/bin/python benchmarks/measure_exchanged_cameras.py [--model-dir models]
                                                                   [--sequences 10] [--frames 30] [--window 30]
                                                                   [--heading-deg 180] [--rig higher|toed-in|wide]
                                                                   [--only 25 ...]
                                                                   [--pose lying_x|lying_z|upside_down]
                                                                   [--second DX,DZ] [--per-sequence]

The simulator films the bench's held-out-like scenes (``ghnerf-bench runtime``'s recipe and cache: held-out motions,
random rig placements, every rig symmetric about its centre plane, both cameras aimed at one point). Each sequence is
estimated twice with the daemon's default estimator settings: as filmed, and with the two frames of every pair
exchanged (the left camera's fed as the right's). Per setting it prints the 3D joints found, the MPJPE, the per-pair
handedness (``PairResult.handedness``: +1 a person, -1 a mirror image; the pairs that have one), the medians over
``--window`` consecutive figures of one sequence, and per sequence the daemon's three calibration checks run over its
pairs (:mod:`firmware_host.daemon.calibration_watch`, the daemon's limits, a ``--window`` window each): the
sequences each flagged, and for the handedness check the pairs read until it did. Only sequences with a full window
of handedness figures are judged (the daemon waits for a full window); ``--per-sequence`` adds a line a sequence:
its figures, their median, its windows' range and the pair the handedness check flagged at, either way. Last, the
pairs' heel peaks as filmed, by the way the true person faces (a heel at the presence threshold in both views gives no
figure since session 66: ``ghnerf_runtime.handedness.BACK_JOINTS``). A tool, not a test.

``--heading-deg`` and ``--rig`` render the same scenes afresh (no cache), each person turned to that heading (180: their
back to the rig for the whole take; the motion's own turns stay) or filmed by another rig than the bench's: ``higher``
raises the second camera 0.3 m (both still aimed at one point: the rig is no longer a mirror image of itself),
``toed-in`` turns the second camera 8 degrees further towards the first's side, ``wide`` is the bench's rig at a 1.2 m
baseline (symmetric). ``--face-seen`` counts only the figures of pairs whose nose and an eye peaked at the presence
threshold in both views. ``--only`` renders just the bench sequences named (afresh), in place of the first
``--sequences``: a long take of one scene without the others'.

``--pose`` renders every pair's body turned as ``benchmarks/measure_lying_rendered.py``'s poses turn it (``lying_x``:
lying along the line of sight, ``lying_z``: lying across the view, ``upside_down``: a handstand's silhouette; turned
about the body's box centre, set on the floor, moved into the working volume), the motion playing on. ``--second
DX,DZ`` adds a second person (bench scene ``k + 1000``'s body, look, motion and heading) standing ``DX`` metres
towards the rig's centre line from the subject and ``DZ`` further away, rendered into the subject's room (the nearer
person's pixel in front, :func:`drivers.sim.render_people`); the summary then counts the pairs the runtime called
``several_people`` (which give no figure) and those figures the pairs it did not call so gave.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.measure_calibration_drift import rolling_medians  # noqa: E402
from firmware_host.daemon.calibration_watch import CalibrationWatch, FloorWatch, HandednessWatch  # noqa: E402
from firmware_host.daemon.config import (CALIBRATION_MAX_FLOOR_M, CALIBRATION_MAX_MIRROR,  # noqa: E402
                                         CALIBRATION_MAX_PX)
from ghnerf_runtime.body25 import JOINT_INDEX  # noqa: E402
from ghnerf_runtime.cli.simdata import (SEQUENCE_CACHE_HELP, Sequence, bench_rig_and_scene,  # noqa: E402
                                        load_sequences, render_frames)
from ghnerf_runtime.geometry import Camera, Rig, look_at  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.handedness import BACK_JOINTS  # noqa: E402

SETTINGS = ("as filmed", "exchanged")
RIGS = ("bench", "higher", "toed-in", "wide")
POSES = ("lying_x", "lying_z", "upside_down")  # --pose: benchmarks/measure_lying_rendered.py's turned poses
RAISE_M = 0.3  # --rig higher: how much higher the second camera is
TOE_DEG = 8.0  # --rig toed-in: how much further the second camera turns towards the first's side
WIDE_BASELINE_M = 1.2  # --rig wide: the simulator's default rig's (RigPlacement.baseline_m), at the bench's placement


def _aimed(cam: Camera, eye: np.ndarray, target: np.ndarray) -> Camera:
    R, t = look_at(eye, target)
    return Camera(cam.name, cam.width, cam.height, cam.K, cam.dist, R, t)


def variant_rig(placement, kind: str, rig_id: str) -> Rig:
    """The bench rig changed as ``--rig`` says (see the module's docstring)."""
    if kind == "wide":
        return replace(placement, baseline_m=WIDE_BASELINE_M).build(rig_id=rig_id)
    rig = placement.build(rig_id=rig_id)
    first, second = rig.pair
    eye, target = second.center.copy(), placement.target.copy()
    if kind == "higher":
        eye[1] -= RAISE_M  # the rig frame's y points down
    elif kind == "toed-in":
        yaw = np.radians(TOE_DEG)  # turn the aim about the camera's own vertical, towards -x
        d = target - eye
        c, s = np.cos(yaw), np.sin(yaw)
        target = eye + np.array([d[0] * c - d[2] * s, d[1], d[0] * s + d[2] * c])
    return Rig((first, _aimed(second, eye, target)), rig.volume, rig_id, metadata=dict(rig.metadata, variant=kind))


#: ``--second``: the second person is bench scene ``k`` + this, far past the sequences a run films (30 in the docs'
#: runs), so not the subject of another sequence of the run.
SECOND_PERSON_SCENE = 1000


def second_person(k: int, scene, offset_xz: tuple[float, float]):
    """Bench scene ``k +`` :data:`SECOND_PERSON_SCENE`'s person standing ``offset_xz`` from scene's: ``dx`` towards
    the rig's centre line (x = 0, where both cameras see most), ``dz`` further away."""
    from drivers.sim import SimScene  # tool only
    x, z = scene.config.position_xz
    dx, dz = offset_xz
    place = (x - dx if x > 0 else x + dx, z + dz)
    return SimScene(replace(bench_rig_and_scene(k + SECOND_PERSON_SCENE)[1].config, position_xz=place))


def render_people_frames(rig, scenes: list, t0: float, frames: int, fps: float, info: dict,
                         pose: str | None) -> Sequence:
    """``frames`` pairs of ``scenes``' people (the first the subject, whose room, sensor and truth they are) from
    ``t0`` at ``fps``, each body turned to ``pose`` (None: as posed); :func:`render_frames`'s sequence otherwise."""
    from benchmarks.measure_lying_rendered import posed_as  # tool only
    from drivers.sim.render import composite_nearest
    h, w = rig.pair[0].height, rig.pair[0].width
    imgs = np.empty((frames, 2, h, w, 3), np.uint8)
    j3, j2, vis = np.empty((frames, 25, 3)), np.empty((frames, 2, 25, 2)), np.empty((frames, 2, 25), bool)
    for i in range(frames):
        t = t0 + i / fps
        bodies = [s.posed(t) if pose is None else posed_as(s.posed(t), pose, rig.volume) for s in scenes]
        for c, cam in enumerate(rig.pair):
            layers = [s.renderer.render(b, cam) for s, b in zip(scenes, bodies)]
            radiance = layers[0][0] if len(layers) == 1 else composite_nearest(
                [image for image, _ in layers], [truth.depth for _, truth in layers])
            imgs[i, c] = scenes[0].capture(radiance, cam, t)
            j2[i, c], vis[i, c] = layers[0][1].joints_2d, layers[0][1].visible
        j3[i] = bodies[0].joints
    return Sequence(rig, imgs, j3, j2, vis, info)


def render_variant(k: int, frames: int, heading_deg, rig_kind: str, fps: float = 30.0, pose: str | None = None,
                   second_xz: tuple[float, float] | None = None) -> Sequence:
    """Bench sequence ``k`` rendered afresh: the person turned to ``heading_deg`` (None: as drawn), the rig as
    ``rig_kind`` says, the body turned to ``pose`` (None: upright), a second person ``second_xz`` away (None: alone)."""
    from drivers.sim import SimScene  # tool only
    rig, scene, t0, placement = bench_rig_and_scene(k)
    if heading_deg is not None:
        scene = SimScene(replace(scene.config, heading_deg=float(heading_deg)))
    if rig_kind != "bench":
        rig = variant_rig(placement, rig_kind, rig.rig_id)
    info = {"index": k, "motion": str(scene.config.motion), "distance_m": placement.distance_m,
            "baseline_m": rig.baseline, "fps": fps, "t0": t0}
    if pose is None and second_xz is None:
        return render_frames(rig, scene, t0, frames, fps, info)
    scenes = [scene] + ([] if second_xz is None else [second_person(k, scene, second_xz)])
    return render_people_frames(rig, scenes, t0, frames, fps, info, pose)


def offset_xz(text: str) -> tuple[float, float]:
    """``--second``'s ``DX,DZ``."""
    try:
        dx, dz = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--second wants DX,DZ in metres (like 1.0,0.4), got {text!r}") from None
    return dx, dz


def watches(w: int) -> dict:
    """The daemon's three checks, each over ``w`` figures."""
    return {"px": CalibrationWatch(w, CALIBRATION_MAX_PX), "floor": FloorWatch(w, CALIBRATION_MAX_FLOOR_M),
            "hand": HandednessWatch(w, CALIBRATION_MAX_MIRROR)}


def run_sequence(est: Estimator, seq, exchanged: bool) -> list:
    """Each pair's result, the frames exchanged or not."""
    t0, fps = float(seq.info["t0"]), float(seq.info["fps"])
    out = []
    for i in range(len(seq)):
        left, right = np.array(seq.images[i, 0]), np.array(seq.images[i, 1])
        out.append(est.estimate([right, left] if exchanged else [left, right], timestamp_s=t0 + i / fps))
    return out


NOSE, EYES = JOINT_INDEX["Nose"], (JOINT_INDEX["REye"], JOINT_INDEX["LEye"])
FACING_COS = 0.5  # a person "faces the rig" (or away) with the torso turned within 60 degrees of it


def true_facing_z(joints: np.ndarray) -> float:
    """The depth part of the way a true skeleton's torso faces (unit; -1: straight at the rig, +1: its back to it),
    from the hips' left and the neck's up as ``ghnerf_runtime.handedness`` reads them."""
    J = JOINT_INDEX
    facing = np.cross(joints[J["LHip"]] - joints[J["RHip"]], joints[J["Neck"]] - joints[J["MidHip"]])
    return float(facing[2] / np.linalg.norm(facing))


def heel_peak(result) -> float:
    """The stronger heel's peak in the view where it is weaker: what ``handedness.BACK_JOINTS`` reads (at the
    presence threshold in both views, a pair gives no figure)."""
    return min(max(float(c[j]) for j in BACK_JOINTS) for c in result.confidence_2d.values())


def face_seen(result, threshold: float) -> bool:
    """The nose and an eye peaked at the presence threshold in both views: the person's face towards the rig (the 3D
    joints are no guide: the skeleton prior places a face whatever the views show; both eyes in both views were
    rarer than that even facing the rig, a head turned a little hides one)."""
    def strong(j: int) -> bool:
        return all(float(c[j]) >= threshold for c in result.confidence_2d.values())
    return strong(NOSE) and any(strong(j) for j in EYES)


def _without_figure(result):
    return replace(result, handedness=None)


def judge(results: list, window: int) -> dict:
    """The three checks over one sequence's results: which flagged, and the pair the handedness check flagged at."""
    hands = [r.handedness for r in results if r.handedness is not None]
    checks = watches(window)
    flagged_at = None
    for n, r in enumerate(results, 1):
        checks["px"].add(r.reprojection_px_median)
        checks["floor"].add(r.lowest_foot_m)
        if checks["hand"].add(r.handedness) and flagged_at is None:
            flagged_at = n
    return {"hands": hands, "flagged_at": flagged_at,
            "ever": {k: c.suspect or (k == "hand" and flagged_at is not None) for k, c in checks.items()}}


def sequence_windows_text(verdict: dict, window: int) -> str:
    """One sequence's windows for its ``--per-sequence`` line: their medians' range (a short take: one window of all
    its figures, as the summary counts it) and the pair the handedness check flagged at."""
    rolled = rolling_medians(verdict["hands"], window)
    text = f", windows {min(rolled):5.2f} to {max(rolled):5.2f}" if rolled else ", windows     - to     -"
    at = verdict["flagged_at"]
    return text + (f", flagged after {at} pairs" if at is not None else ", not flagged")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--window", type=positive_count, default=30, help="figures per window (health.calibration_window)")
    ap.add_argument("--per-sequence", action="store_true", help="also a line per sequence: its handedness figures' "
                                                               "median, windows and flag as filmed and exchanged")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    ap.add_argument("--heading-deg", type=float, help="render afresh, every person turned so (180: back to the rig)")
    ap.add_argument("--rig", choices=RIGS, default="bench", help="render afresh on this rig (module docstring)")
    ap.add_argument("--face-seen", action="store_true", help="count only pairs with the nose and an eye seen")
    ap.add_argument("--only", type=non_negative_count, nargs="+", metavar="K",
                    help="render afresh just these bench sequences")
    ap.add_argument("--pose", choices=POSES, help="render afresh, every body turned so (lying, upside down)")
    ap.add_argument("--second", type=offset_xz, metavar="DX,DZ",
                    help="render afresh with a second person DX m towards the centre line and DZ m further away")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    threshold = cfg.presence.threshold(cfg.heatmaps.source)
    tally = {s: {"found": [], "err": [], "hands": [], "rolled": [], "pairs": 0, "judged": 0, "flags": [],
                 "flagged_at": [], "several": 0, "several_with_figure": 0} for s in SETTINGS}
    heels = {"facing the rig": [], "facing away": []}  # the heel peaks of the pairs as filmed, by the true facing
    if args.only:
        args.sequences = len(args.only)  # (the summary's counts are over the sequences run)
    if args.heading_deg is None and args.rig == "bench" and not (args.only or args.pose or args.second):
        sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache)
    else:
        indices = args.only or range(args.sequences)
        sequences = (render_variant(k, args.frames, args.heading_deg, args.rig, pose=args.pose,
                                    second_xz=args.second) for k in indices)
    for seq in sequences:
        line = (f"  sequence {seq.info['index']:3d} ({seq.info['motion']}, {seq.info['distance_m']:.2f} m away, "
                f"baseline {seq.info['baseline_m']:.2f} m):")
        for setting in SETTINGS:
            acc = tally[setting]
            with Estimator(session, seq.rig, cfg) as est:
                results = run_sequence(est, seq, setting == "exchanged")
            for i, r in enumerate(results):
                ok = ~r.missing
                acc["found"].append(int(ok.sum()))
                acc["err"] += list(1000 * np.linalg.norm(r.joints_3d[ok] - seq.joints_3d[i][ok], axis=1))
            acc["pairs"] += len(results)
            acc["several"] += sum(r.several_people for r in results)
            acc["several_with_figure"] += sum(r.several_people and r.handedness is not None for r in results)
            if setting == "as filmed":
                for i, r in enumerate(results):
                    z = true_facing_z(seq.joints_3d[i])
                    if abs(z) >= FACING_COS:
                        heels["facing away" if z > 0 else "facing the rig"].append(heel_peak(r))
            if args.face_seen:
                results = [r if face_seen(r, threshold) else _without_figure(r) for r in results]
            verdict = judge(results, args.window)
            h = verdict["hands"]
            line += f" {setting} {len(h):3d} figures, median " + (f"{np.median(h):5.2f}" if h else "    -")
            line += sequence_windows_text(verdict, args.window) + ";"
            acc["hands"] += verdict["hands"]
            acc["rolled"] += rolling_medians(verdict["hands"], args.window)
            if len(verdict["hands"]) >= args.window:  # the daemon judges full windows only
                acc["judged"] += 1
                acc["flags"].append(verdict["ever"])
                if verdict["flagged_at"] is not None:
                    acc["flagged_at"].append(verdict["flagged_at"])
        if args.per_sequence:
            print(line)
    scenes = "" if args.heading_deg is None else f", heading {args.heading_deg:g} deg"
    scenes += "" if args.rig == "bench" else f", rig {args.rig}"
    scenes += ", pairs with the face seen only" if args.face_seen else ""
    scenes += f", sequences {' '.join(map(str, args.only))} only" if args.only else ""
    scenes += f", pose {args.pose}" if args.pose else ""
    scenes += f", a second person {args.second[0]:g} m across and {args.second[1]:g} m behind" if args.second else ""
    print(f"{args.sequences} held-out-like sequences x {args.frames} pairs{scenes}, {args.model_dir}, windows of "
          f"{args.window} figures (handedness: +1 a person, -1 a mirror image; limit -{CALIBRATION_MAX_MIRROR:g}):")
    print(f"  {'setting':>9} | 3D joints | MPJPE mm | pairs with a figure | per pair: median   p10   p90 | windows: "
          f"min   max | sequences judged | flagged by px / floor / handedness | pairs to flag: median max")
    for setting, acc in tally.items():
        h, roll = np.asarray(acc["hands"], float), np.asarray(acc["rolled"], float)
        per = f"{np.median(h):6.2f} {np.percentile(h, 10):5.2f} {np.percentile(h, 90):5.2f}" if h.size else "     -"
        rolled = f"{roll.min():5.2f} {roll.max():5.2f}" if roll.size else "    -     -"
        counts = " / ".join(str(sum(f[k] for f in acc["flags"])) for k in ("px", "floor", "hand"))
        at = acc["flagged_at"]
        when = f"{np.median(at):5.0f} {max(at):4d}" if at else "    -    -"
        mpjpe = f"{np.mean(acc['err']):8.1f}" if acc["err"] else f"{'-':>8}"
        print(f"  {setting:>9} | {np.mean(acc['found']):5.1f}/25 | {mpjpe} | {h.size:5d}/{acc['pairs']:<5d}"
              f"       | {' ' * 9}{per} | {' ' * 5}{rolled} | {acc['judged']:8d}/{args.sequences:<7d} | "
              f"{counts:>34} | {' ' * 9}{when}")
    if args.second:
        for setting, acc in tally.items():
            print(f"  {setting:>9}: {acc['several']} of {acc['pairs']} pairs several_people "
                  f"({acc['several_with_figure']} of them with a figure)")
    print(f"  heel peaks as filmed (the stronger heel in its weaker view; limit {threshold:g} in both views gives no "
          f"figure), by the true facing within {np.degrees(np.arccos(FACING_COS)):.0f} degrees:")
    for facing, peaks in heels.items():
        p = (f"median {np.median(peaks):.2f}, p10 {np.percentile(peaks, 10):.2f}, p90 {np.percentile(peaks, 90):.2f}, "
             f"{np.mean(np.asarray(peaks) >= threshold):.0%} at the limit" if peaks else "-")
        print(f"    {facing:>14}: {len(peaks):5d} pairs, {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
