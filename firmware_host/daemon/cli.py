"""``ghnerf-daemon``: the device's headless service (rig -> joints -> sinks), as systemd runs it.

Examples::

    ghnerf-daemon --config /etc/ghnerf/daemon.json
    ghnerf-daemon --config daemon.json --validate-config      # check it (the model loaded too), print it, exit
    ghnerf-daemon --config daemon.json --validate-config --no-model   # the same, the model folder's names only
    ghnerf-daemon --print-example-config > daemon.json        # a starting point (sim:// rig, UDP sink)
    ghnerf-daemon --config daemon.json --measure-floor        # the floor check's standing foot on this rig, exit

Under systemd (``systemd/ghnerf.service``, ``Type=notify``) it reports ``READY=1`` once the model
is loaded, keeps a one-line ``STATUS=`` (``systemctl status ghnerf``), pings the watchdog while its
main loop progresses and logs without timestamps (the journal adds its own).

``--validate-config`` runs the checks the start runs before READY (the model loaded and the estimator
built for a stand-in rig) without opening the rig or a sink, so a config it passes does not exit 2 at start
(bar a rig the model cannot run on, and live cameras that never deliver the rig file's size: known when they open;
``opencv://`` videos of another size it refuses). ``--no-model`` leaves the model unloaded, for a machine without
it.

``--measure-floor [PAIRS]`` (default 60) opens the rig and the model as the start does (no sink), runs pairs with
someone standing until PAIRS of them measured the lower foot (``PairResult.lowest_foot_m``), prints the measurement
as JSON with the ``estimator.joints3d.foot_standing_m`` to set (shoes' soles, a mat: docs/calibration.md, "Shoes,
mats: the standing foot") and exits: 0 measured; 1 not (too few feet seen, feet off any floor, no pair for
``rig.stall_s``, a rig that did not open or failed); 2 for what the start exits 2 for (a bad config, a model that does
not load, a rig URL its backend refuses, a rig the model cannot run on, cameras that deliver another size than the
rig's before any pair on the start's ``SIZE_MISMATCH_OPENS`` opens); 130 after Ctrl-C, 143 after SIGTERM (stopped
as the daemon stops, between two reads: the rig and the estimator closed, one line). Pairs with two people in view
are read past. Stop the service first (it holds the cameras).

SIGHUP (``systemctl reload ghnerf``) reads the config file again: a file that passes every check of
``--validate-config`` (and whose model loads) is applied without a restart, touching only what
changed; one that does not is refused with its error in the journal, and the daemon runs on as it was.
A SIGHUP during the start (imports, config, model load) does not kill it: it is recorded from the
first import of the package on (``early_sighup``); one that came before the config file was read is
met by that read, one after it becomes a reload once the daemon runs. A SIGTERM or SIGINT there is recorded too,
and stops the daemon (or ``--measure-floor``) once its stop handlers are in place, loading no model.

Exit status: 0 after SIGTERM / SIGINT or the end of a recording; 2 for what a restart cannot fix
(a bad config, a sink URL, a model that does not load or cannot serve the estimator's settings: the
message names the file or part and the key; a rig the model cannot run on, or cameras that never deliver the rig
file's size, once the rig opens: ``SIZE_MISMATCH_OPENS``), which the unit file keeps systemd from restarting; 1 for
an unexpected error, which it restarts.
"""
from __future__ import annotations

import argparse
import contextlib
import ctypes
import faulthandler
import json
import logging
import os
import signal
import sys
import threading
from collections.abc import Collection, Iterator, Sequence
from typing import Any
from pathlib import Path

import drivers
from drivers.backends.opencv import (is_nominal_rig, is_video_file, rig_size_message, still_image_message,
                                     video_size)
