"""Benchmark options that take a number or a list of them (``--scale``, ``--margins``, ``--input-scales``,
``--outside``, ``--rig-lift``) refuse what is not one as a usage error in the counts' words, naming the option and
the value (exit 2): a ``type=`` lambda or a bare ``float()`` said argparse's generic ``invalid <lambda> value`` or
``invalid finite_float value``, ``tune_proxy_matte.py --margins x`` was float()'s traceback, and digits of other
scripts (``'\u0663'``), ``'1_0'`` or ``'nan'`` ran as numbers."""
from __future__ import annotations

import argparse
import runpy
import sys

import pytest

from ghnerf_runtime.cli.numbers import finite_number, number_list, number_or, optional_number_list
from tests.benchmarks.test_count_arguments import BENCH, REQUIRED, _parse_only, _Parsed, usage_error

#: (script, option, value, the words said): lists say "comma-separated numbers"
CASES = [("tune_proxy_matte", "--margins", "x", "must be comma-separated numbers"),
         ("tune_proxy_matte", "--feathers", "0.1,\u0663", "must be comma-separated numbers"),
         ("tune_proxy_matte", "--clear-below", "nan", "must be comma-separated numbers"),
         ("time_pretrain_step", "--input-scales", "\u0663", "must be comma-separated numbers"),
         ("measure_edge_padding", "--outside", "0,x", "must be comma-separated numbers"),
         ("measure_body_proxy", "--scale", "x", "must be a number or 'fit'"),
         ("measure_body_proxy", "--scale", "\uff11", "must be a number or 'fit'"),
         ("measure_baseline", "--rig-lift", "\u0663", "a finite number of metres"),
         ("measure_baseline", "--good-find-mm", "x", "a number (inf allowed)"),
         # a list read after the model loaded (float()'s traceback), or taken with nan or '\u0663' in it
         ("measure_baseline", "--distances", "x", "must be comma-separated numbers"),
         ("measure_baseline", "--baselines", "0.1,nan", "must be comma-separated numbers"),
         ("measure_baseline", "--lifts", "0,\u0663", "must be comma-separated numbers"),
         ("measure_orientation_spread", "--tilts", "3,x", "must be comma-separated numbers"),
         ("measure_synth_framing", "--pitches", "17,x", "must be comma-separated numbers"),
         ("measure_synth_framing", "--heights", "nan", "must be comma-separated numbers"),
         ("measure_synth_framing", "--near", "\u0663", "must be a number")]


@pytest.mark.parametrize("script, option, value, words", CASES, ids=[f"{s}{o}={v}" for s, o, v, _ in CASES])
def test_a_number_option_refuses_what_is_no_number_in_words(script, option, value, words, monkeypatch, capsys):
    _parse_only(monkeypatch)
    err = usage_error(monkeypatch, capsys, script, *REQUIRED.get(script, ()), f"{option}={value}")
    assert f"argument {option}: {words}, got {value!r}" in err, err


@pytest.mark.parametrize("text", ["x", "", "\u0663", "\uff13.5", "1_0", "nan", "inf", "-inf", "1e999", "1.2.3"])
def test_a_number_is_finite_and_in_ascii_digits(text):
    with pytest.raises(argparse.ArgumentTypeError, match=f"must be a number, got {text!r}"):
        finite_number(text)
    with pytest.raises(argparse.ArgumentTypeError, match=f"must be comma-separated numbers, got '0.5,{text}'"):
        number_list(f"0.5,{text}")
    with pytest.raises(argparse.ArgumentTypeError, match=f"must be a number or 'fit', got {text!r}"):
        number_or("fit")(text)


def test_numbers_as_written_parse():
    assert [finite_number(t) for t in ("-0.2", " 1e-3 ", ".5", "3.", "+2", "7")] == [-0.2, 1e-3, 0.5, 3.0, 2.0, 7.0]
    assert number_list("-0.2,0, 0.25") == [-0.2, 0.0, 0.25]
    assert number_or("fit")("fit") is None and number_or("fit")("1.5") == 1.5
    assert optional_number_list("") == optional_number_list(" ") == [] and optional_number_list("1,2") == [1.0, 2.0]


def test_an_empty_list_option_parses_as_none(monkeypatch):
    """``measure_baseline.py --baselines "" --lifts ""`` (docs/rig-file.md's command) turns those tables off."""
    seen = {}
    parse_args = argparse.ArgumentParser.parse_args

    def keep(self, args=None, namespace=None):
        seen["args"] = parse_args(self, args, namespace)
        raise _Parsed

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", keep)
    monkeypatch.setattr(sys, "argv", [str(BENCH / "measure_baseline.py"), "--baselines", "", "--lifts", ""])
    with pytest.raises(_Parsed):
        runpy.run_path(str(BENCH / "measure_baseline.py"), run_name="__main__")
    assert seen["args"].baselines == seen["args"].lifts == seen["args"].angles == []
    assert seen["args"].distances == [3.0]
