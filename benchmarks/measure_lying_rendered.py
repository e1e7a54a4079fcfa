"""People lying on the floor and upside down, rendered and run through the runtime with the shipped model.

    .venv/bin/python benchmarks/measure_lying_rendered.py [--model-dir models] [--scenes 12] [--frames 3]
        [--first-scene 0] [--poses upright,lying_x,lying_z,upside_down] [--turned-crops]
        [--turn-search [--turn-search-every 5]] [--then POSE [--change-at N]]
    .venv/bin/python benchmarks/measure_lying_rendered.py --rolls roll_down,roll_up,cartwheel [--frames 30]
        [--scenes 12] [--first-scene 0] [--turn-search-every 5] [--far-m 0.3]

``benchmarks/measure_prior_out_of_range.py`` measures the skeleton prior on turned bodies through a noise
model (exact projections plus Gaussian pixels, the bodies turned as the prior's training copies are). This
renders them instead: the bench's held-out-like scenes (``ghnerf_runtime.cli.simdata.bench_rig_and_scene``: the
rig, room, person and motion of ``ghnerf-bench runtime``'s sequence k), the posed body turned rigidly about its
box's centre, set on the floor (the rig frame is y down, the floor at y = 0: the body's lowest surface point at
y = 0) and moved into the working volume where it fits (:func:`turned`), rendered by the simulator
(``BodyRenderer.render`` with the scene's sensor), and each pair run through the real
:class:`~ghnerf_runtime.estimator.Estimator` at the runtime's defaults (the model folder's int8 graphs, encoder
heatmaps, flip tests; ``roi.turn_search`` off, though on by default since session 57, except in the
``--turn-search`` rows), ``--frames`` consecutive pairs at 30 fps per scene and pose (the first cold, the next
tracked), once with the skeleton prior (``joints3d.skeleton_prior`` ``auto``, the default) and once without
(``off``: gated triangulation). Poses:

* ``upright``: the scene as the bench renders it (the reference);
* ``lying_x``: turned 90 deg about the rig's x axis (lying along the line of sight, head or feet nearest);
* ``lying_z``: turned 90 deg about the rig's z axis (lying across the view);
* ``upside_down``: turned 180 deg about z, resting on its head or hands (a handstand's silhouette; the
  motion's arms are not those of a real handstand).

Per pose and prior: pairs, pairs with no joint, PCK@0.2 of the 2D joints, MPJPE over the joints found and the
share found, the median confidence of the joints found, the median of ``PairResult.prior_disagreement_m`` (what
``joints3d.max_prior_disagreement_m`` checks) and of ``PairResult.lowest_foot_m`` (the daemon's floor check,
``FloorWatch``) over the pairs that give one, and the share of the true joints more than
``joints3d.max_outside_box_m`` outside the rig's working volume (joints the runtime drops wherever it sees
them: a lying body can be longer than a small volume is wide). ``--turned-crops`` adds, for the poses a
turn of the picture can right, the prior with both crops turned with the body (:func:`turn_crops`, an oracle:
the runtime does not know how a person lies): what a search over crop rotations could give at best.
``--turn-search`` adds, for every pose, the prior with ``roi.turn_search`` on (the runtime's search: a weak cold
pass tries each view's crop turned 90, 180 and 270 degrees), with how many pairs searched and how many kept the
turned pass (the ``turn searches`` column; ``Estimator.turn_searches`` and ``turns_kept``), and the turned passes
refused because their body lay as no turn rights (``turns_refused``: ``ghnerf_runtime.body_lie.lies_as_turned``,
asked of a search's passes, and ``lies_as_kept_turn`` of a kept turn's); ``--turn-search-every`` sets
``roi.turn_search_every`` for those rows; their ``upright checks`` column counts the tracked pairs through a kept
turn that were run again through upright crops (``Estimator.turn_checks``) and those that left the turn so
(``turns_left``). ``--then POSE`` changes each scene's body to ``POSE`` from pair
``--change-at`` (default: half the ``--frames``) on, in every row (the pose column says ``lying_z, then upright``):
a person who gets up, or lies down, while tracked.

``--rolls`` measures gradual rolls instead (:func:`measure_rolls`; the poses' options do not apply): over the
``--frames`` pairs of each scene the body turns about the rig's z axis (across the view), by an angle that moves
evenly from the roll's first to its last (:data:`ROLLS`: ``roll_down`` 0 to 90 degrees, lying down across the
view; ``roll_up`` 90 to 0, getting up; ``cartwheel`` 0 to 180, upright to upside down; ``cartwheel_back`` 180 to
0), a few degrees a pair (30 pairs: 3 degrees a pair lying down, 6 in a cartwheel), each pose turned, set on the
floor and moved into the volume as :func:`turned` does. Two rows per roll and 30-degree band of the turn (the
pairs whose angle lies in it): the prior with ``roi.turn_search`` off and on. Per row: pairs (none found),
PCK@0.2, MPJPE over the joints found, the share found, the share of the joints found more than ``--far-m`` (0.3 m)
from the truth (reported far off), and with the search on its searches (kept), turned passes refused, upright
checks (turn left), the pairs read through turned crops and the pairs whose crops' turn changed from the pair
before (flicker).
Deterministic (scene seeds, sensor noise seeded by scene, camera and time). A tool, not a test:
docs/turn-search.md, "Lying and upside down, rendered" and "Gradual rolls" (the search's figures all come from it).
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.config_field import config_field  # noqa: E402
from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, RoiConfig, SessionConfig  # noqa: E402

FPS = 30.0
#: pose name -> (rig axis turned about: 0 x, 2 z; degrees); ``None``: as rendered by the bench.
POSES: dict[str, tuple[int, float] | None] = {
    "upright": None,
    "lying_x": (0, 90.0),
    "lying_z": (2, 90.0),
    "upside_down": (2, 180.0),
}
#: pose -> the crops' extra rotation (degrees counterclockwise, as ``roi.upright``'s) that shows the turned body
#: upright to a level camera (``--turned-crops``); a body lying along the line of sight has none.
CROP_TURN_DEG = {"lying_z": 90.0, "upside_down": 180.0}
#: gradual roll name -> (first, last) turn about the rig's z axis (degrees; ``--rolls``): the body's turn moves
#: evenly from one to the other over the ``--frames`` pairs.
ROLLS: dict[str, tuple[float, float]] = {
    "roll_down": (0.0, 90.0),
    "roll_up": (90.0, 0.0),
    "cartwheel": (0.0, 180.0),
    "cartwheel_back": (180.0, 0.0),
}
#: ``--rolls``: the rows' bands of the body's turn (degrees)
ROLL_BAND_DEG = 30.0


def rotation(axis: int, deg: float) -> np.ndarray:
    """The 3x3 rotation by ``deg`` about rig axis ``axis`` (0 x, 1 y, 2 z)."""
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    i, j = [k for k in range(3) if k != axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def turned(posed, axis: int, deg: float, volume=None):
    """``posed`` (a ``drivers.sim.body.PosedBody`` in the rig frame) turned by ``deg`` about rig axis ``axis``
    through its box's centre, then moved up or down so that its lowest surface point is on the floor (the rig
    frame's y points down, the floor is y = 0: the box's largest y becomes 0). Given the rig's working
    ``volume`` (a ``WorkingVolume``), it is also moved the least in x and z that puts its box inside the volume
    (centred on it along an axis where it is longer than the volume): a person 1.7 m long lying where an upright
    one stood near the volume's side would otherwise stick out of it, and the runtime drops joints more than
    ``joints3d.max_outside_box_m`` outside it; that is the volume's size, not the pose, at work."""
    lo, hi = posed.bounding_box()
    centre = 0.5 * (lo + hi)
    R = rotation(axis, deg)
    body = posed.transformed(R, centre - R @ centre)
    lo, hi = body.bounding_box()
    shift = np.array([0.0, -hi[1], 0.0])
    if volume is not None:
        for a in (0, 2):
            vlo, vhi = volume.min_corner[a], volume.max_corner[a]
            if hi[a] - lo[a] > vhi - vlo:
                shift[a] = 0.5 * (vlo + vhi) - 0.5 * (lo[a] + hi[a])
            else:
                shift[a] = max(vlo - lo[a], 0.0) + min(vhi - hi[a], 0.0)
    return body.transformed(np.eye(3), shift)


