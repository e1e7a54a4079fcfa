"""The main job on the simulated rig (``make demo``): frame pairs -> estimated joints -> a joint stream.

Opens a rig by URL (default: the simulated two-camera rig), loads the model (the
``models`` folder by default; ``--model-dir``, ``--config runtime.json``) and, for a few
seconds of real time, runs :class:`ghnerf_runtime.estimator.Estimator` on the pairs the
rig delivers:

* each estimated pair's 3D joints (rig frame, metres, with confidence) are streamed
  through a joint-stream sink (``file://`` JSON lines, ``OUT/joints.jsonl``, by default);
  a joint the estimator did not find is sent as missing (confidence 0);
* the estimator is slower than 30 fps on a 2-core machine. Under the rig's ``latest``
  pairing policy (the ``sim://`` default) the demo estimates the newest pair the rig has
  delivered and counts the older ones it skipped, so it reports dropped pairs instead of
  falling behind; under ``policy=all`` (e.g. ``replay://``) it estimates every pair. The
  stream numbers the frames it sends (seq 0, 1, 2...), so a skipped pair leaves no gap in it;
* at the end it prints pairs delivered / estimated / skipped, the estimator latency
  (median and p99 of ``PairResult.timing_ms["total"]``), the fraction of joints found
  and, when the frames carry the simulator's ground truth, the accuracy of the estimates
  against it (MPJPE in mm over the joints found; 2D PCK@0.2 over both views);
* the daemon's calibration check (``firmware_host.daemon.calibration_watch``, at the
  daemon's default ``health`` settings) runs on the estimates: while it finds the rig's
  calibration suspect (the views no longer meet in 3D, or the feet have left the floor) the
  frames streamed (and a protocol sink's STATUS packets) carry ``CALIBRATION_SUSPECT`` as the daemon's do, the
  console says when the
  verdict changes, with the symptom's words, and the summary says how it stands at the end
  (or that too few pairs were measured to judge);
* the last estimated pair is written as a PNG (``OUT/sim_pair.png``) with the estimated
  2D joints (magenta crosses and limbs) over the ground truth (dots, yellow limbs), a red
  band with the symptoms across its foot while the calibration is suspect, and
  its estimated 3D joints are printed next to the ground truth.

A camera that vanishes or falls silent (no pair within a second; five for the first pair) mid-run ends the
reading too: the summary of the pairs before it, then one line, ``error: the rig failed after N pairs: ...``
naming the camera, exit status 2 (until session 62 only ``stopping: ...`` among the summary's lines, exit 0: a
loose cable passed the bring-up's camera check). A recording that ends (``replay://``) is no failure; a
``record+`` take whose write failed as it closed is (one line after the summary, exit 2; since session 74), and is said
(one line, exit 2) even where a stop lands after the sink's close: before the take's close, or in the summary; a run
ended by an error (cameras of another size than the rig's, a sink that will not open) says it before the error (it
went unsaid, the take ``complete: false``).

A ``file://`` ``--sink`` on a file the run reads (the rig URL's ``rig=``, ``bvh=`` or video files, the ``--config``
file) or on ``OUT/sim_pair.png`` is a usage error before anything is opened, as the daemon refuses its sinks there
(``ghnerf_runtime.cli.output_path.output_clash``); so is one on a folder, in a folder that is not there or that this
user cannot look up (a folder on its path it may not search: said so, with the error's words, not 'does not exist'),
or one this user may not write (since session 74: the sink, which tries again what it cannot open, failed the run only
after the model load and the run), and any ``--sink`` its parser refuses (an unknown scheme, ``udp://`` without a
host, a bad ``baud=``, an unknown option: the daemon's config check, which opens nothing).

Ctrl-C stops the reading and still prints the summary (exit 0); SIGTERM (``timeout``, ``kill``: how a
``record+`` take is often ended) does the same, a recorder closing its take complete, and exits 143 with one
line. Either before the first pair (the motion loop's first render, the model load) exits 130 or 143. A ``record+``
take that fails as it closes (its last fsync: ``complete: false``) ends any run with exit 2 and one error line,
a stopped one included. A second Ctrl-C or SIGTERM, from the first stop until the take is closed (the sink's close,
the take's and the lines between them), is dropped: the first stop is the one reported, with its summary. The first
stop of a run that read to its end, landing between the sink's close and the take's, waits for the take's close and
check, then ends the run as one in that close does (130 or 143; a failed take: exit 2). One landing as an error
leaves the run, before or after the take's close, is dropped: the error is said, exit 2
(``ghnerf_runtime.cli.error_leaving``).

Without a model in the model folder the demo stops with a one-line error naming the
folder and the command that builds it. ``--truth-only`` skips the model: the simulator's
ground-truth joints are streamed and printed instead, every one labelled ground truth.
"""
from __future__ import annotations

import argparse
import contextlib
import errno
import os
import signal
import statistics
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

import drivers
from drivers.sim.demo import draw_truth
from drivers.url import redact_url
from drivers.url_paths import url_files
from drivers.wrappers import innermost_url
from firmware_host.daemon.calibration_watch import CalibrationWatch, FloorWatch, HandednessWatch, fixes, symptoms
from firmware_host.daemon.config import CALIBRATION_MAX_FLOOR_M, CALIBRATION_MAX_MIRROR, CALIBRATION_MAX_PX, \
    CALIBRATION_WINDOW
from firmware_host.errors import FirmwareHostError, SinkConfigError
from firmware_host.joint_frames import FrameNumbers, announced_scene_flags, capture_time_us, estimate_frame, truth_frame
from firmware_host.protocol.constants import MAX_RIG_ID_LEN
from firmware_host.protocol.messages import JointFrame
from firmware_host.sinks import Sink, check_sink_url, open_sink
from firmware_host.sinks.file_sink import FileSink
from firmware_host.sinks.registry import STAND_IN_CAMERAS
from firmware_host.sinks.url import parse_url
from ghnerf_runtime.body25 import JOINT_NAMES, LIMBS
from ghnerf_runtime.cli.error_leaving import ErrorLeaving, status_keeping_the_error
from ghnerf_runtime.cli.model_folder import model_dir_source, named_by_source
from ghnerf_runtime.cli.output_path import OutputPathError, output_clash, ready_output
from ghnerf_runtime.cli.recorded_take import RecordedTake, status_saying_a_failed_take
from ghnerf_runtime.cli.seconds import positive_seconds
from ghnerf_runtime.cli.sigterm import (closed_with_stops_deferred, exit_status, sigterm_as_interrupt, stop_signal,
                                      stop_signals_deferred, stop_signals_noted, stop_words)
