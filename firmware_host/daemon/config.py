"""The daemon's configuration: one JSON file, one frozen dataclass per component, validated once at load.

Tree (defaults in the classes; ``docs/daemon.md`` has a full example)::

    DaemonConfig
      rig        RigConfig          camera URL, read timeout, when to reopen, reopen backoff
      sinks      tuple[str, ...]    joint-stream sink URLs (serial://, usb://, udp://, vmc://, file://)
      estimator  EstimatorConfig    the runtime's config tree, exactly as docs/runtime.md has it
      health     HealthConfig       status file, systemd watchdog allowance, estimator stall
      log_level  str

Unknown keys are an error naming their dotted path (``rig.urll: unknown key ...``), like the
runtime's config, so a typo on a device fails at start rather than being ignored. Every error
is a :class:`DaemonConfigError` whose message starts with the file and the key.
"""
from __future__ import annotations

import dataclasses
import math
import os
import stat
import typing
from dataclasses import dataclass, field
from typing import Any, Mapping
from urllib.parse import urlsplit

from firmware_host.errors import FirmwareHostError
from firmware_host.sinks.usb_select import PortPath
from firmware_host.sinks.usb_sink import ClaimedInterface, claimed_interface, named_board_now
from ghnerf_runtime.cli.output_path import first_clash
from ghnerf_runtime.config import PATH_KEYS, EstimatorConfig, config_from_dict, read_json_file
from drivers.errors import RigConfigError
from drivers.url import RigUrl, is_refused_character, redact_url, unquote_keeping_bytes, with_kept_bytes_escaped
from drivers.url_paths import rig_url_from_folder, url_files, url_path_problem
from drivers.wrappers import RECORD_PREFIX, wrapper_prefixes
from ghnerf_runtime.config_paths import impossible_path, paths_from_file, values_from_file
from ghnerf_runtime.errors import ConfigError
from ghnerf_runtime.path_check import path_problem, shown

__all__ = ["DaemonConfigError", "RigConfig", "HealthConfig", "DaemonConfig", "daemon_config_from_dict",
           "load_daemon_config", "load_daemon_config_noting_paths", "LOG_LEVELS"]

LOG_LEVELS = ("debug", "info", "warning", "error")
#: The keys holding file-system paths: a relative one written in the config file is read from the file's folder.
DAEMON_PATH_KEYS: tuple[tuple[str, ...], ...] = (("health", "status_file"),) + tuple(("estimator",) + k for k in PATH_KEYS)
#: The keys holding rig URLs: a relative file path in one (``replay://takes/walk``, ``rig=rig.json``) is read from
#: the file's folder too (``drivers.url_paths``). Sink URLs name no relative file: ``file://`` and ``serial://``
#: take absolute paths only.
DAEMON_RIG_URL_KEYS: tuple[tuple[str, ...], ...] = (("rig", "url"),)
#: Time one estimate may take on top of a read before the watchdog's allowance runs out (see DaemonConfig).
LOOP_MARGIN_S = 5.0
#: The calibration check's defaults (HealthConfig): on the simulated rig the true rig's 30-pair medians reached
#: 0.24 px, a camera tilted 1 degree gave 1.17 px or more (128 px crops; benchmarks/measure_calibration_drift.py,
#: docs/calibration.md).
CALIBRATION_WINDOW = 30
CALIBRATION_MAX_PX = 0.8
#: The floor check's default (HealthConfig.calibration_max_floor_m): on the simulated rig the true rig's 30-pair
#: medians of the lower triangulated foot (the median of its joints, since session 56) stayed within 0.03 m of the
#: floor (0 of 27 windows past 0.05 m), and 0.05 m is 1.5 times that, as 0.1 m was for the lowest foot joint's 0.07 m
#: in session 54; either camera panned 1 degree takes 92 of 108 windows past it, 2 degrees 106 of 106 (the lowest
#: joint against 0.1 m: 32 of 112 and 95 of 113, the true rig 1 of 28): benchmarks/measure_calibration_drift.py,
#: docs/calibration.md "The feet on the floor".
CALIBRATION_MAX_FLOOR_M = 0.05
#: How far below 0 the 30-pair median of the pairs' handedness (PairResult.handedness: +1 a person, -1 a mirror
#: image) may go before the cameras look exchanged (a symmetric rig's left camera fed as its right): the default
#: of HealthConfig.calibration_max_mirror. On the simulated rig the true rig's 30-figure windows stayed at +0.14 or
#: more, the exchanged rig's at -0.02 or less over 30-pair takes (-0.35 or less over 150-pair ones), and every
#: exchanged take with a full window was flagged
#: (benchmarks/measure_exchanged_cameras.py, docs/calibration.md "Cameras exchanged"); on three rigs made not
#: symmetric (--rig higher, toed-in, wide) the true rig's windows stayed at +0.06 or more. A person with their back to
#: the rig gives few figures, near 0 (a short window read -0.21): set it null for such a subject. The window is
#: health.calibration_window.
CALIBRATION_MAX_MIRROR = 0.2

