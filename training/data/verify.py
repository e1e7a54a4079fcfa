"""Check a dataset's stored arrays against the checksums recorded when they were written.

``python -m training.data.verify DIR [--split NAME ...] [--record-missing]`` reads every shard the manifest's
splits read (the shards past a smaller count are not data: not read) and prints one line per damaged shard:
an array whose samples differ from their CRC-32, or a shard that is missing, cut short or malformed. Exit
status: 0 every shard is whole (shards without checksums, from before they were recorded, are listed and
counted, not failed), 1 a shard is damaged, 2 the folder is not a readable dataset or a split is unknown.

``--record-missing`` gives the shards without checksums those of their arrays as they are now (holding the
writer's lock, as ``generate`` does), so that later reads check them.
"""
from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence, TextIO

from training.data.cache import (
    MANIFEST, damaged_rows, read_manifest, record_missing_checksums, repair_hint, scan_shard, shard_name, shard_plan,
    writer_lock,
)
from training.data.errors import DatasetError

log = logging.getLogger(__name__)


@dataclass
class VerifyReport:
    """What :func:`verify_dataset` found."""

    shards: int = 0  # shards looked at
    checked: int = 0  # of them, checked against their checksums (the rest: none recorded, or unreadable)
    bytes_read: int = 0
    damaged: list[str] = field(default_factory=list)  # one line per damaged shard
    unchecked: list[Path] = field(default_factory=list)  # shards with no checksums
    recorded: list[Path] = field(default_factory=list)  # shards given checksums (``record_missing``)


def verify_dataset(root: str | Path, splits: Sequence[str] | None = None, *, record_missing: bool = False,
                   out: TextIO | None = None) -> VerifyReport:
    """Check every shard of ``splits`` (default: the manifest's) of the dataset at ``root``.

    Each damaged shard is printed to ``out`` as it is found (a long check shows its findings at once).

    Raises:
        DatasetError: the manifest is missing or malformed, a split is not in it, or (``record_missing``)
            another process writes the folder or a shard's metadata could not be rewritten.
    """
    root = Path(root)
    manifest = read_manifest(root)
    names = list(manifest["splits"]) if splits is None else list(splits)
    for name in names:
        if name not in manifest["splits"]:
            raise DatasetError(root / MANIFEST, f"has no split {name!r}; splits: {sorted(manifest['splits'])}")
    report = VerifyReport()
    if record_missing:
        with writer_lock(root):  # rewrites meta.json files: no generate may write meanwhile
            _verify(root, manifest, names, report, True, out)
    else:
        _verify(root, manifest, names, report, False, out)
    return report


def _verify(root: Path, manifest: dict, names: list[str], report: VerifyReport, record_missing: bool,
            out: TextIO | None) -> None:
    resolution, num_views = int(manifest["resolution"]), len(manifest["view_names"])
    for split in names:
        info = manifest["splits"][split]
        shard_size = int(info["shard_size"])
        for k, first, n in shard_plan(int(info["count"]), shard_size):
            report.shards += 1
            try:
                shard = scan_shard(root / split, k, first, n, shard_size, num_views, resolution)
                bad = damaged_rows(shard)
            except DatasetError as e:  # missing, cut short, malformed: damaged too, and the next shard is checked
                line = f"{e}; {repair_hint(manifest, root, split, root / split / shard_name(k))}"
            else:
                if shard.checksums is None:
                    # (outside the try: a failed rewrite, a full disk, stops the command; it is no damaged shard)
                    if record_missing and record_missing_checksums(shard):
                        report.recorded.append(shard.folder)
                    else:
                        report.unchecked.append(shard.folder)
                    continue
                report.checked += 1
                report.bytes_read += sum(p.stat().st_size for p in shard.folder.glob("*.npy"))
                if not bad:
                    continue
                arrays = "; ".join(f"{name}.npy samples {_rows(rows, first)}" for name, rows in bad.items())
                line = (f"{shard.folder}: does not match its checksums ({arrays}); "
                        f"{repair_hint(manifest, root, split, shard.folder)}")
            report.damaged.append(line)
            if out is not None:
                print(line, file=out, flush=True)


def _rows(rows: list[int], first: int) -> str:
    shown = ", ".join(str(first + j) for j in rows[:8])
    return shown + (f" and {len(rows) - 8} more" if len(rows) > 8 else "")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training.data.verify", description=__doc__.split("\n")[0])
    p.add_argument("root", type=Path, help="dataset folder (holding dataset.json)")
    p.add_argument("--split", action="append", default=None, help="check this split only (repeatable; default all)")
    p.add_argument("--record-missing", action="store_true",
                   help="give the shards written without checksums those of their arrays as they are now")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    start = time.perf_counter()
    try:
        report = verify_dataset(args.root, args.split, record_missing=args.record_missing, out=sys.stdout)
    except DatasetError as e:
        log.error("%s", e)
        return 2
    seconds = time.perf_counter() - start
    if report.unchecked:
        log.warning("%d shard(s) carry no checksums (written before they were recorded), not checked: %s%s; "
                    "--record-missing records them", len(report.unchecked), report.unchecked[0],
                    f" .. {report.unchecked[-1]}" if len(report.unchecked) > 1 else "")
    if report.recorded:
        log.info("recorded the checksums of %d shard(s) that had none", len(report.recorded))
    log.info("%d shard(s) of %s: %d checked (%.0f MB in %.1f s), %d damaged", report.shards, args.root,
             report.checked, report.bytes_read / 1e6, seconds, len(report.damaged))
    return 1 if report.damaged else 0


if __name__ == "__main__":
    raise SystemExit(main())
