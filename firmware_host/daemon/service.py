"""The daemon's main loop: rig -> estimator -> sinks, for as long as it runs, through unplugs and stalls.

One thread does the work in order (read the newest pair, estimate it, hand the frame to every sink);
the rig's driver and each sink have their own threads, and a sink's ``send`` never blocks, so a
pulled serial cable or a slow link never holds up the estimate or the other outputs.

What it rides out, and how (each is counted in the health report, ``docs/daemon.md``):

* **a rig that cannot be opened** (OAK not plugged in yet, USB reset): retried forever with a
  backoff from ``rig.reopen_min_s`` doubling to ``rig.reopen_max_s``; state ``waiting``; so is one lost
  before its pairs flowed for ``rig.stall_s`` (a device that flaps); but not cameras that deliver another size
  than the rig file's on ``SIZE_MISMATCH_OPENS`` opens in a row and never the rig's (a rig file calibrated at
  another resolution; for ``depthai://``, which opens before its first frames, the first read of each open): that
  stops the daemon as a bad config does (exit 2); once they delivered the rig's size (a pair), a camera that changes
  size is retried as any failed open;
* **a camera that vanishes** (``RigDisconnectedError``) or **falls silent** for ``rig.stall_s``:
  the rig is closed and opened again, and the tracker restarts from the working volume; the sinks
  flag ``CAMERA_FAULT`` in their STATUS until pairs flow again;
* **a rig that comes back with another calibration** (another OAK): the estimator is rebuilt for
  it from the loaded model (no reload), and the sinks are reopened when the camera names change;
* **a read that fails once** (a corrupt image in a recording; ``RigOperationError``): counted, read
  on; failing again before a pair, the rig is reopened;
* **a pair the estimator rejects** (``FrameError``) or onnxruntime fails on (``ModelRunError``): counted and
  skipped (``MAX_FAILED_RUNS`` failures of the model in a row stop the daemon, exit 1, for systemd to
  restart it with the model loaded afresh); an estimate slower than
  ``health.slow_estimate_s`` flags ``ESTIMATOR_STALLED``;
* **a camera moved since calibration** (knocked on its mount): the pairs' views stop meeting in 3D (a tilt),
  or the person's feet leave the floor (a pan, which the views' agreement does not show); once the median
  over ``health.calibration_window`` pairs passes ``health.calibration_max_px`` (or, for the lowest
  triangulated foot joint, ``health.calibration_max_floor_m`` from the floor) the status file and systemd's
  STATUS say "calibration suspect: recalibrate (ghcal)" with the symptom, and the log warns once
  (:mod:`firmware_host.daemon.calibration_watch`); the joints still flow;
* **the cameras' inputs exchanged** (plugs or names in ``rig.url``) on a symmetric rig: the triangulated person is a
  mirror image; below ``-health.calibration_max_mirror`` the same flag is raised, and the STATUS and status file say
  "swap the cameras' plugs or names in rig.url" instead (a recalibration would fit the exchanged views);
* **a hang** of the loop itself: :class:`~firmware_host.daemon.notify.HangWatchdog` stops systemd's
  watchdog pings and systemd restarts the service;
* **a camera stuck in a device call** the rig's close could not end (an opencv:// grab that hangs): the
  loop goes on, but the stuck call holds the device, so every reopen fails; once it has lingered
  ``health.open_allowance_s`` after the close, the watchdog's pings stop for good and systemd restarts
  the service, which frees it.

**Sequence numbers**: the daemon numbers the frames it sends itself (0 at start, one more a frame, on
through rig reopens, reloads and reopened sinks), not by the driver's pair numbers (which restart at 0
with each open). A pair the driver skipped or the estimator rejected takes no number (they are the
health report's ``pairs.dropped`` and ``pairs.estimate_errors``), so a gap a receiver sees was lost
after the daemon: in a sink (flagged) or on the link.

**Reloading the config** (SIGHUP, ``systemctl reload ghnerf``; :meth:`Daemon.request_reload`): the
new file is read and checked in full, and a changed model is loaded (and built for the open rig),
before anything is swapped; a file that fails any of it is refused with its error in the log, the
status file and systemd's STATUS, and the daemon runs on with the config it had (nothing is lost,
nothing restarts). Once accepted, only what changed is touched: a new ``rig.url`` closes the rig and
opens the new one; added or removed sinks are opened or closed while the others keep streaming
without a gap; a new estimator tree replaces the estimator between two pairs; the rest (timeouts,
health, log level) applies from the next pass.

What stops it: ``stop`` being set (SIGTERM / SIGINT in the CLI), a finite source ending when
``rig.exit_at_end`` is on, or an error no retry can fix (a model that will not load, or estimator settings it
cannot serve: raised as :class:`DaemonStartError` before the loop starts; a rig file whose size the cameras
never deliver: raised from the loop).
"""
from __future__ import annotations

import dataclasses
import errno
import json
import logging
import os
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Callable, Optional

import numpy as np

import drivers
from drivers.url import RigUrl, redact_url
from firmware_host.daemon.calibration_watch import CalibrationWatch, FloorWatch, HandednessWatch
from firmware_host.daemon.config import DaemonConfig, DaemonConfigError
from firmware_host.daemon.health import Health, State, scene_flags_of, write_status_file
from firmware_host.daemon.memory import pin_mmap_threshold, return_freed_memory
from firmware_host.daemon.notify import HangWatchdog, SystemdNotifier
from firmware_host.daemon.rig_open import open_unless_stopped
from firmware_host.daemon.sandbox import rig_url_hint, service_hint
from firmware_host.daemon.status_claim import StatusFileClaim, StatusFileTaken, names_one_file
from firmware_host.errors import CaptureTimeError, FirmwareHostError
from firmware_host.joint_frames import FrameNumbers, announced_scene_flags, capture_time_us, estimate_frame
from firmware_host.protocol.constants import Fault, Flags
from firmware_host.service_unit import read_only_hint
from firmware_host.sinks.base import Sink
from firmware_host.sinks.registry import STAND_IN_CAMERAS, check_sink_url, sink_class
from firmware_host.sinks.url import parse_url
from firmware_host.sinks.usb_claims import UsbClaims
from ghnerf_runtime.config import config_to_dict
from ghnerf_runtime.errors import FrameError, ModelError, ModelRunError, RuntimeErrorBase
from ghnerf_runtime.estimator import Estimator, load_session
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.rig_file import dumps_rig

if TYPE_CHECKING:  # onnxruntime is imported with the session, when a model loads
    from ghnerf_runtime.session import ModelSession

__all__ = ["Daemon", "DaemonStartError", "check_sink_urls", "load_model", "check_estimator", "size_mismatch_fault"]


#: The parts of the config a reload tells apart ("rig": its fields but the url).
_PARTS = ("rig.url", "rig", "sinks", "estimator", "health", "log_level")

#: One of the three calibration checks (firmware_host.daemon.calibration_watch).
_Watch = CalibrationWatch | FloorWatch | HandednessWatch


@dataclasses.dataclass(frozen=True)
class _CheckWords:
    """What the journal says when one calibration check's verdict changes (:meth:`Daemon._check_changed`): warned
    once on the way to suspect (``calibration suspect: <symptom>: <fix>``), then once when it fits again or is turned
    off (``setting`` null). ``symptom`` and ``fits_again`` are :meth:`str.format` templates of :func:`_figures`."""

    check: str  # the check's name, for "... off"
    setting: str  # the health key whose null turns it off
    symptom: str
    fix: str
    fits_again: str