#: A config file holds a few KB; a bigger file is another one given as the config (as a rig file's cap,
#: ``ghnerf_runtime.rig_file.MAX_RIG_FILE_BYTES``).
MAX_CONFIG_FILE_BYTES = 1 << 20


class DaemonConfigError(FirmwareHostError, ValueError):
    """The daemon's config is invalid; ``key`` is the dotted path (``"rig.read_timeout_s"``)."""

    def __init__(self, message: str, *, key: str | None = None) -> None:
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
        self.message = message  # without the key: for a caller that re-keys it


def _fail(field_name: str, why: str, value: Any) -> None:
    raise DaemonConfigError(f"{why}, got {value!r}", key=field_name)


def _seconds(obj: Any, name: str, lo: float, hi: float) -> None:
    value = getattr(obj, name)
    try:
        seconds = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan
    except OverflowError:  # an integer too large for a float
        seconds = math.nan
    if not math.isfinite(seconds) or not lo <= seconds <= hi:
        _fail(name, f"must be a number of seconds in [{lo:g}, {hi:g}]", value)
    object.__setattr__(obj, name, seconds)


def _boolean(obj: Any, name: str) -> None:
    if not isinstance(getattr(obj, name), bool):
        _fail(name, "must be true or false", getattr(obj, name))


@dataclass(frozen=True)
class RigConfig:
    """Which rig the daemon reads, and how it rides out a camera that stalls or vanishes.

    Attributes:
        url: rig URL (``drivers.open_rig``): ``depthai://`` (the first OAK), ``depthai://<mxid>``,
            ``opencv://?first=/dev/video0&second=/dev/video2&rig=/etc/ghnerf/rig.json`` (two webcams), ``sim://?fps=30``,
            ``replay:///var/lib/ghnerf/take1``...
        read_timeout_s: how long one read waits for a pair before the health report calls the
            camera late (``CAMERA_FAULT`` on the sinks' STATUS).
        stall_s: no pair for this long (the camera is open but silent): close it and open it again.
        reopen_min_s, reopen_max_s: backoff between attempts to open the rig after a failure or an
            unplug, doubling from the first to the second (a missing camera is retried forever).
        exit_at_end: when a finite source (``replay://``) ends, stop the daemon (exit status 0);
            false: open it again from the start.
    """

    url: str = "depthai://"
    read_timeout_s: float = 1.0
    stall_s: float = 10.0
    reopen_min_s: float = 0.5
    reopen_max_s: float = 30.0
    exit_at_end: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.url, str) or "://" not in self.url:
            _fail("url", "must be a rig URL such as 'depthai://' or 'sim://?fps=30'", redact_url(self.url))
        _refuse_edge_space("url", self.url)
        if RECORD_PREFIX in wrapper_prefixes(self.url):  # outermost or inside another wrapper
            # A recorder needs an empty out= folder, and the daemon reopens the rig after every unplug.
            _fail("url", f"{RECORD_PREFIX} is not supported by the daemon (each reopen would need a new out= folder); "
                         f"record with ghnerf-demo --url {RECORD_PREFIX}... instead", redact_url(self.url))
        _seconds(self, "read_timeout_s", 0.01, 60.0)
        _seconds(self, "stall_s", 0.1, 3600.0)
        if self.stall_s < self.read_timeout_s:
            _fail("stall_s", f"must be at least read_timeout_s ({self.read_timeout_s:g})", self.stall_s)
        _seconds(self, "reopen_min_s", 0.01, 600.0)
        _seconds(self, "reopen_max_s", 0.01, 3600.0)
        if self.reopen_max_s < self.reopen_min_s:
            _fail("reopen_max_s", f"must be at least reopen_min_s ({self.reopen_min_s:g})", self.reopen_max_s)
        _boolean(self, "exit_at_end")


