"""Confidence of phantom joints in empty rooms vs joints of real people (sets the presence gate).

    .venv/bin/python benchmarks/measure_presence.py [--model-dir models] [--rooms 8] [--flip-test] [--time]
                                                    [--novel-view] [--time-turn-search-off]

The trained model has only ever seen views with a person in them, so for an empty room it still
answers "someone", with weaker peaks. For each heatmap source (with its best 3D method) this
prints, with the presence gate and the frame check off, the joints found and the 6th-strongest 3D
joint confidence of empty simulated rooms (textured rooms with nobody in them, ``benchmarks/empty_rooms.py``;
until session 65 black frames, which the frame check rejects before the model runs; the skeleton prior off:
the gate is decided on the triangulation before it, and its confidence is its expected error, which it reports
for any noise), and the same of the held-out pairs of ``tests/ghnerf_runtime/test_estimator_accuracy.py`` (4
sequences x 10 pairs). A presence threshold
(``config.PRESENCE_MIN_CONFIDENCE``) belongs between the two. With ``--flip-test`` it also prints the
statistic ``heatmaps.flip_test_skip_below`` is compared with (``flip_test.presence_peak`` of the heatmaps
before the mirrored run); its default belongs between the two as well. ``--time`` then times the runtime's
defaults (the frame check off, as for a textured room) on the empty rooms, ``flip_test_skip_below`` at its
default and at 0 (both run the flip test), the pairs interleaved: median ms per pair; with ``--novel-view``
also the defaults with a novel view requested on every pair (none is rendered for a pair that shows nobody);
and how many of the defaults' pairs searched the crop turns (``roi.turn_search``, on by default since session 57:
an empty-room pair is a cold pair that finds nobody, so it searches unless its peaks say nobody may be there) and
reported someone; with ``--time-turn-search-off`` also the defaults with ``roi.turn_search`` off (what the search
costs; ``--turn-search`` until session 69, a name other benchmarks give rows with the search on).
A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair  # noqa: E402
from ghnerf_runtime.cli.simdata import load_sequences  # noqa: E402
from ghnerf_runtime.config import (  # noqa: E402
    BEST_METHOD,
    HEATMAP_SOURCES,
    EstimatorConfig,
    FrameCheckConfig,
    HeatmapsConfig,
    Joints3DConfig,
    PresenceConfig,
    SessionConfig,
)
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from ghnerf_runtime.flip_test import presence_peak  # noqa: E402


class _PeakRecorder(Estimator):
    """The estimator, noting each pair's :func:`presence_peak` before the flip test's mirrored run."""

    peaks: list = []

    def _flip_test(self, batch, heat, timing, src_P=None, beside=False):
        self.peaks.append(presence_peak(heat, (0, 1), self.config.presence.min_joints))
        return super()._flip_test(batch, heat, timing, src_P, beside)


def empty_rooms(rig, count: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The pairs of ``count`` empty rooms (scene seeds 1..count): textured rooms with nobody in them
    (``benchmarks/empty_rooms.py``), which pass the frame check as a real empty room does."""
    return [empty_room_pair(rig, seed) for seed in range(1, count + 1)]


def sixth_strongest(result) -> float:
    c = np.sort(result.confidence[~result.missing])[::-1]
    return float(c[5]) if len(c) > 5 else 0.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--rooms", type=positive_count, default=8, help="empty textured rooms (scene seeds 1..N)")
    ap.add_argument("--flip-test", action="store_true", help="heatmaps.flip_test on (encoder heatmaps)")
    ap.add_argument("--time", action="store_true",
                    help="also time the empty rooms with the defaults, heatmaps.flip_test_skip_below default vs 0")
    ap.add_argument("--novel-view", action="store_true",
                    help="with --time: also time the defaults with a novel view requested on every pair")
    ap.add_argument("--time-turn-search-off", action="store_true",
                    help="with --time: also time the defaults with roi.turn_search off (the default is on)")
    args = ap.parse_args(argv)
    import drivers.sim as sim

    rig = sim.RigPlacement().build()
    sequences = load_sequences(4, 10)
    for source in HEATMAP_SOURCES:
        heatmaps = HeatmapsConfig(source=source, flip_test=args.flip_test)
        cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir), heatmaps=heatmaps,
                              joints3d=Joints3DConfig(method=BEST_METHOD[source], skeleton_prior="off"),
                              frame_check=FrameCheckConfig(enabled=False), presence=PresenceConfig(enabled=False))
        est = _PeakRecorder.from_config(rig, cfg)
        empty = []
        _PeakRecorder.peaks = []
        for pair in empty_rooms(rig, args.rooms):
            est.reset()
            r = est.estimate(pair)
            empty.append((r.num_found, sixth_strongest(r)))
        empty_peaks, _PeakRecorder.peaks = _PeakRecorder.peaks, []
        real = []
        for seq in sequences:
            est = _PeakRecorder(est.session, seq.rig, cfg)
            for i in range(len(seq)):
                r = est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])))
                real.append((r.num_found, sixth_strongest(r)))
        e, p = np.array(empty), np.array(real)
        flip = ", flip test" if cfg.flips_encoder_heatmaps else ""
        print(f"{source:>8} heatmaps ({BEST_METHOD[source]}{flip}): empty rooms: joints found {int(e[:, 0].min())}-"
              f"{int(e[:, 0].max())}, 6th-strongest confidence max {e[:, 1].max():.3f} | {len(p)} pairs with a "
              f"person: 6th-strongest min {p[:, 1].min():.3f}, 5th percentile {np.percentile(p[:, 1], 5):.3f}")
        if empty_peaks and _PeakRecorder.peaks:
            print(f"{'':>8} before the mirrored run (heatmaps.flip_test_skip_below): empty rooms max "
                  f"{max(empty_peaks):.3f} | with a person min {min(_PeakRecorder.peaks):.3f}")
    if args.time:
        time_empty_rooms(args.model_dir, args.rooms, novel=args.novel_view, search_off=args.time_turn_search_off)
    return 0


