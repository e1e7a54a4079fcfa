"""A shard file cut short after its split was opened (another process truncating or rewriting it in place) is a
data error naming the file and the sample when a sample of the cut part is read, in-process and in a DataLoader
worker: memory-mapped reading died with SIGBUS there (touching a page past the new end of the file).

The reads run in subprocesses: on the code from before, the signal kills the process that reads."""
from __future__ import annotations

import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]  # the subprocesses import this checkout's code (cwd first on sys.path)


@pytest.fixture
def data(data64, tmp_path) -> Path:
    """A private copy of the session's tiny generated dataset (3 train scenes in one shard, 2 val), to cut."""
    return Path(shutil.copytree(data64, tmp_path / "data"))


def _rows_start(array_file: Path, rows: int) -> int:
    """The byte offset of row ``rows`` of a stored array (its length when cut to its first ``rows`` rows)."""
    mapped = np.load(array_file, mmap_mode="r")
    offset = mapped.offset + rows * mapped[0].nbytes
    del mapped
    return offset


def _run(script: str, *args: object) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", script, *map(str, args)], cwd=ROOT, capture_output=True, text=True,
                          timeout=300)


READ_AFTER_CUT = """
import os, sys
from training.data.cache import ShardedSplit
from training.data.errors import DatasetError

root, path, keep = sys.argv[1], sys.argv[2], int(sys.argv[3])
split = ShardedSplit(root, "train")
split.arrays(0)  # the shard is open (mapped, before) and its first sample read
os.truncate(path, keep)  # as another process cutting the file: the split checked its size when it opened
split.arrays(0)  # still whole
try:
    split.arrays(2)
except DatasetError as e:
    print(f"error: {e}", file=sys.stderr)
    sys.exit(2)
print("read a cut sample", file=sys.stderr)
"""


def test_a_sample_of_a_shard_cut_after_the_split_opened_is_a_data_error_not_sigbus(data):
    images = data / "train" / "shard_000000" / "images.npy"
    done = _run(READ_AFTER_CUT, data, images, _rows_start(images, 1) + 100)  # rows 1 and 2 cut (row 1 partly)
    assert done.returncode != -signal.SIGBUS, "killed by SIGBUS reading a memory-mapped page past the file's end"
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"error: {images}: sample 2 "), lines[0]
    assert "cut short" in lines[0] and "after the split was opened" in lines[0]
    assert f"delete {data / 'train' / 'shard_000000'}" in lines[0] and "training.data.generate" in lines[0]


PRETRAIN_CUT_AFTER_A_READ = """
import os, sys
from training.data import cache
from training.pretrain_human import main

path, keep = sys.argv[1], int(sys.argv[2])
read = cache.ShardedSplit.arrays

def read_then_cut(self, index):
    out = read(self, index)
    if os.path.getsize(path) > keep:  # once, after the first sample (the shard is open, mapped before)
        os.truncate(path, keep)  # as a copy or a rewrite starting mid-run: the split checked the size when it opened
    return out

cache.ShardedSplit.arrays = read_then_cut  # (in the worker too: forked after the patch)
sys.exit(main(sys.argv[3:]))
"""


@pytest.mark.parametrize("workers", [0, 1])
def test_pretraining_stops_on_a_shard_cut_mid_run_with_one_line_naming_it_with_or_without_loader_workers(
        data, tmp_path, workers):
    """The pattern of the damaged-checksum test (``test_data_checksums``), with the file cut after the split opened:
    in-process the read was killed by SIGBUS (-7); in a worker, torch reported the worker killed by a bus error."""
    pytest.importorskip("torch")
    images = data / "train" / "shard_000000" / "images.npy"
    argv = ["--out", tmp_path / "run", "--data", data, "--iterations", "1", "--threads", "1", "--quiet",
            "--set", 'preset="tiny"', "--set", "scenes_per_step=2", "--set", "eval_every=0",
            "--set", f"loader_workers={workers}"]  # two scenes a step: the second is read after the cut
    done = _run(PRETRAIN_CUT_AFTER_A_READ, images, _rows_start(images, 0), *argv)  # every sample cut
    assert done.returncode != -signal.SIGBUS, "killed by SIGBUS reading a memory-mapped page past the file's end"
    assert done.returncode == 2, done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"error: {images}: sample ") and "cut short" in lines[0], lines[0]
    assert "Traceback" not in done.stderr