from ghnerf_runtime.cli.simdata import Accuracy
from ghnerf_runtime.config import EstimatorConfig, load_config
from ghnerf_runtime.errors import ConfigError, ImageWriteError, ModelError, ModelLoadError
from ghnerf_runtime.estimator import Estimator, PairResult, check_model_files
from ghnerf_runtime.image_write import write_image_atomic
from ghnerf_runtime.path_check import shown, user_path, user_path_as_path

DEFAULT_URL = "sim://?fps=30&seed=0&motion=wave"
#: How long the first pair is waited for, and each one after it: an OAK streams a second or two after its
#: open, so a camera silent for a second before its first pair has not failed yet (the daemon waits rig.stall_s).
FIRST_PAIR_TIMEOUT_S = 5.0
PAIR_TIMEOUT_S = 1.0
#: said after the docstring's first line in --help: the same run checks a real rig's cameras
HELP_EPILOGUE = ("Any rig URL runs the same way (a real rig's cameras checked before calibrating them: "
                 "docs/bring-up.md, step 2).")
#: Colour of the estimated joints in the PNG (BGR magenta; the ground truth is red/blue/green + yellow).
ESTIMATE_BGR = (255, 0, 255)
#: The band across the PNG's foot while the calibration is suspect (BGR red, white words on it).
SUSPECT_BGR = (0, 0, 255)
#: Height in pixels of that band (two lines of words).
SUSPECT_BAND_PX = 46
#: Links followed in a chain before the OS gives up (ELOOP): Linux's MAXSYMLINKS.
MAX_LINKS_FOLLOWED = 40
#: The console script (pyproject.toml [project.scripts]) and the module run (``make demo``): usage lines and
#: errors name the one the user ran, so the command they show can be typed again as it is.
SCRIPT = "ghnerf-demo"
MODULE = "python -m firmware_host.demo"


def prog_name(argv0: str | None = None) -> str:
    """The command that was run, from ``argv0`` (default ``sys.argv[0]``): :data:`SCRIPT` when it is the console
    script (its wrapper, or a link to it; ``.exe`` on Windows), else :data:`MODULE` (``-m`` puts the module's
    file path there, which names no command)."""
    name = Path(sys.argv[0] if argv0 is None else argv0).name
    return SCRIPT if name.removesuffix(".exe") == SCRIPT else MODULE


class DemoError(Exception):
    """A problem the user fixes (no model, bad config): printed as one line, exit status 2."""


# ------------------------------------------------------------------ model
def _estimator_config(args: argparse.Namespace) -> EstimatorConfig:
    try:
        cfg = load_config(args.config) if args.config else EstimatorConfig()
    except ConfigError as e:
        raise DemoError(f"config: {e}") from None
    if args.model_dir is not None:
        cfg = replace(cfg, session=replace(cfg.session, model_dir=str(args.model_dir)))
    return cfg


def _how_to_build(model_dir: str) -> str:
    out = "models" if Path(model_dir).resolve() == Path("models").resolve() else model_dir
    make = "`make model` or " if out == "models" else ""
    return f"build it with {make}`python -m training.pipeline --out {out}` (or run with --truth-only)"


def _check_model_dir(args: argparse.Namespace, cfg: EstimatorConfig) -> None:
    """Fail early (before the rig is opened) when the model folder is none, or lacks a graph the settings run:
    checked as ``ghnerf-run --validate-config`` checks it (:func:`check_model_files`, nothing loaded), and named
    by what gave it (``--model-dir``, the config's ``session.model_dir``). A file given as ``--model-dir`` was
    "the folder does not exist", naming no option."""
    model_dir = cfg.session.model_dir
    try:
        check_model_files(cfg)
    except ModelError as e:
        where = model_dir_source(args.model_dir, args.config, model_dir) or model_dir
        # building a model helps where there is none; a file given as the folder is a wrong path
        build = isinstance(e, ModelLoadError) and not (Path(model_dir).exists() and not Path(model_dir).is_dir())
        hint = f"; {_how_to_build(model_dir)}" if build else ""
        raise DemoError(f"no model in {named_by_source(where, e, model_dir)}{hint}") from None


def _load_estimator(rig, cfg: EstimatorConfig) -> Estimator:
    t0 = time.monotonic()
    try:
        estimator = Estimator.from_config(rig, cfg)
    except ModelError as e:
        hint = f"; {_how_to_build(cfg.session.model_dir)}" if isinstance(e, OSError) else ""
        raise DemoError(f"cannot load the model in {cfg.session.model_dir}: {e}{hint}") from None
    d = estimator.session.describe()
    folder = Path(next(iter(d["files"].values()))["path"]).parent
    print(f"model {folder} ({d['variant']} {d['resolution']}, graphs {', '.join(d['files'])}; "
          f"3D method {cfg.joints3d.method}, crops padded {estimator.config.roi.pad_fill!r} past the frame) loaded "
          f"in {time.monotonic() - t0:.2f} s")
    return estimator