from drivers.backends.recording_format import MANIFEST, read_manifest
from drivers.backends.replay import ReplayRigSource
from drivers.base import log as rig_source_log
from drivers.url import RigUrl, redact_url, shown_url
from firmware_host.daemon import early_sighup
from firmware_host.daemon.config import DaemonConfig, DaemonConfigError, load_daemon_config_noting_paths
from firmware_host.daemon.measure_floor import (DEFAULT_PAIRS, FloorMeasureError, FloorMeasureStopped,
                                                measure_floor_of_config)
from firmware_host.daemon.sandbox import rig_url_hint, sandbox_warnings, service_hint
from firmware_host.daemon.service import Daemon, DaemonStartError, check_estimator, check_sink_urls, load_model
from firmware_host.protocol.constants import MAX_CAMERA_NAME_LEN, MAX_RIG_ID_LEN
from ghnerf_runtime.cli.rig_messages import log_on_stderr, rig_messages_on_stderr
from ghnerf_runtime.config import config_to_dict
from ghnerf_runtime.config_paths import config_folder
from ghnerf_runtime.errors import ModelLoadError, RuntimeErrorBase
from ghnerf_runtime.geometry.rig import Rig
from ghnerf_runtime.novel_painter import FILE_NAME as PAINTER_FILE
from ghnerf_runtime.novel_painter import NovelPainter
from ghnerf_runtime.rig_file import load_rig
from ghnerf_runtime.session import resolve_model_dir
from ghnerf_runtime.skeleton_prior import FILE_NAME as PRIOR_FILE
from ghnerf_runtime.video_files import is_still_image
from ghnerf_runtime.path_check import shown, user_path

__all__ = ["main", "build_parser", "check_config", "check_model", "read_checked_config", "EXAMPLE_CONFIG"]

PROG = "ghnerf-daemon"

#: ``--print-example-config``: runs as it is on a development machine (the simulated rig).
EXAMPLE_CONFIG = {
    "rig": {"url": "sim://?fps=30&seed=0&motion=wave"},
    "sinks": ["udp://127.0.0.1:9870?send_2d=1"],
    "estimator": {"session": {"model_dir": "models"}},
    "health": {"status_file": "ghnerf-status.json"},
}


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0],
                                 epilog="Config reference: docs/daemon.md")
    ap.add_argument("--config", type=user_path, help="daemon config, JSON (docs/daemon.md)")
    ap.add_argument("--validate-config", action="store_true",
                    help="check the config (keys, values, rig and sink URLs, the model loaded and the estimator "
                         "settings against it, as the start does; no camera or sink opened), print it in full, exit")
    ap.add_argument("--no-model", action="store_true",
                    help="with --validate-config: do not load the model, check only its folder's file names "
                         "(a machine without the model, or where it lives elsewhere)")
    ap.add_argument("--print-example-config", action="store_true", help="print a config to start from, exit")
    ap.add_argument("--measure-floor", type=int, nargs="?", const=DEFAULT_PAIRS, default=None, metavar="PAIRS",
                    help=f"with someone standing in view: measure the lower foot's height over PAIRS pairs "
                         f"(default {DEFAULT_PAIRS}) through the config's rig and model, print it with the "
                         f"estimator.joints3d.foot_standing_m to set (shoes, a mat), exit (the service stopped)")
    ap.add_argument("--max-seconds", type=float, default=None,
                    help="stop after this long (a bounded run for trials; default: until SIGTERM)")
    return ap


