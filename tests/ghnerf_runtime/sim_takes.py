"""Simulated scenes the runtime's tests build alike: two people waving in the working volume (the two-people tests'),
a pair's images of a scene, and the calibration checks' take through the shipped model (a waving person filmed by
the default rig)."""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from ghnerf_runtime.config import EstimatorConfig, SessionConfig
from ghnerf_runtime.geometry.rig import Rig

MODELS = Path(__file__).resolve().parents[2] / "models"


def two_people(seed: int, where: tuple) -> tuple[Any, Any]:
    """Two waving people standing at ``where``'s two places (x, z): the first (``seed``, the one whose images the
    oracle tests film) and the second (``seed + 1000``)."""
    sim = pytest.importorskip("drivers.sim")
    return tuple(sim.SimScene(sim.SceneConfig(seed=seed + 1000 * k, motion="wave", position_xz=where[k]))
                 for k in (0, 1))


def pair_images(scene: Any, rig: Rig, t: float) -> tuple[np.ndarray, ...]:
    """``scene`` at ``t`` seconds through each camera of ``rig``'s pair (no truth)."""
    return tuple(scene.render(c, t, with_truth=False)[0] for c in rig.pair)


def shipped_model_take(times: Sequence[float]) -> tuple[EstimatorConfig, Any, Rig, list[list[np.ndarray]]]:
    """The calibration checks' take: the shipped model's session (no warm-up) and the pairs of a waving person (seed
    2) filmed by the default rig at ``times``, ``(config, session, rig, shots)``; the caller skips where
    ``models/model_card.json`` is missing."""
    sim = pytest.importorskip("drivers.sim")
    from ghnerf_runtime.estimator import load_session

    cfg = EstimatorConfig(session=SessionConfig(model_dir=str(MODELS), warmup=False))
    session = load_session(cfg)
    rig = sim.RigPlacement().build()
    scene = sim.SimScene(sim.SceneConfig(seed=2, motion="wave"))
    shots = [list(pair_images(scene, rig, t)) for t in times]
    return cfg, session, rig, shots