_PX_WORDS = _CheckWords(
    check="calibration check", setting="health.calibration_max_px",
    symptom="the two views' peaks are {median:.2f} px apart over the last {pairs} pairs (health.calibration_max_px "
            "{limit:g})",
    fix="a camera has moved since calibration; recalibrate (ghcal, docs/calibration.md) and restart",
    fits_again="calibration fits again: the views' peaks are {median:.2f} px apart over the last {pairs} pairs")
_FLOOR_WORDS = _CheckWords(
    check="calibration floor check", setting="health.calibration_max_floor_m",
    symptom="{feet} (the lower triangulated foot, median over the last {pairs} pairs with feet in view; "
            "health.calibration_max_floor_m {limit:g})",
    fix="a camera has turned since calibration (a pan moves the depth, not the views' agreement); recalibrate (ghcal, "
        "docs/calibration.md) and restart. Where people stand above the floor (a stage, a bed), set "
        "health.calibration_max_floor_m null",
    fits_again="calibration fits the floor again: {feet} over the last {pairs} pairs")
_HANDEDNESS_WORDS = _CheckWords(
    check="calibration handedness check", setting="health.calibration_max_mirror",
    symptom="the cameras look exchanged: the triangulated person is a mirror image (handedness {median:.2f}, median "
            "over the last {pairs} pairs; +1 a person, -1 a mirror image; health.calibration_max_mirror {limit:g})",
    fix="the left camera's frames come in as the right's; exchange the cameras' plugs or their names in rig.url, no "
        "recalibration is needed (docs/calibration.md, \"Cameras exchanged\"). On a rig built far from symmetric "
        "(a camera above the person, one beside the other), set health.calibration_max_mirror null",
    fits_again="the cameras no longer look exchanged: handedness {median:.2f} over the last {pairs} pairs")


def _figures(watch: _Watch) -> dict[str, Any]:
    """What a check's log templates name: its median (0 where it has none), the pairs it counts, its limit, and for
    the floor check where the feet are (:meth:`FloorWatch.words`)."""
    median = watch.median
    return {"median": 0.0 if median is None else median, "pairs": len(watch.values), "limit": watch.limit,
            "feet": watch.words() if isinstance(watch, FloorWatch) else ""}


def _part(config: DaemonConfig, name: str) -> Any:
    """One part of the config by its name, for telling what a reload changed ("rig": all but its url)."""
    if name == "rig.url":
        return config.rig.url
    return dataclasses.replace(config.rig, url="sim://") if name == "rig" else getattr(config, name)


def _stand_in_rig() -> Rig:
    """A plausible rig (the simulator's default placement) to check estimator settings against while no rig is known."""
    from drivers.sim.placement import RigPlacement  # local: the simulator's scene is not needed otherwise

    return RigPlacement().build(rig_id="stand-in")


def _session_key(config: DaemonConfig) -> tuple:
    """What :func:`load_session` loads for this config: the same key, the same session (kept across a reload)."""
    from ghnerf_runtime.session import ModelSession  # as load_session does: importable without a model

    est = config.estimator.beside_prior(ModelSession.has_skeleton_prior(config.estimator.session))
    return (est.session, tuple(est.required_graphs(ModelSession.has_graph_file(est.session, "human"))),
            est.joints3d.uses_skeleton_prior(True), est.novel_view.uses_painter(True))

_log = logging.getLogger("ghnerf.daemon")


def _lingering(source: drivers.RigSource) -> tuple[str, ...]:
    """:meth:`RigSource.lingering`, nothing for a source that cannot say (a test's stand-in, a failing one)."""
    try:
        return tuple(source.lingering())
    except Exception:  # noqa: BLE001 - asked from the watchdog's thread, which must keep ticking
        return ()


#: The model failing on this many pairs in a row (no estimate between) is no longer one bad pair: the daemon
#: stops with the error (exit 1) and systemd restarts it, the model loaded afresh.
MAX_FAILED_RUNS = 30

#: Opens in a row that fail on a camera delivering a size not its rig camera's (each camera the same one), before
#: the cameras of this rig.url ever delivered the rig's size: a rig file that does not fit (calibrated at another
#: resolution), which no retry fixes. The daemon stops (exit 2) instead of waiting for ever; one or two such opens
#: are retried, for a webcam that comes up in another mode before it takes the size asked of it.
SIZE_MISMATCH_OPENS = 3


def size_mismatch_fault(rig_url: str) -> str:
    """What cameras that never delivered the rig's size on ``SIZE_MISMATCH_OPENS`` opens of ``rig_url`` blame (the
    daemon's stop, ``--measure-floor``'s): without ``rig=`` (``depthai://`` on the device's calibration, at the
    ``width=``/``height=`` asked) no rig file is at fault, the size asked is one the cameras do not deliver; a
    ``replay://`` take carries its rig in its manifest, and no file of it changes size."""
    url = RigUrl.parse(rig_url)
    if url.scheme == "replay":
        return "a take whose images are not the size of the rig in its manifest"
    return "a rig file that does not fit them" if url.options.get("rig") else "a size asked that they do not deliver"


class DaemonStartError(FirmwareHostError):
    """The daemon cannot start and retrying will not help (a model that does not load, a bad sink URL)."""


def _worker_refused(sink: Sink, error: RuntimeError) -> str:
    """Why ``sink`` is refused when its worker thread would not start (``Thread.start``: a task limit), at a rig's
    open as at a reload: its URL, then Python's reason."""
    return f"{sink.shown}: cannot start its worker: {error}"


def check_sink_urls(urls: Sequence[str], **sink_kwargs: Any) -> None:
    """Build (not start: nothing is opened) the sink of every URL, the rig's camera names stood in for.

    :raises DaemonConfigError: keyed ``sinks[k]``: a bad URL, or one naming ``cameras=`` (the daemon
        announces the rig's own).
    """
    for k, url in enumerate(urls):
        try:  # parse_url first: a URL it refuses (a key given twice) must not leave as a traceback
            if "cameras" in parse_url(url).query:
                raise DaemonConfigError("the daemon announces the rig's camera names itself; remove cameras= from "
                                        "the URL", key=f"sinks[{k}]")
            check_sink_url(url, **{**sink_kwargs, "cameras": STAND_IN_CAMERAS})
        except DaemonConfigError:
            raise
        except (FirmwareHostError, ValueError) as e:
            raise DaemonConfigError(str(e), key=f"sinks[{k}]") from None


def load_model(config: DaemonConfig) -> "ModelSession":
    """The :class:`~ghnerf_runtime.session.ModelSession` the start loads for ``config.estimator``: the graphs its
    settings run, each checked against the model contract (and ``session.expected_resolution`` /
    ``expected_variant``), warmed up when ``session.warmup`` is on.

    :raises DaemonConfigError: keyed ``estimator.session``, naming the folder and the file that did not load.
    """
    try:
        return load_session(config.estimator)
    except ModelError as e:
        raise DaemonConfigError(f"cannot load the model in {config.estimator.session.model_dir}: {e}",
                                key="estimator.session") from None


