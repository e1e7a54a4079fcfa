"""Generate (or resume, or extend) the cached synthetic dataset, in parallel.

Usage::

    python -m training.data.generate --out data/synth128 --train 20000 --val 500 --res 128 --workers 2

Every sample is a pure function of ``(split, --seed, index, config)``, so the output is
byte-identical whatever the worker count, and re-running the same command after an
interruption only renders the shards that are missing. Asking for more samples later
extends the splits (the config must match the manifest's; the error names the field).
Shards are the unit of work: each worker renders a shard's samples and writes the shard.
"""
from __future__ import annotations

import argparse
import logging
import multiprocessing as mp
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from training.data.cache import (
    MANIFEST, new_manifest, read_manifest, remove_stale_temporaries, shard_is_complete, shard_name, shard_plan,
    write_manifest, write_shard,
)
from training.data.errors import DataConfigError, DatasetError
from training.data.splits import check_dataset_seed, split_spec
from training.data.synthetic import SyntheticConfig, make_sample

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class GenerationReport:
    """What one :func:`generate` call did."""

    samples_rendered: int
    shards_written: int
    shards_skipped: int
    seconds: float
    bytes_on_disk: int
    samples_on_disk: int

    @property
    def samples_per_s(self) -> float:
        return self.samples_rendered / self.seconds if self.seconds > 0 else float("nan")

    @property
    def bytes_per_sample(self) -> float:
        return self.bytes_on_disk / self.samples_on_disk if self.samples_on_disk else float("nan")


def _render_shard(task: tuple) -> tuple[str, int, int, float]:
    split, k, first, count, folder, dataset_seed, config_json = task
    config = SyntheticConfig.from_json(config_json)
    spec = split_spec(split, config.freestyle_share)
    start = time.perf_counter()
    samples = [make_sample(spec, dataset_seed, i, config) for i in range(first, first + count)]
    write_shard(folder, samples, first)
    return split, k, count, time.perf_counter() - start


def _worker_init() -> None:
    import signal

    import cv2

    # Ctrl-C reaches the whole process group: only the parent acts on it (it terminates the pool); a worker
    # killed by it would be replaced by the pool and its lost shard would keep join() waiting forever
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    cv2.setNumThreads(1)  # one process per core already


def _check_compatible(manifest: dict, fresh: dict, path: Path) -> None:
    for key in ("resolution", "view_names", "source", "source_config"):
        if manifest.get(key) != fresh[key]:
            raise DatasetError(path, f"was generated with a different {key} ({manifest.get(key)!r}, now {fresh[key]!r}); "
                                     f"use a new --out folder or the original settings")


def _folder_bytes(folder: Path) -> int:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())