def time_empty_rooms(model_dir: str, rooms: int, repeats: int = 10, novel: bool = False,
                     search_off: bool = False) -> None:
    """Median ms per empty-room pair with the defaults (frame check off), skipping the flip test's mirrored
    run where nobody may be (the default) against running it always (``flip_test_skip_below`` 0); ``novel``:
    also the defaults with a novel view (alpha 0.5) requested on every pair; and how many of the defaults' pairs
    searched the crop turns (``roi.turn_search``) and reported someone; ``search_off``: also the defaults with
    ``roi.turn_search`` off."""
    import time
    from dataclasses import replace

    import drivers.sim as sim
    from ghnerf_runtime.config import NovelViewConfig
    from ghnerf_runtime.novel_view import NovelViewRequest

    rig = sim.RigPlacement().build()
    base = EstimatorConfig(session=SessionConfig(model_dir=model_dir), frame_check=FrameCheckConfig(enabled=False))
    if novel:  # one session for all (the colour graphs loaded)
        base = replace(base, novel_view=NovelViewConfig(enabled=True))
    skip = Estimator.from_config(rig, base)
    always = Estimator(skip.session, rig, replace(base, heatmaps=HeatmapsConfig(flip_test_skip_below=0.0)))
    order = [("skipped", skip, None), ("always", always, None)]
    if novel:
        order.append(("novel", Estimator(skip.session, rig, base), NovelViewRequest(alpha=0.5)))
    if search_off:
        unsearched = Estimator(skip.session, rig, replace(base, roi=replace(base.roi, turn_search=False)))
        order.append(("no turn search", unsearched, None))
    times: dict[str, list[float]] = {name: [] for name, _, _ in order}
    views = phantoms = 0
    for pair in empty_rooms(rig, rooms):
        for rep in range(repeats + 1):
            for name, est, request in order[::-1] if rep % 2 else order:  # alternate which runs first
                t = time.perf_counter()
                r = est.estimate(pair, novel_view=request)
                if rep:  # the first of each room warms the caches
                    times[name].append((time.perf_counter() - t) * 1e3)
                    views += r.novel_view is not None
                    phantoms += name == "skipped" and bool((~r.missing).any())
    a, b = (float(np.median(times[k])) for k in ("skipped", "always"))
    print(f"empty rooms, the defaults (frame check off): {a:.2f} ms median per pair with the mirrored run skipped, "
          f"{b:.2f} ms with it (flip_test_skip_below 0): {a / b:.2f}x ({len(times['skipped'])} pairs each)")
    if novel:
        print(f"empty rooms, the defaults with a novel view requested on every pair: "
              f"{np.median(times['novel']):.2f} ms median per pair, {views} of {len(times['novel'])} pairs with a "
              f"novel view")
    n = len(times["skipped"])
    search = "on" if skip.config.roi.turn_search else "off"  # as the estimator resolved the default for the model
    print(f"empty rooms, the defaults (roi.turn_search {search}): {skip.turn_searches} of {n + rooms} pairs searched "
          f"the crop turns, {phantoms} of {n} reported someone")
    if search_off:
        off = float(np.median(times["no turn search"]))
        print(f"empty rooms, the defaults with roi.turn_search off: {off:.2f} ms median per pair (the defaults "
              f"{a / off:.2f}x that)")


if __name__ == "__main__":
    sys.exit(main())
