"""Left and right joints: how often the runtime finds each, and how often the simulator's truth shows each.

    PYTHONPATH=$PWD /work/main/.venv/bin/python benchmarks/measure_left_right.py [--model-dir models]
                                    [--sequences 10] [--frames 30] [--precisions int8,fp32] [--flip-tests on,off]
                                    [--mirrored off,on] [--per-sequence] [--cache DIR]

The bench's held-out-like scenes (``ghnerf-bench runtime``'s recipe and cache). For every left/right pair of BODY_25
joints it prints the share of pairs where each side is found (a 2D joint reported, its peak above the decoder's
threshold) in view 0, view 1 and both, per source:

* ``truth``: the simulator's visibility (in the image, in front, not hidden by the body) in view 0, 1 and both;
* ``<precision> flip on|off``: the runtime's own 2D joints (``PairResult.missing_2d``), default settings otherwise;
* ``... mirrored`` (with the flip test off only: :data:`FLIP_TEST_MIRRORED_NOTE`): every crop the keypoint graph
  reads is mirrored left to right before it runs, and its heatmaps mirrored back in place only, their channels left
  as the model named them. The model then sees a mirror-image person, whose right side is the filmed person's left:
  a channel's rate follows the *scene's side* if the scene makes the difference (the rates of R and L exchange), the
  *channel* if the model does (they stay).

A tool, not a test; the figures are in docs/model.md ("Left and right joints").
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.body25 import FLIP_INDEX, JOINT_NAMES  # noqa: E402
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, load_sequences  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, SessionConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator, load_session  # noqa: E402
from ghnerf_runtime.flip_test import mirror_images, mirror_projections  # noqa: E402

#: The left/right pairs, by the part's name (RShoulder/LShoulder -> "Shoulder").
SIDED_PARTS: tuple[str, ...] = tuple(n[1:] for n in JOINT_NAMES if n.startswith("R"))
KEYPOINT_GRAPHS = ("human", "encoder")
#: Why no source is run mirrored with the flip test: the flip test averages each channel of the crops with its mirror
#: channel of the mirrored crops, so on mirrored crops it gives the unmirrored figures with left and right exchanged
#: by construction, whatever the model does; the flip test off is the mirrored check.
FLIP_TEST_MIRRORED_NOTE = ("no mirrored source with the flip test on: it would give the flip test's figures with left "
                           "and right exchanged by construction (it averages each channel with its mirror channel of "
                           "the mirrored crops)")


class MirroringSession:
    """A model session whose keypoint graphs see mirrored crops: heatmaps come back in place, channels unswapped.

    Everything else is the wrapped session's (the estimator reads its contract, files, prior...).
    """

    def __init__(self, session) -> None:
        self._session = session

    def __getattr__(self, name):
        return getattr(self._session, name)

    def run(self, graph: str, feeds):
        if graph not in KEYPOINT_GRAPHS:
            return self._session.run(graph, feeds)
        mirrored = dict(feeds)
        width = feeds["images"].shape[-1]
        mirrored["images"] = mirror_images(feeds["images"])
        if "src_P" in feeds:  # a graph that reads the cameras sees the mirrored crops' cameras
            mirrored["src_P"] = mirror_projections(feeds["src_P"], width)
        out = dict(self._session.run(graph, mirrored))
        # back in place, left to right only: a channel keeps the model's name for what it found
        out["encoder_heatmaps"] = np.ascontiguousarray(out["encoder_heatmaps"][..., ::-1])
        return out

    def run_on_lane(self, graph: str, feeds):
        return self.run(graph, feeds)

    def run_both(self, graph: str, first, second):
        return self.run(graph, first), self.run(graph, second)


def found_by_view(results, camera_names) -> np.ndarray:
    """``(F, C, 25)`` bool: each pair's 2D joints reported, per camera in rig order."""
    return np.array([[~r.missing_2d[name] for name in camera_names] for r in results])


def run_source(session, cfg: EstimatorConfig, sequences, mirrored: bool) -> list[np.ndarray]:
    """Per sequence, ``(pairs, C, 25)`` found joints, a fresh estimator per sequence."""
    runner = MirroringSession(session) if mirrored else session
    found = []
    for seq in sequences:
        fps = float(seq.info.get("fps", 30.0))
        with Estimator(runner, seq.rig, cfg) as est:
            results = [est.estimate((np.array(seq.images[i, 0]), np.array(seq.images[i, 1])), sequence=i,
                                    timestamp_s=i / fps) for i in range(len(seq))]
        found.append(found_by_view(results, [c.name for c in seq.rig.pair]))
    return found


def side_rates(found: np.ndarray) -> dict[str, tuple[float, ...]]:
    """Per joint name: the share of pairs found in view 0, view 1 and both views."""
    both = found.all(axis=1)
    return {name: (float(found[:, 0, j].mean()), float(found[:, 1, j].mean()), float(both[:, j].mean()))
            for j, name in enumerate(JOINT_NAMES)}