# ------------------------------------------------------------------ accuracy
@dataclass
class _Tally:
    """What the estimated pairs produced, pooled for the summary (accuracy: ``cli.simdata.Accuracy``)."""

    live: bool = True  # False where capture times are not this run's clock (a replay keeping the recorded ones)
    totals_ms: list[float] = field(default_factory=list)
    capture_to_joints_ms: list[float] = field(default_factory=list)
    found: list[np.ndarray] = field(default_factory=list)  # (25,) per estimated pair
    accuracy: Accuracy = field(default_factory=Accuracy)  # pairs with 3D truth only
    several_people: int = 0  # estimates flagged several_people (streamed with SEVERAL_PEOPLE)

    def add(self, pair: drivers.FramePair, result: PairResult, done_ns: int) -> None:
        self.totals_ms.append(float(result.timing_ms["total"]))
        self.capture_to_joints_ms.append((done_ns - pair.frames[0].timestamp_ns) / 1e6)
        self.found.append(~np.asarray(result.missing, bool))
        self.several_people += int(bool(result.several_people))
        if pair.joints_3d is not None:
            truths = [f.truth for f in pair.frames]
            with_2d = all(t is not None for t in truths)
            self.accuracy.add_truth(result, pair.joints_3d,
                                    np.stack([t.joints_2d for t in truths]) if with_2d else None,
                                    np.stack([t.visible for t in truths]) if with_2d else None,
                                    frame=(0, pair.sequence))  # a skipped pair breaks the jitter's chain

    def report(self) -> list[str]:
        lines = []
        if not self.totals_ms:
            return ["no pair was estimated"]
        t = np.asarray(self.totals_ms)
        c = np.asarray(self.capture_to_joints_ms)
        lines.append(f"estimator latency (timing_ms total): median {np.median(t):.1f} ms, "
                     f"p99 {np.percentile(t, 99):.1f} ms; capture to joints: "
                     + (f"median {np.median(c):.1f} ms, p99 {np.percentile(c, 99):.1f} ms" if self.live else
                        "not measured (a replay with keep_time=1 or at another speed: its capture times are not this run's)"))
        found = np.asarray(self.found)
        lines.append(f"estimated joints found: {found.mean():.1%} ({int(found.sum())} of {found.size}; "
                     f"the rest are streamed as missing)")
        if self.several_people:  # a second person in view (sim://?second=): what a robot would be told
            lines.append(f"{self.several_people} of the {len(self.totals_ms)} pairs estimated were flagged "
                         "several_people, streamed with SEVERAL_PEOPLE (two people in the maps the joints came "
                         "from: docs/two-people.md)")
        acc = self.accuracy.summary()
        if not acc:
            lines.append("accuracy: the frames carry no ground truth; not measured")
            return lines
        text = f"accuracy of the estimate vs ground truth: {_mpjpe_words(acc)}"
        if "pck@0.2" in acc:
            text += (f"; 2D PCK@0.2 {acc['pck@0.2']:.3f} over {acc['pck_evaluated']} visible joints in both views "
                     f"(not found = wrong)")
        if np.isfinite(acc.get("jitter_mm", float("nan"))):
            text += f"; jitter {acc['jitter_mm']:.1f} mm per pair^2"
        elif "jitter_mm" in acc:  # a host too slow for the rig skips every other pair: the figure was left out unsaid
            text += "; jitter not measured: no joint found in three pairs in a row (a skipped pair breaks the chain)"
        lines.append(text)
        return lines


def _mpjpe_words(acc: dict) -> str:
    """The MPJPE part of the accuracy line. With no joint found there is no error to average: it printed
    "MPJPE nan mm over the 0 joints found" (a 16x16 sim:// image, a subject out of view)."""
    if acc["mpjpe_evaluated"] == 0:
        return f"MPJPE not measured: no joint found ({acc['mpjpe_pred_missing']} not found)"
    return (f"MPJPE {acc['mpjpe_mm']:.0f} mm over the {acc['mpjpe_evaluated']} joints found "
            f"({acc['mpjpe_pred_missing']} not found, not scored)")


# ------------------------------------------------------------------ calibration check
class _CalibrationCheck:
    """The daemon's calibration checks (the views' agreement, the feet on the floor, a mirror-image skeleton: the
    cameras' inputs exchanged) over the demo's estimates,
    with the daemon's default window and limits: a demo run on a rig of one's own is where a camera knocked since
    ``ghcal`` shows first, and its stream should say so as the daemon's would."""

    def __init__(self, window: int) -> None:
        self.view = CalibrationWatch(window, CALIBRATION_MAX_PX)
        self.floor = FloorWatch(window, CALIBRATION_MAX_FLOOR_M)
        self.handedness = HandednessWatch(window, CALIBRATION_MAX_MIRROR)
        self.flagged = 0  # estimates streamed with CALIBRATION_SUSPECT

    @property
    def suspect(self) -> bool:
        return bool(self.view.suspect or self.floor.suspect or self.handedness.suspect)

    def symptoms(self) -> str:
        """The suspect checks' words (``1.46 px > 0.8, feet 0.18 m below the floor > 0.1 m``); empty when none is."""
        return symptoms((self.view, self.floor, self.handedness))

    def fixes(self) -> str:
        """What to do about them (``recalibrate (ghcal)``; the cameras exchanged: swap their plugs or names)."""
        return fixes((self.view, self.floor, self.handedness))

    def band(self) -> tuple[str, ...]:
        """The picture's red band while suspect: what to do, then the symptoms (empty when not suspect)."""
        return (f"CALIBRATION SUSPECT: {self.fixes()}", self.symptoms()) if self.suspect else ()

    def add(self, pair_sequence: int, result: PairResult) -> str | None:
        """Count one estimate; returns the line to print when the verdict changes (else None)."""
        was = self.suspect
        self.view.add(result.reprojection_px_median)
        self.floor.add(result.lowest_foot_m)
        self.handedness.add(result.handedness)
        if self.suspect:
            self.flagged += 1
        if self.suspect == was:
            return None
        if self.suspect:
            return (f"pair {pair_sequence}: CALIBRATION SUSPECT ({self.symptoms()}): the frames streamed from here "
                    f"carry CALIBRATION_SUSPECT; {self.fixes()} (docs/calibration.md)")
        return f"pair {pair_sequence}: the calibration fits again"

    def _state(self, check: CalibrationWatch | FloorWatch | HandednessWatch, figure: str, limit: str) -> str:
        n = len(check.values)
        if n < check.window:  # no verdict before the window is full, as in the daemon
            return f"{n} of the {check.window} pairs it needs, not judged"
        return f"{figure} (median of the last {n} pairs, limit {limit})"

    def report(self, estimated: int) -> str:
        """The summary line: the verdict at the end, each check's figure, how many frames were flagged."""
        view, floor = self.view, self.floor
        peaks = f"peaks {view.median_px or 0.0:.2f} px apart"  # used only once the window is full
        hand = self.handedness
        mirror = f"handedness {hand.median or 0.0:+.2f}"  # used only once the window is full
        parts = [f"views' agreement: {self._state(view, peaks, f'{view.max_px:g} px')}",
                 f"feet: {self._state(floor, floor.words(), f'{floor.max_floor_m:g} m')}",
                 f"mirror image: {self._state(hand, mirror, f'-{hand.max_mirror:g}')}"]
        if self.suspect:
            verdict = f"SUSPECT ({self.symptoms()}): {self.fixes()} (docs/calibration.md)"
        elif any(len(c.values) >= c.window for c in (self.view, self.floor, self.handedness)):
            verdict = "fits"
        else:
            verdict = "not judged (too few pairs measured; run longer with --seconds)"
        flagged = (f"; {self.flagged} of the {estimated} frames streamed carry CALIBRATION_SUSPECT"
                   if self.flagged else "")
        return f"calibration check: {verdict}; {'; '.join(parts)}{flagged}"