@dataclass(frozen=True)
class HealthConfig:
    """What the daemon reports about itself, and when systemd may consider it hung.

    Attributes:
        status_file: JSON health report rewritten (atomically) every ``status_every_s``
            (``docs/daemon.md`` lists its fields); ``null``: none. The unit file uses
            ``/run/ghnerf/status.json``.
        status_every_s: how often the report (and systemd's ``STATUS=`` line) is refreshed.
        open_allowance_s: how long opening the rig (or a reload) may block the main loop before the watchdog
            treats the daemon as hung (an OAK boots its firmware in a few seconds); also how long a camera
            may stay stuck in a device call after its rig was closed before the watchdog's pings stop.
        loop_allowance_s: how long one pass of the main loop (a read plus an estimate) may take
            before the watchdog treats the daemon as hung: systemd's ``WATCHDOG=1`` pings stop, the
            thread stacks go to the journal and systemd restarts the service.
        slow_estimate_s: an estimate slower than this flags ``ESTIMATOR_STALLED`` on the sinks' STATUS.
        calibration_window: pairs (with someone seen well in both views) whose median view agreement
            (``PairResult.reprojection_px_median``) the calibration check takes (:mod:`firmware_host.daemon.calibration_watch`).
        calibration_max_px: that median, in model-input pixels, above which the status file and systemd's
            STATUS line say the calibration is suspect (a camera moved since calibration: recalibrate); ``null``:
            no check. Measured defaults (``benchmarks/measure_calibration_drift.py``, docs/calibration.md).
        calibration_max_floor_m: how far from the floor (metres, above or below) the median over
            ``calibration_window`` pairs of the lower triangulated foot's height (``PairResult.lowest_foot_m``) may be
            before the calibration is suspect: a panned camera, which the view agreement does not show, moves the
            feet off the floor. ``null``: no floor check (people standing on a stage, lying on a bed: not on the
            rig's floor at y = 0). The foot's height counts from ``estimator.joints3d.foot_standing_m`` (bare feet by
            default); shoes' soles or a mat: ``ghnerf-daemon --measure-floor`` measures the value to set.
        calibration_max_mirror: how far below 0 the median over ``calibration_window`` pairs of the pairs'
            handedness (``PairResult.handedness``: +1 a person, -1 a mirror image) may go before the cameras look
            exchanged (the fix is the plugs or the names in ``rig.url``, not a recalibration). ``null``: no check, for a
            rig that is not a mirror image of itself (built far from symmetric). A subject with their back to the rig
            needs none since session 66: a heel seen gives no figure (``ghnerf_runtime.handedness.BACK_JOINTS``).
    """

    status_file: str | None = None
    status_every_s: float = 1.0
    open_allowance_s: float = 60.0
    loop_allowance_s: float = 15.0
    slow_estimate_s: float = 1.0
    calibration_window: int = CALIBRATION_WINDOW
    calibration_max_px: float | None = CALIBRATION_MAX_PX
    calibration_max_floor_m: float | None = CALIBRATION_MAX_FLOOR_M
    calibration_max_mirror: float | None = CALIBRATION_MAX_MIRROR

    def __post_init__(self) -> None:
        if self.status_file is not None and (not isinstance(self.status_file, str) or not self.status_file):
            _fail("status_file", "must be a file path or null", self.status_file)
        _refuse_impossible("status_file", self.status_file)
        _refuse_folder("status_file", self.status_file, "/run/ghnerf/status.json")
        _seconds(self, "status_every_s", 0.05, 3600.0)
        _seconds(self, "open_allowance_s", 1.0, 3600.0)
        _seconds(self, "loop_allowance_s", 1.0, 3600.0)
        _seconds(self, "slow_estimate_s", 0.001, 3600.0)
        window = self.calibration_window
        if isinstance(window, bool) or not isinstance(window, int) or not 1 <= window <= 10000:
            _fail("calibration_window", "must be a whole number of pairs in [1, 10000]", window)
        if self.calibration_max_px is not None:
            limit = self.calibration_max_px
            if isinstance(limit, bool) or not isinstance(limit, (int, float)) or not 0 < limit <= 100:
                _fail("calibration_max_px", "must be a number of pixels in (0, 100], or null for no check", limit)
            object.__setattr__(self, "calibration_max_px", float(limit))
        if self.calibration_max_floor_m is not None:
            limit = self.calibration_max_floor_m
            if isinstance(limit, bool) or not isinstance(limit, (int, float)) or not 0 < limit <= 10:
                _fail("calibration_max_floor_m", "must be a number of metres in (0, 10], or null for no floor check",
                      limit)
            object.__setattr__(self, "calibration_max_floor_m", float(limit))
        if self.calibration_max_mirror is not None:
            limit = self.calibration_max_mirror
            # handedness lies in [-1, 1]: a limit of 1 or more could never be passed
            if isinstance(limit, bool) or not isinstance(limit, (int, float)) or not 0 < limit < 1:
                _fail("calibration_max_mirror", "must be a number in (0, 1) (how far below 0 the handedness median "
                      "may go), or null for no check", limit)
            object.__setattr__(self, "calibration_max_mirror", float(limit))


