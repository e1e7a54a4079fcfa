"""Exponential backoff for reconnect attempts (pure; the worker does the sleeping)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class BackoffPolicy:
    initial_s: float = 0.05
    """Wait after the first failed attempt."""
    factor: float = 2.0
    """Each further failure multiplies the wait by this."""
    max_s: float = 2.0
    """The wait never exceeds this, so a replugged device is found within max_s."""

    def __post_init__(self) -> None:
        if not (self.initial_s > 0 and self.factor >= 1 and self.max_s >= self.initial_s):
            raise ValueError(f"invalid backoff policy {self}")


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
