"""What ``tracking.cold_tiles_below_share`` costs: per-pair time of cold pairs, with people and in empty rooms.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_cold_tiles.py [--model-dir models] [--sequences 6]
        [--frames 10] [--rooms 6] [--pairs 5] [--walk-in-after 0] [--rest-every N]
        --rigs docs/examples/rig.json,synth_rig.json

Per rig file, the runtime's defaults (or ``--rest-every``'s ``cold_tiles_rest_every``) against the same with
``cold_tiles_rest_every = 1`` (tiles that never rest) and with ``cold_tiles_below_share = 0`` (no tiles), interleaved
pair by pair, each its own estimator: ``--sequences`` of the bench's held-out people drawn in the rig's volume (as
``benchmarks/measure_baseline.py --rigs`` films them, ``--frames`` pairs each, one estimator per sequence), each after
``--walk-in-after`` pairs of its own room with nobody in it (the person walks in), and ``--rooms`` empty rooms
(``benchmarks/empty_rooms.py``, the rig's view of a scene's room with nobody in it, ``--pairs`` pairs each, every one
cold). It prints the median ms of the people's cold pairs (those that began without a track: the first of each
sequence, and every one after a pair that found nobody, the empty ones before the person included), how many there
were, the mean ms per pair over all those pairs, the share of the person's pairs with no joint, the median pairs each
person took to be found (0: on their first pair; in brackets the most, the sequence's length where never), the empty
rooms' median and mean ms per pair (a resting search mixes pairs with a tile pass and pairs without), their pairs that
reported a joint (a phantom), the ratios to no tiles and the passes through a tile. A tool, not a test.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_cold_tiles.py --walk-in-sweep [--sequences 6] [--frames 20]
        [--rest-every N] --rigs docs/examples/rig.json,synth_rig.json

The worst case of the rest instead: each of ``--sequences`` people walks into their own room (its empty pairs before
the person's first instant, through the scene's own sensor: fresh noise and exposure jitter each pair) after every
count of empty pairs from the first resting pair through one whole cycle of the rest (``--rest-every`` pairs a tile
pass x the four tiles: 16 counts at 4), so that the walk-in meets every phase of the rest against every next tile,
under the resting config without the wake-up (``cold_tiles_wake_levels`` None), with it (the runtime's threshold) and
with no tiles, a fresh estimator each, interleaved placement by placement. It prints the pairs from walk-in to the
first joint (0: found on the walk-in pair) over the placements found, median, p90 and max, how many placements never
found the person within ``--frames`` pairs, each person's most (``-``: never), the empty pairs' mean ms after the first
round of tiles and its ratio to no tiles, the wakes before the walk-in (false: nobody there) out of the empty pairs
that rested, and the median ms of one pair's scene check (both cameras' copies and the comparison).

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_cold_tiles.py --wake-margin [--sequences 6] [--pairs 30]
        --rigs docs/examples/rig.json,synth_rig.json

The wake-up's margin instead (no model run): the statistic ``tracking.cold_tiles_wake_levels`` thresholds
(``ghnerf_runtime.scene_change.wake_statistic``: each camera's 2nd largest cell difference, the larger camera's) of
each of ``--pairs`` pairs of ``--sequences`` bench rooms with nobody in them, through the scene's own sensor (fresh
noise and exposure jitter each pair), against the room's first pair, and of each person's first pair (where
``--walk-in-sweep`` puts the walk-in) against the same: count, min, median, p90, p99, max, how many are over the
runtime's threshold, and each person's value.

    PYTHONPATH=$PWD .venv/bin/python benchmarks/measure_cold_tiles.py --moving-room [--sequences 6] [--pairs 40]
        [--rest-every N] --rigs docs/examples/rig.json,synth_rig.json

A scene that keeps moving instead: ``--sequences`` bench rooms with nobody in them and a screen playing
(``benchmarks/empty_rooms.py``'s ``scene_with_screen``, a new picture every pair), ``--pairs`` pairs each, through
tiles that never rest, the resting config without the wake-up, with it and no tiles, a fresh estimator each,
interleaved pair by pair. After the first round of tiles it prints the tile passes and the wakes per 100 pairs, the
pairs seen in one view (a 2D person in one camera: it wakes the tiles as anyone seen does) and those with a frame
rejected (no tile pass), the mean ms per pair and its ratio to no tiles, the pairs that reported a joint (nobody
is there), and the most pairs in a row seen in one view in any room, the first round's too (a screen's pictures read as
a person now and then; a person who stays in one camera's view is seen on every pair, and clears the wake: the
estimator's ``ONE_VIEW_NOT_VAIN_PAIRS``).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.config_field import config_field  # noqa: E402
from ghnerf_runtime.cli.model_folder import checked_model_folder, model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count, positive_count  # noqa: E402
from benchmarks.empty_rooms import empty_room_pair, scene_with_screen, scene_without_person  # noqa: E402
from benchmarks.measure_baseline import bench_scene_in, rig_paths  # noqa: E402
from ghnerf_runtime.cli.simdata import SEED_BASE  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig, TrackingConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.rig_file import load_rig  # noqa: E402
from ghnerf_runtime.scene_change import pair_copies, scene_changed, wake_statistic  # noqa: E402
from ghnerf_runtime.tracking import volume_tiles  # noqa: E402


def timed(est: Estimator, images) -> tuple[float, bool, bool]:
    """(ms, whether the pair began without a track, whether it found no joint) of one pair."""
    cold = est.tracker.track is None
    t = time.perf_counter()
    result = est.estimate(images)
    return 1e3 * (time.perf_counter() - t), cold, bool(result.missing.all())


def people_pairs(rig, k: int, frames: int, empty_first: int = 0):
    """Bench sequence ``k``'s person drawn in ``rig``'s volume, ``frames`` pairs at 30 fps (measure_baseline's),
    after ``empty_first`` pairs of the same room with nobody in it (the person walks in)."""
    scene, t0 = bench_scene_in(rig, k)
    empty = [scene_without_person(scene, rig.pair, t0 + (i - empty_first) / 30.0) for i in range(empty_first)]
    return empty + [[scene.render(cam, t0 + i / 30.0, with_truth=False)[0] for cam in rig.pair]
                    for i in range(frames)]


def measure(session, configs: dict, rig, streams, empty_first: int = 0) -> dict:
    """Per config: (cold pairs' ms, empty or not-empty marks, tile passes, pairs until found); ``streams`` is a list
    of pair lists, each run by one fresh estimator per config, the configs interleaved pair by pair; the first
    ``empty_first`` pairs of each show nobody (timed, not marked)."""
    out = {name: {"ms": [], "cold_ms": [], "no_joint": [], "tiles": 0, "until_found": []} for name in configs}
    for pairs in streams:
        ests = {name: Estimator(session, rig, cfg) for name, cfg in configs.items()}
        nobody = {name: [] for name in configs}
        for i, images in enumerate(pairs):
            for name, est in ests.items():
                ms, cold, none = timed(est, images)
                out[name]["ms"].append(ms)
                if i >= empty_first:
                    nobody[name].append(none)
                if cold:
                    out[name]["cold_ms"].append(ms)
        for name, est in ests.items():
            out[name]["no_joint"] += nobody[name]
            out[name]["until_found"].append(nobody[name].index(False) if False in nobody[name] else len(nobody[name]))
            out[name]["tiles"] += est.cold_tile_passes
            est.close()
    return out


# ------------------------------------------------------------------ --walk-in-sweep
def sweep_placements(rest_every: int, tiles: int) -> range:
    """Empty pairs before the walk-in: from the first pair of the rest through one whole cycle of the resting search
    (``rest_every`` pairs per tile pass, ``tiles`` passes a round), so that the walk-in meets every phase of the rest
    against every next tile."""
    return range(tiles, tiles + tiles * rest_every)


def room_before(rig, k: int, count: int):
    """The ``count`` pairs of bench sequence ``k``'s room with nobody in it before its person's first instant, at 30
    fps, each through the scene's own sensor (its noise and exposure jitter, fresh each pair)."""
    scene, t0 = bench_scene_in(rig, k)
    return [scene_without_person(scene, rig.pair, t0 + (i - count) / 30.0) for i in range(count)]


def walk_in(session, cfg, rig, empty, person, tiles: int) -> dict:
    """One fresh estimator through ``empty`` then ``person`` (pair lists): the pairs of the person until the first
    joint (``len(person)`` when none), the ms of each empty pair, the empty pairs that rested (no tile pass after a
    whole round of ``tiles``: those a scene change could wake) and the wakes among them (before the walk-in)."""
    est = Estimator(session, rig, cfg)
    try:
        room_ms, rested = [], 0
        for images in empty:
            passes = est.cold_tile_passes
            room_ms.append(timed(est, images)[0])
            rested += passes >= tiles and est.cold_tile_passes == passes
        out = {"room_ms": room_ms, "rested": rested, "false_wakes": est.cold_tile_wakes, "until": len(person)}
        for i, images in enumerate(person):
            if not timed(est, images)[2]:
                out["until"] = i
                break
        return out
    finally:
        est.close()


def sweep(session, configs: dict, rig, people: list, rooms: list, placements: range, tiles: int) -> dict:
    """Per config, over every person (``people[k]``'s pairs after the last ``e`` of ``rooms[k]``) and every ``e`` of
    ``placements``, the configs interleaved placement by placement: pairs until found (per person), the empty pairs'
    ms after the first round of tiles, the pairs that rested and the false wakes."""
    out = {name: {"until": [[] for _ in people], "room_ms": [], "rested": 0, "false_wakes": 0} for name in configs}
    for k, (person, room) in enumerate(zip(people, rooms)):
        for e in placements:
            for name, cfg in configs.items():
                r = walk_in(session, cfg, rig, room[len(room) - e:], person, tiles)
                out[name]["until"][k].append(r["until"])
                out[name]["room_ms"] += r["room_ms"][tiles:]
                out[name]["rested"] += r["rested"]
                out[name]["false_wakes"] += r["false_wakes"]
    return out


def scene_check_ms(rooms: list, levels: float) -> float:
    """Median ms of one pair's scene check (both cameras' copies and the comparison) over ``rooms``' pairs."""
    times = []
    for room in rooms:
        kept = pair_copies(room[0])
        for images in room[1:]:
            t = time.perf_counter()
            scene_changed(pair_copies(images), kept, levels)
            times.append(1e3 * (time.perf_counter() - t))
    return float(np.median(times))


def until_found_text(until: list, never: int) -> str:
    """Median, p90 and max of the placements found (``never``: the pairs of a person never found), and how many
    were never found."""
    found = [u for u in until if u < never]
    if not found:
        return f"| | | {len(until)} of {len(until)}"
    return (f"{np.median(found):g} | {np.percentile(found, 90):g} | {max(found)} | "
            f"{len(until) - len(found)} of {len(until)}")


def per_person_text(until: list, never: int) -> str:
    """Each person's most pairs until found over the placements (``-`` where never found), and how many placements
    never found them where some did."""
    parts = []
    for u in until:
        found = [x for x in u if x < never]
        missed = len(u) - len(found)
        parts.append("-" if not found else f"{max(found)}{f' ({missed} never)' if missed else ''}")
    return ", ".join(parts)


def resting_every(args, base: EstimatorConfig) -> int:
    """``--rest-every``, else the default config's ``tracking.cold_tiles_rest_every``."""
    return base.tracking.cold_tiles_rest_every if args.rest_every is None else args.rest_every


def resting_configs(base: EstimatorConfig, rest: int) -> dict[str, EstimatorConfig]:
    """The configs a resting search is measured against, by table name: resting every ``rest`` pairs without and with
    the wake-up (at the default config's ``cold_tiles_wake_levels``: never 0 or None), and no tiles at all."""
    levels = base.tracking.cold_tiles_wake_levels

    def tracking(**kw) -> EstimatorConfig:
        return EstimatorConfig(session=base.session, tracking=TrackingConfig(**kw))

    return {f"rest every {rest}, no wake-up": tracking(cold_tiles_rest_every=rest, cold_tiles_wake_levels=None),
            f"rest every {rest}, wake-up at {levels:g} levels": tracking(cold_tiles_rest_every=rest,
                                                                          cold_tiles_wake_levels=levels),
            "no tiles": tracking(cold_tiles_below_share=0.0)}


def run_sweep(args, session, base: EstimatorConfig) -> int:
    """``--walk-in-sweep``: the table of pairs from walk-in to the first joint, over every placement."""
    rest = resting_every(args, base)
    levels = base.tracking.cold_tiles_wake_levels
    configs = resting_configs(base, rest)
    print(f"{args.precision}; {args.sequences} people x {args.frames} pairs, each walking in after every count of "
          f"empty pairs of its room in a whole cycle of the rest; the configs interleaved placement by placement")
    print("| rig file | config | placements | pairs until found: median | p90 | max | never found | most per person | "
          "empty-room mean ms per pair after the first round | ratio to no tiles | false wakes (resting pairs) | "
          "scene check ms per pair |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for path in rig_paths(args.rigs):
        rig = load_rig(path, warn=False)
        tiles = len(volume_tiles(rig, base.roi))
        placements = sweep_placements(rest, tiles)
        people = [people_pairs(rig, k, args.frames) for k in range(args.sequences)]
        rooms = [room_before(rig, k, placements[-1]) for k in range(args.sequences)]
        out = sweep(session, configs, rig, people, rooms, placements, tiles)
        check = scene_check_ms(rooms, levels)
        off = np.mean(out["no tiles"]["room_ms"])
        for name, r in out.items():
            until = [u for person in r["until"] for u in person]
            print(f"| {path} | {name} | {len(until)} | {until_found_text(until, args.frames)} | "
                  f"{per_person_text(r['until'], args.frames)} | {np.mean(r['room_ms']):.1f} | "
                  f"{np.mean(r['room_ms']) / off:.2f} | {r['false_wakes']} ({r['rested']}) | {check:.3f} |", flush=True)
    return 0


# ------------------------------------------------------------------ --wake-margin
def room_statistics(room: list) -> list[float]:
    """The wake statistic (:func:`wake_statistic`) of each pair of ``room`` after its first, against the first's
    copies (kept as a tile pass that found nobody keeps them): what sensor noise and exposure jitter alone give."""
    kept = pair_copies(room[0])
    return [wake_statistic(pair_copies(images), kept) for images in room[1:]]


def walk_in_statistic(rig, k: int, room: list) -> float:
    """The wake statistic of bench sequence ``k``'s first pair with its person (where ``--walk-in-sweep`` puts the
    walk-in) against the copies of ``room``'s first pair (its room before them)."""
    scene, t0 = bench_scene_in(rig, k)
    person = [scene.render(cam, t0, with_truth=False)[0] for cam in rig.pair]
    return wake_statistic(pair_copies(person), pair_copies(room[0]))


def spread_text(values: list) -> str:
    """Count, min, median, p90, p99 and max of ``values`` (8-bit levels)."""
    v = np.asarray(values, dtype=np.float64)
    return (f"{len(v)} | {v.min():.1f} | {np.median(v):.1f} | {np.percentile(v, 90):.1f} | "
            f"{np.percentile(v, 99):.1f} | {v.max():.1f}")


def run_wake_margin(args, base: EstimatorConfig) -> int:
    """``--wake-margin``: the distribution of the statistic the wake-up thresholds, over empty rooms and walk-ins."""
    levels = base.tracking.cold_tiles_wake_levels
    print(f"the wake statistic (each camera's 2nd largest cell difference, the larger camera's; 8-bit levels; "
          f"wakes over {levels:g}): {args.sequences} bench rooms x {args.pairs} pairs each through its scene's own "
          f"sensor, against the room's first pair; the walk-ins: each person's first pair against the same")
    print("| rig file | pairs compared | count | min | median | p90 | p99 | max | over the threshold | per person |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in rig_paths(args.rigs):
        rig = load_rig(path, warn=False)
        rooms = [room_before(rig, k, args.pairs) for k in range(args.sequences)]
        empty = [s for room in rooms for s in room_statistics(room)]
        walk = [walk_in_statistic(rig, k, room) for k, room in enumerate(rooms)]
        for name, values, each in (("empty rooms", empty, ""), ("walk-ins", walk, ", ".join(f"{v:.1f}" for v in walk))):
            over = sum(v > levels for v in values)
            print(f"| {path} | {name} | {spread_text(values)} | {over} of {len(values)} | {each} |", flush=True)
    return 0


# ------------------------------------------------------------------ --moving-room
def moving_stream(rig, k: int, pairs: int) -> list:
    """``pairs`` pairs at 30 fps of bench sequence ``k``'s room with nobody in it and a screen playing
    (``benchmarks/empty_rooms.py``'s ``scene_with_screen``), through the scene's own sensor."""
    scene, t0 = bench_scene_in(rig, k)
    return [scene_with_screen(scene, rig.pair, t0 + i / 30.0) for i in range(pairs)]


def longest_run(flags: list[bool]) -> int:
    """The most True values in a row in ``flags`` (0 where none)."""
    most = run = 0
    for flag in flags:
        run = run + 1 if flag else 0
        most = max(most, run)
    return most


def run_moving(session, configs: dict, rig, streams: list, tiles: int) -> dict:
    """Per config, over ``streams`` (pair lists, a fresh estimator each, the configs interleaved pair by pair): the
    ms of each pair after the first round of ``tiles``, the tile passes and wakes there, the pairs there that saw
    someone in one view (which wakes the tiles as anyone seen does) or had a frame rejected (no tile pass), the
    pairs that reported a joint (nobody is there), and the most pairs in a row seen in one view in any stream."""
    out = {name: {"ms": [], "passes": 0, "wakes": 0, "one_view": 0, "rejected": 0, "phantoms": 0, "pairs": 0,
                  "one_view_run": 0} for name in configs}
    for pairs in streams:
        ests = {name: Estimator(session, rig, cfg) for name, cfg in configs.items()}
        seen = {name: [] for name in configs}
        for i, images in enumerate(pairs):
            for name, est in ests.items():
                before = (est.cold_tile_passes, est.cold_tile_wakes)
                t = time.perf_counter()
                result = est.estimate(images)
                ms = 1e3 * (time.perf_counter() - t)
                out[name]["phantoms"] += not result.missing.all()
                seen[name].append(result.single_view is not None)
                if i >= tiles:  # after the first round: what resting (or not) does
                    r = out[name]
                    r["ms"].append(ms)
                    r["pairs"] += 1
                    r["passes"] += est.cold_tile_passes - before[0]
                    r["wakes"] += est.cold_tile_wakes - before[1]
                    r["one_view"] += result.single_view is not None
                    r["rejected"] += not all(result.frame_ok.values())
        for name, est in ests.items():
            est.close()
            out[name]["one_view_run"] = max(out[name]["one_view_run"], longest_run(seen[name]))
    return out


def run_moving_room(args, session, base: EstimatorConfig) -> int:
    """``--moving-room``: wakes and cost in an empty room whose screen changes every pair."""
    # (tiles that never rest have nothing to wake: no scene check, no wakes counted)
    configs = {"tiles, no rest": EstimatorConfig(session=base.session, tracking=TrackingConfig(
                   cold_tiles_rest_every=1, cold_tiles_wake_levels=None)),
               **resting_configs(base, resting_every(args, base))}
    print(f"{args.precision}; {args.sequences} empty rooms with a screen playing x {args.pairs} pairs; after the "
          f"first round of tiles: per 100 pairs, mean ms per pair; the configs interleaved pair by pair")
    print("| rig file | config | pairs after the first round | tile passes per 100 pairs | wakes per 100 pairs | "
          "seen in one view / a frame rejected, per 100 pairs | mean ms per pair | ratio to no tiles | "
          "pairs with a joint | most pairs in a row seen in one view |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in rig_paths(args.rigs):
        rig = load_rig(path, warn=False)
        tiles = len(volume_tiles(rig, base.roi))
        streams = [moving_stream(rig, k, args.pairs) for k in range(args.sequences)]
        out = run_moving(session, configs, rig, streams, tiles)
        off = np.mean(out["no tiles"]["ms"])
        for name, r in out.items():
            n = max(r["pairs"], 1)
            print(f"| {path} | {name} | {r['pairs']} | {100 * r['passes'] / n:.0f} | {100 * r['wakes'] / n:.0f} | "
                  f"{100 * r['one_view'] / n:.0f} / {100 * r['rejected'] / n:.0f} | {np.mean(r['ms']):.1f} | "
                  f"{np.mean(r['ms']) / off:.2f} | {r['phantoms']} | {r['one_view_run']} |", flush=True)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, help="default: models (not read with --wake-margin)")
    ap.add_argument("--precision", default="int8", choices=("auto", "fp32", "int8"))
    ap.add_argument("--sequences", type=positive_count, default=6)
    ap.add_argument("--frames", type=positive_count, default=10)
    ap.add_argument("--rooms", type=positive_count, default=6)
    ap.add_argument("--pairs", type=positive_count, default=5)
    ap.add_argument("--walk-in-after", type=non_negative_count, default=0,
                    help="empty pairs before each sequence's person")
    ap.add_argument("--rest-every", type=config_field(TrackingConfig, "cold_tiles_rest_every"), default=None,
                    help="the resting config's cold_tiles_rest_every (default: the runtime's)")
    ap.add_argument("--rigs", default="docs/examples/rig.json", help="rig files, comma-separated")
    ap.add_argument("--walk-in-sweep", action="store_true", help="instead: each person walks in after every count "
                    "of empty pairs in a whole cycle of the rest; pairs until found, median, p90 and max")
    ap.add_argument("--wake-margin", action="store_true", help="instead: the distribution of the statistic the "
                    "wake-up thresholds, over --sequences bench rooms x --pairs pairs and their people's walk-ins")
    ap.add_argument("--moving-room", action="store_true", help="instead: wakes and ms per pair in --sequences "
                    "bench rooms with a screen playing, --pairs pairs each, nobody there")
    args = ap.parse_args(argv)
    if args.model_dir is None:  # checked only where a model runs: --wake-margin runs none
        args.model_dir = "models" if args.wake_margin else checked_model_folder(ap, "models")
    base = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=args.precision))
    if args.wake_margin:
        return run_wake_margin(args, base)
    if args.walk_in_sweep:
        return run_sweep(args, load_session(base), base)
    if args.moving_room:
        return run_moving_room(args, load_session(base), base)
    default_rest = base.tracking.cold_tiles_rest_every
    rest = default_rest if args.rest_every is None else args.rest_every
    resting = EstimatorConfig(session=base.session, tracking=TrackingConfig(cold_tiles_rest_every=rest))
    configs = {f"tiles, rest every {rest}{' (default)' if rest == default_rest else ''}": resting,
               "tiles, no rest": EstimatorConfig(session=base.session,
                                                 tracking=TrackingConfig(cold_tiles_rest_every=1)),
               "no tiles": EstimatorConfig(session=base.session, tracking=TrackingConfig(cold_tiles_below_share=0.0))}
    session = load_session(base)
    print(f"{args.precision}; {args.sequences} people x {args.frames} pairs after {args.walk_in_after} empty, "
          f"{args.rooms} empty rooms x {args.pairs} pairs; median ms per pair, the configs interleaved")
    print("| rig file | config | people's cold pairs | their median ms | people's mean ms per pair | pairs with no "
          "joint | pairs until found, median (max) | empty-room median ms | empty-room mean ms per pair | "
          "empty-room pairs with a joint | "
          "tile passes (people / rooms) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for path in rig_paths(args.rigs):
        rig = load_rig(path, warn=False)
        people = measure(session, configs, rig,
                         [people_pairs(rig, k, args.frames, args.walk_in_after) for k in range(args.sequences)],
                         args.walk_in_after)
        rooms = measure(session, configs, rig,
                        [[empty_room_pair(rig, SEED_BASE + r, 0.2)] * args.pairs for r in range(args.rooms)])
        for name in configs:
            p, r = people[name], rooms[name]
            print(f"| {path} | {name} | {len(p['cold_ms'])} | {np.median(p['cold_ms']):.1f} | {np.mean(p['ms']):.1f} | "
                  f"{np.mean(p['no_joint']):.3f} | {np.median(p['until_found']):g} ({max(p['until_found'])}) | "
                  f"{np.median(r['ms']):.1f} | {np.mean(r['ms']):.1f} | {len(r['ms']) - sum(r['no_joint'])} of "
                  f"{len(r['ms'])} | {p['tiles']} / {r['tiles']} |",
                  flush=True)
        p_off, r_off = people["no tiles"], rooms["no tiles"]
        for name in list(configs)[:-1]:
            p_on, r_on = people[name], rooms[name]
            print(f"| {path} | ratio, {name.split(' (')[0]} / no tiles | | "
                  f"{np.median(p_on['cold_ms']) / np.median(p_off['cold_ms']):.2f} | "
                  f"{np.mean(p_on['ms']) / np.mean(p_off['ms']):.2f} | | | "
                  f"{np.median(r_on['ms']) / np.median(r_off['ms']):.2f} | "
                  f"{np.mean(r_on['ms']) / np.mean(r_off['ms']):.2f} | | |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
