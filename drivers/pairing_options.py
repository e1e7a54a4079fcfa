"""The pairing options every rig URL takes, read in one place: ``tolerance_ms``, ``policy``, ``max_pending``.

Each backend read ``tolerance_ms`` and ``policy`` itself; a new pairing option would have had to be added four
times, and ``max_pending`` (fixed at 8) could not be set at all, so a camera whose frames reach the host 8 or
more frames after the other's (a slower USB path) never paired. A backend keeps its own
defaults (``replay://`` delivers every pair, ``opencv://`` derives the tolerance from the cameras' rate).
"""
from __future__ import annotations

from dataclasses import dataclass

from drivers.pairing import MAX_HELD, MAX_TOLERANCE_MS, DropPolicy, PairingConfig
from drivers.url import RigUrl

#: The smallest ``tolerance_ms`` a URL may give (a microsecond).
MIN_TOLERANCE_MS = 0.001


@dataclass(frozen=True)
class PairingOptions:
    """A rig URL's pairing options, validated.

    Attributes:
        tolerance_ms: ``None`` where the URL gives none (the backend's default applies).
        policy: see :class:`~drivers.pairing.DropPolicy`.
        max_pending: frames held per camera while waiting for the other's (``PairingConfig.max_pending``).
    """

    tolerance_ms: float | None = None
    policy: DropPolicy = DropPolicy.LATEST
    max_pending: int = PairingConfig.max_pending

    def config(self, default_tolerance_ms: float = PairingConfig.tolerance_ms) -> PairingConfig:
        """The :class:`PairingConfig` these options make, with ``default_tolerance_ms`` where none was given."""
        tolerance = default_tolerance_ms if self.tolerance_ms is None else self.tolerance_ms
        return PairingConfig(tolerance_ms=tolerance, policy=self.policy, max_pending=self.max_pending)


def take_pairing_options(url: RigUrl, *, policy: DropPolicy = DropPolicy.LATEST,
                         max_tolerance_ms: float = MAX_TOLERANCE_MS) -> PairingOptions:
    """Take ``tolerance_ms`` (at most ``max_tolerance_ms``), ``policy`` (default ``policy``) and ``max_pending``
    (1 to :data:`~drivers.pairing.MAX_HELD`) from ``url``; a value out of range is a ``RigConfigError`` naming the
    option and the value."""
    tolerance = (url.take_float("tolerance_ms", 0.0, lo=MIN_TOLERANCE_MS, hi=max_tolerance_ms)
                 if "tolerance_ms" in url.options else None)
    chosen = url.take_str("policy", policy.value, choices=tuple(p.value for p in DropPolicy))
    max_pending = url.take_int("max_pending", PairingConfig.max_pending, lo=1, hi=MAX_HELD)
    return PairingOptions(tolerance_ms=tolerance, policy=DropPolicy(chosen), max_pending=max_pending)