def posed_as(posed, pose: str, volume=None):
    """``posed`` in pose ``pose`` (a key of :data:`POSES`; ``volume``: :func:`turned`'s)."""
    if pose not in POSES:
        raise ValueError(f"unknown pose {pose!r}; choose from {', '.join(POSES)}")
    how = POSES[pose]
    return posed if how is None else turned(posed, *how, volume=volume)


def render_pair(scene, rig, posed, t: float):
    """The two cameras' pictures of ``posed`` in ``scene``'s room with its sensor, and the truth per camera:
    ``(images (BGR uint8, rig order), joints_2d (2, 25, 2), visible (2, 25))``."""
    images, j2, vis = [], [], []
    for cam in rig.pair:
        radiance, truth = scene.renderer.render(posed, cam)
        images.append(scene.capture(radiance, cam, t))
        j2.append(truth.joints_2d)
        vis.append(truth.visible)
    return tuple(images), np.array(j2), np.array(vis)


def turn_crops(est, deg: float) -> None:
    """Make ``est`` crop both cameras turned ``deg`` more than ``roi.upright`` does (as if each camera were mounted
    rolled by ``-deg``): the crops then show a body turned by ``deg`` in the picture upright. An oracle for
    ``--turned-crops``, reaching into the estimator's per-camera state; the runtime has no such search."""
    from ghnerf_runtime.estimator import _CameraState
    from ghnerf_runtime.tracking import SubjectTracker

    est._cams = [_CameraState(c.camera, c.roll_deg + deg) for c in est._cams]
    est.tracker = SubjectTracker(est.rig, est.config.tracking, est.config.roi, tuple(c.roll_deg for c in est._cams))