def check_estimator(session: "ModelSession", config: DaemonConfig) -> None:
    """Build the estimator of ``config.estimator`` once on ``session`` for a stand-in rig, and close it: settings the
    model cannot serve (``heatmaps.source`` 'encoder' with a model without encoder heatmaps) are refused here.
    What depends on the real rig's calibration is checked only when it opens.

    :raises DaemonConfigError: keyed ``estimator``, naming the model folder and the setting.
    """
    try:
        Estimator(session, _stand_in_rig(), config.estimator).close()
    except (RuntimeErrorBase, ValueError) as e:  # ModelError, ConfigError: as the reload's check
        raise DaemonConfigError(f"the settings do not fit the model in {config.estimator.session.model_dir}: {e}",
                                key="estimator") from None


def _claim_status_file(path: Optional[str], error: type[Exception]) -> StatusFileClaim:
    """This daemon's claim on ``path`` (an empty claim for no status file).

    :raises error: (DaemonStartError at start, DaemonConfigError keyed ``health.status_file`` at a reload)
        another daemon writes it.
    """
    if not path:
        return StatusFileClaim("", None)
    try:
        return StatusFileClaim.take(path)
    except StatusFileTaken as e:
        if error is DaemonConfigError:
            raise DaemonConfigError(str(e), key="health.status_file") from None
        raise error(f"health.status_file: {e}") from None