def check_config(config: DaemonConfig, source: str | os.PathLike | None = None,
                 from_folder: Collection[str] = (), *, warn_of_rig: bool = False) -> None:
    """What can be checked without hardware or the model: the URLs parse for their backends, the model folder holds
    graphs (and the skeleton prior or painter the config turns ``on``). It loads no model: the start and every
    reload run these checks and then load it themselves (once), and build the estimator on it, which checks the
    rest of what the settings need of the model (``heatmaps.source`` 'encoder': encoder heatmaps) before READY;
    ``--validate-config`` does the same after it (:func:`check_model`).

    ``source``: the config file ``config`` was read from, and ``from_folder`` the paths that were relative in it
    (:func:`~firmware_host.daemon.config.load_daemon_config_noting_paths`), for the hint on where they were read
    from: given only where the value that fails is one of them.

    ``warn_of_rig``: log the warnings and notes of the rig file or take ``rig.url`` names, or of the rig its source
    builds in memory (``sim://``) (``--validate-config``, which opens no rig). The start and the reloads leave them
    to the rig's open, which logs each once per ``rig.url``: the check logged them again at the start and at every
    reload.

    :raises DaemonConfigError: naming the key.
    """
    try:
        _check_rig_url(config.rig.url, warn_of_rig=warn_of_rig)
    except DaemonConfigError as e:  # a file it names, read from the config file's folder: say so, as for models
        raise DaemonConfigError(e.message + _where_url_read(e.message, config.rig.url, source, from_folder),
                                key="rig.url") from None
    check_sink_urls(config.sinks)
    try:
        model_dir = resolve_model_dir(config.estimator.session.model_dir)
    except ModelLoadError as e:  # a folder the service's user may not read (was a traceback, exit 1)
        raise DaemonConfigError(f"{e}{service_hint(config.estimator.session.model_dir)}",
                                key="estimator.session.model_dir") from None
    if not model_dir.is_dir():
        # said "holds no *.onnx graphs (make model builds ./models)": the example config's relative
        # "models", read from another folder than the repository's, sent the user to a two-hour build
        what = ("not a folder" if model_dir.exists() else "no such folder" if not model_dir.is_symlink()
                else "a symbolic link that leads to no folder (dangling, or a loop)")
        raise DaemonConfigError(f"{model_dir}: {what}{_where_read(model_dir, source, from_folder)}"
                                f"{service_hint(model_dir)}",
                                key="estimator.session.model_dir")
    if not any(model_dir.glob("*.onnx")):
        raise DaemonConfigError(f"{model_dir} holds no *.onnx graphs (make model builds ./models)",
                                key="estimator.session.model_dir")
    _check_optional_model_files(config, model_dir)


def _check_optional_model_files(config: DaemonConfig, model_dir: Path) -> None:
    """A part the config turns ``on`` needs its file in the model folder. The estimator refuses it, but it is
    built only once the rig opens: such a config passed ``--validate-config``, loaded its model, and exited 2
    when the camera came (or never, waiting for one that does not)."""
    est = config.estimator
    if est.joints3d.skeleton_prior == "on" and not (model_dir / PRIOR_FILE).is_file():
        raise DaemonConfigError(f"'on', but {model_dir} has no {PRIOR_FILE} (make one with python -m "
                                "training.skeleton_prior, or set 'auto' or 'off')",
                                key="estimator.joints3d.skeleton_prior")
    if est.novel_view.enabled and est.novel_view.painter == "on" \
            and NovelPainter.find(model_dir, est.session.precision) is None:
        raise DaemonConfigError(f"'on' with novel_view.enabled, but {model_dir} has no {PAINTER_FILE} (make one "
                                "with python -m training.learnt_fill export, or set 'auto' or 'off')",
                                key="estimator.novel_view.painter")


