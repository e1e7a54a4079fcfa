"""Benchmark options that name something (a precision, seeds, a checkout, an image size, a motion, sim:// options)
refuse what names nothing as a usage error (exit 2) that names the option, before anything runs: ``--precision
int4`` was the session config's traceback once the sequences were rendered, ``--seeds x`` int()'s "invalid literal"
traceback, ``--baseline /nowhere`` a FileNotFoundError from importing its reader (time_replay_open.py: after writing
its take), ``--size not-a-size`` a ValueError from unpacking it, ``--motion nope`` the scene config's SimConfigError
``--options fps=abc`` the rig URL's RigConfigError, ``--threads x`` (time_train_step.py) int()'s traceback and
``--input-scales 0.3`` (time_pretrain_step.py) the model config's ConfigError, and a value the runtime's config
refuses (``--rest-every 0``, ``--dilate 9``) its ConfigError once the model was loaded."""
from __future__ import annotations

import argparse
import runpy
import sys

import pytest

from ghnerf_runtime.cli.counts import image_size, seed_list
from tests.benchmarks.test_count_arguments import BENCH, _parse_only, _Parsed

PRECISION = ("measure_baseline", "measure_cold_tiles", "measure_one_camera", "measure_single_view",
             "measure_synth_framing", "measure_volume_near_edge", "tune_runtime_knobs")
CASES = [(script, ("--precision", "int4"), "--precision") for script in PRECISION]
CASES += [(script, ("--seeds", seeds), "--seeds") for script in ("measure_calibration", "measure_repeated_views")
          for seeds in ("x", "1,,2", "-1")]
CASES += [("time_image_read", ("--baseline", "no-such-checkout"), "--baseline"),
          ("time_replay_open", ("--baseline", "no-such-checkout"), "--baseline")]
CASES += [("time_image_read", ("--baseline", str(BENCH.parent), "--size", size), "--size")
          for size in ("not-a-size", "0x480", "640x")]
CASES += [("time_replay_open", ("--size", size), "--size") for size in ("not-a-size", "320x240x3")]
CASES += [("bench_sim_render", ("--motion", motion), "--motion") for motion in ("nope", "no-such-clip.bvh")]
CASES += [("bench_sim_rig", ("--options", options), "--options")
          for options in ("fps=abc", "fps=30&colour=red", "cache=/tmp")]
CASES += [("time_train_step", ("--threads", threads), "--threads") for threads in ("x", "0", "1,,2")]
CASES += [("time_pretrain_step", ("--scenes-per-step", count), "--scenes-per-step") for count in ("x", "0")]
CASES += [("time_pretrain_step", ("--input-scales", "x"), "--input-scales")]
CASES += [("measure_cold_tiles", ("--rest-every", every), "--rest-every") for every in ("0", "-5", "x")]
CASES += [("measure_novel_rays", ("--dilate", dilate), "--dilate") for dilate in ("-5", "9")]
CASES += [("measure_novel_rays", ("--min-diff", diff), "--min-diff") for diff in ("nan", "-1", "x", "\u0663")]
# digits of other scripts, which int() and float() read as 3: a config field in ASCII digits, as a count
CASES += [("measure_cold_tiles", ("--rest-every", "\u0663"), "--rest-every"),
          ("measure_novel_rays", ("--dilate", "1_0"), "--dilate")]
CASES += [("measure_lying_rendered", ("--turn-search", "--turn-search-every", "0"), "--turn-search-every")]
CASES += [("measure_exchanged_cameras", ("--only", "-5"), "--only")]  # (-5 rendered a scene of no bench number)
#: settings the pretraining's config refuses, checked once parsed (on a dataset that is there)
SETTINGS = [("--input-scales", "0.3"), ("--input-scales", "0"), ("--precisions", "fp16")]


def _value(args: tuple[str, ...], option: str) -> str:
    return args[args.index(option) + 1]


@pytest.mark.parametrize("script, args, option", CASES, ids=[f"{s} {o} {_value(a, o)}" for s, a, o in CASES])
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
    assert f"argument {option}:" in err and _value(args, option) in err, err


@pytest.mark.parametrize("option, value", SETTINGS, ids=[" ".join(setting) for setting in SETTINGS])
def test_a_pretraining_setting_its_config_refuses_is_a_usage_error(option, value, train_only, monkeypatch, capsys):
    """time_pretrain_step.py checks each setting as the pretraining does before it times any: ``--input-scales
    0.3`` (a trunk input of 38.4 px) and ``--precisions fp16`` were ConfigError tracebacks after the steps of the
    settings before them had run."""
    script = BENCH / "time_pretrain_step.py"
    monkeypatch.setattr(sys, "argv", [str(script), "--data", str(train_only), option, value])
    with pytest.raises(SystemExit) as stopped:
        runpy.run_path(str(script), run_name="__main__")
    assert stopped.value.code == 2
    err = capsys.readouterr().err
    assert f"argument {option}: " in err and value in err, err


def test_a_turn_search_period_without_the_turn_search_is_a_usage_error(monkeypatch, capsys):
    """measure_lying_rendered.py's ``--turn-search-every`` sets the turn search's rows: without ``--turn-search``
    (or ``--rolls``) it was ignored, the run measuring no search at all."""
    from benchmarks import measure_lying_rendered as bench

    monkeypatch.setattr(bench, "measure", lambda *a, **k: pytest.fail("the poses were measured"))
    with pytest.raises(SystemExit) as stopped:
        bench.main(["--turn-search-every", "2"])
    assert stopped.value.code == 2
    assert "--turn-search-every sets the turn search's rows: give --turn-search or --rolls" in capsys.readouterr().err


@pytest.mark.parametrize("script, args", [("time_image_read", ("--baseline", str(BENCH.parent), "--size", "64x48")),
                                          ("time_replay_open", ("--size", "64x48")),
                                          ("bench_sim_render", ("--motion", "jumping_jacks")),
                                          ("bench_sim_rig", ("--options", "fps=15&width=320&height=240")),
                                          ("bench_sim_render", ()), ("bench_sim_rig", ())],  # their defaults
                         ids=lambda value: " ".join(value) if isinstance(value, tuple) else value)
def test_what_names_something_is_taken(script, args, monkeypatch):
    """A real checkout, size, motion or set of sim:// options gets through the checks (the scripts stopped once
    their arguments parse)."""
    _parse_only(monkeypatch)
    monkeypatch.setattr(sys, "argv", [str(BENCH / f"{script}.py"), *args])
    with pytest.raises(_Parsed):
        runpy.run_path(str(BENCH / f"{script}.py"), run_name="__main__")


def test_image_size_reads_width_by_height():
    assert image_size("640x480") == (640, 480) and image_size("64X48") == (64, 48)
    with pytest.raises(argparse.ArgumentTypeError, match=r"WIDTHxHEIGHT in pixels, each >= 1 .*, got '0x0'"):
        image_size("0x0")


def test_seed_list_reads_comma_separated_seeds():
    assert seed_list("0,1, 2") == [0, 1, 2]
    with pytest.raises(argparse.ArgumentTypeError, match="whole numbers >= 0, got ''"):
        seed_list("")
