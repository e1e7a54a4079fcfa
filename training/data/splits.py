"""Dataset splits of the synthetic set: which subjects, motions and rigs each split may use.

The held-out split ``val`` shares **nothing** with ``train``:

* **Bodies and appearance** (and room, light, sensor, standing place): every random draw of a
  sample derives from its *scene seed*, and the splits own disjoint scene-seed ranges
  (``seed_base + dataset_seed * SEEDS_PER_DATASET + index``, bases ``2**50`` apart).
* **Rig placements**: drawn from ``RigPlacement.random`` with a stream keyed by the scene seed
  (so disjoint too), and additionally separated by a **baseline gap**: ``train`` never uses a
  source baseline in ``HELD_OUT_BASELINE_M = [0.85, 1.05)`` m, ``val`` uses only baselines in it.
* **Motions**: ``jumping_jacks`` and ``reach`` never appear in ``train``. They are the two
  procedural motions whose poses lie furthest from the others: both arms above the head
  with legs abducted (jumping jacks; training motions raise an arm to ~100 degrees at most
  and never spread the legs), and a 135-degree forward reach with trunk flexion and twist
  (the closest training pose, squatting, lifts the arms forward to 90 degrees). Holding
  them out measures generalisation to unseen poses, the hard case for heatmaps, unless ``train``
  also moves ``freestyle`` (``SyntheticConfig.freestyle_share``, half the scenes in ``make model``):
  its range of motion covers these poses, and ``val`` then measures unseen *sequences* of poses.

``val_seen_motions`` has unseen bodies and rigs (same baseline gap as ``val``) but the
training motions, to tell pose generalisation apart from subject/rig generalisation.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drivers.sim import MOTION_NAMES, RigPlacement
from training.data.errors import DataConfigError

#: Scene seeds reserved per dataset seed (the largest split size).
SEEDS_PER_DATASET = 10**9
#: Largest dataset seed (keeps every split inside its own 2**50-wide seed range).
MAX_DATASET_SEED = 10**5
HELD_OUT_MOTIONS: tuple[str, ...] = ("jumping_jacks", "reach")
#: The choreographed training motions: ``train`` (by default) and ``val_seen_motions`` draw from
#: them. ``freestyle`` (random trajectories over the body's range of motion) joins ``train`` only
#: when a dataset asks for it (``SyntheticConfig.freestyle_share``).
ROUTINE_MOTIONS: tuple[str, ...] = tuple(m for m in MOTION_NAMES if m not in HELD_OUT_MOTIONS + ("freestyle",))
TRAIN_MOTIONS: tuple[str, ...] = ROUTINE_MOTIONS
#: Source baselines only the held-out splits use, metres ``[lo, hi)``.
HELD_OUT_BASELINE_M: tuple[float, float] = (0.85, 1.05)
#: The full range ``RigPlacement.random`` draws baselines from.
BASELINE_RANGE_M: tuple[float, float] = (0.1, 1.8)


@dataclass(frozen=True)
class SplitSpec:
    """What one split may contain.

    Attributes:
        name: split name (also its folder in the dataset).
        seed_base: first scene seed of the split's range.
        motions: procedural motions the split draws from.
        baseline_bands: allowed source baselines, a union of ``[lo, hi)`` intervals in metres,
            sampled uniformly by length.
        motion_weights: relative probability of each motion; ``None``: uniform.
    """

    name: str
    seed_base: int
    motions: tuple[str, ...]
    baseline_bands: tuple[tuple[float, float], ...]
    motion_weights: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("_", "").isalnum():
            raise DataConfigError("SplitSpec.name", f"must be a non-empty identifier, got {self.name!r}")
        bad = [m for m in self.motions if m not in MOTION_NAMES]
        if not self.motions or bad:
            raise DataConfigError("SplitSpec.motions", f"must be a non-empty subset of {MOTION_NAMES}, got {self.motions}")
        w = self.motion_weights
        if w is not None and (len(w) != len(self.motions) or min(w) < 0 or sum(w) <= 0):
            raise DataConfigError("SplitSpec.motion_weights",
                                  f"must be one non-negative weight per motion with a positive sum, got {w}")
        for lo, hi in self.baseline_bands or ((0.0, -1.0),):
            if not BASELINE_RANGE_M[0] <= lo < hi <= BASELINE_RANGE_M[1]:
                raise DataConfigError("SplitSpec.baseline_bands",
                                      f"must be non-empty intervals inside {BASELINE_RANGE_M}, got {self.baseline_bands}")

    def seed_range(self, dataset_seed: int) -> tuple[int, int]:
        """Scene seeds ``[lo, hi)`` this split may use for ``dataset_seed``."""
        check_dataset_seed(dataset_seed)
        lo = self.seed_base + int(dataset_seed) * SEEDS_PER_DATASET
        return lo, lo + SEEDS_PER_DATASET

    def scene_seed(self, dataset_seed: int, index: int) -> int:
        """The scene seed of sample ``index``: the root of all of that sample's randomness."""
        if isinstance(index, bool) or not 0 <= int(index) < SEEDS_PER_DATASET:
            raise DataConfigError("index", f"must be in [0, {SEEDS_PER_DATASET}), got {index!r}")
        return self.seed_range(dataset_seed)[0] + int(index)

    def baseline(self, rng: np.random.Generator) -> float:
        """A baseline drawn uniformly from the union of the bands."""
        lengths = np.array([hi - lo for lo, hi in self.baseline_bands])
        u = float(rng.uniform(0.0, lengths.sum()))
        for (lo, hi), length in zip(self.baseline_bands, lengths):
            if u < length:
                return float(lo + u)
            u -= length
        return self.baseline_bands[-1][1] - 1e-9

    def placement(self, rng: np.random.Generator) -> RigPlacement:
        """A random rig (``RigPlacement.random``) whose baseline respects the split's bands."""
        base = RigPlacement.random(rng)
        return replace(base, baseline_m=self.baseline(rng))

    def to_json(self) -> dict:
        out = {"name": self.name, "seed_base": self.seed_base, "motions": list(self.motions),
               "baseline_bands": [list(b) for b in self.baseline_bands]}
        if self.motion_weights is not None:  # absent when uniform: older manifests compare equal
            out["motion_weights"] = [float(x) for x in self.motion_weights]
        return out


