"""The torch adapter: a ``torch.utils.data.Dataset`` over a cached split (the only module importing torch).

Each item is one sample (one scene: 2 sources, ``V`` targets) as a dict of tensors with
the keys, shapes and dtypes of :data:`training.data.targets.KEYS`, plus ``index``
(int64 scalar). The model takes one scene per call, so use ``batch_size=None`` (or
``batch_size=1`` and drop the leading axis). Example::

    ds = MultiViewDataset("data/synth128", "train")
    loader = torch.utils.data.DataLoader(ds, batch_size=None, shuffle=True)  # num_workers=0: ~5 ms per item
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from training.data.cache import ShardedSplit
from training.data.targets import TargetConfig, model_inputs


class MultiViewDataset(torch.utils.data.Dataset):
    """A split of a cached dataset (synthetic or converted ZJU-MoCap) as tensors.

    Args:
        root: dataset folder (``dataset.json``).
        split: split name.
        targets: heatmap, near/far and frame padding settings (frame padding: synthetic data only, below).
        max_open_shards: shards kept memory-mapped per process.
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


__all__ = ["MultiViewDataset"]
