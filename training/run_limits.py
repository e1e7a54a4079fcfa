"""Bounds on the whole-number settings that training hands to torch, checked when a config is read.

torch takes seeds and thread counts as C integers: a value past them was accepted by ``--validate-config`` and
then failed the run with ``ValueError: Overflow when unpacking long`` after the dataset was opened and
``config.json`` written.
"""
from __future__ import annotations

#: Largest ``seed``. The runs derive further seeds from it (``seed * 1000 + rank`` in ``training.train``,
#: ``seed * 1_000_003 + step`` in ``training.pretrain_human``), which must stay 64-bit integers for torch;
#: the simulator's scene seeds have the same range.
MAX_SEED = 2 ** 32 - 1

#: Most torch (and onnxruntime) threads a run may ask for: more than any host has cores, far below the C
#: ``int`` that ``torch.set_num_threads`` overflows at.
MAX_THREADS = 1024


def seed_problem(seed: int) -> str | None:
    """Why ``seed`` cannot seed a run, or ``None`` when it can."""
    if not 0 <= seed <= MAX_SEED:
        return f"must be an integer in [0, {MAX_SEED}], got {seed}"
    return None


def threads_problem(threads: int, minimum: int) -> str | None:
    """Why ``threads`` is not a thread count (``minimum``: 0 where 0 means every core), or ``None``."""
    if threads < minimum:
        return f"must be at least {minimum}, got {threads}"
    if threads > MAX_THREADS:
        return f"must be at most {MAX_THREADS}, got {threads}"
    return None