@dataclass(frozen=True)
class DaemonConfig:
    """The root. ``sinks`` is required (a daemon that streams nowhere is a mistake, not a default)."""

    rig: RigConfig = field(default_factory=RigConfig)
    sinks: tuple[str, ...] = ()
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    health: HealthConfig = field(default_factory=HealthConfig)
    log_level: str = "info"

    def __post_init__(self) -> None:
        sinks = self.sinks
        if isinstance(sinks, str) or not isinstance(sinks, (tuple, list)) or not sinks:
            _fail("sinks", "must be a non-empty list of sink URLs such as ['udp://192.168.1.20:9870']", sinks)
        for k, url in enumerate(sinks):
            if not isinstance(url, str) or "://" not in url:
                _fail(f"sinks[{k}]", "must be a sink URL such as 'serial:///dev/ttyACM0'", url)
            _refuse_edge_space(f"sinks[{k}]", url)
            place = _destination(url)
            if place is not None and place[0] == "file":  # before the outputs-apart check reads it (realpath)
                _refuse_impossible(f"sinks[{k}]", place[2])
                if place[1] in ("", "localhost"):  # another host: the sink's own check refuses it
                    _refuse_folder(f"sinks[{k}]", place[2], "/var/lib/ghnerf/joints.jsonl")
        if len(set(sinks)) != len(sinks):
            _fail("sinks", "lists a URL twice", [redact_url(url) for url in sinks])  # the journal keeps no password
        _one_sink_per_destination(sinks)
        object.__setattr__(self, "sinks", tuple(sinks))
        if isinstance(self.rig, RigConfig) and isinstance(self.health, HealthConfig):
            _outputs_apart(_outputs(self), _rig_inputs(self.rig.url))
        if self.log_level not in LOG_LEVELS:
            _fail("log_level", f"must be one of {list(LOG_LEVELS)}", self.log_level)
        # One pass of the loop is a read (up to read_timeout_s) and an estimate: the watchdog must not
        # take a silent camera, which the loop handles by reopening it, for a hung loop.
        if isinstance(self.rig, RigConfig) and isinstance(self.health, HealthConfig) \
                and self.health.loop_allowance_s < self.rig.read_timeout_s + LOOP_MARGIN_S:
            _fail("health.loop_allowance_s", f"must be at least rig.read_timeout_s + {LOOP_MARGIN_S:g} s "
                                             f"({self.rig.read_timeout_s + LOOP_MARGIN_S:g})",
                  self.health.loop_allowance_s)


def _refuse_impossible(key: str, path: str | None) -> None:
    """:class:`DaemonConfigError` keyed ``key`` for a ``path`` no file can have (a NUL byte, a name or path too long,
    not UTF-8): ``os.path.realpath`` in the outputs-apart check raised ``ValueError`` for a NUL (a traceback)."""
    problem = path_problem(path) if path else None
    if problem is not None:  # a byte that is not UTF-8 shown as the %XX escape the URL gave it
        raise DaemonConfigError(f"{shown(with_kept_bytes_escaped(path))}: {problem}", key=key)


def _refuse_edge_space(key: str, url: str) -> None:
    """:class:`DaemonConfigError` keyed ``key`` for a URL that starts or ends with a space (a value pasted with one):
    not read as written. A leading one is dropped by URL parsing, but not by the check that reads a relative path
    from the config file's folder (`` replay://takes/walk`` played ``takes/walk`` of the current directory); a
    trailing one became part of the last value (``file:///j.jsonl `` wrote another file, ``fps=30 `` was refused
    as no number). Tabs and line feeds are ``drivers.url.dropped_characters``'."""
    for edge, char in (("starts", url[:1]), ("ends", url[-1:])):
        if char.isspace() and not is_refused_character(char):  # controls, U+2028/U+2029: dropped_characters'
            _fail(key, f"{edge} with a space, which is no part of the URL; remove it", redact_url(url))


