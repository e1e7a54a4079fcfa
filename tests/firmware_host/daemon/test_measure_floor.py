"""``ghnerf-daemon --measure-floor``: the floor check's standing foot (``estimator.joints3d.foot_standing_m``) measured
on the configured rig (docs/calibration.md, "Shoes, mats: the standing foot")."""
from __future__ import annotations

import json
import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import drivers
from firmware_host.daemon import cli
from firmware_host.daemon.config import DaemonConfigError, daemon_config_from_dict
from firmware_host.daemon.measure_floor import (FloorMeasureError, FloorMeasureStopped, measure_floor,
                                                measure_floor_of_config)
from ghnerf_runtime.errors import FrameError, ModelError

REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"
needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                 reason="no trained model yet: models/model_card.json does not exist")


@dataclass
class _Pair:
    images: tuple = ()
    sequence: int = 0
    timestamps_ns: tuple = (0, 0)


class _Counted:
    """What a real source (``drivers.RigSource``) has beside ``read``: its pairing config and its counters, which say
    why no pair came. A pair read counts a frame of each camera; ``came`` adds frames that did not pair."""

    pairing = drivers.PairingConfig()

    def __init__(self) -> None:
        self._counters = drivers.PairingStats(frames_in={"left": 0, "right": 0})

    @property
    def stats(self) -> drivers.PairingStats:
        return self._counters.snapshot()

    def paired(self, pair: _Pair) -> _Pair:
        self.came({cam: 1 for cam in self._counters.frames_in})
        self._counters.pairs_out += 1
        return pair

    def came(self, frames: dict[str, int]) -> None:
        for cam, n in frames.items():
            self._counters.frames_in[cam] += n


class _Source(_Counted):
    """Pairs until ``end`` (then the end of a recording), a timeout at the reads listed in ``timeouts``, a failed
    read (a corrupt frame) at those in ``failures``."""

    def __init__(self, end: int = 10 ** 6, timeouts: tuple[int, ...] = (), failures: tuple[int, ...] = ()) -> None:
        super().__init__()
        self.reads, self.end, self.timeouts, self.failures = 0, end, timeouts, failures

    def read(self, timeout_s: float = 1.0) -> _Pair:
        self.reads += 1
        if self.reads in self.timeouts:
            raise drivers.RigTimeoutError("no pair")
        if self.reads in self.failures:
            raise drivers.RigOperationError(f"frame {self.reads}: a corrupt image")
        if self.reads > self.end:
            raise drivers.EndOfStream("the recording ended")
        return self.paired(_Pair(sequence=self.reads))


@dataclass
class _Result:
    lowest_foot_m: float | None
    several_people: bool = False


class _Estimator:
    """Answers the figures in turn; ``"reject"`` raises a frame check's error, ``("two", f)`` a pair with two people
    in view whose figure is ``f``."""

    def __init__(self, figures: list) -> None:
        self.figures = list(figures)

    def estimate(self, images, *, sequence=None, timestamp_s=None) -> _Result:
        f = self.figures.pop(0)
        if f == "reject":
            raise FrameError("a frame check failed")
        if isinstance(f, tuple):
            return _Result(f[1], several_people=True)
        return _Result(f)


def test_the_standing_foot_is_the_median_figure_plus_the_one_it_was_taken_with():
    """Soles of 3 cm: the figures read about 0.03 m with the default 0.04; the foot stood 0.07 m, the value to set.
    Pairs without a foot, rejected frames and a timeout are read past (the timeout not counted as a pair read)."""
    figures = [0.031, None, 0.029, "reject", 0.030, 0.034, None, 0.026]
    m = measure_floor(_Source(timeouts=(3,)), _Estimator(figures), 0.04, pairs=5)
    assert m.heights_m == pytest.approx((0.071, 0.069, 0.070, 0.074, 0.066))
    assert m.pairs_read == 8 and m.median_m == pytest.approx(0.070) and m.suggested_m == 0.07
    out = m.to_json()
    assert out["set"] == {"estimator": {"joints3d": {"foot_standing_m": 0.07}}}
    assert out["lowest_foot_m_median"] == pytest.approx(0.03) and out["pairs_with_a_foot"] == 5
    # measured again with that value set, the same feet read on the floor and the same value comes back
    again = measure_floor(_Source(), _Estimator([f - 0.03 for f in (0.031, 0.029, 0.030, 0.034, 0.026)]), 0.07, 5)
    assert again.suggested_m == 0.07 and again.to_json()["lowest_foot_m_median"] == pytest.approx(0.0)