def _check_rig_url(text: str, *, warn_of_rig: bool) -> None:
    """:func:`check_config` of ``rig.url``: it parses for its backend, a rig file it names loads and fits the
    joint stream, webcams come with their calibration. ``warn_of_rig``: the rig file's (or take's) warnings too.

    :raises DaemonConfigError: keyed ``rig.url``.
    """
    source = None
    try:
        source = drivers.create_rig_source(text)  # parses and checks the options; opens nothing
    except (drivers.RigConfigError, drivers.BackendNotAvailableError) as e:  # a rig file it cannot read, too
        raise DaemonConfigError(f"{e}{rig_url_hint(text)}", key="rig.url") from None
    except drivers.DriverError:
        pass  # a recording or device not there yet: the daemon waits for it, so the config is fine
    url = RigUrl.parse(text)
    # as the backend reads it ('+' a plus): parse_qs read rig=/etc/rig+1.json as '/etc/rig 1.json'
    rig_file = url.options.get("rig")
    if url.scheme == "opencv" and not rig_file:
        # Its rig without a file is a nominal one, for ghcal capture: 3D joints from it would be wrong.
        raise DaemonConfigError("opencv:// cameras need their calibration: add rig=/path/to/rig.json (ghcal solve)",
                                key="rig.url")
    manifest = Path(url.target) / MANIFEST if url.scheme == "replay" and url.target else None
    if manifest is not None and manifest.is_file():  # a take of such cameras carries the same nominal rig
        try:
            nominal = is_nominal_rig(read_manifest(manifest.parent, warn=warn_of_rig).rig)
        except drivers.DriverError:
            nominal = False  # the source reports a broken take itself, naming the field
        if nominal:
            raise DaemonConfigError(f"{manifest}: the take was recorded from opencv:// cameras without their "
                                    "calibration (rig 'opencv-uncalibrated'): its 3D joints would be wrong; record "
                                    "again with rig=/path/to/rig.json (ghcal solve)", key="rig.url")
    if isinstance(source, ReplayRigSource):
        # A take's images never change size: refused now, not at the rig's third open (as opencv:// videos are)
        size_error = source.size_error()
        if size_error is not None:
            raise DaemonConfigError(str(size_error), key="rig.url")
    if warn_of_rig and source is not None:
        # a sim:// rig is built in memory, read from no file: its source says what its open will (cheap: the rig
        # is built already, nothing rendered). A device's rig is known only once it opens: not said here
        source.warn_of_built_rig()
    if rig_file:  # a calibration of our own (ghcal): the stream announces its id and camera names
        try:
            rig = load_rig(rig_file, warn=warn_of_rig)
        except RuntimeErrorBase as e:
            raise DaemonConfigError(f"{e}{service_hint(rig_file)}", key="rig.url") from None
        names = [("rig id", rig.rig_id, MAX_RIG_ID_LEN)] + [("camera name", c.name, MAX_CAMERA_NAME_LEN)
                                                            for c in rig.pair]
        for what, name, limit in names:
            if not (0 < len(name) <= limit and name.isascii() and name.isprintable()):
                raise DaemonConfigError(f"{rig_file}: its {what} {name!r} cannot go in the joint stream's HELLO "
                                        f"(printable ASCII, at most {limit} characters)", key="rig.url")
        if url.scheme == "opencv":
            _check_video_sizes(url, rig_file, rig)


def _check_video_sizes(url: RigUrl, rig_file: str, rig: Rig) -> None:
    """``opencv://`` videos against the rig file: a video's size, which its container states, is known without
    opening a camera, and no retry changes it (the daemon would stop on it at the rig's third open). Live cameras
    are judged when they open (the daemon's ``SIZE_MISMATCH_OPENS``). A still image, which the open refuses, is
    refused here too: it passed, and the start stopped on it.

    :raises DaemonConfigError: keyed ``rig.url``, naming the video, the rig file and both sizes (or the option).
    """
    for camera, option in zip(rig.pair, ("first", "second")):
        spec = url.options.get(option)
        if not spec or not is_video_file(spec) or not os.path.isfile(spec):
            continue  # a device, a stream, an image sequence, a missing file (the open names it)
        if is_still_image(spec):
            raise DaemonConfigError(still_image_message(option, redact_url(spec), camera.name), key="rig.url")
        size = video_size(spec)
        if size is not None and size != (camera.width, camera.height):
            raise DaemonConfigError(rig_size_message(camera.name, redact_url(spec), size, (camera.width, camera.height),
                                                     rig_file=rig_file, live=False), key="rig.url")