def _refuse_folder(key: str, path: str | None, example: str) -> None:
    """:class:`DaemonConfigError` keyed ``key`` for a ``path`` that is a folder now: it was accepted and every write
    failed (a warning at each start and reload). A folder does not become a file later, a mount point included, so
    the sinks' leniency for a folder not there yet (a USB stick mounted later) does not cover it."""
    if path and os.path.isdir(path):
        _fail(key, f"is a folder, not a file; name the file to write in it, such as {example}", path)


def _destination(url: str) -> tuple[str, str, str] | None:
    """Where a sink URL sends: its scheme, location and path, without its options (None: it names no place, as
    ``memory://``, or does not parse, which the sink's own check reports). The path is decoded as the sinks decode
    it (:func:`drivers.url.unquote_keeping_bytes`): ``unquote`` made both ``%FF`` and ``%FE`` U+FFFD, one place."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return None
    path = _spelling_apart(unquote_keeping_bytes(parts.path))
    if parts.netloc and path == "/":  # udp://h:1/ is udp://h:1, as the sinks read it (a lone '/' is no path)
        path = ""
    if not parts.netloc and not path:
        return None
    return parts.scheme.lower(), parts.netloc.lower(), path


def _spelling_apart(path: str) -> str:
    """``path`` without what only spells it another way (``//``, ``/./``, a trailing ``/``). A ``..`` is kept:
    ``link/..`` is the folder above the link's target, not the link's own folder (``posixpath.normpath`` made two
    files one); the outputs-apart check (``realpath``) sees where it leads."""
    names = [name for name in path.split("/") if name not in ("", ".")]
    return ("/" if path.startswith("/") else "") + "/".join(names)


def _one_sink_per_destination(sinks: typing.Sequence[str]) -> None:
    """Two URLs that differ only in their options (``?queue=8``), the case of the scheme or a ``//`` in a path name
    one destination: two sinks on it would send each frame twice to one UDP port, interleave two writers in one
    file, or leave the second serial sink down for ever behind the first one's lock. So do two serial paths to one
    device and two ``usb://`` URLs that may claim one interface (:func:`_sink_place`, :func:`_one_place`). Two
    ``file://`` paths to one file are the outputs-apart check's (``realpath``), and one board named by its serial
    and by its port, when plugged in at load, :func:`_one_board`'s."""
    earlier: list[tuple[int, tuple[str, str, Any]]] = []
    boards: dict[str, PortPath | None] = {}  # each usb:// URL's board, looked for once per load
    for k, url in enumerate(sinks):
        place = _sink_place(url)
        if place is None:
            continue
        for j, other in earlier:
            if _one_place(place, other):
                _refuse_one_destination(sinks, k, j, _how_one(place, other, url, sinks[j]))
            board = _one_board(place, other, url, sinks[j], boards)
            if board is not None:
                _refuse_one_destination(sinks, k, j, _how_one_board(place[2], other[2], board))
        earlier.append((k, place))


def _refuse_one_destination(sinks: typing.Sequence[str], k: int, j: int, how: str) -> None:
    """:class:`DaemonConfigError` keyed ``sinks[k]``: it sends where ``sinks[j]`` does; ``how`` says why they are one
    (:func:`_how_one`)."""
    _fail(f"sinks[{k}]", f"sends where sinks[{j}] ({redact_url(sinks[j])!r}) does{how}: one URL per destination, "
                         "with all its options", redact_url(sinks[k]))  # shown as the sinks show it: no password


def _one_board(place: tuple[str, str, Any], other: tuple[str, str, Any], url: str, other_url: str,
               boards: dict[str, PortPath | None]) -> PortPath | None:
    """The port path of the one board two ``usb://`` sinks name apart, one by ``serial=`` and one by ``port=``, for
    one interface, when it is plugged in at load (:func:`named_board_now`); None when they name
    two boards, or either is not found (the spellings stand: a board not plugged in at boot is no error). The
    second sink waited at connect for ever behind the first one's claim. Asked of the bus only for such a pair,
    each URL once (``boards``): a config with one usb:// sink reads nothing from the bus."""
    if not _two_names_of_one_interface(place, other):
        return None
    for each in (url, other_url):
        if each not in boards:
            boards[each] = named_board_now(each)
    board = boards[url]
    return board if board is not None and board == boards[other_url] else None


def _how_one_board(claim: ClaimedInterface, other: ClaimedInterface, board: PortPath) -> str:
    """For the refusal, how two ``usb://`` sinks naming one board apart (:func:`_one_board`) are one destination."""
    return f" (both claim interface {claim.interface} of the {claim.vid_pid} board at port {board}, named " \
           f"{other.board} and {claim.board})"


def _usb_claims(place: tuple[str, str, Any], other: tuple[str, str, Any]
                ) -> tuple[ClaimedInterface, ClaimedInterface] | None:
    """The interfaces two places (:func:`_sink_place`) claim, where both are ``usb://`` sinks whose URLs the sink
    takes; None otherwise."""
    if isinstance(place[2], ClaimedInterface) and isinstance(other[2], ClaimedInterface):
        return place[2], other[2]
    return None


def _one_interface(claim: ClaimedInterface, other: ClaimedInterface) -> bool:
    """Whether two claims are one VID:PID and interface, whichever boards they name."""
    return claim.vid_pid == other.vid_pid and claim.interface == other.interface


def _two_names_of_one_interface(place: tuple[str, str, Any], other: tuple[str, str, Any]) -> bool:
    """Whether two ``usb://`` places (:func:`_sink_place`) are one VID:PID and interface, one naming its board by
    ``serial=`` and the other by ``port=``: the pair only the bus can tell apart (two serials or two ports are two
    boards, a sink naming none is :func:`_one_place`'s)."""
    claims = _usb_claims(place, other)
    if claims is None or not _one_interface(*claims):
        return False
    board, other_board = (claim.board for claim in claims)
    return board is not None and other_board is not None and board.by != other_board.by


def _sink_place(url: str) -> tuple[str, str, Any] | None:
    """:func:`_destination`, with a serial port that exists named by the device it is (:func:`_serial_device`):
    ``/dev/serial/by-id/usb-...-if00`` is a link to ``/dev/ttyACM0``, and the second sink on it sat behind the first
    one's lock for ever. A port not there at load keeps its spelling: a board not plugged in at boot is no error.
    A ``usb://`` sink is the interface it claims (:func:`claimed_interface`): with the options dropped, two boards of
    one VID:PID told apart by ``serial=`` or ``port=`` were refused as one destination."""
    place = _destination(url)
    if place is not None and place[0] == "usb":
        claim = claimed_interface(url)
        return place if claim is None else ("usb", claim.vid_pid, claim)
    if place is None or place[0] != "serial" or place[1]:
        return place
    device = _serial_device(place[2])
    return place if device is None else (place[0], place[1], device)


def _one_place(place: tuple[str, str, Any], other: tuple[str, str, Any]) -> bool:
    """Whether two sinks' places (:func:`_sink_place`) may be one. A ``usb://`` sink with no ``serial=`` or
    ``port=`` takes whichever board of its VID:PID libusb lists first: that may be the one another sink names."""
    claims = _usb_claims(place, other)
    if claims is None:
        return place == other
    claim, other_claim = claims
    return _one_interface(claim, other_claim) and (
        claim.board == other_claim.board or claim.board is None or other_claim.board is None)


def _how_one(place: tuple[str, str, Any], other: tuple[str, str, Any], url: str, other_url: str) -> str:
    """For the refusal, how two URLs spelled apart were found one destination: two serial paths one device, two
    ``usb://`` URLs one interface ("" for one place spelled twice)."""
    claims = _usb_claims(place, other)
    if claims is not None:
        claim, other_claim = claims
        if claim.board == other_claim.board:
            board = "listed first" if claim.board is None else f"with {claim.board}"
            return f" (both claim interface {claim.interface} of the {claim.vid_pid} board {board})"
        named = claim.board or other_claim.board
        return f" (both claim interface {claim.interface} of {claim.vid_pid}, and the one with no serial= or port= " \
               f"takes the board listed first, which may be {named}: name each sink's board)"
    if place[0] != "serial" or not isinstance(place[2], tuple) or _destination(url) == _destination(other_url):
        return ""
    kind, major_or_dev, minor_or_ino = place[2]
    if kind == "character device":
        return f" (both paths lead to character device {major_or_dev}:{minor_or_ino})"
    return " (both paths lead to one file)"


def _serial_device(path: str) -> tuple[str, int, int] | None:
    """What the node at ``path`` opens, through links (None: there is none to ``stat``, or it cannot be read).
    A character device is its device number (``st_rdev``), not its inode: two nodes of one device (a copy made with
    ``mknod``, a second ``/dev`` in a container) write one port, and do not even share pyserial's ``flock``, which
    is the node's. ``stat`` opens nothing: no port sees its DTR raised by a config check. Anything else (a file
    standing in for a port) is its inode."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):  # missing, unreadable folder, a NUL: the spelling stands, the sink says the rest
        return None
    if stat.S_ISCHR(st.st_mode):
        return "character device", os.major(st.st_rdev), os.minor(st.st_rdev)
    return "inode", st.st_dev, st.st_ino


def _outputs(config: "DaemonConfig") -> list[tuple[str, str]]:
    """The files the daemon writes, as ``(key, path)``: the status file (replaced whole every few seconds) and the
    ``file://`` sinks (appended to)."""
    found = [("health.status_file", config.health.status_file)] if config.health.status_file else []
    for k, url in enumerate(config.sinks):
        place = _destination(url)
        if place is not None and place[0] == "file" and place[2]:
            found.append((f"sinks[{k}]", place[2]))
    return found


def _rig_inputs(url: str) -> list[tuple[str, str]]:
    """The files ``rig.url`` reads (its ``rig=`` calibration, a ``bvh=`` motion, ``opencv://`` videos), as
    ``(what, path)``; none for a URL that does not parse, which the rig's own check reports."""
    return [(f"rig.url's {part}= file", path) for part, path in url_files(url) if part != "target"]


def _outputs_apart(outputs: list[tuple[str, str]], inputs: list[tuple[str, str]]) -> None:
    """Refuse a file the daemon writes that is one it reads, or that it also writes another way: the status file
    set to the rig file replaced the calibration with a health report at the first beat, and a ``file://`` sink
    on it appended joint lines to it; a status file that is also a sink interleaved the two writers."""
    clash = first_clash(outputs, inputs)
    if clash is None:
        return
    if clash.other_is_input:
        _fail(clash.output, f"is {clash.other} ({clash.other_path}), which the daemon reads: writing there would "
                            "destroy it; give another path", clash.path)
    _fail(clash.output, f"is where {clash.other} writes too: two writers would mix in one file; give another path",
          clash.path)


def outputs_apart_from_config_file(config: "DaemonConfig", config_path: str | os.PathLike) -> None:
    """Refuse a status file or ``file://`` sink that is the config file itself: the first status beat replaced the
    config with a health report (the next start then failed), a sink appended joint lines to it."""
    _outputs_apart(_outputs(config), [("the config file itself", os.fspath(config_path))])


def _build(cls: type, data: Any, path: str) -> Any:
    if not isinstance(data, Mapping):
        raise DaemonConfigError(f"must be a mapping (JSON object), got {type(data).__name__}", key=path or None)
    names = {f.name for f in dataclasses.fields(cls)}
    for key in data:
        if key not in names:
            raise DaemonConfigError(f"unknown key; {cls.__name__} has {sorted(names)}",
                                    key=f"{path}.{key}" if path else str(key))
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        where = f"{path}.{key}" if path else key
        if hints[key] is EstimatorConfig:
            try:
                kwargs[key] = config_from_dict(value)
            except ConfigError as e:  # the runtime's error, keyed within the estimator tree
                raise DaemonConfigError(str(e).split(": ", 1)[-1],
                                        key=f"{where}.{e.key}" if e.key else where) from None
        elif dataclasses.is_dataclass(hints[key]):
            kwargs[key] = _build(hints[key], value, where)
        else:
            kwargs[key] = value
    try:
        return cls(**kwargs)
    except DaemonConfigError as e:  # a field's own check: put the section in front of its key
        raise DaemonConfigError(str(e).split(": ", 1)[-1],
                                key=f"{path}.{e.key}" if path and e.key else (e.key or path)) from None


def daemon_config_from_dict(data: Mapping[str, Any]) -> DaemonConfig:
    """Build and validate the tree from plain data.

    >>> daemon_config_from_dict({"sinks": ["udp://127.0.0.1:9870"], "rig": {"url": "sim://"}}).rig.url
    'sim://'
    >>> daemon_config_from_dict({"sinks": ["udp://127.0.0.1:9870"], "rig": {"ulr": "sim://"}})
    Traceback (most recent call last):
    ...
    firmware_host.daemon.config.DaemonConfigError: rig.ulr: unknown key; RigConfig has [...]
    """
    return _build(DaemonConfig, data, "")


def load_daemon_config(path: str | os.PathLike) -> DaemonConfig:
    """Read the daemon's JSON config file; every error names the file and the key. Relative paths written in
    it (``estimator.session.model_dir``, ``health.status_file``, and the files in ``rig.url``: a replay:// take,
    ``rig=``, ``bvh=``...) are read from the file's folder, whatever the current directory
    (:mod:`ghnerf_runtime.config_paths`). (The tree back to plain data, for ``--validate-config``, is the
    runtime's ``config_to_dict``: it walks any dataclass tree.)"""
    return load_daemon_config_noting_paths(path)[0]


def load_daemon_config_noting_paths(path: str | os.PathLike) -> tuple[DaemonConfig, frozenset[str]]:
    """:func:`load_daemon_config`, and the paths that were relative in the file, as read from its folder (absolute):
    an error naming one of them may say where it was read from, one naming a path written absolute must not."""
    _refuse_unlike_a_config_file(path)
    written = read_json_file(path, lambda message: DaemonConfigError(message, key=str(path)), "the config file",
                             max_chars=MAX_CONFIG_FILE_BYTES)  # a pipe, a file grown since the stat: not read whole
    try:
        refuse_impossible_paths(written)
    except DaemonConfigError as e:
        raise DaemonConfigError(str(e), key=str(path)) from None
    data = values_from_file(paths_from_file(written, DAEMON_PATH_KEYS, path), DAEMON_RIG_URL_KEYS, path,
                            rig_url_from_folder)
    try:
        config = daemon_config_from_dict(data)
        outputs_apart_from_config_file(config, path)
    except DaemonConfigError as e:
        raise DaemonConfigError(str(e), key=str(path)) from None
    return config, _made_absolute(written, data)


def _refuse_unlike_a_config_file(path: str | os.PathLike) -> None:
    """:class:`DaemonConfigError` keyed with ``path`` for a file bigger than any config (``MAX_CONFIG_FILE_BYTES``) or a
    device, told by ``stat`` before the read: read whole, another file given as the config (a take's frames,
    ``/dev/zero``) took the memory at the start and at every reload, or its read never ended. A pipe (``--config
    <(...)``) is read as before; a path that cannot be stat'ed is left to the read, which says why."""
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return
    if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode):
        raise DaemonConfigError("a device, not a config file", key=str(path))
    if stat.S_ISREG(info.st_mode) and info.st_size > MAX_CONFIG_FILE_BYTES:
        raise DaemonConfigError(f"the file holds {info.st_size} bytes, over the {MAX_CONFIG_FILE_BYTES} (1 MiB, "
                                "MAX_CONFIG_FILE_BYTES) a config file may: not the config file?", key=str(path))


