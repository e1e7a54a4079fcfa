"""Exponential backoff for reconnect attempts (pure; the worker does the sleeping)."""
from __future__ import annotations

import math
import numbers
import threading
from dataclasses import dataclass

from ghnerf_runtime.plain_values import is_real_number


@dataclass(frozen=True)
class BackoffPolicy:
    initial_s: float = 0.05
    """Wait after the first failed attempt."""
    factor: float = 2.0
    """Each further failure multiplies the wait by this."""
    max_s: float = 2.0
    """The wait never exceeds this, so a replugged device is found within max_s; finite, at most
    ``threading.TIMEOUT_MAX`` (a longer wait raised OverflowError in the worker, which died)."""

    def __post_init__(self) -> None:
        for name in ("initial_s", "factor", "max_s"):
            value = getattr(self, name)
            # a Python or numpy number, kept as a float: True was a 1 s wait, text a bare TypeError
            if not is_real_number(value):
                raise ValueError(f"invalid backoff policy: {name} must be a number, got {value!r}")
            object.__setattr__(self, name, _as_float(value))
        if not (self.initial_s > 0 and math.isfinite(self.factor) and self.factor >= 1
                and self.initial_s <= self.max_s <= threading.TIMEOUT_MAX):
            raise ValueError(f"invalid backoff policy {self}: want 0 < initial_s <= max_s <= "
                             f"{threading.TIMEOUT_MAX:g} s and a finite factor >= 1")


def _as_float(value: numbers.Real) -> float:
    """``value`` as a float; an integer past the float range (10**400) as the infinity of its sign, which the policy's
    bounds refuse by name (``float()`` raised a bare OverflowError)."""
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


class Backoff:
    """Yields initial, initial*factor, ... capped at max_s; ``reset()`` after a success."""

    def __init__(self, policy: BackoffPolicy) -> None:
        self.policy = policy
        self._next = policy.initial_s

    def next_delay(self) -> float:
        delay = self._next
        self._next = min(self._next * self.policy.factor, self.policy.max_s)
        return delay

    def reset(self) -> None:
        self._next = self.policy.initial_s
