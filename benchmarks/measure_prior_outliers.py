"""The skeleton prior's worst answers, and the far DLT points behind them.

    .venv/bin/python benchmarks/measure_prior_outliers.py --model-dir models/ghnerf --data data/edge128_fs50
        [--split train] [--limit 0] [--prior FILE ...]

Collects the model's flip-tested int8 2D joints on a split as ``training.skeleton_prior`` does, counts the
joints whose two peaks triangulate farther than ``MAX_JOINT_FROM_ROOT_M`` from the body's robust centre
(nearly parallel rays through wrong peaks), and runs each prior file on the split: MPJPE over every
joint, its p99 and maximum, the joints more than 0.5 m off, and the mean in the scenes with a far DLT
point against the others. A file of feature version 1 (before such points were dropped) is run on the
features it was trained on (the same with no distance limit), straight through onnxruntime, so an old
and a new file compare on the same joints. A tool, not a test.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.model_folder import model_folder_option  # noqa: E402
from ghnerf_runtime.cli.counts import non_negative_count  # noqa: E402
from training.cli.dataset_split import check_dataset_split  # noqa: E402
from ghnerf_runtime.skeleton_prior import (  # noqa: E402
    FILE_NAME, MAX_JOINT_FROM_ROOT_M, META_PREFIX, SkeletonPrior, prior_inputs,
)


def _answers(path: Path, arrays: dict) -> np.ndarray:
    """The file's joints (rig frame) with the runtime's flip test, on the features of its version
    (``SkeletonPrior.load`` refuses version 1: the session is made here)."""
    import onnxruntime as ort

    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    meta = dict(sess.get_modelmeta().custom_metadata_map)
    bound = np.inf if meta.get(META_PREFIX + "feature_version") == "1" else MAX_JOINT_FROM_ROOT_M
    inp = prior_inputs(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"], max_joint_from_root_m=bound)
    return SkeletonPrior(sess, path, meta).answer(inp).points


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model-dir", type=model_folder_option, default="models/ghnerf")
    ap.add_argument("--data", required=True)
    ap.add_argument("--split", default="train")
    ap.add_argument("--limit", type=non_negative_count, default=0, help="scenes (0: all)")
    ap.add_argument("--prior", action="append", default=[], help=f"prior files (default: <model-dir>/{FILE_NAME})")
    args = ap.parse_args(argv)
    check_dataset_split(ap, args.data, args.split)
    from training.skeleton_prior import collect

    arrays = collect(args.model_dir, args.data, args.split, args.limit, progress=False)
    truth, valid = arrays["joints_3d"], arrays["joints_3d_valid"].astype(bool)
    kept = prior_inputs(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"])
    loose = prior_inputs(arrays["uv"], arrays["confidence"], arrays["valid"], arrays["P"],
                         max_joint_from_root_m=np.inf)
    far = loose.triangulated & ~kept.triangulated
    far_scene = far.any(1)
    print(f"{args.split}: {len(truth)} scenes; DLT points farther than {MAX_JOINT_FROM_ROOT_M:g} m from the body: "
          f"{int(far.sum())} in {int(far_scene.sum())} scenes ({far_scene.mean():.1%}); the farthest "
          f"{np.abs(loose.joint_features[..., :3][far]).max(initial=0.0):.0f} m from the floor origin")
    for path in [Path(p) for p in args.prior] or [Path(args.model_dir) / FILE_NAME]:
        err = np.linalg.norm(_answers(path, arrays) - truth, axis=-1)
        e = err[valid]

        def mean_mm(mask) -> str:
            return f"{1e3 * err[mask].mean():.1f} mm" if mask.any() else "n/a"

        print(f"{path}: MPJPE {1e3 * e.mean():.1f} mm, p99 {1e3 * np.percentile(e, 99):.0f} mm, max {e.max():.2f} m, "
              f"{int((e > 0.5).sum())} joints > 0.5 m off; scenes with a far DLT point "
              f"{mean_mm(valid & far_scene[:, None])}, the others {mean_mm(valid & ~far_scene[:, None])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