@pytest.mark.parametrize("source, figures, message", [
    (_Source(), [None] * 50, "0 of 50 pairs read gave a foot figure, 10 wanted"),  # READS_PER_PAIR * pairs
    (_Source(end=3), [0.0] * 3, "3 of 3 pairs read gave a foot figure, 10 wanted"),  # the recording ended
    (_Source(), [0.35] * 10, "read a median 0.390 m above the floor, outside [0, 0.3] m"),  # a pan, a bad floor
    (_Source(), [-0.12] * 10, "read a median -0.080 m above the floor"),
])
def test_too_few_feet_or_feet_off_any_floor_are_refused_with_why(source, figures, message):
    with pytest.raises(FloorMeasureError, match=message.replace("[", r"\[").replace("]", r"\]")):
        measure_floor(source, _Estimator(figures), 0.04, pairs=10)


def test_pairs_with_two_people_in_view_are_read_past_not_measured():
    """A second person in view (a passer-by mid-stride, someone on another mat): the pair's figure is the subject's
    own feet or, since session 57, the median of both people's (``SubjectSelector.matched_foot``), not the measured
    person's alone. Such pairs are counted, not measured; before, their figures (here 0.2 m up) went into the
    median, which here they would have set to 0.24 m."""
    figures = [0.03, ("two", 0.2), ("two", 0.2), 0.03, ("two", 0.2), ("two", 0.2), 0.03]
    m = measure_floor(_Source(), _Estimator(figures), 0.04, pairs=3)
    assert m.heights_m == pytest.approx((0.07, 0.07, 0.07)) and m.pairs_read == 7 and m.pairs_two_people == 4
    assert m.to_json()["pairs_with_two_people"] == 4
    # a room that always shows two people gives no measurement, and says why
    with pytest.raises(FloorMeasureError, match=r"0 of 15 pairs read gave a foot figure, 3 wanted; 15 of them "
                                                r"showed two people, read past: one person alone in view"):
        measure_floor(_Source(), _Estimator([("two", 0.03)] * 15), 0.04, pairs=3)


class _SilentSource(_Counted):
    """A rig that stops pairing: every read times out after ``timeout_s`` on the fake clock, after ``pairs`` pairs,
    while the cameras deliver ``arriving`` frames each (default none: a camera open but silent, unplugged mid-run
    or held by the running service)."""

    def __init__(self, pairs: int = 0, arriving: dict[str, int] | None = None) -> None:
        super().__init__()
        self.now, self.reads, self.pairs, self.arriving = 0.0, 0, pairs, arriving or {}

    def clock(self) -> float:
        return self.now

    def read(self, timeout_s: float = 1.0) -> _Pair:
        self.reads += 1
        if self.reads <= self.pairs:
            return self.paired(_Pair(sequence=self.reads))
        self.now += timeout_s
        self.came(self.arriving)
        raise drivers.RigTimeoutError("no pair")


def test_a_silent_rig_is_given_up_after_the_stall_time_not_after_every_read_allowed():
    """Each timeout counted as a pair read, a silent rig kept ``--measure-floor`` waiting READS_PER_PAIR * PAIRS
    timeouts (300 s for the default 60 pairs at rig.read_timeout_s 1) and then said nobody stood in view. Now it
    gives up once no pair came for ``rig.stall_s``, as the daemon reopens such a rig, and says so."""
    rig = _SilentSource(pairs=2)
    with pytest.raises(FloorMeasureError, match=r"no pair for 10\.0 s \(rig\.stall_s 10\) after 2 pairs read: "
                                                r"neither camera delivered a frame \(unplugged, or held by another "
                                                r"process: stop the service first\)"):
        measure_floor(rig, _Estimator([0.03, 0.03]), 0.04, pairs=60, read_timeout_s=1.0, stall_s=10.0,
                      clock=rig.clock)
    assert rig.reads == 2 + 10 and rig.now == 10.0