def sided_means(found: np.ndarray) -> tuple[float, float]:
    """The share of (pair, view, joint) found over the right joints and over the left ones."""
    right = [j for j, n in enumerate(JOINT_NAMES) if n.startswith("R")]
    left = [FLIP_INDEX[j] for j in right]
    return float(found[..., right].mean()), float(found[..., left].mean())


def print_per_sequence(sequences, truth: list[np.ndarray], model: list[np.ndarray], source: str) -> None:
    """Each sequence's heading (the person's turn about the vertical, 0 facing the rig) and right/left shares."""
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene  # the scene's own draw, for its heading

    print(f"per sequence: heading, right / left share of joint views, truth visible and {source} found")
    for seq, t, m in zip(sequences, truth, model):
        heading = bench_rig_and_scene(int(seq.info["index"]))[1].config.heading_deg
        print(f"  {seq.info['index']:3d} {seq.info['motion']:<14} heading {heading:7.1f} deg   truth "
              "%.2f / %.2f   found %.2f / %.2f" % (*sided_means(t), *sided_means(m)))


def print_table(rows: dict[str, dict[str, tuple[float, ...]]]) -> None:
    """One line per source: per part, right vs left both-view rates (and per view in brackets)."""
    print("share of pairs found in both views, right / left (view 0 R/L, view 1 R/L)")
    for part in SIDED_PARTS:
        print(f"  {part}")
        for source, rates in rows.items():
            r, l_ = rates["R" + part], rates["L" + part]
            print(f"    {source:<24} {r[2]:.2f} / {l_[2]:.2f}   ({r[0]:.2f}/{l_[0]:.2f}, {r[1]:.2f}/{l_[1]:.2f})")


def sided_both_view_means(rates: dict[str, tuple[float, ...]]) -> tuple[float, float]:
    """The mean over the sided parts of the both-view rates, right and left."""
    return (float(np.mean([rates["R" + p][2] for p in SIDED_PARTS])),
            float(np.mean([rates["L" + p][2] for p in SIDED_PARTS])))


def summary_line(rows: dict[str, dict[str, tuple[float, ...]]]) -> None:
    """Per source its :func:`sided_both_view_means`; and a source run both ways pooled with its mirrored run (the
    scenes and their mirror images: balanced by side by construction, the runs being of equal size)."""
    print("mean over the 11 sided parts, both views: right / left")
    for source, rates in rows.items():
        right, left = sided_both_view_means(rates)
        print(f"  {source:<28} {right:.3f} / {left:.3f}")
    for source, rates in rows.items():
        if (mirrored := rows.get(source + " mirrored")) is not None:
            right, left = np.mean([sided_both_view_means(rates), sided_both_view_means(mirrored)], axis=0)
            print(f"  {source + ' with mirrored':<28} {right:.3f} / {left:.3f}")


def _on_off(text: str) -> list[bool]:
    return [p == "on" for p in text.split(",") if p]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models")
    ap.add_argument("--sequences", type=positive_count, default=10)
    ap.add_argument("--frames", type=positive_count, default=30)
    ap.add_argument("--precisions", default="int8,fp32")
    ap.add_argument("--flip-tests", default="on,off", type=_on_off)
    ap.add_argument("--mirrored", default="off,on", type=_on_off)
    ap.add_argument("--per-sequence", action="store_true",
                    help="also each sequence's heading and right/left shares (truth and the first source)")
    ap.add_argument("--cache", help=SEQUENCE_CACHE_HELP)
    args = ap.parse_args(argv)
    sequences = load_sequences(args.sequences, args.frames, cache_dir=args.cache)
    truth = [np.asarray(s.visible, bool) for s in sequences]
    rows = {"truth visible": side_rates(np.concatenate(truth))}
    first = None
    for precision in [p for p in args.precisions.split(",") if p]:
        base = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir, precision=precision))
        session = load_session(base)
        for flip in args.flip_tests:
            cfg = replace(base, heatmaps=replace(base.heatmaps, flip_test=flip))
            for mirrored in args.mirrored:
                if mirrored and flip:
                    continue  # (FLIP_TEST_MIRRORED_NOTE)
                name = f"{precision} flip {'on' if flip else 'off'}" + (" mirrored" if mirrored else "")
                found = run_source(session, cfg, sequences, mirrored)
                first = first or (name, found)
                rows[name] = side_rates(np.concatenate(found))
                print(f"ran {name}", flush=True)
    print(f"{len(sequences)} sequences x {args.frames} pairs, {args.model_dir}")
    if any(args.mirrored) and any(args.flip_tests):
        print(FLIP_TEST_MIRRORED_NOTE)
    if args.per_sequence and first is not None:
        print_per_sequence(sequences, truth, first[1], first[0])
    print_table(rows)
    summary_line(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