def _where_url_read(why: str, url: str, source: str | os.PathLike | None, from_folder: Collection[str]) -> str:
    """The hint of :func:`_where_read` for the error ``why`` of the rig URL ``url`` when it names a path written
    relative in the config file (``drivers.url_paths`` read it from the file's folder), outside the URL it quotes
    (which holds all of them). Not for one written absolute: a config under /etc/ghnerf was told of relative paths it
    did not have."""
    named = why
    # every form a message quotes the URL in, repr first: its escapes (a backslash doubled, a control character
    # written \x1b) kept the URL, and the path in it, in the text, and the hint came for an option's error
    for form in (repr(redact_url(url)), shown_url(url), redact_url(url), url):
        named = named.replace(form, "")
    if source is not None and any(path in named or shown(path) in named for path in from_folder):
        return f" (a relative path in {source} is read from its folder, {config_folder(source)})"
    return ""


def _where_read(folder: Path, source: str | os.PathLike | None, from_folder: Collection[str]) -> str:
    """Where a model folder that is not there was looked for, when that is not plain from the path."""
    if not folder.is_absolute():  # not from a file (the default, where the file leaves model_dir out)
        return (f", read from the current directory {Path.cwd()}: give the folder in the config file (a relative "
                "path there is read from the file's folder) or an absolute one")
    if source is not None and any(folder == Path(path) for path in from_folder):  # written relative, not absolute
        return f" (a relative path in {source} is read from its folder, {config_folder(source)})"
    return ""


def check_model(config: DaemonConfig) -> str:
    """What the start does with the model before READY, for ``--validate-config``: load it (:func:`load_model`:
    every graph the settings run, checked against the model contract) and build the estimator once for a stand-in
    rig (:func:`check_estimator`), so settings the model cannot serve fail the check, not the start (exit 2 before
    READY). Opens no camera and no sink. ``check_config`` runs first: a missing folder is named by it.

    :returns: one line saying what was checked.
    :raises DaemonConfigError: keyed ``estimator.session`` (does not load) or ``estimator`` (does not fit).
    """
    session = load_model(config)
    check_estimator(session, config)
    files = list(session.files.values())
    precision = "+".join(sorted({f.precision for f in files}))
    contract = session.contract
    parts = list(session.graphs) + [name for name, part in (("skeleton prior", session.skeleton_prior),
                                                            ("novel-view painter", session.novel_painter))
                                    if part is not None]
    # the fill and the crop turn search the estimator runs (an unset roi.pad_fill is the model's, an unset
    # roi.turn_search on where the model has encoder heatmaps): the config printed says null there
    roi = config.estimator.beside_model(contract.frame_padding, contract.encoder_heatmaps).roi
    return (f"model: {files[0].path.parent} ({contract.variant}, {precision}, {contract.width}x{contract.height}; "
            f"{', '.join(parts)}) loaded, the estimator settings fit it (roi.pad_fill {roi.pad_fill}, "
            f"roi.turn_search {'on' if roi.turn_search else 'off'})")


def read_checked_config(path: str, *, warn_of_rig: bool = False) -> DaemonConfig:
    """Load the config file and run :func:`check_config` on it; every error names the file and the key."""
    config, from_folder = load_daemon_config_noting_paths(path)
    try:
        check_config(config, path, from_folder, warn_of_rig=warn_of_rig)
    except DaemonConfigError as e:
        raise DaemonConfigError(str(e), key=str(path)) from None
    return config


def _set_log_level(config: DaemonConfig) -> None:
    logging.getLogger().setLevel(getattr(logging, config.log_level.upper()))


def _setup_logging(level: str) -> None:
    # Under systemd the journal stamps every line itself; elsewhere the time helps.
    fmt = "%(levelname)s %(name)s: %(message)s" if os.environ.get("JOURNAL_STREAM") else \
        "%(asctime)s %(levelname)s %(name)s: %(message)s"
    logging.basicConfig(level=getattr(logging, level.upper()), format=fmt, stream=sys.stderr, force=True)