class Daemon:
    """Run :class:`DaemonConfig` until ``stop`` is set; see the module docstring.

    ``rig_kwargs`` go to :func:`drivers.create_rig_source` (tests pass a clock), ``sink_kwargs`` to
    every :func:`firmware_host.sinks.open_sink` (tests pass a fast backoff); ``notifier`` defaults
    to systemd's socket from the environment. ``reload_config`` reads and checks the config file again
    for :meth:`request_reload` (raising :class:`DaemonConfigError`), and ``on_reload`` receives each
    config it accepted (the CLI sets the log level from it).
    """

    def __init__(self, config: DaemonConfig, *, notifier: Optional[SystemdNotifier] = None,
                 rig_kwargs: Optional[dict[str, Any]] = None, sink_kwargs: Optional[dict[str, Any]] = None,
                 clock: Callable[[], float] = time.monotonic,
                 reload_config: Optional[Callable[[], DaemonConfig]] = None,
                 on_reload: Optional[Callable[[DaemonConfig], None]] = None) -> None:
        self.config = config
        self.notifier = notifier if notifier is not None else SystemdNotifier()
        self.health = Health(clock=clock, rig_url=redact_url(config.rig.url))
        self.health.calibration.configure(config.health.calibration_window, config.health.calibration_max_px)
        self.health.floor.configure(config.health.calibration_window, config.health.calibration_max_floor_m)
        self.health.handedness.configure(config.health.calibration_window, config.health.calibration_max_mirror)
        # Woken often enough to flag a stuck estimate within about half of slow_estimate_s.
        self.watchdog = HangWatchdog(self.notifier, config.health.loop_allowance_s, clock=clock,
                                     interval_s=min(config.health.slow_estimate_s / 2, 1.0),
                                     on_tick=self._on_watchdog_tick)
        self._clock = clock
        self._rig_kwargs = dict(rig_kwargs or {})
        # The rig warnings already in the journal for this rig.url: each reopen after a lost camera logged them
        # again. A reload to another rig.url empties it, so a rig returned to is warned of again (_reload_checked).
        self._rig_warnings_logged: set[str] = set()
        self._sink_kwargs = dict(sink_kwargs or {})
        self._session: Any = None
        self._estimator: Optional[Estimator] = None
        self._rig_text: Optional[str] = None
        self._sinks: dict[str, Sink] = {}
        # Which usb:// sink holds which board's interface: a board named by serial= in one URL and port= in
        # another, plugged in after the config check, is named to the second sink, not met as EBUSY for ever.
        self._usb_claims = UsbClaims()
        self._sinks_for: Optional[tuple[str, tuple[str, ...]]] = None  # (rig_id, camera names)
        self._backoff_s = config.rig.reopen_min_s
        self._steady = False  # the open rig has delivered pairs for rig.stall_s (the backoff was reset)
        # The cameras of this rig.url have delivered the rig's size (a pair was read): a wrong size after that is a
        # camera that changed mode, retried; before it, a rig file that does not fit them. Not set by an open that
        # passed: depthai:// opens before its first frames, and checks their size as they are read.
        self._size_fitted = False
        # Opens in a row failed so, and each camera's (rig size, size) in them (either camera may be the one named)
        self._size_mismatches: tuple[dict[str, tuple], int] = ({}, 0)
        self._next_status = 0.0
        self._fault = int(Fault.OK)
        self._calibration_sent = False  # what the sinks' STATUS says of the calibration (CALIBRATION_SUSPECT)
        self._fault_lock = threading.RLock()  # the watchdog's thread flags a stuck estimate too
        self._dropped_closed = 0  # pairs the driver skipped, summed over rigs already closed
        # The wire's seq: one numbering for the daemon's life, through rig reopens (whose pair numbers start
        # at 0 again), reloads and reopened sinks, so a receiver's gap means lost after the daemon.
        self._frame_numbers = FrameNumbers()
        self._status_file_failing = False
        self._status_claim: Optional[StatusFileClaim] = None  # held while running: one status file, one daemon
        self._closed_sink_stats: dict[str, Any] = {}  # the last counters of sinks already closed
        self._carried_gaps: dict[str, int] = {}  # gap flags a closed sink could not report, by URL
        self._carried_totals: dict[str, tuple[int, int]] = {}  # (dropped, decimated) of closed sinks, by URL
        self._reload_config = reload_config
        self._on_reload = on_reload
        # A plain flag, not an Event: set from a signal handler, which must never wait on a lock the
        # interrupted main thread may hold.
        self._reload_requested = False
        self._reload_loaded_model = False  # the reload under way loaded a model (freed again if it is refused)
        self._reopen_rig = False  # a reload changed rig.url: close the open rig and open the new one
        # Closed rigs still inside a device call (RigSource.lingering), with when they were closed; the
        # watchdog's thread checks them, the main loop adds them.
        self._lingering: list[tuple[drivers.RigSource, float]] = []
        self._lingering_lock = threading.Lock()

    def request_reload(self) -> None:
        """Ask the main loop to reload the config at its next pass (safe from a signal handler)."""
        self._reload_requested = True

    # ------------------------------------------------------------------ run
    def run(self, stop: threading.Event) -> int:
        """The main loop; returns the exit status (0). :raises DaemonStartError: cannot start."""
        # First: a status file another daemon writes must not get this one's reports, nor its last "stopping"
        self._status_claim = _claim_status_file(self.config.health.status_file, DaemonStartError)
        try:
            return self._run_claimed(stop)
        finally:
            self._status_claim.release()

    def _run_claimed(self, stop: threading.Event) -> int:
        try:
            if not stop.is_set():  # a stop during the imports or the config read: no model loaded for nothing
                self._load_model()
                self._check_estimator()
                self._check_sinks()
        except Exception as e:
            self._report_unstarted(f"stopped by {type(e).__name__}: {e}")
            raise
        if stop.is_set():  # SIGTERM before or while the model loaded: never report ready
            self.notifier.notify(stopping=1)
            self._report_unstarted(None)
            return 0
        self.watchdog.start()
        self.notifier.notify(ready=1, status="started: opening the rig", mainpid=os.getpid())
        _log.info("started: rig %s, sinks %s", redact_url(self.config.rig.url),
                  ", ".join(redact_url(url) for url in self.config.sinks))  # the journal keeps no password
        try:
            while not stop.is_set():
                source = self._open_rig(stop)
                if source is None:
                    break
                self._steady = False  # set by _stream once pairs have flowed for rig.stall_s
                read_before = self.health.pairs_read
                try:
                    ended = self._stream(source, stop)
                finally:
                    self._close_rig(source)
                if self._reopen_rig:  # the reloaded config names another rig: open it now
                    self._reopen_rig = False
                    self._backoff_s = self.config.rig.reopen_min_s
                    continue
                if ended and self.config.rig.exit_at_end:
                    _log.info("the rig's stream ended (rig.exit_at_end): stopping")
                    break
                if (not self._steady and not ended) or self.health.pairs_read == read_before:
                    # Lost before pairs had flowed for rig.stall_s (a flapping device, up for a pair or two):
                    # back off as after a failed open. A pair alone reset the backoff: a device lost right after
                    # each open was reopened at once, for ever, with two log lines each time.
                    if self._wait(stop, self._backoff_s):
                        self._backoff_s = min(self._backoff_s * 2, self.config.rig.reopen_max_s)
        except Exception as e:
            # What stopped it stays in the status file, which outlives the process (the traceback: the journal).
            self.health.last_error = f"stopped by {type(e).__name__}: {e}"
            raise
        finally:
            self._shutdown()
        return 0

    def _report_unstarted(self, why: Optional[str]) -> None:
        """The status file of a start that ended before the loop (``why``: the error, None for a stop): it outlives
        the process (RuntimeDirectoryPreserve=yes), and left unwritten it showed the previous run's report, its pid
        and state, as if that one had been the last."""
        self.health.last_error = why
        self.health.enter(State.STOPPING)
        self._tick(force=True, tell_systemd=False)

    # ------------------------------------------------------------------ model
    def _load_model(self) -> None:
        # Before the first model's blocks are allocated: so that they, and every reload's, are mapped and go
        # back to the system when freed (firmware_host.daemon.memory)
        pin_mmap_threshold()
        t0 = time.monotonic()
        try:
            self._session = load_model(self.config)
        except DaemonConfigError as e:
            raise DaemonStartError(str(e)) from None
        _log.info("model %s loaded in %.2f s", self.config.estimator.session.model_dir, time.monotonic() - t0)

    def _check_estimator(self) -> None:
        """Build the estimator once for a stand-in rig, as a reload does: settings the loaded model cannot serve
        (``heatmaps.source`` 'encoder' with a model that has no encoder heatmaps) stop the start here, before
        READY. Built only once the rig opened, such a config exited 2 when the camera came, or waited for ever for
        one that never did. What depends on the real rig is still checked when it opens (:meth:`_estimator_for`).
        ``--validate-config`` runs the same check (:func:`check_estimator`)."""
        try:
            check_estimator(self._session, self.config)
        except DaemonConfigError as e:
            raise DaemonStartError(str(e)) from None

    def _estimator_for(self, rig: Rig) -> Estimator:
        """The estimator of ``rig``: kept across reopens of the same rig, rebuilt for another one."""
        text = dumps_rig(rig)
        if self._estimator is None or text != self._rig_text:
            if self._estimator is not None:
                _log.warning("rig %s has another calibration than the estimator's: estimator rebuilt", rig.rig_id)
                self._estimator.close()
            try:
                # quiet: the settings check of this config (the start's, or the reload's) logged how its
                # settings resolve against the model; the rig's estimator would say it a second time
                self._estimator = Estimator(self._session, rig, self.config.estimator, log_settings=False)
            except (RuntimeErrorBase, ValueError) as e:  # ModelError, a rig the runtime cannot use
                raise DaemonStartError(f"the model does not fit rig {rig.rig_id!r}: {e}") from None
            self._rig_text = text
            self._reset_calibration()  # the pairs of another calibration say nothing of this one
        else:
            self._estimator.reset()  # the subject may have moved while the camera was away
        return self._estimator

    # ------------------------------------------------------------------ rig
    def _open_rig(self, stop: threading.Event) -> Optional[drivers.RigSource]:
        """Open the rig, retrying with backoff until it opens or ``stop`` is set (then None). A stop during an open
        does not wait for it (an OAK's may take longer than systemd's TimeoutStopSec): :func:`open_unless_stopped`."""
        while not stop.is_set():
            self._maybe_reload(None)  # nothing is open: this attempt opens the reloaded rig.url
            rig_cfg = self.config.rig
            self.health.rig_url = redact_url(rig_cfg.url)  # shown (status file, logs): no password
            self.health.enter(State.OPENING)
            self._set_fault(Fault.CAMERA_FAULT)
            self._tick(force=True)
            source = None
            try:
                with self.watchdog.allow(self.config.health.open_allowance_s, "opening the rig"):
                    source = drivers.create_rig_source(rig_cfg.url, **self._rig_kwargs)
                    source.log_rig_warnings_once(self._rig_warnings_logged)
                    if not open_unless_stopped(source, stop):
                        _log.info("stopped while the rig was opening: not waiting for the open")
                        return None  # (closed by open_unless_stopped, which cancels the open)
                    if stop.is_set():  # opened just as the stop came: no estimator or sinks built for it
                        self._close_rig(source)
                        return None
                    self._estimator_for(source.rig)
                    self._open_sinks(source.rig)
            except (drivers.RigConfigError, drivers.BackendNotAvailableError) as e:
                self._close_rig(source)
                raise DaemonStartError(f"rig.url {self.health.rig_url!r}: {e}") from None
            except drivers.DriverError as e:
                self._close_rig(source)
                self.health.rig_open_failures += 1
                self._check_size_mismatch(e)
                self.health.last_error = f"cannot open {self.health.rig_url}: {e}{rig_url_hint(rig_cfg.url)}"
                self.health.enter(State.WAITING)
                _log.warning("%s; retrying in %.1f s", self.health.last_error, self._backoff_s)
                if self._wait(stop, self._backoff_s):  # not cut short by a new rig section
                    self._backoff_s = min(self._backoff_s * 2, self.config.rig.reopen_max_s)
                continue
            except BaseException:
                self._close_rig(source)
                raise
            self.health.rig_opens += 1
            self.health.cameras = tuple(c.name for c in source.rig.pair)
            _log.info("rig open: cameras %s, baseline %.3f m", list(self.health.cameras), source.rig.baseline)
            return source
        return None

    def _check_size_mismatch(self, error: drivers.DriverError) -> None:
        """After an open failed with ``error``: ``SIZE_MISMATCH_OPENS`` opens in a row failed on a camera delivering
        another size than its rig camera's (the same size each time for each camera; which camera the driver names
        first is a race), before this rig.url's cameras ever delivered the rig's size, is a rig file that does not
        fit them, which no retry fixes: the start's error (exit 2), not a wait for ever. Cameras that delivered the
        rig's size once (a pair was read) and then another (a webcam renegotiating) are retried as before. Also
        called by :meth:`_stream` for a first read failing so (``depthai://`` checks sizes as frames are read).

        :raises DaemonStartError: naming the rig URL (its rig file), the camera, both sizes and what to do.
        """
        if self._size_fitted or not isinstance(error, drivers.FrameSizeError):
            self._size_mismatches = ({}, 0)
            return
        sizes, count = self._size_mismatches
        seen = (error.expected, error.delivered)
        if sizes.get(error.camera, seen) != seen:  # this camera came with another size: not one fixed mismatch
            sizes, count = {}, 0
        sizes, count = {**sizes, error.camera: seen}, count + 1
        self._size_mismatches = (sizes, count)
        if count >= SIZE_MISMATCH_OPENS:
            raise DaemonStartError(
                f"rig.url {self.health.rig_url!r}: {error} (the same on {count} opens in a row, the cameras never "
                f"having delivered the rig's size: {size_mismatch_fault(self.config.rig.url)}, which no restart fixes)"
            ) from None

    def _close_rig(self, source: Optional[drivers.RigSource]) -> None:
        if source is None:
            return
        try:
            self._dropped_closed += source.stats.pairs_dropped
            self.health.pairs_dropped = self._dropped_closed
        except Exception:  # noqa: BLE001 - counters of a dead device: not worth failing over
            pass
        try:
            source.close()
        except Exception as e:  # noqa: BLE001 - a vanished device may fail its close too; it is gone either
            _log.warning("closing the rig: %s", e)  # way, and raising here would hide why it was closed
        if _lingering(source):
            with self._lingering_lock:
                self._lingering.append((source, self._clock()))

    def _check_lingering(self) -> None:
        """From the watchdog's thread: a closed rig still inside a device call ``health.open_allowance_s`` (what
        an open may take) after its close holds the device for good: every reopen fails, the loop beats on,
        and only a new process frees it. So the pings stop (systemd restarts the service)."""
        with self._lingering_lock:
            self._lingering = [(source, since) for source, since in self._lingering if _lingering(source)]
            oldest = self._lingering[0] if self._lingering else None
        if oldest is None or self.watchdog.wedged is not None:
            return
        source, since = oldest
        age = self._clock() - since
        if age > self.config.health.open_allowance_s:
            why = (f"{', '.join(_lingering(source))} still in a device call {age:.0f} s after the rig was closed "
                   f"(health.open_allowance_s {self.config.health.open_allowance_s:g}): it holds the device, "
                   f"which only a new process frees")
            self.health.last_error = why
            self.watchdog.wedge(why)

    def _stream(self, source: drivers.RigSource, stop: threading.Event) -> bool:
        """Read and estimate pairs until the rig is lost (False) or ends (True) or ``stop`` is set (False)."""
        self.health.enter(State.RUNNING)
        last_pair = opened_at = self._clock()
        stats_at_pair = source.stats  # what came since: why no pair formed, when none does for rig.stall_s
        read_failed = False  # the last read raised a RigOperationError and no pair came since
        failed_runs = 0  # pairs in a row the model failed on (ModelRunError)
        while not stop.is_set():
            if "rig.url" in self._maybe_reload(source.rig):
                self._reopen_rig = True  # run() closes this rig and opens the new rig.url
                return False
            rig_cfg = self.config.rig  # a reload may have changed its timeouts
            self.watchdog.beat("reading a pair")
            self._tick()
            try:
                pair = source.read(timeout_s=rig_cfg.read_timeout_s)
            except drivers.EndOfStream as e:
                self.health.last_error = f"{self.health.rig_url}: {e}"
                return True
            except drivers.RigTimeoutError:
                self._set_fault(Fault.CAMERA_FAULT)
                silent = self._clock() - last_pair
                if silent >= rig_cfg.stall_s:
                    why = drivers.why_no_pair(stats_at_pair, source.stats, source.pairing)
                    self._lost(f"no pair for {silent:.1f} s (rig.stall_s {rig_cfg.stall_s:g}), {why}: reopening "
                               f"the rig")
                    return False
                continue
            except drivers.RigDisconnectedError as e:  # unplugged, device reset
                self._lost(f"the rig failed: {e}")
                return False
            except drivers.RigOperationError as e:
                if isinstance(e, drivers.FrameSizeError) and not self._size_fitted:
                    # a first frame of another size than the rig's (depthai:// checks them as they are read, after
                    # its open): as an open failing on it, counted towards SIZE_MISMATCH_OPENS. Lost first, so that
                    # the status file's rig.lost counts the last of them too, as rig.open_failures does opencv://'s
                    self._lost(f"the rig failed: {e}", size_counted=True)
                    self._check_size_mismatch(e)
                    return False
                # A frame the backend could not deliver (a corrupt image in a recording, a malformed device
                # message) is raised once and the next read goes on (RigSource.read): reopening for it played a
                # replay:// from its start again, for ever. Raised again before a pair: the rig itself failed.
                if read_failed:
                    self._lost(f"the rig failed: {e}")
                    return False
                read_failed = True
                self.health.read_errors += 1
                self.health.last_error = f"{self.health.rig_url}: a read failed: {e}"
                if self.health.read_errors == 1 or self.health.read_errors % 100 == 0:
                    _log.warning("%s (%d so far); reading on", self.health.last_error, self.health.read_errors)
                continue
            except drivers.DriverError as e:  # a failed driver thread
                self._lost(f"the rig failed: {e}")
                return False
            read_failed = False
            if not self._size_fitted:  # the cameras deliver the rig's size: a wrong one later is retried
                self._size_fitted, self._size_mismatches = True, ({}, 0)
            last_pair = self._clock()
            stats_at_pair = source.stats
            self.health.pairs_read += 1
            self.health.pairs_dropped = self._dropped_closed + source.stats.pairs_dropped
            if not self._steady and last_pair - opened_at >= rig_cfg.stall_s:
                self._steady = True  # pairs flow, and have for a while: the next loss retries quickly
                self._backoff_s = rig_cfg.reopen_min_s
            self.watchdog.beat("estimating a pair")
            t0 = self._clock()
            # self._estimator, as a reload may have replaced it, and never kept in a local: one held across the
            # loop kept the replaced estimator, and through it the old model's sessions, alive through the
            # reload's trim (return_freed_memory), which then could not hand their pages back
            assert self._estimator is not None
            try:
                capture_time_us(pair)  # one the stream cannot carry is refused before the model runs on it
                result = self._estimator.estimate(pair.images, sequence=pair.sequence,
                                                  timestamp_s=pair.timestamps_ns[0] * 1e-9)
            except (FrameError, CaptureTimeError, ModelRunError) as e:
                # One pair onnxruntime fails on is skipped like a rejected one; it took the daemon down (exit 1,
                # a restart: the model loaded again, the seqs from 0), with nothing in the status file to say why.
                # So did a capture time before the clock's zero (a replay's keep_time=1 of such a take).
                failed_runs = failed_runs + 1 if isinstance(e, ModelRunError) else 0
                self.health.estimate_errors += 1
                self.health.last_error = f"pair {pair.sequence}: the model failed: {e}" \
                    if isinstance(e, ModelRunError) else f"pair {pair.sequence} rejected: {e}"
                if failed_runs >= MAX_FAILED_RUNS:
                    _log.error("the model failed on %d pairs in a row: stopping, for a restart", failed_runs)
                    raise
                if self.health.estimate_errors == 1 or self.health.estimate_errors % 100 == 0 or failed_runs == 1:
                    _log.warning("%s (%d so far)", self.health.last_error, self.health.estimate_errors)
                continue
            failed_runs = 0
            took = self._clock() - t0
            self.watchdog.beat("handing the joints to the sinks")
            self.health.estimated(result.timing_ms["total"], float(np.mean(~np.asarray(result.missing, bool))),
                                  scene_flags_of(result), result.someone_else)
            self.health.frames_checked(result.frame_reason)
            health = self.health
            self._check_changed(_PX_WORDS, health.calibration, health.calibration.add(result.reprojection_px_median))
            self._check_changed(_FLOOR_WORDS, health.floor, health.floor.add(result.lowest_foot_m))
            self._check_changed(_HANDEDNESS_WORDS, health.handedness, health.handedness.add(result.handedness))
            self._sync_calibration()
            self.health.estimator_stalled = took > self.config.health.slow_estimate_s
            self.health.camera_fault = False
            self._set_fault(Fault.ESTIMATOR_STALLED if self.health.estimator_stalled else Fault.OK)
            frame = estimate_frame(pair, result, sequence=self._frame_numbers.take(),
                                   calibration_suspect=self.health.calibration_suspect)
            for sink in self._sinks.values():
                sink.send(frame)
        return False

    def _check_changed(self, words: _CheckWords, watch: _Watch, suspect: Optional[bool]) -> None:
        """Log a calibration check's verdict when it changes (not every pair: the status file has the figure):
        ``suspect`` is ``watch``'s answer to the pair or the reload, said in ``words``."""
        if suspect:
            _log.warning("calibration suspect: %s: %s", words.symptom.format_map(_figures(watch)), words.fix)
        elif suspect is not None and watch.limit is None:
            _log.info("%s off (%s null)", words.check, words.setting)
        elif suspect is not None:
            _log.info("%s", words.fits_again.format_map(_figures(watch)))

    def _reset_calibration(self) -> None:
        """The calibration checks start afresh (another calibration, model or settings), and the sinks hear it."""
        self.health.calibration.reset()
        self.health.floor.reset()
        self.health.handedness.reset()
        self._sync_calibration()

    def _lost(self, why: str, *, size_counted: bool = False) -> None:
        """The open rig failed (``why``); ``size_counted``: on a frame size, counted by :meth:`_check_size_mismatch`."""
        if not self._size_fitted and not size_counted:  # lost for another reason: the opens in a row start again
            self._size_mismatches = ({}, 0)
        self.health.rig_lost += 1
        self.health.last_error = why
        self.health.enter(State.WAITING)
        self._set_fault(Fault.CAMERA_FAULT)
        _log.warning(why)

    # ------------------------------------------------------------------ sinks
    @property
    def sinks(self) -> dict[str, Sink]:
        """The open sinks by URL (opened once the rig's camera names are known)."""
        return dict(self._sinks)

    def _check_sinks(self) -> None:
        """A bad sink URL stops the start instead of waiting for a rig (:func:`check_sink_urls`)."""
        try:
            check_sink_urls(self.config.sinks, **self._sink_kwargs)
        except DaemonConfigError as e:
            raise DaemonStartError(str(e)) from None

    def _open_sinks(self, rig: Rig) -> None:
        """Open every sink for this rig's id and camera names (reopened only when either changes; after a
        reload with the same rig, only the sinks added are opened and those removed closed).

        :raises DaemonStartError: a sink does not fit this rig's id or camera names, or its worker thread would not
            start (``sinks[k]``, naming its URL); every sink is closed first, those started before it too.
        """
        key = (rig.rig_id, tuple(c.name for c in rig.pair))
        with self._fault_lock:
            if key != self._sinks_for:
                self._close_sinks()
            for url in [u for u in self._sinks if u not in self.config.sinks]:
                self._close_sink(url)
            for k, url in enumerate(self.config.sinks):
                if url in self._sinks:
                    continue
                try:
                    sink = self._build_sink(url, key, self.config)
                except FirmwareHostError as e:
                    self._close_sinks()
                    raise DaemonStartError(f"sinks: {e}") from None
                try:
                    self._start_sink(url, sink)
                except RuntimeError as e:  # no thread to be had (a task limit): a stop (exit 2), not a traceback
                    sink.close()
                    self._close_sinks()
                    raise DaemonStartError(f"sinks[{k}]: {_worker_refused(sink, e)}") from None
            self._sinks_for = key

    def _build_sink(self, url: str, key: tuple[str, tuple[str, ...]], config: DaemonConfig) -> Sink:
        """The sink of ``url`` for a rig's (id, camera names), built but not started (it holds nothing yet), its
        HELLO announcing the scene flags the estimator of ``config`` sets."""
        kw = dict(self._sink_kwargs)
        kw["cameras"] = key[1]  # 2D joints are keyed by index in rig.pair order
        kw["scene_flags"] = announced_scene_flags(config.estimator)
        parsed = parse_url(url)
        if "rig_id" not in parsed.query:
            kw["rig_id"] = key[0]
        if parsed.scheme == "usb":
            kw["claims"] = self._usb_claims
        sink = sink_class(url).from_url(url, **kw)  # type: ignore[attr-defined]
        carried = self._carried_gaps.get(url, 0)  # dropped from the dict once the sink starts (_place_sink)
        if carried:  # frames the sink it replaces lost at close: its first frame says so, not a silent gap
            sink.carry_gap(carried)
        if url in self._carried_totals and hasattr(sink, "carry_totals"):  # STATUS totals go on, not from zero
            sink.carry_totals(*self._carried_totals[url])
        last = self._frame_numbers.last
        if last is not None and hasattr(sink, "carry_seq"):  # its HELLO and STATUS: the numbering runs on
            sink.carry_seq(last)
        self._apply_fault(sink)  # before start: its first STATUS already carries the fault
        return sink

    def _start_sink(self, url: str, sink: Sink) -> None:
        """Start a sink built by :meth:`_build_sink` and make it the daemon's (:meth:`_place_sink`)."""
        self._place_sink(url, sink.start())

    def _place_sink(self, url: str, sink: Sink) -> None:
        """``sink``, started, made the daemon's for ``url``: only now has the gap it carries been handed on (a build
        thrown away, by a refused reload, leaves the gap for the next one)."""
        self._sinks[url] = sink
        self._carried_gaps.pop(url, None)

    def _close_sink(self, url: str) -> None:
        sink = self._sinks.pop(url)
        try:
            sink.close()
            self._closed_sink_stats[url] = stats = self._stats_of(sink)
            d, k = self._carried_totals.get(url, (0, 0))
            self._carried_totals[url] = (d + stats["dropped"], k + stats["decimated"])
            gap = sink.pending_gap_flags()
        except Exception as e:  # noqa: BLE001 - a link that fails even to close (a USB error): it is gone
            _log.warning("closing sink %s: %s", redact_url(url), e)
            gap = int(Flags.DROPPED)  # what it still held is unknown: assume lost
        if gap:  # passed on to the next sink of this URL (_build_sink)
            self._carried_gaps[url] = self._carried_gaps.get(url, 0) | gap

    def _close_sinks(self) -> None:
        with self._fault_lock:
            for url in list(self._sinks):
                self._close_sink(url)
            self._sinks_for = None

    # ------------------------------------------------------------------ reload
    def _maybe_reload(self, rig: Optional[Rig]) -> list[str]:
        """Apply a requested reload; ``rig`` is the open rig (None: none). Returns what changed (``_reload``);
        empty when nothing was requested, nothing changed or the reload was refused."""
        if not self._reload_requested:
            return []
        self._reload_requested = False
        _log.info("reloading the config")
        self.notifier.notify(reloading=1, monotonic_usec=time.monotonic_ns() // 1000, status="reloading the config")
        self._reload_loaded_model = False
        try:
            with self.watchdog.allow(self.config.health.open_allowance_s, "reloading the config"):
                changed = self._reload(rig)
        except Exception as e:  # noqa: BLE001 - whatever a reload hits, the running service must not die of it
            self.health.reload_failures += 1
            self.health.reload_error = f"reload refused: {e}"  # (last_error keeps the rig's or estimator's)
            _log.error("%s; running on with the config loaded before", self.health.reload_error,
                       exc_info=not isinstance(e, DaemonConfigError))  # a bug's traceback, not a bad file's
            self.notifier.notify(ready=1, status=self.health.status_line(self.sink_stats()))
            changed = None
        if changed is None:
            # Here, not in the except: its traceback's frames held the refused model's session until it ended.
            if self._reload_loaded_model:  # as an accepted reload that replaced the model hands the old one's back
                return_freed_memory()
            return []
        self.health.reloads += 1
        self.health.reload_error = None
        _log.info("config reloaded: %s", ", ".join(changed) or "nothing changed")
        if _log.isEnabledFor(logging.DEBUG):
            _log.debug("the config now: %s", json.dumps(config_to_dict(self.config), sort_keys=True))
        self.notifier.notify(ready=1, status=self.health.status_line(self.sink_stats()))
        return changed

    def _reload(self, rig: Optional[Rig]) -> list[str]:
        """Read, check and apply the config file again; returns the parts that changed (``_PARTS``).

        Everything that can fail is done first, while nothing of the running daemon has changed: the
        file and its checks, the claim on a new status file (another daemon may write it), the rig URL, the model
        (loaded again only when the session's settings or graphs change) and the new estimator, built for the open
        rig, else the rig the estimator was last built for, else a stand-in; the added sinks, built for the rig's
        id and camera names when one has been open and started held (their workers running, nothing opened: the
        swap releases them once the removed sinks have let go of their ports). The swap after that cannot fail, so
        a refusal leaves the daemon as it was.

        :raises DaemonConfigError: the reload is refused.
        """
        if self._reload_config is None:
            raise DaemonConfigError("this daemon was started without a config file to read again")
        old, new = self.config, self._reload_config()
        check_sink_urls(new.sinks, **self._sink_kwargs)
        changed = [name for name in _PARTS if _part(old, name) != _part(new, name)]
        claim = None
        if not names_one_file(old.health.status_file, new.health.status_file):  # (this daemon holds that one)
            claim = _claim_status_file(new.health.status_file, DaemonConfigError)
        try:
            return self._reload_checked(rig, old, new, changed, claim)
        except BaseException:
            if claim is not None:
                claim.release()
            raise

    def _reload_checked(self, rig: Optional[Rig], old: DaemonConfig, new: DaemonConfig, changed: list[str],
                        claim: Optional[StatusFileClaim]) -> list[str]:
        """The rest of :meth:`_reload`, with the claim on a new status file taken (``claim``; None: the same)."""
        if "rig.url" in changed:
            try:
                drivers.create_rig_source(new.rig.url, **self._rig_kwargs)  # parses the URL; opens nothing
            except (drivers.RigConfigError, drivers.BackendNotAvailableError) as e:
                raise DaemonConfigError(str(e), key="rig.url") from None
            except drivers.DriverError:
                pass  # a device or recording not there yet: waited for, as at start
        session, estimator = self._session, self._estimator
        if "estimator" in changed:
            # Built now, so a model or settings that do not fit are refused, not found when a rig opens: for
            # the open rig, or the one it last ran on; with none (or another rig.url) for a stand-in rig, as
            # what the settings need of the model does not depend on the rig.
            fit = rig if rig is not None else (self._estimator.rig if self._estimator is not None else None)
            keep = fit is not None and "rig.url" not in changed
            allowance = max(old.health.open_allowance_s, new.health.open_allowance_s)
            try:
                with self.watchdog.allow(allowance, "loading the model for a reload"):
                    if _session_key(new) != _session_key(old):
                        session = load_session(new.estimator)
                        self._reload_loaded_model = True  # a refusal from here on frees it: _maybe_reload trims
                    estimator = Estimator(session, fit if keep else _stand_in_rig(), new.estimator)
            except (RuntimeErrorBase, ValueError) as e:  # ModelError, a rig the new settings cannot use
                raise DaemonConfigError(f"does not load: {e}", key="estimator") from None
            if not keep:
                estimator.close()
                estimator = None  # built for the rig when it opens
        try:
            added = self._added_sinks(new, changed)
        except BaseException:
            if estimator is not None and estimator is not self._estimator:  # the new one's worker thread, stopped
                estimator.close()
            raise
        try:
            self._swap(new, changed, session, estimator, added, claim)
        except BaseException:  # (nothing there should raise) a held sink left so would wait for ever, frames queued
            self._settle_added_sinks(added)
            raise
        if self._on_reload is not None:
            try:
                self._on_reload(new)
            except Exception:  # noqa: BLE001 - the reload is applied; a failing hook must not undo or hide it
                _log.exception("after the reload")
        return changed

    def _swap(self, new: DaemonConfig, changed: list[str], session: Any, estimator: Optional[Estimator],
              added: dict[str, Sink], claim: Optional[StatusFileClaim]) -> None:
        """The accepted reload of :meth:`_reload_checked`, put in force touching only what changed: nothing here
        should raise (what could fail was done before). ``session`` and ``estimator``: the model and estimator of
        ``new`` (the running ones when its estimator section did not change); ``added``: the sinks it adds, started
        held (released here); ``claim``: the claim on a new status file (None: the same file)."""
        old_status_file = self.config.health.status_file
        self.config = new
        if "rig.url" in changed:
            # The journal's last warnings are another rig's now: the rig returned to warns again, once
            self._rig_warnings_logged = set()
        if "estimator" in changed:  # (then ``estimator`` is a new one, or None)
            if self._estimator is not None:
                self._estimator.close()
            replaced = session is not self._session
            self._session, self._estimator = session, estimator  # None: built when the next rig opens
            self._rig_text = dumps_rig(estimator.rig) if estimator is not None else None
            self._reset_calibration()  # another model or settings: its peaks are judged afresh
            if replaced:  # the old model's sessions are free now: hand their pages back (firmware_host.daemon.memory)
                return_freed_memory()
        with self._fault_lock:
            for url in [u for u in self._sinks if u not in new.sinks]:
                self._close_sink(url)  # at once, rig or not: a removed serial sink frees its port now
            if "estimator" in changed:  # the scan for others turned on or off: SOMEONE_ELSE's meaning with it
                self._announce_scene_flags(announced_scene_flags(new.estimator))
            for url, sink in added.items():  # started held before the swap (_added_sinks): their ports are free now
                self._place_sink(url, sink)
                sink.release()
        if "health" in changed:
            health, window = self.health, new.health.calibration_window
            self._check_changed(_PX_WORDS, health.calibration,
                                health.calibration.configure(window, new.health.calibration_max_px))
            self._check_changed(_FLOOR_WORDS, health.floor,
                                health.floor.configure(window, new.health.calibration_max_floor_m))
            self._check_changed(_HANDEDNESS_WORDS, health.handedness,
                                health.handedness.configure(window, new.health.calibration_max_mirror))
            self._sync_calibration()
            self.watchdog.configure(new.health.loop_allowance_s, interval_s=min(new.health.slow_estimate_s / 2, 1.0))
            self._next_status = 0.0
            if claim is not None:  # the new file is this daemon's now; the old one is no longer written
                if self._status_claim is not None:
                    self._status_claim.release()
                self._status_claim = claim
            if old_status_file and not names_one_file(old_status_file, new.health.status_file):
                # left in place it would read "running" for ever, frozen, to a monitor still watching it
                try:
                    os.unlink(old_status_file)
                except OSError as e:
                    if e.errno != errno.ENOENT:
                        _log.warning("cannot remove the old status file %s: %s", old_status_file, e)
        if "rig.url" in changed:
            self._backoff_s = new.rig.reopen_min_s  # a new rig is tried at once, then from the start of its backoff
            self._size_fitted, self._size_mismatches = False, ({}, 0)  # its cameras and rig file are judged afresh
        elif "rig" in changed:
            self._backoff_s = min(max(self._backoff_s, new.rig.reopen_min_s), new.rig.reopen_max_s)

    def _settle_added_sinks(self, added: dict[str, Sink]) -> None:
        """After a swap that raised: each sink it added and put in place is released (it is the daemon's, closed
        with the others), every other one closed: none is left held, its worker waiting for a release that
        would never come while frames queue in it."""
        with self._fault_lock:
            for url, sink in added.items():
                if self._sinks.get(url) is sink:
                    sink.release()
                else:
                    sink.close()  # a held worker wakes and ends, having opened nothing

    def _added_sinks(self, new: DaemonConfig, changed: list[str]) -> dict[str, Sink]:
        """The sinks ``new`` adds, built for the rig they were last opened for and started held (their workers
        running, opening nothing until the swap releases them: :meth:`Sink.start`); none when the rig URL changed
        (opened with the next rig) or no rig has been open. All are built before any starts; one that fails to build
        or start closes every sink this reload built, before any opened a thing: a refused reload leaves none behind.

        :raises DaemonConfigError: keyed ``sinks[k]``, naming its URL: the real rig id or camera names do not fit
            that sink, or its worker thread would not start.
        """
        added: dict[str, Sink] = {}
        if self._sinks_for is None or "rig.url" in changed:
            return added
        key = {url: f"sinks[{k}]" for k, url in enumerate(new.sinks)}
        try:
            for url in [u for u in new.sinks if u not in self._sinks]:  # all built first: a misfit starts nothing
                try:
                    added[url] = self._build_sink(url, self._sinks_for, new)
                except FirmwareHostError as e:
                    raise DaemonConfigError(str(e), key=key[url]) from None
            for url, sink in added.items():
                try:
                    sink.start(held=True)
                except RuntimeError as e:  # no thread to be had (a task limit): the whole reload waits
                    raise DaemonConfigError(_worker_refused(sink, e), key=key[url]) from None
        except BaseException:
            for sink in added.values():
                sink.close()  # a held worker wakes and ends, having opened nothing
            raise
        return added

    def _set_fault(self, fault: Fault) -> None:
        with self._fault_lock:
            if fault == Fault.CAMERA_FAULT:
                self.health.camera_fault = True
            if int(fault) != self._fault:
                self._fault = int(fault)
                for sink in self._sinks.values():
                    self._apply_fault(sink)

    def _on_watchdog_tick(self, where: str, silent_s: float) -> None:
        """From the watchdog's thread: an estimate still running past ``slow_estimate_s`` is flagged now,
        not only once it returns; a camera stuck past its rig's close stops the pings (:meth:`_check_lingering`)."""
        self._check_lingering()
        if where == "estimating a pair" and silent_s > self.config.health.slow_estimate_s \
                and self._fault != int(Fault.ESTIMATOR_STALLED):
            self.health.estimator_stalled = True
            self._set_fault(Fault.ESTIMATOR_STALLED)

    def _announce_scene_flags(self, flags: int) -> None:
        """Announce ``flags`` in the HELLO of every open sink that sends one (the binary-protocol sinks)."""
        for sink in self._sinks.values():
            announce = getattr(sink, "announce_scene_flags", None)
            if announce is not None:
                announce(flags)

    def _apply_fault(self, sink: Sink) -> None:
        set_fault = getattr(sink, "set_fault", None)  # the binary-protocol sinks carry STATUS
        if set_fault is not None:
            set_fault(self._fault)
        set_suspect = getattr(sink, "set_calibration_suspect", None)
        if set_suspect is not None:
            set_suspect(self._calibration_sent)

    def _sync_calibration(self) -> None:
        """Tell the sinks' STATUS (header flag CALIBRATION_SUSPECT) the calibration check's verdict when it
        changed: a receiver learns it while no frame flows too, not from the status file alone."""
        with self._fault_lock:
            suspect = self.health.calibration_suspect
            if suspect != self._calibration_sent:
                self._calibration_sent = suspect
                for sink in self._sinks.values():
                    self._apply_fault(sink)

    # ------------------------------------------------------------------ health
    @staticmethod
    def _stats_of(sink: Sink) -> dict[str, Any]:
        stats = sink.stats()
        return {**dataclasses.asdict(stats), "dropped": stats.dropped}

    def sink_stats(self) -> dict[str, Any]:
        """Each sink's counters by URL as configured (those closed by a reopen or the shutdown: as they were last):
        the config's sinks first, in its order, then those a reload removed. The report names them in this order
        (``health.sink_keys``: redacted, ``#2`` for a second URL that differs only in its password)."""
        stats = {**self._closed_sink_stats, **{url: self._stats_of(sink) for url, sink in self._sinks.items()}}
        return {**{url: stats[url] for url in self.config.sinks if url in stats}, **stats}

    def _tick(self, force: bool = False, tell_systemd: bool = True) -> None:
        """Refresh the status file and systemd's STATUS line every ``health.status_every_s``."""
        now = self._clock()
        if not force and now < self._next_status:
            return
        self._next_status = now + self.config.health.status_every_s
        if self._status_claim is not None:
            self._status_claim.let_askers_go()  # a refused daemon's question for the pid, answered: its queue freed
        if tell_systemd:
            self.notifier.notify(status=self.health.status_line(self.sink_stats()))
        path = self.config.health.status_file
        if path:
            try:
                write_status_file(path, self.health.report(self.sink_stats()))
                self._status_file_failing = False
            except (OSError, ValueError) as e:
                if not self._status_file_failing:  # once until it works again, not every tick
                    hint = service_hint(path, written=True) or read_only_hint(e)  # worded as the file sink's
                    _log.warning("cannot write the status file %s: %s%s", path, e, hint)
                self._status_file_failing = True

    def _wait(self, stop: threading.Event, seconds: float) -> bool:
        """Sleep ``seconds`` or until stopped, beating the watchdog, refreshing the status and taking a reload;
        a new ``rig`` section ends the wait (the next attempt uses it: False). True: waited it out (or stopped)."""
        deadline = self._clock() + seconds
        while not stop.is_set():
            left = deadline - self._clock()
            if left <= 0:
                return True
            if {"rig.url", "rig"} & set(self._maybe_reload(None)):  # (no rig is open while it waits)
                return False  # another rig or backoff: try it now
            self.watchdog.beat("waiting to reopen the rig")
            self._tick()
            stop.wait(min(left, 0.2))
        return True

    def _shutdown(self) -> None:
        self.health.enter(State.STOPPING)
        self.watchdog.stop()  # stopping is bounded by systemd's TimeoutStopSec, not the watchdog
        self.notifier.notify(stopping=1, status="stopping")
        self._close_sinks()
        if self._estimator is not None:
            self._estimator.close()
        self._tick(force=True, tell_systemd=False)  # the final counters; STOPPING stays systemd's last word
        self.notifier.close()
        _log.info("stopped: %d pairs read, %d estimated, rig opened %d times (%d lost)",
                  self.health.pairs_read, self.health.pairs_estimated, self.health.rig_opens, self.health.rig_lost)