@pytest.mark.parametrize("arriving, message", [
    ({"left": 30}, "camera 'right' delivered no frame (left: 300) (unplugged, or held by another process: stop the "
                   "service first)"),
    # both cameras deliver (out of sync, or one lagging): not a camera to unplug or a service to stop
    ({"left": 30, "right": 30}, "frames came from both cameras (left 300, right 300) but none paired within the "
                                "pairing tolerance of 11 ms"),
])
def test_a_rig_that_stops_pairing_is_given_up_saying_what_came_meanwhile(arriving, message):
    """``--measure-floor`` blamed a silent camera for any stretch with no pair, where the daemon says what the
    counters show since the last pair (``drivers.why_no_pair``): one camera silent, or frames that never paired."""
    rig = _SilentSource(pairs=2, arriving=arriving)
    with pytest.raises(FloorMeasureError) as raised:
        measure_floor(rig, _Estimator([0.03, 0.03]), 0.04, pairs=60, read_timeout_s=1.0, stall_s=10.0,
                      clock=rig.clock)
    text = str(raised.value)
    assert text.startswith("--measure-floor: no pair for 10.0 s (rig.stall_s 10) after 2 pairs read: " + message)
    assert ("stop the service" in text) == (len(arriving) == 1)


def test_one_failed_read_is_read_past_as_the_daemon_does_two_in_a_row_are_the_rig_failing():
    """A recording with a corrupt frame (``RigOperationError``, raised once by ``RigSource.read``) ended the
    measurement (exit 1) where the daemon reads on past it; two failed reads before a pair are the rig failing."""
    m = measure_floor(_Source(failures=(2,)), _Estimator([0.03] * 3), 0.04, pairs=3)
    assert m.heights_m == pytest.approx((0.07, 0.07, 0.07)) and m.pairs_read == 3
    with pytest.raises(drivers.RigOperationError, match="frame 3: a corrupt image"):
        measure_floor(_Source(failures=(2, 3)), _Estimator([0.03] * 3), 0.04, pairs=3)


def test_frames_of_another_size_before_any_pair_are_a_rig_that_does_not_fit_after_one_a_failed_read():
    """depthai:// opens before its first frames and checks their size as they are read: a FrameSizeError before
    any pair is the open's fault (a rig that does not fit the cameras: the CLI's exit 2, keyed rig.url), where it was
    read past and then raised (exit 1); after a pair of the rig's size it is a failed read, read past once as before."""

    class _Sized(_Source):
        def read(self, timeout_s: float = 1.0) -> _Pair:
            if self.reads + 1 in self.failures:
                self.reads += 1
                raise drivers.FrameSizeError("camera 'left' delivered 320x200, but its rig camera is 160x100", "left",
                                             (160, 100), (320, 200))
            return super().read(timeout_s)

    with pytest.raises(DaemonConfigError, match=r"^rig\.url: camera 'left' delivered 320x200, but its rig camera is "
                                                r"160x100$"):
        measure_floor(_Sized(failures=(1,)), _Estimator([0.03] * 3), 0.04, pairs=3)
    m = measure_floor(_Sized(failures=(2,)), _Estimator([0.03] * 3), 0.04, pairs=3)
    assert m.heights_m == pytest.approx((0.07, 0.07, 0.07)) and m.pairs_read == 3


class _RigSource(_Counted):
    """What ``drivers.create_rig_source`` gives, for the CLI's tests: ``signum`` sent to this process at read
    ``signal_at`` (SIGTERM from systemd or ``timeout``, Ctrl-C's SIGINT), after which no pair comes (each read times
    out); ``open_error`` raised by ``open``. Says whether it was opened and closed."""

    def __init__(self, signum: int | None = None, signal_at: int = 2,
                 open_error: Exception | None = None) -> None:
        super().__init__()
        self.rig = SimpleNamespace(rig_id="bench")
        self.signum, self.signal_at, self.open_error = signum, signal_at, open_error
        self.reads, self.opened, self.closed = 0, False, False

    def open(self) -> "_RigSource":
        self.opened = True
        if self.open_error is not None:
            raise self.open_error
        return self

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> "_RigSource":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def read(self, timeout_s: float = 1.0) -> _Pair:
        self.reads += 1
        if self.signum is not None and self.reads >= self.signal_at:
            if self.reads == self.signal_at:
                os.kill(os.getpid(), self.signum)
            time.sleep(timeout_s)
            raise drivers.RigTimeoutError("no pair")
        return self.paired(_Pair(sequence=self.reads))


class _RigEstimator(_Estimator):
    """The runtime's ``Estimator`` as ``measure_floor_of_config`` builds it: a foot 0.03 m up in every pair, or
    ``error`` raised when built (a rig the model cannot run on). Says whether it was closed."""

    error: Exception | None = None
    built: list["_RigEstimator"] = []

    def __init__(self, session, rig, config) -> None:
        if self.error is not None:
            raise self.error
        super().__init__([0.03] * 100)
        self.closed = False
        _RigEstimator.built.append(self)

    def close(self) -> None:
        self.closed = True

    def __enter__(self) -> "_RigEstimator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@pytest.fixture
