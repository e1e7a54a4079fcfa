"""The torch adapter: a ``torch.utils.data.Dataset`` over a cached split (the only module importing torch).

Each item is one sample (one scene: 2 sources, ``V`` targets) as a dict of tensors with
the keys, shapes and dtypes of :data:`training.data.targets.KEYS`, plus ``index``
(int64 scalar). The model takes one scene per call, so use ``batch_size=None`` (or
``batch_size=1`` and drop the leading axis). Example::

    ds = MultiViewDataset("data/synth128", "train")
    loader = torch.utils.data.DataLoader(ds, batch_size=None, shuffle=True)  # num_workers=0: ~5 ms per item

Loaded in worker processes, go through :func:`load_in_workers`: a data error raised in a worker then reaches the
trainer as itself (the same type, file and message as in-process), not as torch's ``RuntimeError`` holding the
worker's traceback, so the command line reports it in the same one line.
"""
from __future__ import annotations

import pickle
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from training.data.cache import ShardedSplit
from training.data.errors import DataError
from training.data.targets import TargetConfig, model_inputs


class MultiViewDataset(torch.utils.data.Dataset):
    """A split of a cached dataset (synthetic or converted ZJU-MoCap) as tensors.

    Args:
        root: dataset folder (``dataset.json``).
        split: split name.
        targets: heatmap, near/far and frame padding settings (frame padding: synthetic data only, below).
        max_open_shards: shards whose files are kept open per process.
    """

    def __init__(self, root: str | Path, split: str, targets: TargetConfig | None = None, *,
                 max_open_shards: int = 16) -> None:
        self.split = ShardedSplit(root, split, max_open_shards=max_open_shards)
        self.targets = targets or TargetConfig()
        if self.targets.frame_padding and self.split.manifest.get("source") != "synthetic":
            # Recorded crops (ZJU-MoCap) are cut from the real frames by the runtime's own maps, lens included
            # (zju_samples.py): they hold the padding already, where a pinhole redo would misplace its edge.
            self.targets = replace(self.targets, frame_padding=False, edge_cut=0.0)
        self.resolution = self.split.resolution
        self.view_names = self.split.view_names

    def __len__(self) -> int:
        return len(self.split)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        arrays = model_inputs(self.split.arrays(index), self.resolution, self.targets, index=int(index) % len(self))
        out = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in arrays.items()}
        out["index"] = torch.tensor(int(index) % len(self), dtype=torch.int64)
        return out

    def metadata(self, index: int) -> dict:
        return self.split.metadata(index)


class _CarriedError:
    """A data error raised in a DataLoader worker, sent to the parent as the item instead of raised there."""

    def __init__(self, error: DataError) -> None:
        self.error = error


class _CarryDataErrors(torch.utils.data.Dataset):
    """``dataset``, with a :class:`DataError` of an item returned as a :class:`_CarriedError`.

    torch re-raises a worker's exception as ``type(e)(message_with_traceback)``; a ``DatasetError`` takes
    ``(path, message)``, so the parent got a ``RuntimeError`` with a traceback in it. The error object itself
    pickles with its fields (``DataError`` subclasses define ``__reduce__``), so it travels as data instead."""

    def __init__(self, dataset) -> None:
        self.dataset = dataset

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, index):
        try:
            return self.dataset[index]
        except DataError as e:
            try:  # one that would not survive the trip (a subclass without __reduce__) keeps torch's report
                pickle.loads(pickle.dumps(e))
            except Exception:  # noqa: BLE001 - any pickling failure: raise the original below
                raise e from None
            return _CarriedError(e)


def load_in_workers(dataset, **loader_args) -> Iterator:
    """The items of ``torch.utils.data.DataLoader(dataset, **loader_args)``; a :class:`DataError` raised by
    ``dataset`` in a worker process is raised here as itself (type, ``path`` / ``field`` and message), as the
    in-process loop would raise it. Other exceptions keep torch's report (a bug's traceback is worth reading)."""
    for item in torch.utils.data.DataLoader(_CarryDataErrors(dataset), **loader_args):
        if isinstance(item, _CarriedError):
            raise item.error  # leaving the loop ends the loader: its workers are shut down
        yield item


__all__ = ["MultiViewDataset", "load_in_workers"]
