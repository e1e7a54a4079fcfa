"""What the dataset's checksums cost: a sample read with and without its CRC-32 check, and a whole-dataset verify.

    .venv/bin/python benchmarks/time_dataset_checksums.py [--res 128] [--views 4] [--samples 64] [--rounds 5]

Writes one shard of ``--samples`` random samples (the stored arrays of ``--res`` px and ``--views`` views, as
``generate`` stores them) into a temporary folder, and a copy whose ``meta.json`` holds no checksums (a dataset
of the code from before them). Prints the median over ``--rounds`` of the mean ``ShardedSplit.arrays`` time
per sample over the shard in random order, for each copy, and the rate of ``training.data.verify`` over the
shard. The files are in the page cache (just written): this is the CPU's share, the one the checks add; a
read from a cold disk costs the same check and more waiting. One host, whatever else runs on it.
"""
from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from ghnerf_runtime.cli.counts import positive_count  # noqa: E402
from ghnerf_runtime.preprocess import Roi  # noqa: E402
from training.data.cache import (  # noqa: E402
    CHECKSUMS, SHARD_META, ShardedSplit, new_manifest, write_manifest, write_shard,
)
from training.data.sample import Sample, ViewData  # noqa: E402
from training.data.verify import verify_dataset  # noqa: E402


def random_sample(rng: np.random.Generator, res: int, names: list[str]) -> Sample:
    """A sample of random content with the stored shapes and dtypes (the checks do not look at the values)."""
    views = []
    for name in names:
        mask = rng.uniform(size=(res, res)) < 0.3
        views.append(ViewData(
            name=name, image=rng.integers(0, 256, (res, res, 3), dtype=np.uint8), mask=mask,
            depth=np.where(mask, rng.uniform(1, 5, (res, res)), 0).astype(np.float16), has_depth=True,
            joints_2d=rng.uniform(0, res, (25, 2)).astype(np.float32), visible=rng.uniform(size=25) < 0.8,
            K=np.eye(3), R=np.eye(3), t=rng.normal(size=3), roi=Roi(0, 0, 100), roi_from_volume=False,
            full_K=np.eye(3), full_size=(640, 480)))
    return Sample(tuple(views), rng.normal(size=(25, 3)), np.ones(25, bool), np.array([[-1.0, -2, 2], [1, 0, 4]]),
                  {})


def make_dataset(root: Path, res: int, views: int, samples: int) -> None:
    names = ["src0", "src1"] + [f"novel{i}" for i in range(views - 2)]
    rng = np.random.default_rng(0)
    root.mkdir(parents=True)
    write_shard(root / "train" / "shard_000000", [random_sample(rng, res, names) for _ in range(samples)], 0)
    manifest = new_manifest(resolution=res, view_names=names, source="benchmark", source_config={})
    manifest["splits"]["train"] = {"count": samples, "shard_size": samples}
    write_manifest(root, manifest)


def per_sample_ms(root: Path, rounds: int) -> float:
    split = ShardedSplit(root, "train")
    order = np.random.default_rng(1).permutation(len(split))
    means = []
    for _ in range(rounds):
        start = time.perf_counter()
        for i in order:
            split.arrays(int(i))
        means.append((time.perf_counter() - start) / len(order) * 1e3)
    return statistics.median(means)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--res", type=positive_count, default=128)
    p.add_argument("--views", type=positive_count, default=4)
    p.add_argument("--samples", type=positive_count, default=64)
    p.add_argument("--rounds", type=positive_count, default=5)
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        checked, bare = Path(tmp) / "checked", Path(tmp) / "bare"
        make_dataset(checked, args.res, args.views, args.samples)
        shutil.copytree(checked, bare)
        meta_path = bare / "train" / "shard_000000" / SHARD_META
        meta = json.loads(meta_path.read_text())
        del meta[CHECKSUMS]
        meta_path.write_text(json.dumps(meta))
        size = sum(f.stat().st_size for f in (checked / "train" / "shard_000000").glob("*.npy"))
        with_ms, without_ms = per_sample_ms(checked, args.rounds), per_sample_ms(bare, args.rounds)
        start = time.perf_counter()
        report = verify_dataset(checked)
        seconds = time.perf_counter() - start
    assert not report.damaged, report.damaged
    print(f"{args.samples} samples of {args.res} px, {args.views} views: {size / args.samples / 1e3:.0f} KB a sample")
    print(f"ShardedSplit.arrays per sample: {with_ms:.3f} ms checked, {without_ms:.3f} ms without checksums "
          f"(+{with_ms - without_ms:.3f} ms, {100 * (with_ms - without_ms) / without_ms:+.0f} %)")
    print(f"verify: {size / 1e6:.1f} MB in {seconds * 1e3:.0f} ms ({size / 1e6 / seconds:.0f} MB/s)")


if __name__ == "__main__":
    main()