def cli_rig(tmp_path, monkeypatch):
    """``cli.main`` on a config whose rig, model and estimator are the stand-ins above (a read times out in 0.05 s,
    a silent rig is given up after 0.5 s); returns (config path, a function taking the ``_RigSource`` to open)."""
    import ghnerf_runtime.estimator

    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({"rig": {"url": "sim://", "read_timeout_s": 0.05, "stall_s": 0.5,
                                        "reopen_min_s": 0.01},
                                "sinks": ["memory://"]}))
    monkeypatch.setattr(cli, "read_checked_config", lambda p: daemon_config_from_dict(json.loads(Path(p).read_text())))
    monkeypatch.setattr(cli, "load_model", lambda config: "session")
    monkeypatch.setattr(ghnerf_runtime.estimator, "Estimator", _RigEstimator)
    monkeypatch.setattr(_RigEstimator, "error", None)
    monkeypatch.setattr(_RigEstimator, "built", [])

    def rig(source: _RigSource) -> None:
        monkeypatch.setattr(drivers, "create_rig_source", lambda url, **kwargs: source)

    return path, rig


@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_sigterm_or_ctrl_c_stops_measure_floor_as_the_daemon_stops(cli_rig, capsys, signum, status):
    """Under systemd or ``timeout`` a SIGTERM killed ``--measure-floor`` outright (the rig and the estimator not
    closed); Ctrl-C raised a KeyboardInterrupt wherever it landed. Now both set the daemon's stop
    (``_StopOnSignal``), looked at between two reads: the rig and the estimator are closed, one line says what
    stopped it, exit 128 + the signal's number (143, 130), and the handlers that were there are put back."""
    path, rig = cli_rig
    source = _RigSource(signum=signum, signal_at=2)
    rig(source)
    caught: list[int] = []

    def guard(got: int, _frame) -> None:  # where the old code left the signal: not killed, no KeyboardInterrupt
        caught.append(got)

    previous = {s: signal.signal(s, guard) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        got = cli.main(["--config", str(path), "--measure-floor", "5"])
        handlers_after = [signal.getsignal(s) for s in previous]
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    assert caught == [], f"{signal.Signals(signum).name} reached the handler from before: --measure-floor left it"
    assert got == status
    assert handlers_after == [guard, guard]
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.strip() == (f"ghnerf-daemon: {path}: {signal.Signals(signum).name} received: --measure-floor "
                                    f"stopped before 5 pairs measured a foot (1 did, of 1 read): nothing to set")
    assert source.closed and [e.closed for e in _RigEstimator.built] == [True]
    assert source.reads < 5  # stopped at the next read, not given up after rig.stall_s (10 reads)


@pytest.mark.parametrize("estimator_error, open_error, message", [
    (ModelError("the model is 256x192, this rig's cameras 320x240", path="models/ghnerf"), None,
     "the model does not fit rig 'bench': models/ghnerf: the model is 256x192, this rig's cameras 320x240"),
    (None, drivers.RigConfigError("rig URL 'opencv://0,1?rig=r.json': camera 0 gives 640x480, rig file 320x240"),
     "rig.url: rig URL 'opencv://0,1?rig=r.json': camera 0 gives 640x480, rig file 320x240"),
    # since session 58: the daemon stops on it (exit 2), where --measure-floor exited 1; on the third open, as the
    # daemon (sim:// has no rig=: the size asked is at fault)
    (None, drivers.FrameSizeError("camera 'left' (/dev/video0) delivered 640x400, but its rig camera in r.json is "
                                  "1280x800", "left", (1280, 800), (640, 400)),
     "rig.url: camera 'left' (/dev/video0) delivered 640x400, but its rig camera in r.json is 1280x800 (on 3 opens "
     "in a row, the cameras never having delivered the rig's size: a size asked that they do not deliver)"),
])
def test_a_model_or_rig_that_the_start_refuses_exits_2_as_the_start_does(cli_rig, capsys, estimator_error,
                                                                          open_error, message):
    """The daemon's start exits 2 for a rig the model cannot run on, or a rig URL its backend refuses when it
    opens (what the config, model or rig file must fix; systemd does not restart it): ``--measure-floor`` exited 1
    for them, its code for "measured, no value". The rig is closed all the same."""
    path, rig = cli_rig
    source = _RigSource(open_error=open_error)
    rig(source)
    _RigEstimator.error = estimator_error
    assert cli.main(["--config", str(path), "--measure-floor", "5"]) == 2
    assert capsys.readouterr().err.strip() == f"ghnerf-daemon: error: {path}: {message}"
    assert source.opened and source.closed and source.reads == 0


class _ComesUpInAnotherMode(_RigSource):
    """A webcam whose first ``wrong`` opens deliver another size than the rig's (``at_read``: at the first read of
    the open, as ``depthai://`` checks them; else at the open, as ``opencv://``), then the rig's. Counts opens."""

    def __init__(self, wrong: int, at_read: bool = False) -> None:
        super().__init__()
        self.wrong, self.at_read, self.opens, self.closes = wrong, at_read, 0, 0

    def _size_error(self) -> drivers.FrameSizeError:
        return drivers.FrameSizeError("camera 'left' (/dev/video0) delivered 640x480, but its rig camera in r.json is "
                                      "1280x800", "left", (1280, 800), (640, 480))

    def open(self) -> "_RigSource":
        self.opens += 1
        self.opened = True
        if self.opens <= self.wrong and not self.at_read:
            raise self._size_error()
        return self

    def close(self) -> None:
        self.closes += 1
        super().close()

    def read(self, timeout_s: float = 1.0) -> _Pair:
        if self.opens <= self.wrong and self.at_read:
            raise self._size_error()
        return super().read(timeout_s)


@pytest.mark.parametrize("at_read", [False, True], ids=["at the open", "at the first read"])
def test_a_camera_of_another_size_on_the_first_open_only_is_opened_again_and_measured(cli_rig, capsys, at_read):
    """The daemon's start opens again on frames of another size (up to ``SIZE_MISMATCH_OPENS``) before it blames the
    rig file: a webcam may come up in another mode first. ``--measure-floor`` blamed the rig file (exit 2) on the
    first such open; now it opens again, after the daemon's backoff, and measures."""
    path, rig = cli_rig
    source = _ComesUpInAnotherMode(wrong=1, at_read=at_read)
    rig(source)
    assert cli.main(["--config", str(path), "--measure-floor", "5"]) == 0
    assert json.loads(capsys.readouterr().out)["pairs_with_a_foot"] == 5
    assert (source.opens, source.closes) == (2, 2)  # the first open closed before the second


@pytest.mark.parametrize("at_read", [False, True], ids=["at the open", "at the first read"])
def test_a_camera_of_another_size_on_every_open_exits_2_after_the_daemon_s_opens(cli_rig, capsys, at_read):
    from firmware_host.daemon.service import SIZE_MISMATCH_OPENS

    path, rig = cli_rig
    source = _ComesUpInAnotherMode(wrong=10 ** 6, at_read=at_read)
    rig(source)
    assert cli.main(["--config", str(path), "--measure-floor", "5"]) == 2
    assert source.opens == source.closes == SIZE_MISMATCH_OPENS
    assert capsys.readouterr().err.strip() == (
        f"ghnerf-daemon: error: {path}: rig.url: camera 'left' (/dev/video0) delivered 640x480, but its rig camera in "
        f"r.json is 1280x800 (on {SIZE_MISMATCH_OPENS} opens in a row, the cameras never having delivered the rig's "
        f"size: a size asked that they do not deliver)")


def test_a_stop_set_while_waiting_to_open_again_opens_no_more(monkeypatch):
    stop = threading.Event()
    source = _ComesUpInAnotherMode(wrong=10 ** 6)
    created: list[str] = []

    def create(url, **kwargs):
        created.append(url)
        stop.set()  # SIGTERM during the first open: the backoff ends at once and no second open comes
        return source

    monkeypatch.setattr(drivers, "create_rig_source", create)
    config = daemon_config_from_dict({"rig": {"url": "sim://", "reopen_min_s": 30}, "sinks": ["memory://"]})
    t0 = time.monotonic()
    with pytest.raises(FloorMeasureStopped, match=r"\(0 did, of 0 read\)"):
        measure_floor_of_config(config, 5, load_model=lambda c: "session", stop=stop)
    assert created == ["sim://"] and source.opens == 1 and time.monotonic() - t0 < 10


def test_stop_set_ends_the_measurement_before_the_next_read_or_before_the_rig_opens(monkeypatch):
    stop = threading.Event()

    class _Stops(_Source):
        def read(self, timeout_s: float = 1.0) -> _Pair:
            if self.reads == 2:
                stop.set()
            return super().read(timeout_s)

    source = _Stops()  # stop set while the third pair is read: that pair is measured, no fourth read
    with pytest.raises(FloorMeasureStopped, match=r"stopped before 5 pairs measured a foot \(3 did, of 3 read\)") \
            as e:
        measure_floor(source, _Estimator([0.03] * 5), 0.04, pairs=5, stop=stop)
    assert (e.value.pairs_read, e.value.feet, source.reads) == (3, 3, 3)
    # a SIGTERM while the model loaded: no camera is opened for a measurement nobody waits for
    opened: list[str] = []
    monkeypatch.setattr(drivers, "create_rig_source", lambda url, **kwargs: opened.append(url))
    config = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"]})
    loads: list[object] = []
    with pytest.raises(FloorMeasureStopped, match=r"\(0 did, of 0 read\)"):
        measure_floor_of_config(config, 5, load_model=loads.append, stop=stop)
    assert opened == []
    assert loads == []  # set before the load (a stop during ghnerf-daemon's imports): no model loaded for nothing


def test_measure_floor_refuses_a_pair_count_that_is_no_count():
    for bad in (0, -3, True, 2.5):
        with pytest.raises(ValueError, match="pairs must be a whole number"):
            measure_floor(_Source(), _Estimator([]), 0.04, pairs=bad)


@pytest.mark.parametrize("value", [-0.01, 0.31, "0.05", True, float("nan")])
def test_a_daemon_config_with_a_bad_standing_foot_names_the_key(value):
    with pytest.raises(DaemonConfigError, match=r"estimator\.joints3d\.foot_standing_m: must be a number in "
                                                r"\[0\.0, 0\.3\]"):
        daemon_config_from_dict({"sinks": ["memory://"], "estimator": {"joints3d": {"foot_standing_m": value}}})
    ok = daemon_config_from_dict({"sinks": ["memory://"], "estimator": {"joints3d": {"foot_standing_m": 0.065}}})
    assert ok.estimator.joints3d.foot_standing_m == 0.065


def test_measure_floor_usage_errors(tmp_path, capsys):
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({"rig": {"url": "sim://"}, "sinks": ["memory://"]}))
    assert cli.main(["--config", str(path), "--measure-floor", "0"]) == 2
    assert "--measure-floor: PAIRS must be at least 1, got 0" in capsys.readouterr().err
    assert cli.main(["--config", str(path), "--measure-floor", "--validate-config"]) == 2
    assert "--measure-floor runs on its own" in capsys.readouterr().err


