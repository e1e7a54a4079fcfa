"""The human-encoder pretraining's checkpoints: ``last.pt`` and the one before it, ``prev.pt``.

The pretraining keeps no ``ckpt_*.pt`` (``ghnerf-train`` does), so a damaged ``last.pt`` (a file corrupted
after it was written, a non-finite state) used to lose the whole run. Each checkpoint now moves the previous
``last.pt`` to ``prev.pt`` once the new one is written whole (``train.save_atomic``), and ``--resume`` falls
back to ``prev.pt`` when ``last.pt`` is missing, does not load or holds a non-finite tensor, saying so in one
line that names both files. A file of the wrong kind (a ``human.pt`` copied to ``last.pt``) or of another config
is no damage: it is refused by the caller, not skipped.
"""
from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from training.model.config import ConfigError
from training.train import load_checkpoint, save_atomic

LAST, PREV = "last.pt", "prev.pt"

#: What to do when no checkpoint of the folder reads: the trainer's advice (delete it, resume from the newest
#: ``ckpt_*.pt``) would restart the pretraining from step 0 here.
DAMAGED_HINT = ("the pretraining keeps no other checkpoint than last.pt and prev.pt (its human.pt holds the "
                "encoder's weights of the last step, without the optimiser): restore one from a copy, or move the "
                "folder away and start again; deleting them makes --resume start again from step 0")


def save(state: dict, out: Path, rotate: bool) -> None:
    """Write ``out/last.pt``; with ``rotate`` the ``last.pt`` it replaces becomes ``prev.pt`` (without, as after a
    resume from ``prev.pt``, a damaged ``last.pt`` is overwritten and the good ``prev.pt`` kept)."""
    save_atomic(state, out / LAST, keep_previous=out / PREV if rotate else None)


def non_finite_tensor(ck: Any) -> str | None:
    """The name of the first weight or optimiser-state tensor of ``ck`` holding a NaN or an infinity (None: all
    finite, or not a pretraining checkpoint, which ``require_resume_keys`` names)."""
    if not isinstance(ck, Mapping):
        return None
    human = ck.get("human")
    named = list(human.items()) if isinstance(human, Mapping) else []
    opt_state = (ck.get("optimizer") or {}).get("state", {}) if isinstance(ck.get("optimizer"), Mapping) else {}
    for idx, entry in (opt_state.items() if isinstance(opt_state, Mapping) else []):
        if isinstance(entry, Mapping):
            named += [(f"optimizer.state.{idx}.{k}", v) for k, v in entry.items()]
    for name, t in named:
        if isinstance(t, torch.Tensor) and t.is_floating_point() and not bool(torch.isfinite(t).all()):
            return name
    return None


def read(path: Path, map_location: str | torch.device = "cpu") -> dict:
    """``path`` loaded; unreadable or holding a non-finite tensor: a ``ConfigError`` naming it."""
    ck = load_checkpoint(path, map_location, hint=DAMAGED_HINT)
    bad = non_finite_tensor(ck)
    if bad is not None:
        raise ConfigError(f"{path}: non-finite checkpoint ({bad} holds NaN or inf); {DAMAGED_HINT}")
    return ck


def resume_point(out: Path, map_location: str | torch.device = "cpu") -> tuple[Path, dict] | None:
    """The checkpoint ``--resume`` continues from, loaded: ``last.pt``, else ``prev.pt`` (with one line on stderr
    naming both); None when the folder holds neither (a fresh start).

    Raises:
        ConfigError: neither reads (the ``last.pt`` error, and ``prev.pt``'s when there is one).
    """
    last, prev = out / LAST, out / PREV
    if not last.exists() and not prev.exists():
        return None
    try:
        if not last.exists():
            raise FileNotFoundError(last)
        return last, read(last, map_location)
    except (ConfigError, FileNotFoundError) as e:
        why = "is missing" if isinstance(e, FileNotFoundError) else f"cannot be used ({_first_clause(e)})"
        if not prev.exists():
            raise
        try:
            ck = read(prev, map_location)
        except ConfigError as e2:
            if isinstance(e, FileNotFoundError):
                raise
            raise ConfigError(f"{last}: {_first_clause(e)}; the checkpoint before it, {prev}, cannot be used "
                              f"either ({_first_clause(e2)}); {DAMAGED_HINT}") from e2
    step = ck.get("step", "?") if isinstance(ck, Mapping) else "?"
    print(f"pretrain_human: {last} {why}: resuming from the previous checkpoint {prev} (step {step}); the next "
          f"checkpoint replaces {last.name}", file=sys.stderr)
    return prev, ck


def _first_clause(e: Exception) -> str:
    """A load error without its path and advice: ``unreadable checkpoint (EOFError: ...)``."""
    text = str(e).split(": ", 1)[-1]
    return text.split("; ", 1)[0]