def refuse_impossible_paths(data: Any) -> None:
    """:class:`DaemonConfigError` keyed with the first path in ``data`` (the file as written: before a relative
    path is joined to the file's folder, so a ``~`` is seen as written) that no file can have
    (:func:`ghnerf_runtime.path_check.path_problem`: a NUL byte, a name or path too long, not UTF-8, a leading
    ``~``). Said here, once: further on such a value raised ``ValueError`` from ``os.path.realpath`` (a traceback)
    or ``ENAMETOOLONG`` from wherever it was first touched."""
    impossible = impossible_path(data, DAEMON_PATH_KEYS)
    if impossible is not None:
        raise DaemonConfigError(impossible[1], key=impossible[0])
    for key in DAEMON_RIG_URL_KEYS:
        url = _at(data, key)
        problem = url_path_problem(url) if isinstance(url, str) else None
        if problem is not None:
            raise DaemonConfigError(problem, key=".".join(key))


def _made_absolute(written: Any, read: Any) -> frozenset[str]:
    """The values :func:`load_daemon_config` changed from ``written`` (the file's data) to ``read``: relative paths,
    made absolute; in a rig URL, its target or option values (as the backend reads them), not the whole URL."""
    found: set[str] = set()
    for key in DAEMON_PATH_KEYS + DAEMON_RIG_URL_KEYS:
        before, after = _at(written, key), _at(read, key)
        if not isinstance(before, str) or not isinstance(after, str) or before == after:
            continue
        if key not in DAEMON_RIG_URL_KEYS:
            found.add(after)
            continue
        try:
            old, new = RigUrl.parse(before), RigUrl.parse(after)
        except RigConfigError:  # changed, so it parsed for rig_url_from_folder; the check names what is wrong
            continue
        if new.target != old.target:
            found.add(new.target)
        found.update(value for name, value in new.options.items() if old.options.get(name) != value)
    return frozenset(found)


def _at(data: Any, key: tuple[str, ...]) -> Any:
    for part in key:
        if not isinstance(data, Mapping):
            return None
        data = data.get(part)
    return data