@needs_model
def test_measure_floor_on_the_simulated_rig_prints_the_standing_foot_to_set(tmp_path, capsys):
    """Through the shipped model on ``sim://`` (the simulated bare feet): the median of the lower foot's joints is
    the default standing foot, 0.04 m, to within 3 cm (0.054 m over 30 pairs here: this placement's own offset; the
    pairs a real-time rig delivers depend on the host's speed), and the JSON says the key to set."""
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({
        "rig": {"url": f"sim://?fps=30&seed=0&motion=wave&width=320&height=240&cache={tmp_path / 'sim'}"},
        "sinks": ["memory://"], "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}}}))
    assert cli.main(["--config", str(path), "--measure-floor", "12"]) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert out["pairs_with_a_foot"] == 12 and out["foot_standing_m"] == 0.04
    standing = out["set"]["estimator"]["joints3d"]["foot_standing_m"]
    assert abs(standing - 0.04) < 0.03, out
    assert out["foot_height_m"]["p10"] <= out["foot_height_m"]["median"] <= out["foot_height_m"]["p90"]
    assert np.isclose(out["lowest_foot_m_median"], out["foot_height_m"]["median"] - 0.04, atol=1e-3)
    assert f"set it to {standing:g}" in captured.err


def test_what_the_rig_s_library_prints_on_stdout_does_not_land_in_the_json(cli_rig, capfd):
    """depthai's logger writes to the process's stdout (file descriptor 1) as it opens a device: ``--measure-floor |
    jq`` read its line before the JSON. It goes to stderr now, and stdout holds the measurement alone."""
    path, rig = cli_rig

    class _Chatty(_RigSource):
        def open(self) -> "_RigSource":
            os.write(1, b"[depthai] [warning] USB protocol not available\n")  # below Python, as a C++ logger writes
            return super().open()

    rig(_Chatty())
    assert cli.main(["--config", str(path), "--measure-floor", "5"]) == 0
    captured = capfd.readouterr()
    assert json.loads(captured.out)["pairs_with_a_foot"] == 5
    assert "[depthai] [warning] USB protocol not available" in captured.err
