"""``ghnerf-daemon --config FILE --measure-floor [PAIRS]``: this install's standing foot, measured.

The floor check (:class:`~firmware_host.daemon.calibration_watch.FloorWatch`) compares the lower foot's height
(``PairResult.lowest_foot_m``: the median height of its triangulated joints less ``joints3d.foot_standing_m``) with
the floor. The default standing foot (0.04 m) is the simulated people's bare feet; shoes' soles or a mat raise every
foot joint by their thickness, which would eat into ``health.calibration_max_floor_m`` (docs/calibration.md, "Shoes,
mats: the standing foot"). This opens the config's rig and model as the daemon does, runs pairs through the estimator
until ``PAIRS`` of them gave a foot figure, and says the median height of the lower foot's joints: the value of
``estimator.joints3d.foot_standing_m`` that puts this person's feet on the floor. Run it right after calibrating (a
camera panned since would be measured as a sole), with someone standing in their usual shoes, both feet in view,
alone: a pair with two people in view (``PairResult.several_people``) is read past, as whose feet its figure is (the
subject's, or since session 57 both people's) is not this person's alone.

Errors follow the daemon's start: what the config, the model or the rig file must fix is a ``DaemonConfigError``
(the CLI's exit 2, as the start's); a measurement taken that gave no value is a :class:`FloorMeasureError` (exit 1);
``stop`` set (SIGTERM, SIGINT in the CLI) a :class:`FloorMeasureStopped` (exit 128 + the signal's number).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from typing import Any, Optional, Protocol

import numpy as np

import drivers
from firmware_host.daemon.config import DaemonConfig, DaemonConfigError
from firmware_host.daemon.service import SIZE_MISMATCH_OPENS, size_mismatch_fault
from firmware_host.errors import FirmwareHostError
from ghnerf_runtime.config import MAX_FOOT_STANDING_M
from ghnerf_runtime.errors import FrameError, RuntimeErrorBase

__all__ = ["FloorMeasureError", "FloorMeasureStopped", "FloorMeasurement", "measure_floor", "measure_floor_of_config",
           "DEFAULT_PAIRS", "READS_PER_PAIR"]

#: Pairs with a foot figure measured when ``--measure-floor`` names no number (two seconds at 30 fps).
DEFAULT_PAIRS = 60
#: Pairs read per pair wanted before giving up: a person with their feet out of view, or nobody, gives no figure.
READS_PER_PAIR = 5


class FloorMeasureError(FirmwareHostError):
    """The standing foot could not be measured (too few pairs showed a foot, or it reads off any floor)."""


class FloorMeasureStopped(FloorMeasureError):
    """``stop`` was set (SIGTERM, Ctrl-C) before the pairs wanted measured a foot; ``pairs_read``, ``feet``: so far."""

    def __init__(self, pairs_wanted: int, pairs_read: int = 0, feet: int = 0) -> None:
        super().__init__(f"--measure-floor stopped before {pairs_wanted} pairs measured a foot ({feet} did, of "
                         f"{pairs_read} read): nothing to set")
        self.pairs_read, self.feet = pairs_read, feet


class _FramesOfAnotherSize(DaemonConfigError):
    """Keyed ``rig.url``: ``error`` (a ``drivers.FrameSizeError``) before any pair of the rig's size, at the open or
    at the first read (``depthai://``); :func:`measure_floor_of_config` opens again on it, as the daemon's start
    does."""

    def __init__(self, error: drivers.FrameSizeError) -> None:
        super().__init__(str(error), key="rig.url")
        self.error = error


class _Estimates(Protocol):
    def estimate(self, images: Any, *, sequence: Any = ..., timestamp_s: Optional[float] = ...) -> Any: ...


class _Reads(Protocol):
    """What is read of the rig (``drivers.RigSource``): its pairs, and its counters and pairing config to say why
    none came."""

    pairing: drivers.PairingConfig

    @property
    def stats(self) -> drivers.PairingStats: ...

    def read(self, timeout_s: float = ...) -> Any: ...


@dataclass(frozen=True)
class FloorMeasurement:
    """What ``--measure-floor`` measured.

    Attributes:
        pairs_read: pairs the rig delivered and the estimator ran.
        heights_m: per pair with a foot figure, the median height of the lower foot's triangulated joints (the figure
            plus the standing foot it was taken with).
        foot_standing_m: the config's ``joints3d.foot_standing_m``, the figures were taken with.
        pairs_two_people: pairs read past for showing two people (``several_people``), a foot figure or not.
    """

    pairs_read: int
    heights_m: tuple[float, ...]
    foot_standing_m: float
    pairs_two_people: int = 0

    @property
    def median_m(self) -> float:
        return float(np.median(self.heights_m))

    @property
    def suggested_m(self) -> float:
        """``joints3d.foot_standing_m`` to set: the median height, to the millimetre."""
        return round(self.median_m, 3)

    def to_json(self) -> dict:
        h = np.asarray(self.heights_m, float)
        return {
            "pairs_read": self.pairs_read,
            "pairs_with_a_foot": int(h.size),
            "pairs_with_two_people": self.pairs_two_people,
            "foot_height_m": {"median": round(self.median_m, 4), "p10": round(float(np.percentile(h, 10)), 4),
                              "p90": round(float(np.percentile(h, 90)), 4)},
            "foot_standing_m": self.foot_standing_m,
            # what the floor check reads now: the median figure with the config's standing foot
            "lowest_foot_m_median": round(self.median_m - self.foot_standing_m, 4),
            "set": {"estimator": {"joints3d": {"foot_standing_m": self.suggested_m}}},
        }


def measure_floor(source: _Reads, estimator: _Estimates, foot_standing_m: float, pairs: int = DEFAULT_PAIRS, *,
                  read_timeout_s: float = 5.0, max_reads: Optional[int] = None, stall_s: float = 10.0,
                  clock: Callable[[], float] = time.monotonic,
                  stop: Optional[threading.Event] = None) -> FloorMeasurement:
    """Read pairs from the open ``source`` through ``estimator`` (whose config's ``joints3d.foot_standing_m`` is
    ``foot_standing_m``) until ``pairs`` of them gave a foot figure (``PairResult.lowest_foot_m``).

    ``max_reads`` (default ``READS_PER_PAIR * pairs``): pairs read before giving up. A pair the estimator rejects
    (a frame check) counts as read, and so does one with two people in view (``several_people``), which gives no
    figure here: its figure may be the other person's feet, or both people's. The end of a recording ends the
    reading. A read that times out is waited for again, until no pair came for ``stall_s`` (the daemon's
    ``rig.stall_s``: a camera open but silent); a read that fails (``RigOperationError``: a corrupt frame of a
    recording) is read past once, as the daemon reads past it, and raised when the next read fails too. ``stop``
    is looked at before each read, as the daemon's loop does (a read waits ``read_timeout_s`` at most).

    :raises FloorMeasureError: fewer than ``pairs`` figures within ``max_reads`` pairs (or the recording's end, or a
        silent rig), or a median height outside ``[0, MAX_FOOT_STANDING_M]`` (not a foot standing on this rig's floor).
    :raises FloorMeasureStopped: ``stop`` was set first.
    :raises DaemonConfigError: keyed ``rig.url``: frames of another size than the rig's before any pair
        (``drivers.FrameSizeError``), a rig that does not fit the cameras.
    :raises drivers.DriverError: the rig failed (not a timeout: a slow pair is waited for again; not one failed read).
    """
    if isinstance(pairs, bool) or not isinstance(pairs, int) or pairs < 1:
        raise ValueError(f"measure_floor: pairs must be a whole number >= 1, got {pairs!r}")
    limit = READS_PER_PAIR * pairs if max_reads is None else max_reads
    heights: list[float] = []
    read = two_people = 0
    last_pair = clock()
    stats_at_pair = source.stats  # what came since: why no pair formed, when none does for stall_s
    read_failed = False  # the last read raised a RigOperationError and no pair came since
    while len(heights) < pairs and read < limit:
        if stop is not None and stop.is_set():
            raise FloorMeasureStopped(pairs, read, len(heights))
        try:
            pair = source.read(timeout_s=read_timeout_s)
        except drivers.EndOfStream:
            break
        except drivers.RigTimeoutError:
            # no pair is no pair read; counted as one, a silent rig kept it waiting READS_PER_PAIR * pairs timeouts
            # (five minutes for the default 60 at rig.read_timeout_s 1) and then said nobody stood in view
            waited = clock() - last_pair
            if waited >= stall_s:
                raise FloorMeasureError(
                    f"--measure-floor: no pair for {waited:.1f} s (rig.stall_s {stall_s:g}) after {read} pairs read: "
                    f"{_why_no_pair(stats_at_pair, source)}") from None
            continue
        except drivers.RigDisconnectedError:
            raise  # unplugged, a device reset: the rig is gone
        except drivers.RigOperationError as e:
            if isinstance(e, drivers.FrameSizeError) and read == 0:
                # no pair yet of the rig's size (depthai:// checks it as frames are read, after its open): a rig that
                # does not fit the cameras, as at an open (measure_floor_of_config, which opens again on it, as the
                # daemon does, up to SIZE_MISMATCH_OPENS); the daemon stops on it then (exit 2)
                raise _FramesOfAnotherSize(e) from None
            if read_failed:  # twice before a pair: the rig itself failed
                raise
            read_failed = True
            continue
        read_failed = False
        last_pair = clock()
        stats_at_pair = source.stats
        read += 1
        try:
            result = estimator.estimate(pair.images, sequence=pair.sequence, timestamp_s=pair.timestamps_ns[0] * 1e-9)
        except FrameError:
            continue
        if result.several_people:  # whose feet the figure is (the subject's, or both people's) is not known here
            two_people += 1
            continue
        if result.lowest_foot_m is not None:
            heights.append(float(result.lowest_foot_m) + foot_standing_m)
    if len(heights) < pairs:
        crowded = f"; {two_people} of them showed two people, read past: one person alone in view" if two_people else ""
        raise FloorMeasureError(
            f"--measure-floor: {len(heights)} of {read} pairs read gave a foot figure, {pairs} wanted{crowded}: stand "
            f"on the floor, both feet in view of both cameras and away from the frames' edges (someone lying, sitting "
            f"on the floor or upside down gives none)")
    m = FloorMeasurement(read, tuple(heights), foot_standing_m, two_people)
    if not 0.0 <= m.median_m <= MAX_FOOT_STANDING_M:
        raise FloorMeasureError(
            f"--measure-floor: the lower foot's joints read a median {m.median_m:.3f} m above the floor, outside "
            f"[0, {MAX_FOOT_STANDING_M:g}] m for joints3d.foot_standing_m: not a person standing on this rig's floor "
            f"in shoes or on a mat. A camera moved since calibration reads so too (ghcal check); so does a rig file "
            f"whose floor is off (docs/rig-file.md)")
    return m


def _why_no_pair(stats_at_pair: drivers.PairingStats, source: _Reads) -> str:
    """The daemon's account of a stretch with no pair (``drivers.why_no_pair``), with what a silent camera means
    here: this command opens the cameras beside the service, which may hold them. Blaming a silent camera for any
    such stretch sent the operator to a cable where both cameras delivered frames that never paired."""
    stats = source.stats
    why = drivers.why_no_pair(stats_at_pair, stats, source.pairing)
    if drivers.silent_cameras(stats_at_pair, stats):
        why += " (unplugged, or held by another process: stop the service first)"
    return why


def measure_floor_of_config(config: DaemonConfig, pairs: int = DEFAULT_PAIRS, *,
                            load_model: Callable[[DaemonConfig], Any],
                            rig_kwargs: Optional[dict[str, Any]] = None,
                            stop: Optional[threading.Event] = None) -> FloorMeasurement:
    """:func:`measure_floor` on the rig of ``config.rig.url`` and the model and estimator settings of
    ``config.estimator``, opened as the daemon opens them (``load_model``: the daemon's, raising
    ``DaemonConfigError``; ``rig_kwargs`` to :func:`drivers.create_rig_source`, tests pass a clock). ``stop`` set
    while the model loads: the rig is not opened (set before: nor the model loaded). The rig and the estimator are
    closed however it ends.

    Cameras that deliver another size than the rig's before any pair (``drivers.FrameSizeError`` at the open, or at
    the first read for ``depthai://``) are opened again, after the daemon's backoff (``rig.reopen_min_s`` doubling
    to ``rig.reopen_max_s``), up to the daemon's ``SIZE_MISMATCH_OPENS`` opens in all: a webcam that comes up in
    another mode before it takes the size asked is not a rig file that does not fit.

    :raises DaemonConfigError: as the daemon's start exits 2 for it: the model does not load (``load_model``), a
        rig URL its backend refuses once opened, cameras that deliver another size than the rig's on
        ``SIZE_MISMATCH_OPENS`` opens in a row (both keyed ``rig.url``), a rig the model cannot run on.
    :raises FloorMeasureError: as :func:`measure_floor` (:class:`FloorMeasureStopped` for ``stop``).
    :raises drivers.DriverError: the rig did not open, or failed.
    """
    from ghnerf_runtime.estimator import Estimator  # the model's runtime: only once the config checked out

    stop = threading.Event() if stop is None else stop  # waited on between opens
    if stop.is_set():  # a stop during the imports or the config read (ghnerf-daemon's): no model loaded for nothing
        raise FloorMeasureStopped(pairs)
    session = load_model(config)
    backoff_s = config.rig.reopen_min_s
    for opens in range(1, SIZE_MISMATCH_OPENS + 1):
        if stop.is_set():  # SIGTERM while the model loaded, or between opens: no camera opened for nothing
            raise FloorMeasureStopped(pairs)
        try:
            return _measure_on_one_open(config, pairs, session, Estimator, rig_kwargs, stop)
        except _FramesOfAnotherSize as e:
            if opens == SIZE_MISMATCH_OPENS:
                raise DaemonConfigError(
                    f"{e.error} (on {opens} opens in a row, the cameras never having delivered the rig's size: "
                    f"{size_mismatch_fault(config.rig.url)})", key="rig.url") from None
            stop.wait(backoff_s)
            backoff_s = min(backoff_s * 2, config.rig.reopen_max_s)
    raise AssertionError("unreachable: the last open returns or raises")


def _measure_on_one_open(config: DaemonConfig, pairs: int, session: Any, estimator_class: Any,
                         rig_kwargs: Optional[dict[str, Any]], stop: threading.Event) -> FloorMeasurement:
    """One open of the rig and one estimator for :func:`measure_floor_of_config`, both closed however it ends.

    :raises _FramesOfAnotherSize: cameras of another size than the rig's, before any pair.
    """
    with ExitStack() as closing:
        try:
            source = drivers.create_rig_source(config.rig.url, **(rig_kwargs or {}))
            closing.push(source)  # closed on the way out, an open that failed half way too (as the daemon does)
            source.open()
        except drivers.FrameSizeError as e:  # reopened by the caller, as the daemon's start reopens
            raise _FramesOfAnotherSize(e) from None
        except (drivers.RigConfigError, drivers.BackendNotAvailableError) as e:
            # the daemon's start exits 2 for these (no reopen fixes them); other driver errors are the rig's
            raise DaemonConfigError(str(e), key="rig.url") from None
        try:
            est = estimator_class(session, source.rig, config.estimator)
        except (RuntimeErrorBase, ValueError) as e:  # as the daemon's start: a rig the model cannot run on (exit 2)
            raise DaemonConfigError(f"the model does not fit rig {source.rig.rig_id!r}: {e}") from None
        closing.enter_context(est)
        return measure_floor(source, est, config.estimator.joints3d.foot_standing_m, pairs,
                             read_timeout_s=config.rig.read_timeout_s, stall_s=config.rig.stall_s, stop=stop)