def measure(model_dir: str, scenes: int, frames: int, poses: list[str], first_scene: int = 0,
            turned_crops: bool = False, log=print, turn_search: bool = False,
            turn_search_every: int | None = None, then: str | None = None,
            change_at: int | None = None) -> dict[tuple[str, str], dict]:
    """``{(pose, "prior" | "no prior" | "turned crops" | "turn search"): Accuracy summary + pairs, empty pairs,
    lowest feet, turn searches}`` (module docstring); ``turned crops`` (with ``turned_crops``, for the poses of
    :data:`CROP_TURN_DEG`): the prior on, the crops turned with the body (:func:`turn_crops`); ``turn search``
    (with ``turn_search``, every pose): the prior on and ``roi.turn_search`` on (``turn_search_every``: its
    ``roi.turn_search_every``, ``None`` the default). ``then``: the pose every scene's body takes from pair
    ``change_at`` (default ``frames // 2``) on; the rows' pose is then ``"<pose>, then <then>"``."""
    from ghnerf_runtime.cli.simdata import Accuracy, bench_rig_and_scene
    from ghnerf_runtime.estimator import Estimator, load_session

    # the search set off (it is on by default since session 57): the rows without it are what upright crops give
    on = EstimatorConfig(session=SessionConfig(model_dir=model_dir), roi=RoiConfig(turn_search=False))
    off = replace(on, joints3d=replace(on.joints3d, skeleton_prior="off"))
    with_prior = load_session(on)
    configs = {"prior": (on, with_prior), "no prior": (off, load_session(off))}
    if turned_crops:
        configs["turned crops"] = (on, with_prior)
    if turn_search:
        every = on.roi.turn_search_every if turn_search_every is None else turn_search_every
        configs["turn search"] = (replace(on, roi=replace(on.roi, turn_search=True, turn_search_every=every)),
                                  with_prior)
    if then is not None:
        if then not in POSES:  # refused before any rendering
            raise ValueError(f"unknown pose {then!r} for then; choose from {', '.join(POSES)}")
        change_at = frames // 2 if change_at is None else change_at
    runs = [(p, c) for p in poses for c in configs if c != "turned crops" or p in CROP_TURN_DEG]
    acc = {key: Accuracy() for key in runs}
    extra = {key: {"pairs": 0, "empty": 0, "feet": [], "confidence": [], "apart": [], "searches": 0, "kept": 0,
                   "tracked_searches": 0, "checks": 0, "left": 0, "refused": 0, "ms": []} for key in runs}
    outside = {p: [] for p in poses}  # per pose: each pair's share of true joints the box gate would drop
    margin = on.joints3d.max_outside_box_m
    for k in range(first_scene, first_scene + scenes):
        start = time.perf_counter()
        rig, scene, t0, _ = bench_rig_and_scene(k)
        lo, hi = rig.volume.min_corner - margin, rig.volume.max_corner + margin
        for pose in poses:
            shots = []
            for i in range(frames):
                t = t0 + i / FPS
                now = pose if then is None or i < change_at else then
                posed = posed_as(scene.posed(t), now, rig.volume)
                shots.append((t, posed.joints.copy()) + render_pair(scene, rig, posed, t))
                outside[pose].append(float(np.mean(np.any((posed.joints < lo) | (posed.joints > hi), axis=1))))
            for name, (cfg, session) in configs.items():
                if (pose, name) not in acc:
                    continue
                with Estimator(session, rig, cfg) as est:
                    if name == "turned crops":
                        turn_crops(est, CROP_TURN_DEG[pose])
                    for i, (t, j3, images, j2, vis) in enumerate(shots):
                        searched = est.turn_searches
                        tracked_before = est.tracker.track is not None
                        r = est.estimate(images, sequence=i, timestamp_s=t - t0)
                        acc[pose, name].add_truth(r, j3, j2, vis, frame=(k, i))
                        e = extra[pose, name]
                        # a pair that came with a track and still searched (its tracked pass lost the subject,
                        # or was weak through upright crops)
                        e["tracked_searches"] += int(tracked_before and est.turn_searches > searched)
                        e["pairs"] += 1
                        e["ms"].append(r.timing_ms["total"])
                        e["empty"] += int(r.missing.all())
                        e["confidence"].extend(r.confidence[~r.missing].tolist())
                        if r.prior_disagreement_m is not None:
                            e["apart"].append(r.prior_disagreement_m)
                        if r.lowest_foot_m is not None:
                            e["feet"].append(r.lowest_foot_m)
                    e = extra[pose, name]
                    e["searches"] += est.turn_searches
                    e["kept"] += est.turns_kept
                    e["refused"] += est.turns_refused
                    e["checks"] += est.turn_checks
                    e["left"] += est.turns_left
        log(f"scene {k} ({scene.config.motion}): {time.perf_counter() - start:.1f} s")
    out = {}
    for key in acc:
        s = acc[key].summary()
        e = extra[key]
        s.update(pairs=e["pairs"], empty=e["empty"], feet_pairs=len(e["feet"]), turn_searches=e["searches"],
                 turns_kept=e["kept"], turns_refused=e["refused"], tracked_searches=e["tracked_searches"],
                 turn_checks=e["checks"], turns_left=e["left"], ms_median=float(np.median(e["ms"])),
                 outside_frac=float(np.mean(outside[key[0]])),
                 disagreement_median_m=float(np.median(e["apart"])) if e["apart"] else float("nan"),
                 confidence_median=float(np.median(e["confidence"])) if e["confidence"] else float("nan"),
                 feet_median_m=float(np.median(e["feet"])) if e["feet"] else float("nan"))
        out[key if then is None else (f"{key[0]}, then {then}", key[1])] = s
    return out