class _StopOnSignal:
    """SIGTERM / SIGINT set ``stop`` from a thread of this class, never from the signal handler.

    Python runs a handler on the main thread between two bytecodes, possibly inside ``stop.wait()`` while
    that thread holds the Event's lock (a plain Lock, not reentrant): ``stop.set()`` there would wait for
    ever, and systemd would SIGKILL the daemon with its sinks unflushed. (Handing ``set`` to a new thread
    is no better: starting one takes threading's own locks.) So the handler only writes the signal's
    number to a pipe, which takes no lock; the thread reads it, logs it and sets ``stop``, which wakes
    the loop's waits at once. A context manager: the handlers are put back (``ignore_after``: set to ignore the
    signals, for a process on its way out) and the pipe closed on exit.
    """

    def __init__(self, stop: threading.Event, signums: Sequence[int] = early_sighup.STOP_SIGNALS, *,
                 ignore_after: bool = False) -> None:
        self._stop = stop
        # on exit, ignore the signals rather than put back what they replaced: for the process's own stop
        self._ignore_after = ignore_after
        #: the first signal received (set before ``stop``), for a caller whose exit status names it
        self.received: int | None = None
        self._signums = tuple(signums)
        self._previous: dict[int, object] = {}
        self._read_fd, self._write_fd = os.pipe()
        os.set_blocking(self._write_fd, False)  # a full pipe (a burst of signals) must not block the handler
        self._thread = threading.Thread(target=self._watch, name="ghnerf-signals", daemon=True)

    def __enter__(self) -> "_StopOnSignal":
        self._thread.start()
        for signum in self._signums:
            self._previous[signum] = signal.signal(signum, self.handler)
        early = early_sighup.take_stop()  # one during the imports or the config read: stop as for one now
        if early is not None:  # (not in a handler: set here, so that the caller starts nothing for nothing)
            self._note(early)
            self._stop.set()
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, signal.SIG_IGN if self._ignore_after else previous)  # type: ignore[arg-type]
        os.close(self._write_fd)  # the thread reads the end of the pipe and returns
        self._thread.join(timeout=5)
        os.close(self._read_fd)

    def handler(self, signum: int, _frame: object) -> None:
        try:
            os.write(self._write_fd, bytes([signum]))
        except OSError:  # full: the numbers already in it stop the daemon
            pass

    def _note(self, signum: int) -> None:
        logging.getLogger("ghnerf.daemon").info("%s received: stopping", signal.Signals(signum).name)
        if self.received is None:
            self.received = signum

    def _watch(self) -> None:
        while data := os.read(self._read_fd, 64):
            for signum in data:
                self._note(signum)
            self._stop.set()


def main(argv: Sequence[str] | None = None) -> int:
    # Already installed on import in ghnerf-daemon; here for any other caller, put back on return.
    installed_here = early_sighup.install()
    try:
        return _main(argv)
    finally:
        # a mode that installed no stop handlers to take it (--print-example-config, a usage error, a config the
        # start refused) meets a stop recorded during its imports as before it was recorded: it was dropped
        early_sighup.release_stop()
        if early_sighup.is_daemon_process():
            # On its way out, as _StopOnSignal leaves SIGTERM and SIGINT: the finalization resets the recording
            # handler to SIGHUP's default, and a reload landing then killed it (restarted: RestartForceExitStatus).
            signal.signal(signal.SIGHUP, signal.SIG_IGN)
        elif installed_here:
            early_sighup.uninstall()


def _print_json(data: Any) -> int:
    """Print ``data`` as JSON; a reader that stopped early (``| head``) is not an error (it was a
    BrokenPipeError traceback, at the print or at the interpreter's last flush)."""
    try:
        print(json.dumps(data, indent=2), flush=True)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the interpreter's last flush would fail again
        os.close(devnull)
    return 0