def generate(out: str | Path, counts: Mapping[str, int], config: SyntheticConfig, *, dataset_seed: int = 0,
             workers: int = 2, shard_size: int = 64) -> GenerationReport:
    """Make (or complete) the splits ``counts`` (``{"train": N, "val": M}``) under ``out``.

    Args:
        out: dataset folder (created if needed).
        counts: samples per split name (see ``training.data.splits.SPLITS``).
        config: how samples are drawn and rendered; must match an existing dataset's.
        dataset_seed: root seed (different seeds give disjoint datasets).
        workers: processes; ``<= 1`` renders in this process.
        shard_size: samples per shard; must match an existing split's.

    Raises:
        DataConfigError: a bad argument (the message names it).
        DatasetError: ``out`` holds an incompatible dataset (the message names the manifest).
    """
    check_dataset_seed(dataset_seed)
    if isinstance(shard_size, bool) or not isinstance(shard_size, int) or not 1 <= shard_size <= 100_000:
        raise DataConfigError("shard_size", f"must be an int in [1, 100000], got {shard_size!r}")
    for split, n in counts.items():
        split_spec(split)
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise DataConfigError(f"counts.{split}", f"must be a non-negative int, got {n!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    source_config = {"synthetic": config.to_json(), "dataset_seed": int(dataset_seed)}
    fresh = new_manifest(resolution=config.resolution, view_names=config.view_names, source="synthetic",
                         source_config=source_config)
    if (out / MANIFEST).exists():
        manifest = read_manifest(out)
        _check_compatible(manifest, fresh, out / MANIFEST)
    else:
        manifest = fresh
        write_manifest(out, manifest)

    tasks = []
    skipped = 0
    for split, count in counts.items():
        if count == 0:
            continue
        known = manifest["splits"].get(split)
        if known is not None and known["shard_size"] != shard_size:
            raise DatasetError(out / MANIFEST, f"split {split!r} uses shard_size {known['shard_size']}, not {shard_size}")
        spec = split_spec(split, config.freestyle_share).to_json()
        if known is not None and known.get("spec") != spec:
            # e.g. a dataset made before a motion joined the split: resuming would mix two recipes
            raise DatasetError(out / MANIFEST, f"split {split!r} was generated with spec {known.get('spec')}, this "
                                               f"request's is {spec}: generate into a new folder")
        split_dir = out / split
        split_dir.mkdir(exist_ok=True)
        remove_stale_temporaries(split_dir)
        for k, first, n in shard_plan(count, shard_size):
            folder = split_dir / shard_name(k)
            if shard_is_complete(folder, first, n):
                skipped += 1
                continue
            tasks.append((split, k, first, n, folder, int(dataset_seed), config.to_json()))
    total = sum(t[3] for t in tasks)
    log.info("%d shards (%d samples) to render, %d already complete, %d worker(s)", len(tasks), total, skipped, workers)

    start = time.perf_counter()
    done = 0
    if workers <= 1 or len(tasks) <= 1:
        results = map(_render_shard, tasks)
        pool = None
    else:
        pool = mp.get_context("spawn").Pool(workers, initializer=_worker_init)
        results = pool.imap_unordered(_render_shard, tasks)
    try:
        for split, k, n, seconds in results:
            done += n
            elapsed = time.perf_counter() - start
            log.info("%s shard %d: %d samples in %.1f s; %d/%d done, %.2f samples/s", split, k, n, seconds, done, total,
                     done / elapsed)
    except BaseException:
        if pool is not None:
            # Ctrl-C or a failed shard: stop the workers now (close() would wait for every queued shard); a
            # shard cut short is only a *.tmp-* folder, which the next run removes
            pool.terminate()
            pool.join()
        raise
    if pool is not None:
        pool.close()
        pool.join()
    seconds = time.perf_counter() - start

    for split, count in counts.items():
        if count:
            manifest["splits"][split] = {"count": int(count), "shard_size": int(shard_size),
                                         "spec": split_spec(split, config.freestyle_share).to_json(),
                                         "seed_range": list(split_spec(split).seed_range(dataset_seed))}
    write_manifest(out, manifest)
    on_disk = sum(int(info["count"]) for info in manifest["splits"].values())
    size = sum(_folder_bytes(out / s) for s in manifest["splits"])
    return GenerationReport(total, len(tasks), skipped, seconds, size, on_disk)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training.data.generate", description=__doc__.split("\n")[0])
    p.add_argument("--out", required=True, type=Path, help="dataset folder (created, resumed or extended)")
    p.add_argument("--train", type=int, default=0, help="samples in the train split")
    p.add_argument("--val", type=int, default=0, help="samples in the held-out val split (unseen bodies, motions, rigs)")
    p.add_argument("--val-seen-motions", type=int, default=0, help="samples of val_seen_motions (unseen bodies and rigs)")
    p.add_argument("--res", type=int, default=128, help="crop resolution S (multiple of 8)")
    p.add_argument("--novel-views", type=int, default=2, help="novel target cameras per sample (0..4)")
    p.add_argument("--supersample", type=int, default=2, help="render factor before the INTER_AREA reduction")
    p.add_argument("--cold-start", type=float, default=0.2, help="share of samples with working-volume source ROIs")
    p.add_argument("--freestyle-share", type=float, default=0.0,
                   help="share of train scenes moving 'freestyle' (random poses over the range of motion); 0: routines only")
    p.add_argument("--seed", type=int, default=0, help="dataset seed")
    p.add_argument("--workers", type=int, default=2, help="processes")
    p.add_argument("--shard-size", type=int, default=64, help="samples per shard")
    p.add_argument("-v", "--verbose", action="store_true")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    try:
        config = SyntheticConfig(resolution=args.res, novel_views=args.novel_views, supersample=args.supersample,
                                 cold_start_fraction=args.cold_start, freestyle_share=args.freestyle_share)
        counts = {"train": args.train, "val": args.val, "val_seen_motions": args.val_seen_motions}
        report = generate(args.out, counts, config, dataset_seed=args.seed, workers=args.workers,
                          shard_size=args.shard_size)
    except (DataConfigError, DatasetError) as e:
        log.error("%s", e)
        return 2
    except KeyboardInterrupt:
        log.error("interrupted: the finished shards are kept; run the same command again to resume")
        return 130
    log.info("rendered %d samples in %.1f s (%.2f samples/s); %d shards written, %d skipped; %.0f bytes/sample on disk",
             report.samples_rendered, report.seconds, report.samples_per_s, report.shards_written, report.shards_skipped,
             report.bytes_per_sample)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