def roll_angles(roll: str, frames: int) -> np.ndarray:
    """The body's turn about the rig's z axis (degrees) at each of ``frames`` pairs of roll ``roll`` (a key of
    :data:`ROLLS`): evenly from its first angle at the first pair to its last at the last."""
    if roll not in ROLLS:
        raise ValueError(f"unknown roll {roll!r}; choose from {', '.join(ROLLS)}")
    if frames < 2:
        raise ValueError(f"a roll needs at least 2 frames (its first and last angle), got {frames}")
    return np.linspace(*ROLLS[roll], frames)


def roll_band(deg: float, roll: str) -> tuple[float, float]:
    """The :data:`ROLL_BAND_DEG` band of turn ``deg`` within roll ``roll``'s range (the last band closed)."""
    top = max(ROLLS[roll])
    lo = min(math.floor(deg / ROLL_BAND_DEG), math.ceil(top / ROLL_BAND_DEG) - 1) * ROLL_BAND_DEG
    return lo, lo + ROLL_BAND_DEG


def measure_rolls(model_dir: str, scenes: int, frames: int, rolls: list[str], first_scene: int = 0,
                  log=print, turn_search_every: int | None = None, far_m: float = 0.3
                  ) -> dict[tuple[str, tuple[float, float], str], dict]:
    """``{(roll, band, "search off" | "search on"): Accuracy summary + pairs, empty pairs, far-off share, turn
    counts}`` (the module docstring's ``--rolls``): each scene's ``frames`` pairs with the body turned about the rig's
    z axis by :func:`roll_angles`, run once with ``roi.turn_search`` off and once on (``turn_search_every``: its
    ``roi.turn_search_every``, ``None`` the default), the prior on; each pair counted in the band of its angle.
    ``far_m``: a found joint further than this from the truth is reported far off."""
    from ghnerf_runtime.cli.simdata import Accuracy, bench_rig_and_scene
    from ghnerf_runtime.estimator import Estimator, load_session

    for roll in rolls:
        roll_angles(roll, frames)  # refused before any rendering
    off = EstimatorConfig(session=SessionConfig(model_dir=model_dir), roi=RoiConfig(turn_search=False))
    every = off.roi.turn_search_every if turn_search_every is None else turn_search_every
    on = replace(off, roi=replace(off.roi, turn_search=True, turn_search_every=every))
    session = load_session(off)
    configs = {"search off": off, "search on": on}
    counts = ("searches", "kept", "refused", "checks", "left")
    acc: dict = {}
    extra: dict = {}
    for k in range(first_scene, first_scene + scenes):
        start = time.perf_counter()
        rig, scene, t0, _ = bench_rig_and_scene(k)
        for roll in rolls:
            shots = []
            for i, deg in enumerate(roll_angles(roll, frames)):
                t = t0 + i / FPS
                posed = turned(scene.posed(t), 2, float(deg), rig.volume)
                shots.append((t, roll_band(float(deg), roll), posed.joints.copy()) + render_pair(scene, rig, posed, t))
            for name, cfg in configs.items():
                with Estimator(session, rig, cfg) as est:
                    before_turns = est._turns
                    for i, (t, band, j3, images, j2, vis) in enumerate(shots):
                        key = (roll, band, name)
                        if key not in acc:
                            acc[key] = Accuracy()
                            extra[key] = {"pairs": 0, "empty": 0, "found": 0, "far": 0, "turned": 0, "changes": 0,
                                          **{c: 0 for c in counts}}
                        was = (est.turn_searches, est.turns_kept, est.turns_refused, est.turn_checks,
                               est.turns_left)
                        r = est.estimate(images, sequence=i, timestamp_s=t - t0)
                        acc[key].add_truth(r, j3, j2, vis, frame=((k, roll), i))
                        e = extra[key]
                        now = (est.turn_searches, est.turns_kept, est.turns_refused, est.turn_checks, est.turns_left)
                        for c, a, b in zip(counts, was, now):
                            e[c] += b - a
                        ok = ~r.missing
                        e["pairs"] += 1
                        e["empty"] += int(r.missing.all())
                        e["found"] += int(ok.sum())
                        e["far"] += int((np.linalg.norm(r.joints_3d[ok] - j3[ok], axis=1) > far_m).sum())
                        # the crops' turn this pair's answer was read through (est._turns: the search's state)
                        e["turned"] += int(est._turns != (0, 0) and not r.missing.all())
                        e["changes"] += int(i > 0 and est._turns != before_turns)
                        before_turns = est._turns
        log(f"scene {k} ({scene.config.motion}): {time.perf_counter() - start:.1f} s")
    out = {}
    for key in sorted(acc, key=lambda q: (rolls.index(q[0]), q[1][0] if ROLLS[q[0]][0] <= ROLLS[q[0]][1]
                                                                     else -q[1][0], q[2])):
        s = acc[key].summary()
        e = extra[key]
        s.update(e, far_frac=e["far"] / e["found"] if e["found"] else float("nan"))
        out[key] = s
    return out