@contextlib.contextmanager
def _stdout_for_the_json_alone() -> Iterator[None]:
    """File descriptor 1 points at stderr while the checks run, so stdout carries the JSON printed after them and
    nothing else: depthai's logger writes to the process's stdout as it loads and opens a device (in a container
    without USB, ``[depthai] [warning] USB protocol not available ...``), and ``--validate-config > full.json`` or
    ``--measure-floor | jq`` read that line first, not JSON. A closed stdout or stderr is left as it is."""
    saved: int | None = None
    try:
        sys.stdout.flush()
        saved = os.dup(1)
        os.dup2(2, 1)
    except (OSError, ValueError):  # fd 1 or 2 closed, or sys.stdout a closed file: nothing to guard
        if saved is not None:
            os.close(saved)
        saved = None
    try:
        yield
    finally:
        if saved is not None:
            # what was buffered meanwhile goes out now, to stderr, not after the switch back: Python's and C's stdio
            with contextlib.suppress(OSError, ValueError):
                sys.stdout.flush()
            with contextlib.suppress(OSError, AttributeError):  # no C library to ask (not Linux or macOS)
                ctypes.CDLL(None).fflush(None)
            os.dup2(saved, 1)
            os.close(saved)


def _validate(path: str, *, with_model: bool) -> int:
    """``--validate-config``: the config in full on stdout (JSON), then on stderr one line saying what was checked.

    :raises DaemonConfigError: naming the file and the key.
    """
    early_sighup.release_stop()  # no stop handlers here: a stop during the imports, and any from now on, kills
    # the rig's notes on stderr beside its warnings, bare (no logging is set up here: Python showed the warnings
    # only), a rig file's and a rig built in memory's (sim://, said by its source as its open says it); depthai may
    # log to stdout
    with _stdout_for_the_json_alone(), rig_messages_on_stderr(), log_on_stderr(rig_source_log):
        config = read_checked_config(path, warn_of_rig=True)  # no rig opens to warn of it
        checked = "model: not loaded (--no-model), its folder holds graph files"
        if with_model:
            try:
                checked = check_model(config)
            except DaemonConfigError as e:
                raise DaemonConfigError(str(e), key=str(path)) from None
    status = _print_json(config_to_dict(config))
    # this runs outside the unit's sandbox, so it sees paths the service will not: say so, but pass (the config
    # may be meant for a run from a shell)
    for line in sandbox_warnings(config):
        print(f"{PROG}: warning: {path}: {line}", file=sys.stderr)
    print(f"{PROG}: {path}: ok; {checked}", file=sys.stderr)
    return status


def _measure_floor(path: str, pairs: int) -> int:
    """``--measure-floor``: the measurement as JSON on stdout, what to set on stderr; 1 when it could not be taken,
    128 + the signal's number when SIGTERM or SIGINT stopped it (130 Ctrl-C, 143 SIGTERM: the shell's figures).

    :raises DaemonConfigError: naming the file and the key (a bad config, a model that does not load, a rig the
        model cannot run on, cameras that deliver another size than the rig's before any pair: what the start exits
        2 for).
    """
    with _stdout_for_the_json_alone():  # a depthai:// URL loads depthai, which may log to stdout
        config = read_checked_config(path)
    stop = threading.Event()
    # as the daemon stops: the signal sets ``stop``, looked at between two reads, so the rig and the estimator
    # close by their ``with`` (a SIGTERM from systemd or timeout killed it with neither closed; Ctrl-C's
    # KeyboardInterrupt could land inside a close). Ignored on the way out, as the daemon's: a second Ctrl-C as it
    # exited raised KeyboardInterrupt there (a traceback)
    with _StopOnSignal(stop, ignore_after=early_sighup.is_daemon_process()) as signals:
        try:
            with _stdout_for_the_json_alone():  # and as it opens and runs the device
                m = measure_floor_of_config(config, pairs, load_model=load_model, stop=stop)
        except DaemonConfigError as e:
            raise DaemonConfigError(str(e), key=str(path)) from None
        except FloorMeasureStopped as e:
            signum = signals.received or signal.SIGTERM  # (set before stop: never None here)
            print(f"{PROG}: {path}: {signal.Signals(signum).name} received: {e}", file=sys.stderr)
            return 128 + signum
        except (FloorMeasureError, drivers.DriverError) as e:
            print(f"{PROG}: {path}: {e}", file=sys.stderr)
            return 1
    status = _print_json(m.to_json())
    print(f"{PROG}: {path}: the lower foot's joints stood a median {m.median_m:.3f} m above the floor over "
          f"{len(m.heights_m)} pairs (the floor check read {m.median_m - m.foot_standing_m:+.3f} m with "
          f"estimator.joints3d.foot_standing_m {m.foot_standing_m:g}): set it to {m.suggested_m:g}",
          file=sys.stderr)
    return status


