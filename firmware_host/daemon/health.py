"""The daemon's health: counters kept by the main loop, a JSON report, and its atomic status file.

The report (``docs/daemon.md`` lists the fields) is what an operator reads to tell a pulled camera
from a slow estimator from a dead link: the state, what the rig delivered and what was estimated,
latency, joints found and the pairs of each scene flag over the last window, camera reopen counts with the last error, the frames
the estimator's frame check rejected per camera and reason, whether the rig's calibration still fits
(:mod:`firmware_host.daemon.calibration_watch`), and each sink's counters.
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Optional

import numpy as np

from drivers.url import redact_url, shown_url
from firmware_host.daemon.calibration_watch import CalibrationWatch, FloorWatch, HandednessWatch, fixes, \
    status_words
from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M, CALIBRATION_MAX_MIRROR, CALIBRATION_MAX_PX, \
    CALIBRATION_WINDOW
from ghnerf_runtime.frame_reasons import REASONS
from ghnerf_runtime.rig_file import write_bytes_into

__all__ = ["SCENE_FLAGS", "State", "Health", "scene_flags_of", "write_status_file", "sink_keys"]

#: Window of recent estimates the latency, joints-found and scene-flag figures are taken over.
WINDOW = 100
#: The pair's scene flags the report counts over the window, as ``PairResult`` names them (docs/protocol.md, "Scene
#: flags"; CALIBRATION_SUSPECT is the report's ``calibration``): how many of the last pairs showed two people, fell
#: back from the skeleton prior or were seen by one camera alone.
SCENE_FLAGS = ("several_people", "prior_fallback", "single_view")
#: Running with no estimate for this long: the rate reads 0 and the status line says so (the rate of the last
#: window stayed on, reading healthy while every pair was rejected or none came).
STALE_S = 2.0


def sink_keys(urls: Iterable[str]) -> dict[str, str]:
    """Each sink URL and the name the report's ``sinks`` and the STATUS line give it: the URL with any password as
    ``***`` (``drivers.url.redact_url``; the status file is world-readable). Two URLs that differ only in their
    password (two ``memory://`` test sinks: the other sinks refuse a ``user:pass@``) would share that name: the
    later ones in ``urls``' order get ``#2``, ``#3``... (no sink URL holds a ``#``: each sink refuses one)."""
    keys: dict[str, str] = {}
    taken: set[str] = set()
    for url in urls:
        shown = key = redact_url(url)
        n = 1
        while key in taken:
            n += 1
            key = f"{shown}#{n}"
        taken.add(key)
        keys[url] = key
    return keys


def scene_flags_of(result: Any) -> frozenset[str]:
    """The :data:`SCENE_FLAGS` a pair's estimate (a ``PairResult``) carries: ``single_view`` is a camera's name or
    ``None``, the others booleans."""
    return frozenset(name for name in SCENE_FLAGS if getattr(result, name))


class State:
    """The daemon's states, as written in the report and systemd's STATUS line."""

    STARTING = "starting"
    OPENING = "opening"  # opening the rig
    WAITING = "waiting"  # the rig could not be opened, or vanished: retrying after a backoff
    RUNNING = "running"  # reading and estimating pairs
    STOPPING = "stopping"


@dataclass
class Health:
    """Counters of one daemon run; the main loop is the only writer, :meth:`report` the reader."""

    clock: Any = time.monotonic
    state: str = State.STARTING
    started: float = 0.0
    state_since: float = 0.0
    rig_url: str = ""
    cameras: tuple[str, ...] = ()
    pairs_read: int = 0
    pairs_estimated: int = 0
    pairs_dropped: int = 0  # skipped by the driver under the latest-pair policy, or lost whole (an OAK's host queue)
    estimate_errors: int = 0
    read_errors: int = 0  # reads that failed once and the next went on (a corrupt frame in a recording)
    rig_opens: int = 0
    rig_open_failures: int = 0
    rig_lost: int = 0  # an open rig that vanished, ended or fell silent
    last_pair_at: Optional[float] = None
    last_error: Optional[str] = None
    camera_fault: bool = False
    estimator_stalled: bool = False
    reloads: int = 0  # config reloads accepted (SIGHUP)
    reload_failures: int = 0  # refused: the daemon ran on with the config it had
    reload_error: Optional[str] = None  # why the last reload was refused (None once one is accepted)
    # camera name -> frame-check reason -> frames rejected for it (bounded: the rig's cameras x REASONS)
    frames_rejected: dict = field(default_factory=dict)
    latencies_ms: deque = field(default_factory=lambda: deque(maxlen=WINDOW))
    found_fraction: deque = field(default_factory=lambda: deque(maxlen=WINDOW))
    estimate_times: deque = field(default_factory=lambda: deque(maxlen=WINDOW))
    scene_flags: deque = field(default_factory=lambda: deque(maxlen=WINDOW))  # each estimate's, scene_flags_of
    # each estimate's PairResult.someone_else (presence.scan_every_s): True, False or None (no scan's answer)
    someone_else: deque = field(default_factory=lambda: deque(maxlen=WINDOW))
    calibration: CalibrationWatch = field(default_factory=lambda: CalibrationWatch(CALIBRATION_WINDOW,
                                                                                    CALIBRATION_MAX_PX))
    # the calibration's second symptom: the feet off the floor (a pan, which the view agreement does not show)
    floor: FloorWatch = field(default_factory=lambda: FloorWatch(CALIBRATION_WINDOW, CALIBRATION_MAX_FLOOR_M))
    # the third: a mirror-image skeleton (the cameras' inputs exchanged, which neither of the others shows)
    handedness: HandednessWatch = field(default_factory=lambda: HandednessWatch(CALIBRATION_WINDOW,
                                                                                 CALIBRATION_MAX_MIRROR))

    def __post_init__(self) -> None:
        self.started = self.state_since = self.clock()

    def enter(self, state: str) -> None:
        if state != self.state:
            self.state, self.state_since = state, self.clock()

    @property
    def calibration_suspect(self) -> bool:
        """Any check says the rig no longer fits (the CALIBRATION_SUSPECT flag): moved, or its inputs exchanged."""
        return bool(self.calibration.suspect or self.floor.suspect or self.handedness.suspect)

    def _calibration_report(self) -> dict[str, Any]:
        """The status file's ``calibration``: each check's figures, ``suspect`` for any (``px_suspect``,
        ``floor_suspect`` and ``exchanged_suspect`` say which), ``fix`` what to do (null when none is suspect)."""
        px = self.calibration.report()
        return {**px, "px_suspect": px["suspect"], **self.floor.report(), **self.handedness.report(),
                "suspect": self.calibration_suspect, "fix": fixes(self._calibration_checks()) or None}

    def _calibration_checks(self) -> tuple:
        return self.calibration, self.floor, self.handedness

    def _calibration_status(self) -> str:
        """The STATUS= line's words while any check is suspect: what to do first, then each symptom (empty
        otherwise)."""
        return status_words(self._calibration_checks())

    def estimated(self, total_ms: float, found: float, flags: frozenset[str] = frozenset(),
                  someone_else: Optional[bool] = None) -> None:
        """One pair estimated in ``total_ms``, ``found`` the fraction of its 3D joints found, ``flags`` its
        :func:`scene_flags_of`, ``someone_else`` its ``PairResult.someone_else``."""
        now = self.clock()
        self.pairs_estimated += 1
        self.last_pair_at = now
        self.latencies_ms.append(float(total_ms))
        self.found_fraction.append(float(found))
        self.estimate_times.append(now)
        self.scene_flags.append(frozenset(flags))
        self.someone_else.append(None if someone_else is None else bool(someone_else))

    def frames_checked(self, frame_reason: dict[str, Optional[str]]) -> None:
        """Count each camera's frame the estimator's frame check rejected (``PairResult.frame_reason``), by
        reason: the answer to "why no joints?" when a lens is covered or a stream sends garbage."""
        for camera, why in frame_reason.items():
            if why is not None:
                counts = self.frames_rejected.setdefault(camera, dict.fromkeys(REASONS, 0))
                counts[why] = counts.get(why, 0) + 1

    def _flagged_report(self) -> dict[str, int]:
        """The status file's ``estimator.flagged``: of the window's estimates, how many carried each scene flag
        (an operator's answer to "why fewer joints?" when two people stand in view)."""
        return {name: sum(name in flags for flags in self.scene_flags) for name in SCENE_FLAGS}

    def _someone_else_report(self) -> Optional[int]:
        """The status file's ``estimator.someone_else``: of the window's estimates, how many said someone besides
        the tracked subject is in the working volume; None where none had a scan's answer (``presence.scan_every_s``
        off, the default, or nobody tracked): not "nobody else", but not looked."""
        answers = [a for a in self.someone_else if a is not None]
        return sum(answers) if answers else None

    def _rejected_report(self) -> dict[str, dict[str, int]]:
        """Every camera of the rig (and any counted before a rig change) with every reason, 0 included."""
        cameras = list(self.cameras) + [c for c in self.frames_rejected if c not in self.cameras]
        return {c: {**dict.fromkeys(REASONS, 0), **self.frames_rejected.get(c, {})} for c in cameras}

    def report(self, sinks: Optional[dict[str, Any]] = None) -> dict[str, Any]:
        now = self.clock()
        lat = np.asarray(self.latencies_ms, float)
        times = self.estimate_times
        rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
        if times and now - times[-1] > STALE_S:
            rate = 0.0
        return {
            "state": self.state,
            "state_for_s": round(now - self.state_since, 3),
            "uptime_s": round(now - self.started, 3),
            "updated_unix": round(time.time(), 3),
            "pid": os.getpid(),
            "rig": {"url": self.rig_url, "cameras": list(self.cameras), "opens": self.rig_opens,
                    "open_failures": self.rig_open_failures, "lost": self.rig_lost,
                    "camera_fault": self.camera_fault, "frames_rejected": self._rejected_report(),
                    "last_pair_age_s": None if self.last_pair_at is None else round(now - self.last_pair_at, 3)},
            "pairs": {"read": self.pairs_read, "estimated": self.pairs_estimated, "dropped": self.pairs_dropped,
                      "estimate_errors": self.estimate_errors, "read_errors": self.read_errors},
            "estimator": {"stalled": self.estimator_stalled,
                          "pairs_per_s": round(rate, 2),
                          "latency_ms_median": round(float(np.median(lat)), 2) if lat.size else None,
                          "latency_ms_p99": round(float(np.percentile(lat, 99)), 2) if lat.size else None,
                          "joints_found": round(float(np.mean(self.found_fraction)), 3)
                          if self.found_fraction else None,
                          "flagged": self._flagged_report(),
                          "someone_else": self._someone_else_report(),
                          "window": len(lat)},
            "calibration": self._calibration_report(),
            "last_error": self.last_error,
            "config": {"reloads": self.reloads, "reload_failures": self.reload_failures,
                       "reload_error": self.reload_error},
            "sinks": _shown_sinks(sinks or {}),
        }

    def status_line(self, sinks: Optional[dict[str, Any]] = None) -> str:
        """One line for systemd's ``STATUS=`` (``systemctl status ghnerf``); a refused reload stays on it
        until one is accepted (``systemctl reload`` returns before the daemon has read the file). ``sinks``:
        each sink's counters by URL (as in :meth:`report`); those down or stalled are named with their error, by
        their :func:`sink_keys` name."""
        last = self.state_since if self.last_pair_at is None else max(self.state_since, self.last_pair_at)
        idle_s = self.clock() - last  # (since the rig opened: it may have been away)
        if self.state == State.RUNNING and idle_s > STALE_S:
            why = f"; last error: {self.last_error}" if self.last_error else ""
            line = f"running: no pair estimated for {idle_s:.0f} s{why}"
        elif self.state == State.RUNNING:
            r = self.report()["estimator"]
            lat = f", {r['latency_ms_median']:.0f} ms" if r["latency_ms_median"] is not None else ""
            line = f"running: {r['pairs_per_s']:.1f} pairs/s{lat}, {self.pairs_estimated} estimated"
        elif self.state == State.WAITING and self.last_error:
            line = f"waiting for the rig: {self.last_error}"
        else:
            line = self.state
        return _fit_status(line, self._calibration_status(), self.reload_error, sinks or {})


#: systemd shows this much of the status line; the daemon's state keeps at least STATUS_KEEP of it.
STATUS_MAX, STATUS_KEEP = 200, 60
#: A refused reload's part of the status line at most ("; " and its error cut there): with the state's STATUS_KEEP
#: it leaves the sinks down some of the line too.
STATUS_RELOAD_MAX = 120


def _fit_status(line: str, calibration: str, reload_error: Optional[str], sinks: dict[str, Any]) -> str:
    """The state's ``line``, the sinks down, the calibration's words and a refused reload within STATUS_MAX.

    A rig that no longer fits its calibration is said whatever else the line holds (about 55 characters, up to
    about 185 with all three symptoms: it then takes part of the state's STATUS_KEEP); a refused reload gets what
    is left of the rest once the state has its STATUS_KEEP (at most STATUS_RELOAD_MAX), the sinks down what is
    left after both. Every room is at least 0: a negative slice would keep all but the end of a part instead of
    none of it."""
    calibration = calibration[:STATUS_MAX]
    reload_room = max(0, min(STATUS_RELOAD_MAX, STATUS_MAX - STATUS_KEEP - len(calibration)))
    refused = calibration + (f"; {reload_error}"[:reload_room] if reload_error else "")
    state_keep = min(len(line), STATUS_KEEP)
    down = _sinks_down(sinks, max(0, STATUS_MAX - len(refused) - state_keep))
    return line[:max(0, STATUS_MAX - len(refused) - len(down))] + down + refused


def _shown_sinks(sinks: dict[str, Any]) -> dict[str, Any]:
    """``sinks`` (counters by URL as configured) keyed by their :func:`sink_keys` names, in the order given."""
    keys = sink_keys(sinks)
    return {keys[url]: counters for url, counters in sinks.items()}


def _sinks_down(sinks: dict[str, Any], room: int) -> str:
    """``; sink URL down: why`` for each sink that is down, ``; sink URL stalled N s: why`` for each whose receiver
    stopped reading, or ``; N sinks down, M stalled`` when that does not fit (URL: its :func:`sink_keys` name)."""
    keys = sink_keys(sinks)
    down = {url: s for url, s in sinks.items() if s.get("state") == "down"}
    stalled = {url: s for url, s in sinks.items() if s.get("state") == "stalled"}
    if not down and not stalled:
        return ""
    text = "".join(f"; sink {keys[url]} down: {_why(url, s.get('last_error'))}" for url, s in down.items())
    text += "".join(f"; sink {keys[url]} stalled {s.get('stalled_s') or 0:.0f} s: "
                    f"{_why(url, s.get('last_error'), 'a write that has not returned')}" for url, s in stalled.items())
    if len(text) <= room:
        return text
    if room >= 40:  # the first sink's URL and the start of its error say more than a count
        return text[:room]
    counts = [f"{len(down)} sink{'s' if len(down) > 1 else ''} down"] if down else []
    if stalled:
        counts.append(f"{len(stalled)} stalled" if down else
                      f"{len(stalled)} sink{'s' if len(stalled) > 1 else ''} stalled")
    return ("; " + ", ".join(counts))[:max(room, 0)]


def _why(url: str, error: Optional[str], unknown: str = "not connected") -> str:
    """A sink's error without the URL (as its errors show it: redacted) and the ``unavailable:`` (``write
    failed:``) its exception message starts with; ``unknown`` where it has none."""
    why = (error or unknown).removeprefix(f"{shown_url(url)}: ")
    return why.removeprefix("unavailable: ").removeprefix("write failed: ")


def write_status_file(path: str | os.PathLike, report: dict[str, Any]) -> None:
    """Replace ``path`` with the report in one step (a reader never sees half a file).

    A symbolic link is written through (its target replaced, the link kept: a rename over the link cut it, and
    its target was never written again). A path that is there and is no regular file (``/dev/null``, a FIFO a
    monitor reads) is written into: a rename would replace the device node itself when the daemon runs as root.
    """
    target = Path(os.path.realpath(path))
    if target.exists() and not target.is_file():
        # a FIFO with no reader: an OSError (warned once), not a daemon blocked in its open
        write_bytes_into(target, (json.dumps(report, indent=1, allow_nan=False) + "\n").encode("utf-8"),
                         wait_for_reader=False)
        return
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", dir=target.parent)
    try:
        os.fchmod(fd, 0o644)  # mkstemp makes it private; operators read it without being the service user
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1, allow_nan=False)
            fh.write("\n")
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
