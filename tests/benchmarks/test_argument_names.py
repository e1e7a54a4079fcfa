"""Benchmark options that name something (a precision, seeds, a checkout) refuse what names nothing as a usage
error (exit 2) that names the option, before anything runs: ``--precision int4`` was the session config's
traceback once the sequences were rendered, ``--seeds x`` int()'s "invalid literal" traceback, ``--baseline
/nowhere`` a FileNotFoundError from importing its reader (time_replay_open.py: after writing its take)."""
from __future__ import annotations

import argparse
import runpy
import sys

import pytest

from ghnerf_runtime.cli.counts import seed_list
from tests.benchmarks.test_count_arguments import BENCH, _parse_only, _Parsed

PRECISION = ("measure_baseline", "measure_cold_tiles", "measure_one_camera", "measure_single_view",
             "measure_synth_framing", "measure_volume_near_edge", "tune_runtime_knobs")
CASES = [(script, ("--precision", "int4"), "--precision") for script in PRECISION]
CASES += [(script, ("--seeds", seeds), "--seeds") for script in ("measure_calibration", "measure_repeated_views")
          for seeds in ("x", "1,,2", "-1")]
CASES += [("time_image_read", ("--baseline", "no-such-checkout"), "--baseline"),
          ("time_replay_open", ("--baseline", "no-such-checkout"), "--baseline")]


@pytest.mark.parametrize("script, args, option", CASES, ids=[f"{s}{' '.join(a)}" for s, a, _ in CASES])
def test_a_name_that_names_nothing_is_a_usage_error(script, args, option, monkeypatch, capsys):
    _parse_only(monkeypatch)
    monkeypatch.setattr(sys, "argv", [str(BENCH / f"{script}.py"), *args])
    with pytest.raises(SystemExit) as stopped:
        try:
            runpy.run_path(str(BENCH / f"{script}.py"), run_name="__main__")
        except _Parsed:  # the script's own check, after parsing, runs too
            pytest.fail(f"{script} {' '.join(args)} was accepted")
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert option in err and args[1] in err, err


def test_a_baseline_that_is_a_checkout_is_taken(monkeypatch):
    """A real checkout gets through ``--baseline``'s check: the script goes on to read ``--size``."""
    monkeypatch.setattr(sys, "argv", [str(BENCH / "time_image_read.py"), "--baseline", str(BENCH.parent),
                                      "--rounds", "1", "--size", "not-a-size"])
    with pytest.raises(ValueError):  # --size, parsed after the check: the check let the checkout through
        runpy.run_path(str(BENCH / "time_image_read.py"), run_name="__main__")


def test_seed_list_reads_comma_separated_seeds():
    assert seed_list("0,1, 2") == [0, 1, 2]
    with pytest.raises(argparse.ArgumentTypeError, match="whole numbers >= 0, got ''"):
        seed_list("")
