"""Confidence of phantom joints in empty rooms vs joints of real people (sets the presence gate).

    .venv/bin/python benchmarks/measure_presence.py [--model-dir models] [--rooms 8] [--flip-test]

The trained model has only ever seen views with a person in them, so for an empty room it still
answers "someone", with weaker peaks. For each heatmap source (with its best 3D method) this
prints, with the presence gate and the frame check off, the joints found and the 6th-strongest 3D
joint confidence of empty simulated rooms, and the same of the held-out pairs of
``tests/ghnerf_runtime/test_estimator_accuracy.py`` (4 sequences x 10 pairs). A presence threshold
(``config.PRESENCE_MIN_CONFIDENCE``) belongs between the two. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

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


def sixth_strongest(result) -> float:
    c = np.sort(result.confidence[~result.missing])[::-1]
    return float(c[5]) if len(c) > 5 else 0.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", default="models")
    ap.add_argument("--rooms", type=int, default=8, help="empty rooms (scene seeds 1..N)")
    ap.add_argument("--flip-test", action="store_true", help="heatmaps.flip_test on (encoder heatmaps)")
    args = ap.parse_args(argv)
    import drivers.sim as sim

    rig = sim.RigPlacement().build()
    sequences = load_sequences(4, 10)
    for source in HEATMAP_SOURCES:
        heatmaps = HeatmapsConfig(source=source, flip_test=args.flip_test)
        cfg = EstimatorConfig(session=SessionConfig(model_dir=args.model_dir), heatmaps=heatmaps,
                              joints3d=Joints3DConfig(method=BEST_METHOD[source]),
                              frame_check=FrameCheckConfig(enabled=False), presence=PresenceConfig(enabled=False))
        est = Estimator.from_config(rig, cfg)
        empty = []
        for seed in range(1, args.rooms + 1):
            room = sim.SimScene(sim.SceneConfig(seed=seed, motion="wave", position_xz=(40.0, 3.0)))  # nobody in view
            pair = tuple(room.render(c, 0.2, with_truth=False)[0] for c in rig.pair)
            est.reset()
            r = est.estimate(pair)
            empty.append((r.num_found, sixth_strongest(r)))
        real = []
        for seq in sequences:
            est = Estimator(est.session, seq.rig, cfg)
            for i in range(len(seq)):
                r = est.estimate((np.asarray(seq.images[i, 0]), np.asarray(seq.images[i, 1])))
                real.append((r.num_found, sixth_strongest(r)))
        e, p = np.array(empty), np.array(real)
        flip = ", flip test" if cfg.flips_encoder_heatmaps else ""
        print(f"{source:>8} heatmaps ({BEST_METHOD[source]}{flip}): empty rooms: joints found {int(e[:, 0].min())}-"
              f"{int(e[:, 0].max())}, 6th-strongest confidence max {e[:, 1].max():.3f} | {len(p)} pairs with a "
              f"person: 6th-strongest min {p[:, 1].min():.3f}, 5th percentile {np.percentile(p[:, 1], 5):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