def roll_table(results: dict[tuple[str, tuple[float, float], str], dict], far_m: float = 0.3) -> str:
    """:func:`measure_rolls`'s results as a Markdown table, a row per roll, band and search setting, in the roll's
    order."""
    rows = ["| roll | turn (degrees) | `roi.turn_search` | pairs (none found) | PCK@0.2 | "
            f"MPJPE over the joints found | found | found but over {far_m:g} m off | searches (kept) | "
            "turned passes refused | upright checks (turn left) | pairs read turned | turn changes |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for (roll, (lo, hi), name), s in results.items():
        mp = f"{s['mpjpe_mm']:.1f} mm" if np.isfinite(s["mpjpe_mm"]) else "-"
        far = f"{100 * s['far_frac']:.1f} %" if np.isfinite(s["far_frac"]) else "-"
        counts = (f" {s['searches']} ({s['kept']}) | {s['refused']} | {s['checks']} ({s['left']}) | {s['turned']} |"
                  f" {s['changes']} |" if name == "search on" else " - | - | - | - | - |")
        rows.append(f"| {roll} | {lo:.0f}-{hi:.0f} | {name.split()[1]} | {s['pairs']} ({s['empty']}) | "
                    f"{s.get('pck@0.2', float('nan')):.3f} | {mp} | {100 * s['found_3d_frac']:.1f} % | {far} |"
                    + counts)
    return "\n".join(rows)


PRIOR_WORDS = {"prior": "on", "no prior": "off", "turned crops": "on, crops turned with the body (oracle)",
               "turn search": "on, `roi.turn_search` on"}


def table(results: dict[tuple[str, str], dict]) -> str:
    """The results as a Markdown table (one row per pose and prior; with ``turn search`` rows, four last columns:
    the pairs that searched the turns, those that kept the turned pass, and those that came tracked; the turned
    passes that found someone better but were refused, their body lying as no turn rights (``turns_refused``); the
    tracked pairs through a kept turn run again upright, and those that left the turn so; and the median of the pairs'
    ``timing_ms["total"]``, the whole estimate, on whatever else the host runs)."""
    searched = any(prior == "turn search" for _, prior in results)
    rows = ["| pose | skeleton prior | pairs (none found) | PCK@0.2 | MPJPE over the joints found | found | "
            "their confidence (median) | prior disagreement (median) | lowest foot (median, pairs) | true joints "
            "outside the volume |" + (" turn searches (kept, on tracked pairs) | turned passes refused | "
                                      "upright checks (turn left) | ms per pair (median) |" if searched else ""),
            "|---|---|---|---|---|---|---|---|---|---|" + ("---|---|---|---|" if searched else "")]
    for (pose, prior), s in results.items():
        conf = f"{s['confidence_median']:.2f}" if np.isfinite(s["confidence_median"]) else "-"
        mp = f"{s['mpjpe_mm']:.1f} mm" if np.isfinite(s["mpjpe_mm"]) else "-"
        apart = f"{1e3 * s['disagreement_median_m']:.0f} mm" if np.isfinite(s["disagreement_median_m"]) else "-"
        feet = f"{s['feet_median_m']:.2f} m ({s['feet_pairs']})" if s["feet_pairs"] else "none"
        rows.append(f"| {pose} | {PRIOR_WORDS[prior]} | {s['pairs']} ({s['empty']}) | "
                    f"{s.get('pck@0.2', float('nan')):.3f} | {mp} | {100 * s['found_3d_frac']:.1f} % | "
                    f"{conf} | {apart} | {feet} | {100 * s['outside_frac']:.1f} % |"
                    + ((f" {s['turn_searches']} ({s['turns_kept']}, {s['tracked_searches']}) |"
                         f" {s['turns_refused']} | {s['turn_checks']} ({s['turns_left']}) |"
                         if prior == "turn search" else " - | - | - |")
                       + f" {s['ms_median']:.1f} |" if searched else ""))
    return "\n".join(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--scenes", type=positive_count, default=12, help="bench scenes (ghnerf-bench runtime's sequences)")
    ap.add_argument("--first-scene", type=non_negative_count, default=0, help="the first bench scene's number")
    ap.add_argument("--frames", type=positive_count, default=3, help="consecutive pairs per scene and pose, at 30 fps")
    ap.add_argument("--poses", default=",".join(POSES), help=f"comma list of {', '.join(POSES)}")
    ap.add_argument("--turned-crops", action="store_true",
                    help="also run the prior with the crops turned with the body (lying across the view: 90 deg, "
                         "upside down: 180), what a search over crop rotations could give at best")
    ap.add_argument("--turn-search", action="store_true",
                    help="also run the prior with roi.turn_search on (the runtime's search over crop turns)")
    ap.add_argument("--turn-search-every", type=config_field(RoiConfig, "turn_search_every"), default=None,
                    help="roi.turn_search_every for --turn-search (default: the config's)")
    ap.add_argument("--then", default=None, help=f"change every body to this pose (one of {', '.join(POSES)}) "
                                                  "at --change-at")
    ap.add_argument("--change-at", type=int, default=None, help="with --then: the first pair in that pose "
                                                                 "(default: half the --frames)")
    ap.add_argument("--rolls", default=None,
                    help=f"comma list of gradual rolls ({', '.join(ROLLS)}) to measure instead of the poses, over "
                         "--frames pairs a scene, with the turn search off and on")
    ap.add_argument("--far-m", type=float, default=None,
                    help="with --rolls: a found joint further than this from the truth (metres) is far off (0.3)")
    args = ap.parse_args(argv)
    if args.far_m is not None and args.rolls is None:
        ap.error("--far-m needs --rolls")
    if args.turn_search_every is not None and not (args.turn_search or args.rolls):  # (was ignored, no word)
        ap.error("--turn-search-every sets the turn search's rows: give --turn-search or --rolls with it")
    if args.rolls is not None:
        args.far_m = 0.3 if args.far_m is None else args.far_m
        rolls = [r.strip() for r in args.rolls.split(",") if r.strip()]
        bad = [r for r in rolls if r not in ROLLS]
        if bad or not rolls:
            ap.error(f"--rolls: unknown {bad or args.rolls!r}; choose from {', '.join(ROLLS)}")
        if args.frames < 2:
            ap.error(f"--rolls needs --frames of at least 2, got {args.frames}")
        if args.then is not None or args.turned_crops or args.turn_search:
            ap.error("--rolls runs the search off and on by itself: without --then, --turned-crops, --turn-search")
        if not (math.isfinite(args.far_m) and args.far_m > 0):
            ap.error(f"--far-m must be a positive distance in metres, got {args.far_m}")
        results = measure_rolls(args.model_dir, args.scenes, args.frames, rolls, args.first_scene,
                                log=lambda m: print(m, file=sys.stderr), turn_search_every=args.turn_search_every,
                                far_m=args.far_m)
        print(roll_table(results, args.far_m))
        return 0
    poses = [p.strip() for p in args.poses.split(",") if p.strip()]
    bad = [p for p in poses if p not in POSES]
    if bad or not poses:
        ap.error(f"--poses: unknown {bad or args.poses!r}; choose from {', '.join(POSES)}")
    if args.then is not None and args.then not in POSES:
        ap.error(f"--then: unknown {args.then!r}; choose from {', '.join(POSES)}")
    if args.change_at is not None and (args.then is None or not 0 <= args.change_at <= args.frames):
        ap.error(f"--change-at needs --then and must lie within 0..--frames ({args.frames}), got {args.change_at}")
    results = measure(args.model_dir, args.scenes, args.frames, poses, args.first_scene, args.turned_crops,
                      log=lambda m: print(m, file=sys.stderr), turn_search=args.turn_search,
                      turn_search_every=args.turn_search_every, then=args.then, change_at=args.change_at)
    print(table(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