def check_dataset_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < MAX_DATASET_SEED:
        raise DataConfigError("dataset_seed", f"must be an int in [0, {MAX_DATASET_SEED}), got {seed!r}")
    return int(seed)


_LO, _HI = HELD_OUT_BASELINE_M
SPLITS: dict[str, SplitSpec] = {
    "train": SplitSpec("train", 0, TRAIN_MOTIONS, ((BASELINE_RANGE_M[0], _LO), (_HI, BASELINE_RANGE_M[1]))),
    "val": SplitSpec("val", 1 << 50, HELD_OUT_MOTIONS, ((_LO, _HI),)),
    "val_seen_motions": SplitSpec("val_seen_motions", 2 << 50, ROUTINE_MOTIONS, ((_LO, _HI),)),
}


def split_spec(name: str, freestyle_share: float = 0.0) -> SplitSpec:
    """The split ``name``; for ``train`` with ``freestyle_share`` > 0, that share of its scenes move
    ``freestyle`` and the routines share the rest equally (the held-out splits never change)."""
    if name not in SPLITS:
        raise DataConfigError("split", f"unknown split {name!r}; splits: {sorted(SPLITS)}")
    if not 0.0 <= freestyle_share < 1.0:
        raise DataConfigError("freestyle_share", f"must be in [0, 1), got {freestyle_share!r}")
    spec = SPLITS[name]
    if name != "train" or freestyle_share == 0.0:
        return spec
    routine = (1.0 - freestyle_share) / len(spec.motions)
    return replace(spec, motions=spec.motions + ("freestyle",),
                   motion_weights=(routine,) * len(spec.motions) + (float(freestyle_share),))


__all__ = ["SEEDS_PER_DATASET", "MAX_DATASET_SEED", "HELD_OUT_MOTIONS", "TRAIN_MOTIONS", "ROUTINE_MOTIONS", "HELD_OUT_BASELINE_M",
           "BASELINE_RANGE_M", "SplitSpec", "SPLITS", "split_spec", "check_dataset_seed"]
