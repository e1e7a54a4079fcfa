"""2D joints of a person seen by one camera only (``frame_check.single_view_2d``, since session 53).

    .venv/bin/python benchmarks/measure_one_camera.py [--model-dir models] [--sequences 8] [--frames 10]
                                                      [--rooms 32] [--turn-search on|off]

Someone entering at the edge of one camera's view, outside the other's: both frames pass the frame check, the pair
has no 3D joints, and the camera that sees them reports its 2D joints (``PairResult.single_view``). Made from the
held-out-like bench sequences (``ghnerf-bench runtime``'s): each pair is run as it is, and with one camera's frame
replaced in turn by the same room, at the same instant, without the person (the sequence's scene with its person left
out, ``benchmarks/empty_rooms.py``; until session 65 its person moved 40 m to the side, which took the room along and
left black frames). It prints, for the camera that sees them, PCK@0.2 and the share of pairs whose answer is that
camera's (``single_view``), beside the same camera's PCK in the normal pair; each run keeps its own estimator. Per
run too: how many pairs searched the crop turns (``roi.turn_search``, on by default since session 57;
``Estimator.turn_searches``; ``--turn-search off`` sets it off), the median, mean and slowest of the pairs'
``timing_ms["total"]`` (on whatever else the host runs), and, over the pairs answered with one camera's 2D joints,
the median and the lowest of that view's median joint confidence, and the highest 6th-strongest joint peak of the
other view (what decides whether such a pair may search: a view read under ``roi.turn_search_below`` beside
another at 0.1 or more, ``Estimator._one_view_needs_no_search``). Then the false alarms: the pairs of those rooms
with nobody in either camera, and ``--rooms`` empty simulated rooms (``measure_presence.py``'s: textured rooms with
nobody in them; black frames until session 65), each room cold:
how many report anyone, how many ran the flip test's mirrored run (each view alone is asked whether someone may be
there), and each view's 6th-strongest heatmap peak before it (the per-view presence rule asks for 6 at >= 0.35;
the mirrored run's skip, 0.1). The frame check is off throughout, as before session 65, when the empty frames were
black and it would have rejected them (the rejected frame's path is ``measure_single_view.py``'s); the textured
rooms pass it.
A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair, scene_without_person  # noqa: E402
from ghnerf_runtime.cli.simdata import HELD_OUT_MOTIONS, load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig, RoiConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.flip_test import presence_peak  # noqa: E402
from ghnerf_runtime.metrics import pck  # noqa: E402


class _ViewPeaks(Estimator):
    """The estimator, noting each view's :func:`presence_peak` of the pair's heatmaps before the flip test's run
    (only where the pass reaches it: the pair's views may show someone)."""

    peaks: list = []

    def _may_be_someone(self, heat, views, peaks=None):
        if len(views) == 1:
            self.peaks.append(presence_peak(heat, views, self.config.presence.min_joints))
        return super()._may_be_someone(heat, views, peaks)


class _OtherView(Estimator):
    """The estimator, noting for each pass answered with one camera's 2D joints the other view's
    :func:`presence_peak` (whether the turn search could find that view's person too)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.other_peaks: list[float] = []

    def _weak_pass(self, p):
        if p.single_view is not None and p.env is not None:
            other = 1 - self.camera_names.index(p.single_view)
            self.other_peaks.append(presence_peak(p.env["encoder_heatmaps"], (other,), self.config.presence.min_joints))
        return super()._weak_pass(p)


def empty_counterpart(seq) -> list:
    """Per pair of ``seq``, its two frames of the same room at the same instant without the person: the sequence's
    scene with its person left out (moving the person away would take the room along: black frames)."""
    import drivers.sim as sim  # a tool: the runtime library never imports drivers

    scene = sim.random_scene(int(seq.info["scene_seed"]), volume=seq.rig.volume, motions=HELD_OUT_MOTIONS)
    t0, fps = float(seq.info["t0"]), float(seq.info["fps"])
    return [list(scene_without_person(scene, seq.rig.pair, t0 + i / fps)) for i in range(len(seq))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=8)
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--rooms", type=non_negative_count, default=32,
                    help="empty rooms (scene seeds 1..N), the frame check off")
    ap.add_argument("--turn-search", choices=("on", "off"), default="on",
                    help="roi.turn_search (on: the default, resolved for the model; off: the opt-out)")
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision),
                          frame_check=FrameCheckConfig(enabled=False),
                          roi=RoiConfig(turn_search=None if args.turn_search == "on" else False))
    session = load_session(cfg)
    runs = {"both": None, "camera 0 alone": 0, "camera 1 alone": 1}  # run -> the camera that sees them
    scored = {name: {c: ([], [], [], []) for c in (0, 1)} for name in runs}  # pred, true, visible, found
    answered = {name: 0 for name in runs}  # pairs whose answer is the seeing camera's (single_view)
    searches = {name: 0 for name in runs}  # pairs that searched the crop turns (Estimator.turn_searches)
    ms = {name: [] for name in runs}  # each pair's timing_ms["total"]
    view_conf = {name: [] for name in runs}  # a single_view pair's median confidence of its view's joints found
    other_peak = {name: [] for name in runs}  # the other view's presence_peak on such pairs' passes
    pairs = alarms = empty_pairs = 0
    for seq in load_sequences(args.sequences, args.frames):
        rooms = empty_counterpart(seq)
        ests = {name: _OtherView(session, seq.rig, cfg) for name in runs}
        nobody = Estimator(session, seq.rig, cfg)
        names = nobody.camera_names
        for i in range(len(seq)):
            pairs += 1
            for name, seen in runs.items():
                images = [np.array(seq.images[i, 0]), np.array(seq.images[i, 1])]
                if seen is not None:
                    images[1 - seen] = rooms[i][1 - seen]
                before = ests[name].turn_searches
                r = ests[name].estimate(images, sequence=i)
                searches[name] += int(ests[name].turn_searches > before)
                ms[name].append(r.timing_ms["total"])
                if r.single_view is not None:
                    found = ~r.missing_2d[r.single_view]
                    view_conf[name].append(float(np.median(r.confidence_2d[r.single_view][found])))
                if seen is not None and not r.missing.all():
                    raise SystemExit(f"{name}, pair {i}: 3D joints were found where one camera sees nobody")
                answered[name] += r.single_view == (None if seen is None else names[seen])
                for c in ((0, 1) if seen is None else (seen,)):
                    for lst, value in zip(scored[name][c], (r.joints_2d[names[c]], seq.joints_2d[i, c],
                                                            seq.visible[i, c], ~r.missing_2d[names[c]])):
                        lst.append(value)
            r = nobody.estimate(rooms[i], sequence=i)
            empty_pairs += 1
            alarms += int(r.single_view is not None or not all(m.all() for m in r.missing_2d.values()))
        for name, est in ests.items():
            other_peak[name].extend(est.other_peaks)
        for est in (*ests.values(), nobody):
            est.close()
    print(f"{pairs} pairs of {args.sequences} held-out-like sequences, {args.precision}, the frame check off, "
          f"roi.turn_search {args.turn_search}, the other camera showing the room without the person:")
    for name, seen in runs.items():
        for c in ((0, 1) if seen is None else (seen,)):
            p, t, v, f = (np.array(a) for a in scored[name][c])
            print(f"  {name:>14}: camera {c} PCK@0.2 {pck(p, t, v, pred_valid=f).value:.3f}, visible joints found "
                  f"{float(f[v].mean()):.3f}")
        what = "3D joints (single_view null)" if seen is None else f"camera {seen}'s 2D joints (single_view)"
        print(f"  {name:>14}: {answered[name]} of {pairs} pairs answered with {what}")
        conf = view_conf[name]
        seen_conf = (f", the view's median joint confidence {np.median(conf):.2f} median, {min(conf):.2f} lowest, "
                     f"the other view's 6th-strongest peak <= {max(other_peak[name], default=0.0):.3f}" if conf else "")
        print(f"  {name:>14}: {searches[name]} of {pairs} pairs searched the crop turns, "
              f"{np.median(ms[name]):.1f} ms per pair (median; mean {np.mean(ms[name]):.1f}, "
              f"slowest {max(ms[name]):.1f}){seen_conf}")
    print(f"the same rooms without anyone, both cameras: {alarms} of {empty_pairs} pairs report a person")

    import drivers.sim as sim

    rig = sim.RigPlacement().build()
    est = _ViewPeaks(session, rig, cfg)
    _ViewPeaks.peaks = []
    alarms = flips = 0
    for seed in range(1, args.rooms + 1):
        est.reset()
        r = est.estimate(list(empty_room_pair(rig, seed)))
        alarms += int(r.single_view is not None or not all(m.all() for m in r.missing_2d.values()))
        flips += "encoder_flip" in r.timing_ms
    est.close()
    peak = max(_ViewPeaks.peaks) if _ViewPeaks.peaks else 0.0
    print(f"{args.rooms} empty rooms: {alarms} report a person, {flips} ran the mirrored run; "
          f"each view's 6th-strongest peak before it <= {peak:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
