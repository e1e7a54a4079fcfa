"""Temporal smoothing of the reported 3D joints: a One Euro filter per joint (Casiez et al., CHI 2012).

Jitter is what users of peer systems complain about most (MediaPipe, OpenPose, EasyMocap: PEERS.md),
and a robot arm or an avatar driven by the stream shows every millimetre of it. The One Euro filter
is an exponential low-pass whose cutoff rises with the joint's speed: a still joint is smoothed hard
(cutoff ``min_cutoff_hz``), a fast one hardly lags (cutoff ``min_cutoff_hz + beta * speed``). Speed
is the filtered derivative of the position (its own low-pass at ``d_cutoff_hz``), in metres per
second, measured on the whole 3D point so the three axes move together.

Time comes from the pairs' capture timestamps, so a dropped pair is a longer step, not a jump. A
joint that goes missing restarts from its next reported position; a gap longer than ``max_gap_s``
(the subject left, the stream stalled) restarts every joint; a pair at the last pair's instant again is
answered from the state where a joint comes back where it was (the same frames estimated twice: the filter's
limit as the step goes to 0), and restarts a joint that moved (a clock that did not tick between two
captures: a coarse clock, a caller's constant stamp; answered from the state, the joints froze at the first
pair while the subject walked on). Only what is reported is smoothed: the tracker still follows the raw
joints, so the crop never lags the subject.

Pure numpy; the state is the filter object's own (one per estimator).
"""
from __future__ import annotations

import math

import numpy as np

from ghnerf_runtime.config import SmoothingConfig
from ghnerf_runtime.errors import FrameError, ShapeError
from ghnerf_runtime.plain_values import is_real_number, plain_scalar

__all__ = ["OneEuroJoints", "smoothing_alpha"]


def smoothing_alpha(cutoff_hz: np.ndarray | float, dt_s: float) -> np.ndarray:
    """The exponential smoothing factor of a first-order low-pass at ``cutoff_hz`` over a step ``dt_s``."""
    tau = 1.0 / (2.0 * math.pi * np.asarray(cutoff_hz, np.float64))
    # dt / (dt + tau), not 1 / (1 + tau / dt): tau / dt overflowed (a RuntimeWarning) for a denormal step
    return dt_s / (dt_s + tau)


class OneEuroJoints:
    """One Euro filters over ``(J, 3)`` joints with a validity mask, driven by timestamps (seconds)."""

    def __init__(self, config: SmoothingConfig) -> None:
        self.config = config
        self.reset()

    def reset(self) -> None:
        """Forget every joint (the next call reports its input unchanged)."""
        self._x: np.ndarray | None = None  # (J, 3) filtered positions
        self._dx: np.ndarray | None = None  # (J, 3) filtered velocities, m/s
        self._alive: np.ndarray | None = None  # (J,) joints with a state
        self._raw: np.ndarray | None = None  # (J, 3) the last pair's joints as given (a repeat is told by them)
        self._t: float | None = None

    def __call__(self, t_s: float, points: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """The smoothed joints at time ``t_s``: ``points`` where a joint restarts, filtered elsewhere.

        Args:
            t_s: capture time of the pair, seconds (any origin; increasing); ``None``: no capture time, as the
                estimator's ``timestamp_s=None`` (a still image): ``points`` come back raw and every joint restarts.
            points: ``(J, 3)`` joints, metres.
            valid: ``(J,)`` the joints reported in this pair; the others keep no state.

        Returns:
            ``(J, 3)`` float64; invalid joints are returned as given.

        Raises:
            ShapeError: ``points`` is not ``(J, 3)`` or ``valid`` not ``(J,)``.
            FrameError: ``t_s`` is neither None nor a number (a string, True), or an integer past float64.
        """
        cfg = self.config
        x = np.asarray(points, np.float64)
        valid = np.asarray(valid, bool)
        if x.ndim != 2 or x.shape[-1] != 3 or valid.shape != x.shape[:1]:  # (3,) points came back (3, 3)
            raise ShapeError(f"points (J, 3) and valid (J,) expected, got {x.shape} and {valid.shape}")
        if t_s is None:  # nothing to filter on: raw, as the estimator reports a pair given no capture time
            self.reset()
            return x.copy()
        if not is_real_number(plain_scalar(t_s)):  # was a bare TypeError (None, a string) or True read as 1 s
            raise FrameError(f"t_s must be a capture time in seconds (a number) or None, got {t_s!r}")
        try:
            t_s = float(t_s)
        except OverflowError:  # an int past float64 (10**400): the daemon's loop skips a FrameError, not this
            raise FrameError(f"t_s must be a capture time in seconds within float64's range, got {t_s!r}") from None
        # a non-finite joint is not reported: it must not enter (and poison) the state
        valid = valid & np.isfinite(x).all(axis=-1)
        dt = None if self._t is None else t_s - self._t
        if dt == 0.0 and self._x is not None and self._x.shape == x.shape:
            return self._same_instant(x, valid)
        if dt is None or not (0.0 < dt <= cfg.max_gap_s) or self._x is None or self._x.shape != x.shape:
            # First pair, a gap, or time running backwards (a restarted source): start over.
            self._x, self._dx = x.copy(), np.zeros_like(x)
            self._alive = valid.copy()
            self._raw = x.copy()
            self._t = t_s
            return x.copy()
        keep = valid & self._alive
        a_d = smoothing_alpha(cfg.d_cutoff_hz, dt)
        tau_d = 1.0 / (2.0 * math.pi * cfg.d_cutoff_hz)
        # the low-passed velocity dx + a_d * (step / dt - dx), with a_d / dt = 1 / (dt + tau_d): step / dt overflowed
        # for a tiny step of time (5e-324 s), warning on the device's log. Only a jump near the float range (1e308 m)
        # still overflows; it is caught below (the joint restarts), so numpy is not to warn of it either.
        with np.errstate(over="ignore", invalid="ignore"):
            step = x - self._x
            dx_hat = (1.0 - a_d) * self._dx + step / (dt + tau_d)
            speed = np.linalg.norm(dx_hat, axis=-1, keepdims=True)
            a = smoothing_alpha(cfg.min_cutoff_hz + cfg.beta * speed, dt)
            x_hat = self._x + a * step
        out = np.where(keep[:, None], x_hat, x)
        keep &= np.isfinite(out).all(axis=-1)  # an overflowing step (a jump of 1e308 m) restarts the joint
        out = np.where(keep[:, None], out, x)
        dx_hat = np.where(np.isfinite(dx_hat), dx_hat, 0.0)
        self._dx = np.where(keep[:, None], dx_hat, 0.0)
        self._x = out
        self._alive = valid.copy()
        self._raw = x.copy()
        self._t = t_s
        return out.copy()

    def _same_instant(self, x: np.ndarray, valid: np.ndarray) -> np.ndarray:
        """A second pair at the last pair's time. A joint given where it was given last (the same frames again): a
        step of 0 gives it no weight (alpha 0), so it keeps its state; restarting there reported the raw joint and
        lost the state. A joint given elsewhere moved while the clock stood still (a coarse clock, a constant
        stamp): there is no step to filter over, so it restarts where it is; kept, every joint stayed at the first
        pair of that instant however far the subject went."""
        keep = valid & self._alive & np.all(x == self._raw, axis=-1)
        out = np.where(keep[:, None], self._x, x)
        self._dx = np.where(keep[:, None], self._dx, 0.0)
        self._x, self._alive, self._raw = out, valid.copy(), x.copy()
        return out.copy()
