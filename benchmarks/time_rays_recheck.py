"""What the whole-volume recheck of a plain crop on the rays costs per pair (session 71).

    .venv/bin/python benchmarks/time_rays_recheck.py [--width 1280] [--height 800] [--pairs 24] [--rounds 5]
                                                     [--every 8]

A person seen by camera 0 only, a plain grey panel hiding them from camera 1 (the test's scene,
``tests/ghnerf_runtime/test_estimator_oracle.py -k plain_crop``, at ``--width`` x ``--height``): camera 1's crop on
the rays shows the panel alone, which the frame check rejects as flat, and the camera's whole-volume crop of the
frame says it works. Runs ``--pairs`` such pairs with ``frame_check.volume_recheck_every`` 1 (every pair checked
again, session 70) and ``--every`` (the verdict cached), alternating, ``--rounds`` times each, a fresh estimator per
run, through the oracle session (the preprocess stage does not depend on the model). Prints per setting the median
over the runs of the median ``timing_ms["preprocess"]`` of the pairs after the first (which finds the rays), the
whole-volume rechecks per pair (``Estimator.volume_rechecks``) and the ratio of the two settings' preprocess times,
with the host's load average. Not a test.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import drivers.sim as sim  # noqa: E402
from benchmarks.bench_runtime_common import OracleSession, edge128_contract  # noqa: E402
from ghnerf_runtime.config import EstimatorConfig, FrameCheckConfig  # noqa: E402
from ghnerf_runtime.estimator import Estimator  # noqa: E402
from training.cli import at_least  # noqa: E402

PANEL_LEVEL = 128
PANEL_MARGIN_PX = 16


def clip(width: int, height: int, pairs: int):
    """The rig, and ``pairs + 1`` pairs of frames with the truth that camera 0 alone sees the person."""
    rig = sim.RigPlacement(width=width, height=height).build()
    scene = sim.SimScene(sim.SceneConfig(seed=11, motion="wave", position_xz=(0.0, 3.0)))
    frames, truth = [], []
    for i in range(pairs + 1):
        rendered = [scene.render(c, i / 30) for c in rig.pair]
        visible = np.stack([tr.visible for _, tr in rendered])
        visible[1] = False
        frames.append(tuple(img for img, _ in rendered))
        truth.append((scene.joints_3d(i / 30), visible))
    return rig, frames, truth


def with_panel(image: np.ndarray, roi) -> np.ndarray:
    """``image`` with a plain grey panel over ``roi`` grown by ``PANEL_MARGIN_PX`` each side."""
    out = image.copy()
    x0, y0 = max(0, int(roi.x0) - PANEL_MARGIN_PX), max(0, int(roi.y0) - PANEL_MARGIN_PX)
    x1, y1 = int(roi.x0 + roi.size) + PANEL_MARGIN_PX, int(roi.y0 + roi.size) + PANEL_MARGIN_PX
    out[y0:max(0, y1), x0:max(0, x1)] = PANEL_LEVEL
    return out


def run(rig, frames, truth, every: int) -> tuple[float, float]:
    """One run: the median preprocess ms of the pairs behind the panel and the rechecks per such pair."""
    oracle = OracleSession(edge128_contract())
    est = Estimator(oracle, rig, EstimatorConfig(frame_check=FrameCheckConfig(volume_recheck_every=every)))
    oracle.set_truth(*truth[0])
    est.estimate(frames[0])
    panel = est.tracker.view_other
    if panel is None:
        raise RuntimeError("camera 1 got no crop on the rays after the first pair: no panel to time")
    ms = []
    for pair, (joints, visible) in zip(frames[1:], truth[1:]):
        oracle.set_truth(joints, visible)
        r = est.estimate((pair[0], with_panel(pair[1], panel)))
        if r.frame_reason[est.camera_names[1]] is not None:
            raise RuntimeError(f"camera 1 rejected behind the panel: {r.frame_reason}")
        ms.append(r.timing_ms["preprocess"])
    return float(np.median(ms)), est.volume_rechecks / len(ms)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=at_least(1), default=1280)
    ap.add_argument("--height", type=at_least(1), default=800)
    ap.add_argument("--pairs", type=at_least(1), default=24)
    ap.add_argument("--rounds", type=at_least(1), default=5)
    ap.add_argument("--every", type=at_least(1), default=FrameCheckConfig().volume_recheck_every)
    args = ap.parse_args(argv)
    rig, frames, truth = clip(args.width, args.height, args.pairs)
    settings = (1, args.every)
    found: dict[int, list[tuple[float, float]]] = {s: [] for s in settings}
    for _ in range(args.rounds):
        for every in settings:
            found[every].append(run(rig, frames, truth, every))
    print(f"{args.width}x{args.height}, {args.pairs} pairs behind the panel, {args.rounds} runs each, alternating; "
          f"load average {' / '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print("volume_recheck_every   preprocess ms (median)   rechecks per pair")
    medians = {}
    for every in settings:
        medians[every] = float(np.median([m for m, _ in found[every]]))
        print(f"{every:>20}   {medians[every]:>22.2f}   {np.median([r for _, r in found[every]]):>17.3f}")
    print(f"ratio ({args.every} / 1): {medians[args.every] / medians[1]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