# ------------------------------------------------------------------ pictures and tables
def _draw_estimate(image: np.ndarray, uv: np.ndarray, missing: np.ndarray) -> None:
    """Draw estimated joints in place: magenta limbs between found joints, a tilted cross per joint."""
    pts = np.clip(np.rint(np.nan_to_num(uv)), -10_000, 10_000).astype(int)
    for a, b in LIMBS:
        if not missing[a] and not missing[b]:
            cv2.line(image, tuple(pts[a]), tuple(pts[b]), ESTIMATE_BGR, 2, cv2.LINE_AA)
    for k, (u, v) in enumerate(pts):
        if not missing[k]:
            cv2.drawMarker(image, (int(u), int(v)), ESTIMATE_BGR, cv2.MARKER_TILTED_CROSS, 10, 2, cv2.LINE_AA)


def _draw_suspect(panel: np.ndarray, lines: tuple[str, ...]) -> None:
    """A red band across the foot of ``panel`` (in place) saying the calibration is suspect, what to do, and why
    (:meth:`_CalibrationCheck.band`)."""
    h = panel.shape[0]
    cv2.rectangle(panel, (0, h - SUSPECT_BAND_PX), (panel.shape[1] - 1, h - 1), SUSPECT_BGR, cv2.FILLED)
    for k, text in enumerate(lines):
        cv2.putText(panel, text, (10, h - SUSPECT_BAND_PX + 18 + 20 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    (255, 255, 255), 1, cv2.LINE_AA)


def _annotated(pair: drivers.FramePair, result: PairResult | None = None, suspect: tuple[str, ...] = ()) -> np.ndarray:
    """Both views side by side with what was drawn on them; ``suspect``: the calibration check's band lines while it
    finds the calibration suspect (a red band across each view's foot), empty otherwise."""
    panels = []
    for frame in pair.frames:
        panel = draw_truth(frame.image, frame.truth) if frame.truth is not None else frame.image.copy()
        cv2.putText(panel, f"{frame.camera}  pair {pair.sequence}", (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7,
                    (255, 255, 255), 2, cv2.LINE_AA)
        y = 48
        if result is not None:
            missing = np.asarray(result.missing_2d[frame.camera], bool)
            _draw_estimate(panel, result.joints_2d[frame.camera], missing)
            cv2.putText(panel, f"estimate: magenta x ({int((~missing).sum())}/25 joints)", (10, y),
                        cv2.FONT_HERSHEY_SIMPLEX, 0.55, ESTIMATE_BGR, 2, cv2.LINE_AA)
            y += 22
        if frame.truth is not None:
            cv2.putText(panel, "ground truth: dots, yellow limbs", (10, y), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                        (0, 255, 255), 2, cv2.LINE_AA)
        if suspect:
            _draw_suspect(panel, suspect)
        panels.append(panel)
    return np.hstack(panels)


def _print_joints(pair: drivers.FramePair, result: PairResult | None) -> None:
    truth = pair.joints_3d
    if result is None:
        if truth is None:
            return
        print("ground-truth BODY_25 joints of that pair, rig frame (m; x right, y down, z forward):")
        for name, (x, y, z) in zip(JOINT_NAMES, truth):
            print(f"  {name:10s} {x:+.3f} {y:+.3f} {z:+.3f}")
        return
    print("BODY_25 joints of that pair, rig frame (m; x right, y down, z forward):")
    print(f"  {'joint':10s} {'estimate':20s}   {'ground truth':20s}   error")
    for k, name in enumerate(JOINT_NAMES):
        est = "missing" if result.missing[k] else " ".join(f"{v:+.3f}" for v in result.joints_3d[k])
        line = f"  {name:10s} {est:20s}"
        if truth is not None:
            line += "   " + " ".join(f"{v:+.3f}" for v in truth[k])
            if not result.missing[k]:
                line += f"   {1000 * np.linalg.norm(result.joints_3d[k] - truth[k]):4.0f} mm"
        print(line)


# ------------------------------------------------------------------ main
def _sink_url(text: str) -> str:
    """A ``--sink`` value: an empty one (a ``"$UNSET"`` in a script) is refused; it was read as no --sink given and
    the joints went to the default file sink without a word."""
    if text == "":
        raise argparse.ArgumentTypeError("is empty: give a sink URL, or leave the option out for OUT/joints.jsonl")
    return text


def build_parser(prog: str | None = None) -> argparse.ArgumentParser:
    """The parser; ``prog`` (default :func:`prog_name`) heads its usage line and errors."""
    parser = argparse.ArgumentParser(prog=prog or prog_name(), description=__doc__.splitlines()[0] + " " + HELP_EPILOGUE)
    # the defaults are named: a rig's bring-up (docs/bring-up.md, step 2) runs this with its own --url and --out
    parser.add_argument("--url", default=DEFAULT_URL, help="rig URL (sim://, replay://DIR, depthai://, opencv://; "
                                                            "relative files read from the current directory; "
                                                            f"default: {DEFAULT_URL.replace('%', '%%')}, the "
                                                            "simulated rig)")
    parser.add_argument("--seconds", type=positive_seconds, default=3.0,
                        help="how long to read pairs (default: %(default)s)")
    parser.add_argument("--out", type=user_path_as_path, default=Path("out/demo"),
                        help="output folder: sim_pair.png (the last pair, whatever the rig) and the default sink's joints.jsonl "
                             "(default: %(default)s)")
    parser.add_argument("--sink", type=_sink_url, default=None,
                        help="joint-stream sink URL (default: file://OUT/joints.jsonl, rewritten each run)")
    parser.add_argument("--model-dir", type=user_path, default=None,
                        help="model folder (default: the --config's session.model_dir, else ./models)")
    parser.add_argument("--config", type=user_path, default=None, help="estimator config, JSON (docs/runtime.md)")
    parser.add_argument("--truth-only", action="store_true",
                        help="no model: stream the simulator's ground-truth joints instead of estimates")
    return parser


@contextlib.contextmanager
def _closed_on_an_error(sink: Sink) -> Iterator[Sink]:
    """``sink``, closed here when the block raises. A run that ends without an error closes it itself, its stop
    said (a second close here, its stops held and raised, raised a second Ctrl-C past the first stop's summary);
    one stopped by an error closes it here with the stop signals held: a Ctrl-C or SIGTERM landing in that close
    (it delivers what it holds queued, up to a second) was raised there in place of the error, its message and exit
    status lost. That error is the one reported; a stop noted there is dropped."""
    try:
        yield sink
    except BaseException:
        with stop_signals_deferred(then_raise=False):
            sink.close()
        raise


def _run(args: argparse.Namespace, prog: str) -> int:
    cfg = None
    if not args.truth_only:
        cfg = _estimator_config(args)
        _check_model_dir(args, cfg)
    if args.out.exists() and not args.out.is_dir():
        raise DemoError(f"--out {args.out}: is a file; give a folder for the demo's outputs")
    try:  # a path through a file or a link to nothing: was OSError's bare "[Errno 17] File exists"
        ready_output(args.out, "--out", "folder")
    except OutputPathError as e:
        raise DemoError(str(e)) from None
    if args.sink:
        sink_url = args.sink
    else:
        sink_path = (args.out / "joints.jsonl").resolve()
        sink_path.unlink(missing_ok=True)  # the file sink appends: keep this run only
        sink_url = sink_path.as_uri()  # percent-encoded: a space or "#" in --out stays part of the path

    scheme = innermost_url(args.url).partition("://")[0]
    # a camera URL may carry a password (rtsp://user:pass@..., token=): shown without it
    print(f"opening {redact_url(args.url)}"
          + (" (the first open pre-renders the motion loop; later opens use the cache)" if scheme == "sim" else ""))
    source = drivers.create_rig_source(args.url)
    take = RecordedTake(source, prog)
    # a stop landing after the reading, between the sink's close and the source's or in the summary, was said
    # "stopped", 130 or 143, of a take that failed; one landing as an error left, after the take's close, in the
    # error's place
    return status_keeping_the_error(lambda leaving: status_saying_a_failed_take(
        lambda: _read_and_summarise(args, prog, cfg, source, sink_url, take, leaving), take))


def _read_and_summarise(args: argparse.Namespace, prog: str, cfg: EstimatorConfig | None, source: drivers.RigSource,
                        sink_url: str, take: RecordedTake, leaving: ErrorLeaving) -> int:
    """The run on ``source``, opened here and closed however the run ends: the pairs read, estimated and streamed
    to ``sink_url`` for ``--seconds``, then the summary; the exit status. An error on its way out is noted in
    ``leaving`` as it leaves the reading."""
    stopped: KeyboardInterrupt | None = None  # the Ctrl-C or SIGTERM that ended the reading
    read_to_its_end = False  # the reading ended without an error or a stop on its way out (the close's raise)
    late_stop: KeyboardInterrupt | None = None  # one that landed in the close of a run that read to its end
    late_stops: list[KeyboardInterrupt] = []  # one that landed after the sink's close, before the take's
    # entered at the first stop, left once the take is closed: a second Ctrl-C or SIGTERM landing between the
    # closes (outside their own deferrals) was raised there, 130 or 143 without the summary, the take's close
    # skipped where it landed just before it. Noted and dropped: the first stop is the one reported. Entered too
    # as the reading ends without a stop: a first stop landing just before the take's close skipped it, the take
    # left complete: false; noted (late_stops), it is raised once the take is closed and checked. And as an error
    # leaves: a stop landing there skipped the close (the error is the one reported)
    second_stops_dropped = contextlib.ExitStack()
    try:
        estimator = None
        if cfg is not None:
            try:
                rig = source.rig  # known before open for sim:// and replay://: load first, so no backlog builds up
            except drivers.RigOperationError:
                rig = None
            if rig is not None:
                estimator = _load_estimator(rig, cfg)
        t0 = time.monotonic()
        source.open()
        print(f"open in {time.monotonic() - t0:.2f} s; cameras {list(source.rig.names)}, "
              f"baseline {source.rig.baseline:.2f} m")
        if cfg is not None and estimator is None:
            estimator = _load_estimator(source.rig, cfg)
        latest = source.pairing.policy is drivers.DropPolicy.LATEST
        tally = _Tally(live=source.live_timestamps)
        calibration = _CalibrationCheck(CALIBRATION_WINDOW)
        delivered, skipped, skews = 0, 0, []
        read_failed, failed_reads, first_failure = False, 0, ""  # a failed read since the last pair; all of them
        last_pair, last_result = None, None
        rig_failed: str | None = None  # a camera that vanished or fell silent mid-run: what the rig said of it
        stats_at_pair = source.stats  # the pairing counters at the open, then at the last pair (why_no_pair)
        numbers = FrameNumbers()  # the stream's seq: frames sent, not the pairs the rig skipped (a gap: lost)
        # The 2D joints are keyed by camera index (rig.pair order): announce those names in HELLO, with the
        # rig's id as the daemon does (unless the URL names one, or the id does not fit HELLO: then none).
        sink_kw = {"cameras": tuple(camera.name for camera in source.rig.pair)}
        if cfg is not None:  # HELLO says whether SOMEONE_ELSE means anything: the estimator's scan for others
            sink_kw["scene_flags"] = announced_scene_flags(cfg)
        rig_id = source.rig.rig_id
        if ("rig_id" not in parse_url(sink_url).query and 0 < len(rig_id) <= MAX_RIG_ID_LEN and rig_id.isascii()
                and rig_id.isprintable()):
            sink_kw["rig_id"] = rig_id
        with _closed_on_an_error(open_sink(sink_url, **sink_kw)) as sink:
            start = time.monotonic()
            deadline = start + args.seconds
            while time.monotonic() < deadline:
                # Ctrl-C: the summary of what ran, not a traceback. It lands in the estimate far more often than
                # in the read (the estimate is most of a pair's time), so it is caught around both.
                try:
                    try:
                        pair = source.read(timeout_s=PAIR_TIMEOUT_S if delivered else FIRST_PAIR_TIMEOUT_S)
                    except drivers.EndOfStream:
                        print("the rig's stream ended")
                        break
                    except (drivers.RigTimeoutError, drivers.RigDisconnectedError) as e:
                        print(f"stopping: {e}")
                        # the summary first, then the run fails (a loose cable in a camera check); a silent rig says
                        # why, as the daemon's warning does: a camera silent, out of sync or lagging (max_pending)
                        rig_failed = str(e) if isinstance(e, drivers.RigDisconnectedError) else (
                            f"{e}: {drivers.why_no_pair(stats_at_pair, source.stats, source.pairing)}")
                        break
                    except drivers.RigOperationError as e:
                        # A frame the rig could not deliver (a corrupt image in a take, one resized since its open)
                        # is raised once and the next read goes on, as the daemon reads on: one such
                        # frame ended the whole run. Again before a pair, or cameras of another size than the
                        # rig's (FrameSizeError): the rig itself failed. A record+ take that can no longer be
                        # written (RecordingError, disk full) is no lost frame: run on, the demo (the documented
                        # way to record a take) streamed for its --seconds while recording nothing.
                        if read_failed or isinstance(e, (drivers.FrameSizeError, drivers.RecordingError)):
                            raise
                        read_failed, failed_reads = True, failed_reads + 1
                        first_failure = first_failure or str(e)
                        print(f"skipped a frame: {e}")
                        continue
                    read_failed = False
                    # a capture time the stream cannot carry (a take's negative stamps kept) is refused before the
                    # model runs on it, as the daemon refuses it: it was refused only as its frame was made, the
                    # model and tracking run on it for nothing
                    capture_time_us(pair)
                    delivered += 1
                    stats_at_pair = source.stats
                    result = None
                    if estimator is not None:
                        result = estimator.estimate(pair.images, sequence=pair.sequence,
                                                    timestamp_s=pair.timestamps_ns[0] * 1e-9)
                    # A pair read (and estimated) is counted, streamed and kept as the last pair whole: a Ctrl-C
                    # landing there waits for it. It counted an estimate the sink never got ("9 estimated", 8
                    # sent), drew one pair's joints over the pair before it, or, in the send, escaped this loop
                    # as exit 130 without the summary.
                    with stop_signals_deferred():
                        if result is None:
                            frame = truth_frame(pair, sequence=numbers.take()) if pair.joints_3d is not None else None
                        else:
                            frame = _counted_estimate(pair, result, tally, calibration, sink, numbers)
                            last_result = result
                        if frame is not None:
                            sink.send(frame)
                        skews.append(pair.skew_ns / 1e6)
                        last_pair = pair
                except KeyboardInterrupt as e:  # SIGTERM too (main's sigterm_as_interrupt)
                    second_stops_dropped.enter_context(stop_signals_deferred(then_raise=False))
                    stopped = e
                    print(f"stopping: {stop_words(e)}")
                    break
            elapsed = max(time.monotonic() - start, 1e-9)
            # the sink delivers what it holds queued as it closes (up to a second: a file:// sink's last lines, a
            # slow serial link): a second Ctrl-C pressed there cut it short and ended the run without its summary,
            # 130 for a run the first Ctrl-C ended with 0. Raised after the close only when it is the first stop,
            # and only once the take is closed and checked (below): raised here, it went past both
            late_stop = closed_with_stops_deferred(sink.close, then_raise=stopped is None)
        sink_stats = sink.stats()
        stats = source.stats
        # under LATEST the rig hands out the newest pair and drops (counts) the older ones; an OAK's count
        # also holds the pairs lost whole from its host queue (drivers' pairs_dropped)
        skipped = stats.pairs_dropped
        delivered += skipped
        read_to_its_end = True
        second_stops_dropped.enter_context(stop_signals_noted(late_stops))
    except KeyboardInterrupt as e:
        if not read_to_its_end:  # before the pairs (the open, the model load): main says it
            raise
        # it landed as the noting above began: the late stop of a run that read to its end, as ghcal capture's.
        # Raised on from here, it skipped the summary of a run whose take failed (said, exit 2)
        second_stops_dropped.enter_context(stop_signals_deferred(then_raise=False))
        late_stops.append(e)
    except Exception as error:  # main says it (exit 2), once the take is closed, whatever stop lands meanwhile
        leaving.held(error, second_stops_dropped)
        raise
    finally:
        # a Ctrl-C or SIGTERM that lands in the close waits for it: a recorder writes what it holds queued and
        # rewrites its manifest complete: true, which the signal raised there tore (timeout's SIGTERM as --seconds
        # ran out, a second Ctrl-C pressed after the one that stopped the run). A stop that lands there is raised
        # once the take is whole only when it is the first: a stop caught above, or an error on its way, is the one
        # reported (its summary and exit status)
        with second_stops_dropped:
            closing_stop = closed_with_stops_deferred(
                source.close, then_raise=read_to_its_end and stopped is None and late_stop is None)
        if stopped is None:  # the first stop to land: in the sink's close, after it, in the take's close
            late_stop = late_stop or next(iter(late_stops), None) or closing_stop
    if late_stop is not None and take.failure() is None:
        raise late_stop  # main says it (130, 143); a failed take is said after the summary, 2

    rate = delivered / elapsed
    skew = f"median skew {statistics.median(skews):.2f} ms" if skews else "no pairs"
    print(f"the rig delivered {delivered} pairs in {elapsed:.1f} s ({rate:.1f} pairs/s), {skew}")
    if failed_reads:
        print(f"{failed_reads} frame(s) the rig could not deliver were skipped, the first: {first_failure}")
    if estimator is None:
        print("no model (--truth-only): every joint streamed and printed is GROUND TRUTH")
    else:
        estimated = len(tally.totals_ms)
        policy = ("newest pair first: older pairs waiting are skipped" if latest
                  else "pairing policy 'all': every pair estimated")
        print(f"pairs: {delivered} delivered, {estimated} estimated ({estimated / elapsed:.1f}/s), "
              f"{skipped} skipped ({policy}); latency, joints found and accuracy below are of the ESTIMATES")
        lost_frames = sum(stats.camera_gaps.values())
        if lost_frames:
            print(f"before pairing the rig lost {lost_frames} camera frames (see the driver counters)")
        for line in tally.report():
            print(line)
        print(calibration.report(estimated))
    # read again after close: a recorder (record+) writes what it still holds queued as it closes, and the
    # counters read before it showed frames_written short of what the take's manifest records
    print(f"driver counters: {source.stats}")
    print(f"sink {redact_url(sink_url)}: {sink_stats}")
    png = args.out / "sim_pair.png"
    suspect = calibration.band() if estimator is not None else ()  # as the check stood at the last estimate
    picture_problem: str | None = None
    if last_pair is not None:
        picture_problem = _write_picture(png, last_pair, last_result, suspect)
        _print_joints(last_pair, last_result)
    failed = False
    if picture_problem is not None:  # a full disk (libpng's "Write Error") was once not a word
        print(f"{prog}: error: could not write {picture_problem}", file=sys.stderr)
        failed = True
    if rig_failed is not None:
        print(f"{prog}: error: the rig failed after {delivered} pairs: {rig_failed}", file=sys.stderr)
        failed = True
    if take.say_failure():  # a record+ take: exit 0 said it was whole
        failed = True
    if sink_stats.submitted and not sink_stats.sent:  # a sink that never connected: say so in the status too
        print(f"{prog}: error: the sink {redact_url(sink_url)} sent none of the {sink_stats.submitted} frames "
              f"({sink_stats.connect_failures} failed connects; last error: {sink_stats.last_error})",
              file=sys.stderr)
        failed = True
    if failed:
        return 2
    if stopped is not None and stop_signal(stopped) == signal.SIGTERM:
        # Ctrl-C is a user ending the run and reading its summary (0); SIGTERM came from outside (timeout, a
        # supervisor), and its caller reads the shell's figure for it, as the other tools give it
        print(f"{prog}: stopped (SIGTERM); the summary above is of the pairs read until then", file=sys.stderr)
        return exit_status(stopped)
    return 0


def _counted_estimate(pair: drivers.FramePair, result: PairResult, tally: _Tally, calibration: _CalibrationCheck,
                      sink: Sink, numbers: FrameNumbers) -> JointFrame:
    """``result`` added to the summary's tally and to the calibration check (a change of its verdict printed and
    flagged on the sink), as the frame to stream."""
    tally.add(pair, result, time.monotonic_ns())
    change = calibration.add(pair.sequence, result)
    if change is not None:
        print(change)
        # a protocol sink's STATUS packets carry the flag too, as the daemon's do (its _sync_calibration); vmc://
        # has no STATUS
        set_suspect = getattr(sink, "set_calibration_suspect", None)
        if set_suspect is not None:
            set_suspect(calibration.suspect)
    return estimate_frame(pair, result, sequence=numbers.take(), calibration_suspect=calibration.suspect)


def _write_picture(png: Path, pair: drivers.FramePair, result: PairResult | None,
                   suspect: tuple[str, ...]) -> str | None:
    """The last pair drawn into ``png``, said on stdout, written whole or not at all (imwrite truncated an earlier
    picture first); where it could not be, why (``png`` named), else None."""
    try:
        write_image_atomic(png, _annotated(pair, result, suspect))
    except ImageWriteError as e:
        return f"{shown(e.path)}: {e.reason}"
    what = ("estimated 2D joints (magenta) over the ground truth (dots)" if result is not None
            else "its ground-truth 2D joints")
    if suspect:
        what += ", marked CALIBRATION SUSPECT"
    print(f"wrote {png} (pair {pair.sequence} with {what})")
    return None


def _refuse_ignored_flags(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """--truth-only runs no model: a --config or --model-dir given with it was neither read nor used (a config
    holding a NaN, or a folder that is not there, ran and exited 0)."""
    if not args.truth_only:
        return
    given = [flag for flag, value in (("--config", args.config), ("--model-dir", args.model_dir)) if value is not None]
    if given:
        parser.error(f"{' and '.join(given)} with --truth-only: no model runs, so there is nothing to apply it to")


def _refuse_bad_sink_url(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A --sink its parser refuses (an unknown scheme, udp:// without a host, a bad baud=, an unknown option): a
    usage error before anything is opened (since session 74; the open after the rig's and the model's load said
    it). The daemon's config check, which opens no device: a serial port busy now may be free by the run."""
    if args.sink is None:
        return
    try:
        check_sink_url(args.sink, cameras=STAND_IN_CAMERAS)  # the rig's own names, announced in the run, win
    except SinkConfigError as e:  # its message names the URL, without its passwords
        parser.error(f"--sink {e}")


def _sink_file(url: str | None) -> str | None:
    """The file a ``file://`` ``--sink`` appends to; None for another sink, or a URL the sink's open reports."""
    if url is None or not url.lower().startswith("file:"):
        return None
    try:
        return FileSink.from_url(url).path
    except FirmwareHostError:
        return None


def _refuse_clashing_outputs(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A ``file://`` --sink on a file the run reads (the rig URL's ``rig=`` calibration, its ``bvh=`` motion or
    videos, the --config file) appended joint lines to it, and one on ``OUT/sim_pair.png`` was replaced by the
    picture: refused before anything is opened, as the daemon refuses its sinks there
    (:func:`ghnerf_runtime.cli.output_path.output_clash`, one check for both)."""
    rig_files = {f"--url's {part}=": path for part, path in url_files(innermost_url(args.url))
                 if part != "target"}
    clash = output_clash({"--sink": _sink_file(args.sink), "--out's sim_pair.png": args.out / "sim_pair.png"},
                         {"--config": args.config, **rig_files})
    if clash:
        parser.error(clash)


def _sink_file_problem(path: str) -> str | None:
    """Why a ``file://`` sink can never write ``path``: a folder, a file in a folder that is not there (a file or a
    link to nothing further up said as such), a loop of symbolic links or a link naming a folder (since session 75),
    one in a folder this user cannot look up (EACCES or EPERM on the way: it was said 'does not exist'), or one this
    user may not write (None: it may). The sink tries again what it cannot open (a daemon's USB stick
    mounted later), so the demo loaded the model and ran its seconds against a sink that never opened, and only then
    failed ("sent none of the frames")."""
    if os.path.isdir(path):
        return f"{shown(path)} is a folder, not a file; name a file in it ({Path(path, 'joints.jsonl').as_uri()})"
    looping = _link_loop(path)
    if looping is not None:  # ELOOP at every open, which the sink retried for the whole run
        return f"{shown(looping)} is a loop of symbolic links (ELOOP): no file can be opened there"
    folder_link = _link_to_a_folder(path)
    if folder_link is not None:  # EISDIR (or ENOTDIR) at every open: the link names a folder, never a file
        return f"{shown(path)} is a link to {shown(folder_link)}, a folder's path (it ends in '/'), not a file's"
    # the open (O_CREAT) makes a dangling link's target: that file's folder is the one it needs
    target = os.path.realpath(path) if os.path.islink(path) else path
    folder = os.path.dirname(target)
    if os.path.isdir(folder):
        return _sink_access_problem(path, folder)
    denied = _search_denied(folder)
    if denied is not None:  # whether the folder is there is not known: "does not exist" sent the user to make it
        return f"its folder {shown(folder)} cannot be looked up: {denied}"
    link = f"; {shown(path)} is a link to {shown(target)}" if target != path else ""
    return f"its folder {shown(folder)} {_missing_folder_words(folder)} (the sink makes the file, not its folder{link})"


def _link_loop(path: str) -> str | None:
    """The first of ``path``'s components (``path`` itself last) that is a loop of symbolic links (None: none)."""
    for component in _leading_paths(path):
        try:
            os.stat(component)
        except OSError as e:
            if e.errno == errno.ELOOP:
                return component
    return None


def _leading_paths(path: str) -> list[str]:
    """``path``'s leading components as paths, ``path`` itself last (``/a/b``: ``/``, ``/a``, ``/a/b``)."""
    parts = Path(path).parts
    return [os.path.join(*parts[:end]) for end in range(1, len(parts) + 1)]


def _search_denied(folder: str) -> str | None:
    """The first of ``folder``'s components (``folder`` itself last) whose look-up this user is refused, EACCES or
    EPERM (a folder on the way it may not search, a link into one), named with the error's words; None: none is."""
    for component in _leading_paths(folder):
        try:
            os.stat(component)
        except PermissionError as e:
            code = errno.errorcode.get(e.errno, str(e.errno))
            return f"{shown(component)}: {e.strerror} ({code}: this user may not search a folder on its path)"
        except OSError:
            return None  # not there, a file on the way: _missing_folder_words says which
    return None


def _link_to_a_folder(path: str) -> str | None:
    """What a link in ``path``'s chain of links names where it ends in ``/`` (a folder's path: opening it for a file
    fails, EISDIR or ENOTDIR, whether or not that folder exists); None: no such link."""
    for _ in range(MAX_LINKS_FOLLOWED):
        if not os.path.islink(path):
            return None
        path = os.path.join(os.path.dirname(path), os.readlink(path))  # (an absolute text stays as it is)
        if os.path.basename(path) in ("", ".", ".."):
            return path
    return None  # a longer chain: the open's own ELOOP (_link_loop) says it


def _missing_folder_words(folder: str) -> str:
    """Why ``folder`` (not a folder) is none, said of its first component that is not one: a file, a link to
    nothing, or not there."""
    for component in _leading_paths(folder):
        if os.path.isdir(component):
            continue
        if os.path.islink(component) and not os.path.exists(component):
            target = os.path.join(os.path.dirname(component), os.readlink(component))
            return f"does not exist: {shown(component)} is a link to {shown(target)}, which is not there"
        if os.path.exists(component):
            return "is a file, not a folder" if component == folder else f"cannot exist: {shown(component)} is a file"
        break
    return "does not exist"


def _sink_access_problem(path: str, folder: str) -> str | None:
    """Why this user may not write ``path`` (a file there) or make it in ``folder`` (no file yet): the EACCES or
    EROFS the sink's open would meet, and retry, for the whole run (None: it may)."""
    why = "(no permission, or a read-only file system)"
    if os.path.exists(path):  # appended to: the file's own mode
        return None if os.access(path, os.W_OK) else f"{shown(path)} is not writable here {why}"
    return None if os.access(folder, os.W_OK | os.X_OK) else f"its folder {shown(folder)} is not writable here {why}"


def _refuse_unwritable_sink(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """A ``file://`` --sink on a folder, in a folder that is not there, or one this user may not write: a usage
    error before anything is opened (since session 74), not a run that ends failed."""
    path = _sink_file(args.sink)
    problem = _sink_file_problem(path) if path is not None else None
    if problem is not None:
        parser.error(f"--sink {redact_url(args.sink)}: {problem}")


def main(argv: Sequence[str] | None = None) -> int:
    prog = prog_name()
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    _refuse_ignored_flags(parser, args)
    _refuse_bad_sink_url(parser, args)
    _refuse_clashing_outputs(parser, args)
    _refuse_unwritable_sink(parser, args)
    try:
        # SIGTERM stops it as Ctrl-C does: its default action killed it outright, a record+ take left
        # complete: false and the frames still queued for the recorder lost
        with sigterm_as_interrupt():
            return _run(args, prog)
    except (DemoError, drivers.DriverError, FirmwareHostError, OSError) as e:
        # a wrong --url / --sink / --out, a camera that is not there: one line, not a traceback
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # before the pairs (the motion loop's first render, the model load) or after them
        print(f"{prog}: stopped ({stop_words(e)})", file=sys.stderr)
        return exit_status(e)


if __name__ == "__main__":
    sys.exit(main())