def _main(argv: Sequence[str] | None) -> int:
    args = build_parser().parse_args(argv)
    if args.print_example_config:
        return _print_json(EXAMPLE_CONFIG)
    if not args.config:
        print(f"{PROG}: error: --config is required (--print-example-config prints one to start from)",
              file=sys.stderr)
        return 2
    # inf (or 1e12) passed "> 0", then killed the stop timer's thread with an OverflowError: an unbounded run
    if args.max_seconds is not None and not 0 < args.max_seconds <= threading.TIMEOUT_MAX:
        print(f"{PROG}: error: --max-seconds must be > 0 and at most {threading.TIMEOUT_MAX:g}, "
              f"got {args.max_seconds}", file=sys.stderr)
        return 2
    if args.measure_floor is not None and (args.validate_config or args.max_seconds is not None):
        print(f"{PROG}: error: --measure-floor runs on its own (not with --validate-config or --max-seconds)",
              file=sys.stderr)
        return 2
    if args.measure_floor is not None and args.measure_floor < 1:
        print(f"{PROG}: error: --measure-floor: PAIRS must be at least 1, got {args.measure_floor}", file=sys.stderr)
        return 2
    if args.no_model and not args.validate_config:
        print(f"{PROG}: error: --no-model goes with --validate-config (the daemon itself needs its model)",
              file=sys.stderr)
        return 2
    try:
        if args.validate_config:
            return _validate(args.config, with_model=not args.no_model)
        if args.measure_floor is not None:
            return _measure_floor(args.config, args.measure_floor)
        early_sighup.take()  # a SIGHUP until now: the file is read now
        config = read_checked_config(args.config)  # as a reload checks it: what starts also reloads
    except DaemonConfigError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    _setup_logging(config.log_level)
    faulthandler.enable()  # a crash inside onnxruntime or depthai leaves its stack in the journal

    stop = threading.Event()
    daemon = Daemon(config, reload_config=lambda: read_checked_config(args.config), on_reload=_set_log_level)

    # SIGHUP only sets a plain flag, taking no lock either (the reload logs itself).
    previous_hup = signal.signal(signal.SIGHUP, lambda _signum, _frame: daemon.request_reload())
    if early_sighup.take():  # one since the config was read (recorded, not fatal): the file may have changed
        logging.getLogger("ghnerf.daemon").info("SIGHUP received while starting: reloading the config once running")
        daemon.request_reload()
    if args.max_seconds is not None:
        timer = threading.Timer(args.max_seconds, stop.set)
        timer.daemon = True
        timer.start()
    try:
        # In ghnerf-daemon itself, a stop signal after the stop (systemctl stop, then kill; Ctrl-C twice) finds the
        # handlers ignoring it as the process exits: put back, their defaults killed it (143) or raised
        # KeyboardInterrupt in the exit. SIG_IGN outlives the interpreter's finalization; a Python handler does not.
        with _StopOnSignal(stop, ignore_after=early_sighup.is_daemon_process()):
            return daemon.run(stop)
    except DaemonStartError as e:
        print(f"{PROG}: error: {e}", file=sys.stderr)
        return 2
    finally:
        signal.signal(signal.SIGHUP, previous_hup)


if __name__ == "__main__":
    sys.exit(main())

