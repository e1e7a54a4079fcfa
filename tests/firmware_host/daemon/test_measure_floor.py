"""``ghnerf-daemon --measure-floor``: the floor check's standing foot (``estimator.joints3d.foot_standing_m``) measured
on the configured rig (docs/calibration.md, "Shoes, mats: the standing foot")."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

import drivers
from firmware_host.daemon import cli
from firmware_host.daemon.config import DaemonConfigError, daemon_config_from_dict
from firmware_host.daemon.measure_floor import FloorMeasureError, measure_floor
from ghnerf_runtime.errors import FrameError

REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"
needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                 reason="no trained model yet: models/model_card.json does not exist")


@dataclass
class _Pair:
    images: tuple = ()
    sequence: int = 0
    timestamps_ns: tuple = (0, 0)


class _Source:
    """Pairs until ``end`` (then the end of a recording), a timeout at the reads listed in ``timeouts``, a failed
    read (a corrupt frame) at those in ``failures``."""

    def __init__(self, end: int = 10 ** 6, timeouts: tuple[int, ...] = (), failures: tuple[int, ...] = ()) -> None:
        self.reads, self.end, self.timeouts, self.failures = 0, end, timeouts, failures

    def read(self, timeout_s: float = 1.0) -> _Pair:
        self.reads += 1
        if self.reads in self.timeouts:
            raise drivers.RigTimeoutError("no pair")
        if self.reads in self.failures:
            raise drivers.RigOperationError(f"frame {self.reads}: a corrupt image")
        if self.reads > self.end:
            raise drivers.EndOfStream("the recording ended")
        return _Pair(sequence=self.reads)


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
    own feet or, since session 57, the median of both people's (``Estimator._matched_foot``), not the measured
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


class _SilentSource:
    """A camera open but silent (unplugged mid-run, or held by the running service): every read times out after
    ``timeout_s`` on the fake clock, after ``pairs`` pairs."""

    def __init__(self, pairs: int = 0) -> None:
        self.now, self.reads, self.pairs = 0.0, 0, pairs

    def clock(self) -> float:
        return self.now

    def read(self, timeout_s: float = 1.0) -> _Pair:
        self.reads += 1
        if self.reads <= self.pairs:
            return _Pair(sequence=self.reads)
        self.now += timeout_s
        raise drivers.RigTimeoutError("no pair")


def test_a_silent_rig_is_given_up_after_the_stall_time_not_after_every_read_allowed():
    """Each timeout counted as a pair read, a silent rig kept ``--measure-floor`` waiting READS_PER_PAIR * PAIRS
    timeouts (300 s for the default 60 pairs at rig.read_timeout_s 1) and then said nobody stood in view. Now it
    gives up once no pair came for ``rig.stall_s``, as the daemon reopens such a rig, and says so."""
    rig = _SilentSource(pairs=2)
    with pytest.raises(FloorMeasureError, match=r"no pair for 10\.0 s \(rig\.stall_s 10\) after 2 pairs read: a "
                                                r"camera is silent"):
        measure_floor(rig, _Estimator([0.03, 0.03]), 0.04, pairs=60, read_timeout_s=1.0, stall_s=10.0,
                      clock=rig.clock)
    assert rig.reads == 2 + 10 and rig.now == 10.0


def test_one_failed_read_is_read_past_as_the_daemon_does_two_in_a_row_are_the_rig_failing():
    """A recording with a corrupt frame (``RigOperationError``, raised once by ``RigSource.read``) ended the
    measurement (exit 1) where the daemon reads on past it; two failed reads before a pair are the rig failing."""
    m = measure_floor(_Source(failures=(2,)), _Estimator([0.03] * 3), 0.04, pairs=3)
    assert m.heights_m == pytest.approx((0.07, 0.07, 0.07)) and m.pairs_read == 3
    with pytest.raises(drivers.RigOperationError, match="frame 3: a corrupt image"):
        measure_floor(_Source(failures=(2, 3)), _Estimator([0.03] * 3), 0.04, pairs=3)


def test_ctrl_c_stops_measure_floor_with_a_line_not_a_traceback(tmp_path, capsys, monkeypatch):
    """Run from a shell, Ctrl-C is how a measurement is stopped: exit 130 with one line (the rig and the estimator
    are closed by their ``with``), not a KeyboardInterrupt traceback."""
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps({"rig": {"url": "sim://"}, "sinks": ["memory://"]}))
    monkeypatch.setattr(cli, "read_checked_config", lambda p: daemon_config_from_dict(json.loads(Path(p).read_text())))

    def interrupted(config, pairs, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "measure_floor_of_config", interrupted)
    try:
        status = cli.main(["--config", str(path), "--measure-floor", "5"])
    except KeyboardInterrupt:  # (not let through: it would stop the test session)
        pytest.fail("Ctrl-C came out of ghnerf-daemon --measure-floor as a KeyboardInterrupt (a traceback)")
    assert status == 130
    captured = capsys.readouterr()
    assert "--measure-floor interrupted before 5 pairs measured a foot: nothing to set" in captured.err
    assert captured.out == ""


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
