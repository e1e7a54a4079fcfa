"""Training data: the synthetic multi-view set, the ZJU-MoCap loader, the cache and the torch adapter.

``import training.data`` does not import torch; only :mod:`training.data.torch_dataset`
(``MultiViewDataset``, also reachable as ``training.data.MultiViewDataset``) does.
See ``docs/dataset.md`` for the sample schema, the splits and the CLI.
"""
from __future__ import annotations

from typing import Any

from training.data.cache import ShardedSplit, read_manifest, write_shard
from training.data.errors import DataConfigError, DataError, DatasetError
from training.data.sample import FIELDS, NUM_SOURCES, Sample, ViewData
from training.data.splits import HELD_OUT_BASELINE_M, HELD_OUT_MOTIONS, SPLITS, TRAIN_MOTIONS, SplitSpec
from training.data.synthetic import SyntheticConfig, make_sample
from training.data.targets import KEYS, TargetConfig, model_inputs

__all__ = [
    "FIELDS", "HELD_OUT_BASELINE_M", "HELD_OUT_MOTIONS", "KEYS", "NUM_SOURCES", "SPLITS", "TRAIN_MOTIONS",
    "DataConfigError", "DataError", "DatasetError", "MultiViewDataset", "Sample", "ShardedSplit", "SplitSpec",
    "SyntheticConfig", "TargetConfig", "ViewData", "make_sample", "model_inputs", "read_manifest", "write_shard",
]


def __getattr__(name: str) -> Any:
    if name == "MultiViewDataset":  # the torch adapter, imported on first use
        from training.data.torch_dataset import MultiViewDataset

        return MultiViewDataset
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
