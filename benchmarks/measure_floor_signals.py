"""The floor check and half-degree pans: which window statistic separates a panned camera from the true rig.

    .venv/bin/python benchmarks/measure_floor_signals.py [--model-dir models] [--sequences 30] [--frames 30]
                                                         [--window 30] [--pan-degrees 0.5] [--tilt-degrees 1]

A research tool for docs/calibration.md, "Half-degree pans: other signals tried". The bench's held-out-like
sequences (``benchmarks/measure_calibration_drift.py``'s, the same cache) are estimated through the true rig, the
second camera's and the first camera's rig entries panned ``--pan-degrees`` either way and the second's tilted
``--tilt-degrees`` either way; per pair it keeps the floor check's figure (``PairResult.lowest_foot_m``) and the
reported person's position across the floor. Each placement is also filmed, through the true rig, with another
person (the scene's seed plus 1000, another held-out motion) and with the same person 2 s later: what an install-time
measurement (``ghnerf-daemon --measure-floor``) would have read there.

Each signal is a statistic of a sequence's ``--window`` pairs with a foot (one window per sequence when
``--frames`` equals it, as the daemon's first full window): the median (the floor check's), a 20 % trimmed mean, the
mean, the median of each pair's figure over the pan's own effect there (:func:`floor_height_per_pan_deg`: the figure
read as degrees of pan), the median over the person's distance, and the median less the install-time median (another
person's; the same person's). For each signal its limit is set from the true rig's worst window (times 1, 1.25,
1.5 and 5/3, the floor check's 0.05 m being 5/3 of 0.03), and the windows past it are counted per setting: a signal
is better where it catches more turned windows at the same margin over the true rig. A second table gives, per
placement, the pan's effect on the feet (metres per degree) and how far the person moved in depth within the window
(what a slope test of height against depth would need). A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from benchmarks.measure_calibration_drift import turned  # noqa: E402
from ghnerf_runtime.cli.simdata import (HELD_OUT_MOTIONS, SEED_BASE, SEQUENCE_CACHE_HELP,  # noqa: E402
                                        bench_rig_and_scene, load_sequences)
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.geometry import Rig, triangulate_dlt  # noqa: E402

#: the margins over the true rig's worst window a signal's limit is counted at
MARGINS = (1.0, 1.25, 1.5, 5 / 3)
#: the share of a window's figures a trimmed mean drops at each end
TRIM = 0.2
#: the install-time takes: name, scene seed offset (0: the sequence's own person), seconds after the sequence's start
INSTALL_TAKES = (("other person", 1000, None), ("same person 2 s later", 0, 2.0))


def floor_height_per_pan_deg(rig: Rig, point: np.ndarray, camera: int, step_deg: float = 0.1) -> float:
    """How much a pan of ``camera``'s rig entry raises the triangulated ``point`` (metres of height, the rig frame's
    ``-y``, per degree): ``point`` projected through ``rig``, triangulated again through the rig with that entry
    panned ``step_deg``. A pan's depth error grows with the distance and shows in height through the rays' slope, so
    the same pan moves the feet more in one placement than another.

    Example:
        >>> from ghnerf_runtime.geometry import Camera, WorkingVolume, look_at
        >>> K = [[400.0, 0, 319.5], [0, 400.0, 239.5], [0, 0, 1]]
        >>> eyes = (("l", -0.5), ("r", 0.5))
        >>> cams = tuple(Camera(n, 640, 480, K, [], *look_at((x, -1.6, 0), (0, -1.0, 3))) for n, x in eyes)
        >>> rig = Rig(cams, WorkingVolume((-0.5, -2, 2.5), (0.5, 0, 3.5)), "doc")
        >>> s = floor_height_per_pan_deg(rig, np.array([0.0, 0.0, 3.0]), 1)
        >>> bool(0.02 < abs(s) < 0.2), floor_height_per_pan_deg(rig, np.array([0.0, 0.0, 3.0]), 0) * s < 0
        (True, True)
    """
    point = np.asarray(point, float)
    uv = np.stack([c.project(point[None])[0] for c in rig.cameras])
    moved = turned(rig, camera, "pan", step_deg)
    again = triangulate_dlt(uv, list(moved.cameras)).points[0]
    return float(point[1] - again[1]) / step_deg  # y down: a height is -y


def trimmed_mean(values: np.ndarray, trim: float = TRIM) -> float:
    """The mean of ``values`` less the ``trim`` share at each end (all of them when too few to drop any).

    Example:
        >>> trimmed_mean(np.array([0.0, 0.01, 0.02, 0.03, 0.5]))
        0.02
    """
    v = np.sort(np.asarray(values, float))
    cut = int(trim * v.size)
    return float(np.mean(v[cut:v.size - cut]))


def caught(values: list[float], limit: float) -> int:
    """How many windows' statistics are further than ``limit`` from 0 (either way), the floor check's test.

    Example:
        >>> caught([0.06, -0.07, 0.01], 0.05)
        2
    """
    return int(np.sum(np.abs(np.asarray(values, float)) > limit))


@dataclass
class Take:
    """One sequence's pairs under one setting: the floor figures and the person's position, where there was a foot."""

    foot: list[float] = field(default_factory=list)
    where: list[np.ndarray] = field(default_factory=list)  # the reported joints' median (x, y, z)

    def window(self, size: int) -> tuple[np.ndarray, np.ndarray]:
        """The last ``size`` pairs with a foot (the daemon's window; all of them when fewer)."""
        return np.asarray(self.foot[-size:], float), np.asarray(self.where[-size:], float).reshape(-1, 3)


def run_take(session, cfg, rig: Rig, pairs, t0: float, fps: float) -> Take:
    """Estimate ``pairs`` through ``rig``; keep the pairs that gave a floor figure."""
    take = Take()
    with Estimator(session, rig, cfg) as est:
        for i, pair in enumerate(pairs):
            r = est.estimate(list(pair), timestamp_s=t0 + i / fps)
            if r.lowest_foot_m is None or r.missing.all():
                continue
            take.foot.append(r.lowest_foot_m)
            take.where.append(np.median(r.joints_3d[~r.missing], axis=0))
    return take


def install_pairs(k: int, seed_offset: int, later_s: float | None, frames: int, fps: float):
    """Bench placement ``k``'s rig filming, through the true rig, another person (``seed_offset``) or its own person
    ``later_s`` after the sequence's start: the pairs and their first instant."""
    from drivers.sim import random_scene  # tool only

    rig, scene, t0, _ = bench_rig_and_scene(k)
    if seed_offset:
        scene, t0 = random_scene(SEED_BASE + seed_offset + k, volume=rig.volume, motions=HELD_OUT_MOTIONS), 0.3
    else:
        t0 += later_s
    return [[scene.render(cam, t0 + i / fps)[0] for cam in rig.pair] for i in range(frames)], t0


def settings(pan_deg: float, tilt_deg: float) -> list[tuple[str, str, float, int]]:
    """(name, axis, degrees, camera) of each rig entry the estimator is given; the true rig first."""
    out = [("true rig", "pan", 0.0, 1)]
    for cam, who in ((1, "second"), (0, "first")):
        out += [(f"{who} panned {d:+g}", "pan", d, cam) for d in (-pan_deg, pan_deg)]
    out += [(f"second tilted {d:+g}", "tilt", d, 1) for d in (-tilt_deg, tilt_deg)]
    return out


def signals(install: list[str]) -> dict[str, Callable]:
    """Each signal: a function of (feet, positions, pan effects m/deg, install medians) giving a window's value."""
    out = {
        "median (today)": lambda f, w, s, o: float(np.median(f)),
        f"{TRIM:.0%} trimmed mean": lambda f, w, s, o: trimmed_mean(f),
        "mean": lambda f, w, s, o: float(np.mean(f)),
        "median of figure / pan effect (deg)": lambda f, w, s, o: float(np.median(f / np.abs(s))),
        "median of figure / distance": lambda f, w, s, o: float(np.median(f / w[:, 2])),
    }
    for name in install:
        out[f"median less install's ({name})"] = (lambda f, w, s, o, n=name: None if o.get(n) is None
                                                  else float(np.median(f)) - o[n])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=30)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--window", type=positive_count, default=30, help="pairs with a foot per window")
    ap.add_argument("--pan-degrees", type=float, default=0.5)
    ap.add_argument("--tilt-degrees", type=float, default=1.0)
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir))
    session = load_session(cfg)
    rows = settings(args.pan_degrees, args.tilt_degrees)
    install_names = [name for name, _, _ in INSTALL_TAKES]
    funcs = signals(install_names)
    values = {(sig, row[0]): [] for sig in funcs for row in rows}
    placements = []
    for seq in load_sequences(args.sequences, args.frames, cache_dir=args.cache):
        k, t0, fps = int(seq.info["index"]), float(seq.info["t0"]), float(seq.info["fps"])
        pairs = [(np.array(seq.images[i, 0]), np.array(seq.images[i, 1])) for i in range(len(seq))]
        offsets = {}
        for name, seed_offset, later_s in INSTALL_TAKES:
            take = run_take(session, cfg, seq.rig, *install_pairs(k, seed_offset, later_s, args.frames, fps), fps)
            offsets[name] = float(np.median(take.foot)) if take.foot else None
        for name, axis, deg, cam in rows:
            feet, where = run_take(session, cfg, turned(seq.rig, cam, axis, deg), pairs, t0, fps).window(args.window)
            if not feet.size:
                continue
            effect = np.array([floor_height_per_pan_deg(seq.rig, np.array([x, 0.0, z]), 1) for x, _, z in where])
            for sig, f in funcs.items():
                v = f(feet, where, effect, offsets)
                if v is not None:
                    values[(sig, name)].append(v)
            if name == "true rig":
                placements.append((float(np.median(effect)), float(np.ptp(where[:, 2])), float(np.median(feet)),
                                   offsets))
        print(f"sequence {k} done", file=sys.stderr, flush=True)
    print(f"{args.sequences} sequences x {args.frames} pairs, one {args.window}-pair window each, {args.model_dir}: "
          f"windows past each signal's limit (the limit: the margin times the true rig's worst window)")
    print(f"  {'signal':>42} | margin | limit  | " + " | ".join(f"{n:>17}" for n, *_ in rows[1:]))
    for sig in funcs:
        if not values[(sig, "true rig")]:
            print(f"  {sig:>42} | the true rig gave no window: no limit")
            continue
        worst = max(abs(v) for v in values[(sig, "true rig")])
        for m in MARGINS:
            counts = [f"{caught(values[(sig, n)], m * worst):>3d} / {len(values[(sig, n)]):<11d}" for n, *_ in rows[1:]]
            print(f"  {sig:>42} | x{m:4.2f}  | {m * worst:6.4f} | " + " | ".join(counts)
                  + f"   (true rig {len(values[(sig, 'true rig')])} windows)")
    if not placements:
        return 0
    eff = np.array([p[0] for p in placements])
    spread = np.array([p[1] for p in placements])
    print(f"per placement, true rig: the pan's effect on the feet {np.abs(eff).min():.3f} to {np.abs(eff).max():.3f} "
          f"m/deg (median {np.median(np.abs(eff)):.3f}); the person's depth within the window spans "
          f"{spread.min():.3f} to {spread.max():.3f} m (median {np.median(spread):.3f})")
    for name in install_names:
        both = np.array([(p[3][name], p[2]) for p in placements if p[3][name] is not None])
        if len(both) > 2:
            print(f"install take, {name}: its median against the true rig's window, correlation "
                  f"{np.corrcoef(both[:, 0], both[:, 1])[0, 1]:.2f} over {len(both)} placements, install medians "
                  f"{both[:, 0].min():+.3f} to {both[:, 0].max():+.3f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
