"""A ``--data`` folder checked with the split a script reads from it, as a usage error (exit 2) naming the option.

The benchmarks that read a cached dataset (``bench_runtime_vs_eval.py``, ``time_train_step.py``...) handed
``--data`` to the reader unchecked: a mistyped folder, one that is no dataset, or one without the split was a
``DatasetError`` traceback, in some scripts only after a model was loaded or trained for minutes.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from training.data.cache import ShardedSplit
from training.data.errors import DatasetError

__all__ = ["check_dataset_split"]


def check_dataset_split(parser: argparse.ArgumentParser, data: str | Path, split: str,
                        option: str = "--data") -> None:
    """Stop with ``parser``'s usage error unless ``data`` is a dataset folder whose ``split`` can be read (its
    manifest, shard folders and array headers: :class:`~training.data.cache.ShardedSplit`). The message is the
    reader's, which names the file."""
    try:
        ShardedSplit(data, split)
    except DatasetError as e:
        parser.error(f"argument {option}: {e}")
