"""Every benchmark script refuses a count no run can use (``--frames -5``, ``--repeats 0``) and a ``--model-dir``
that is no folder, or a folder holding no model, as a usage error that names the option and the value (exit 2), at
parsing: an unchecked ``type=int`` let them through to a traceback (numpy's "negative dimensions", an empty median,
an index out of range) once the model and sequences were loaded, or to a run of nothing; a mistyped model folder, or
an empty one, was a ModelLoadError traceback. ``parse_args`` is stopped once it returns, so no script runs past its
parsing here."""
from __future__ import annotations

import argparse
import runpy
import sys
from pathlib import Path

import pytest

from ghnerf_runtime.cli.counts import (ascii_integer, bounded_count, image_size, non_negative_count, positive_count,
                                       positive_count_list, seed_list)
from ghnerf_runtime.cli.model_folder import model_folder_option

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"

#: script -> (options that need 1 at least, options where 0 means none); ``--seconds``-like ones need > 0 s.
COUNTS = {
    "bench_graph_threads": (("--sequences", "--pairs", "--rounds"), ("--warmup",)),
    "bench_protocol": (("--frames", "--repeats"), ()),
    "bench_runtime_regions": (("--repeats", "--sequences", "--frames"), ("--warmup",)),
    "bench_runtime_vs_eval": (("--limit",), ()),
    "bench_sim_render": (("--repeats",), ()),
    "bench_sim_rig": (("--seconds",), ()),
    "compare_3d_methods": (("--sequences", "--frames"), ()),
    "measure_baseline": (("--sequences", "--frames"), ()),
    "measure_body_proxy": (("--threads",), ("--limit",)),
    "measure_calibration": (("--count", "--edge-count"), ()),
    "measure_calibration_drift": (("--sequences", "--frames", "--window"), ()),
    "measure_cold_tiles": (("--sequences", "--frames", "--rooms", "--pairs"), ("--walk-in-after",)),
    "measure_edge_padding": (("--sequences", "--frames"), ("--training-samples",)),
    "measure_exchanged_cameras": (("--sequences", "--frames", "--window"), ()),
    "measure_floor_signals": (("--sequences", "--frames", "--window"), ()),
    "measure_foot_spread": (("--sequences", "--frames"), ()),
    "measure_frame_check": (("--sequences", "--frames", "--pairs-per-sequence"), ()),
    "measure_import_common_view": (("--placements",), ()),
    "measure_left_right": (("--sequences", "--frames"), ()),
    "measure_lying_rendered": (("--scenes", "--frames"), ("--first-scene",)),
    "measure_mounting": (("--sequences", "--frames"), ()),
    "measure_noisy_scenes": (("--sequences", "--frames"), ("--rooms",)),
    "measure_novel_ceiling": (("--threads",), ("--limit",)),
    "measure_novel_overlap": (("--sequences", "--frames", "--repeats"), ("--warmup",)),
    "measure_novel_quality": (("--sequences", "--frames", "--every"), ()),
    "measure_novel_rays": (("--sequences", "--frames", "--silhouette-stride"), ("--interior-stride",)),
    "measure_one_camera": (("--sequences", "--frames"), ("--rooms",)),
    "measure_orientation_spread": (("--seeds", "--views"), ()),
    "measure_pair_outliers": (("--seeds",), ()),
    "measure_pairing": (("--seconds", "--seeds"), ()),
    "measure_presence": (("--rooms",), ()),
    "measure_prior_out_of_range": (("--scenes",), ()),
    "measure_prior_outliers": ((), ("--limit",)),
    "measure_prior_peak_shape": (("--steps", "--hidden", "--threads"), ("--limit",)),
    "measure_reload_memory": (("--loads", "--pairs"), ("--arena-max", "--mmap-threshold")),
    "measure_repeated_views": (("--count", "--edge-count"), ("--same-pose",)),
    "measure_single_view": (("--sequences", "--frames"), ("--rooms",)),
    "measure_still_pairs": (("--sequences", "--frames", "--every"), ()),
    "measure_synth_framing": (("--frames",), ("--sequences", "--floor-seeds")),
    "measure_two_people": (("--scenes", "--pairs", "--sequences", "--frames"), ("--alone",)),
    "measure_volume_near_edge": (("--sequences", "--frames"), ()),
    "soak_daemon": (("--sample-s",), ()),
    "time_dataset_checksums": (("--res", "--views", "--samples", "--rounds"), ()),
    "time_demo_stages": (("--pairs",), ("--profile",)),
    "time_frame_check": (("--size", "--repeats", "--rounds"), ()),
    "time_image_read": (("--rounds",), ()),
    "time_lanes": (("--seconds", "--rounds", "--threads"), ("--steps", "--scenes")),
    "time_pretrain_step": (("--steps", "--threads"), ("--profile",)),
    "time_replay_open": (("--frames", "--rounds"), ()),
    "time_scenes": (("--pairs",), ()),
    "time_train_step": (("--steps",), ()),
    "time_triangulation": (("--calls", "--rounds"), ()),
    "tune_proxy_matte": (("--threads",), ("--limit",)),
    "tune_runtime_knobs": (("--sequences", "--frames", "--every"), ()),
}
#: options a script requires whatever else it is given: present, so that only the count can be refused
REQUIRED = {
    "measure_body_proxy": ("--data", "d", "--model", "m", "--joints", "j"),
    "tune_proxy_matte": ("--data", "d", "--model", "m", "--joints", "j"),
    "measure_prior_outliers": ("--data", "d"),
    "measure_prior_peak_shape": ("--data", "d"),
    "time_image_read": ("--baseline", str(BENCH.parent)),
}
CASES = [(script, option, "0") for script, (positive, _) in COUNTS.items() for option in positive]
CASES += [(script, option, "-1") for script, (_, non_negative) in COUNTS.items() for option in non_negative]
# digits of other scripts, which int() takes: '\u0663' (Arabic-Indic) and '\uff13' (full-width) ran as 3
CASES += [("measure_calibration", "--seeds", "0,\u0663"), ("measure_pairing", "--seeds", "\uff13"),
          ("measure_synth_framing", "--sequences", "\u0663"), ("time_train_step", "--threads", "1,\u0663"),
          ("time_pretrain_step", "--scenes-per-step", "\uff12")]
# mallopt's threshold: -5 reached glibc as a size_t near 2**64 (no block mapped), past 32 MiB man mallopt's limit
CASES += [("measure_reload_memory", "--mmap-threshold", value) for value in ("-5", str((32 << 20) + 1))]
#: the scripts whose --model-dir names the folder the session loads
MODEL_DIR = ("bench_graph_threads", "bench_runtime_regions", "bench_runtime_vs_eval", "compare_3d_methods",
             "measure_baseline", "measure_calibration_drift", "measure_cold_tiles", "measure_edge_padding",
             "measure_exchanged_cameras", "measure_floor_signals", "measure_foot_spread", "measure_frame_check",
             "measure_left_right", "measure_lying_rendered", "measure_mounting", "measure_noisy_scenes",
             "measure_novel_overlap", "measure_novel_quality", "measure_novel_rays", "measure_one_camera",
             "measure_presence", "measure_prior_outliers", "measure_prior_peak_shape", "measure_single_view",
             "measure_still_pairs", "measure_synth_framing", "measure_volume_near_edge", "tune_runtime_knobs",
             # the daemon's (soak, reloads), the demo's stages, the scenes', the lanes' workers', the two people's
             "measure_reload_memory", "measure_two_people", "soak_daemon", "time_demo_stages", "time_lanes",
             "time_scenes")
# (measure_prior_out_of_range checks its --model-dir once parsed, in the runs that read it: below)
#: a folder that is there and holds no model: no .onnx in it, in a ghnerf/ subfolder or in a single subfolder
NO_MODEL = str(BENCH.parent / "tests" / "benchmarks")
CASES += [(script, "--model-dir", folder) for script in MODEL_DIR for folder in ("no-such-model-folder", NO_MODEL)]


class _Parsed(Exception):
    """Raised once a script's arguments parse: the script never runs."""


def _parse_only(monkeypatch) -> None:
    parse_args = argparse.ArgumentParser.parse_args

    def stop_after_parsing(self, args=None, namespace=None):
        parse_args(self, args, namespace)
        raise _Parsed

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop_after_parsing)


def usage_error(monkeypatch, capsys, script: str, *args: str) -> str:
    """``benchmarks/<script>.py args`` refused as a usage error (exit 2) before it runs: its stderr. A script
    whose arguments parse fails the test where :func:`_parse_only` is on; one that needs torch is skipped."""
    path = BENCH / f"{script}.py"
    monkeypatch.setattr(sys, "argv", [str(path), *args])
    with pytest.raises(SystemExit) as stopped:
        try:
            runpy.run_path(str(path), run_name="__main__")
        except ModuleNotFoundError as e:  # torch: the training extra
            pytest.skip(f"{script} needs {e.name}")
        except _Parsed:
            pytest.fail(f"{script} {' '.join(args)} was accepted")
    assert stopped.value.code == 2
    return capsys.readouterr().err


@pytest.mark.parametrize("script, option, value", CASES,
                         ids=[f"{s}{o}={'a-folder-holding-no-model' if v == NO_MODEL else v}" for s, o, v in CASES])
def test_a_count_no_run_can_use_is_a_usage_error(script, option, value, monkeypatch, capsys):
    _parse_only(monkeypatch)
    monkeypatch.setattr(sys, "argv", [str(BENCH / f"{script}.py"), *REQUIRED.get(script, ()), option, value])
    try:
        runpy.run_path(str(BENCH / f"{script}.py"), run_name="__main__")
    except ModuleNotFoundError as e:  # torch: the training extra
        pytest.skip(f"{script} needs {e.name}")
    except _Parsed:
        pytest.fail(f"{script} {option} {value} was accepted")
    except SystemExit as e:
        assert e.code == 2
        err = capsys.readouterr().err
        assert f"argument {option}:" in err and value in err, err
    else:
        pytest.fail(f"{script} ran to its end")


@pytest.mark.parametrize("script, option, value", [("measure_novel_ceiling", "--limit", "0"),
                                                    ("bench_graph_threads", "--warmup", "0"),
                                                    ("bench_protocol", "--frames", "1"),
                                                    ("measure_one_camera", "--rooms", "0"),  # docs/turn-search.md
                                                    ("measure_synth_framing", "--sequences", "0")])  # docs/rig-file.md
def test_the_least_count_each_option_takes_parses(script, option, value, monkeypatch):
    _parse_only(monkeypatch)
    monkeypatch.setattr(sys, "argv", [str(BENCH / f"{script}.py"), option, value])
    with pytest.raises(_Parsed):
        runpy.run_path(str(BENCH / f"{script}.py"), run_name="__main__")


@pytest.mark.parametrize("text", ["0", "-3", "1.5", "x", ""])
def test_positive_count_refuses_what_is_not_a_whole_number_above_zero(text):
    with pytest.raises(argparse.ArgumentTypeError, match=f"must be a whole number >= 1, got {text!r}"):
        positive_count(text)


@pytest.mark.parametrize("text", ["\u0663", "\uff13", "1\uff12", "1_000"])
def test_a_count_in_digits_int_takes_but_a_command_line_does_not_show_is_refused(text):
    """int() reads Arabic-Indic '\u0663' and full-width '\uff13' as 3, and '1_000' as 1000: such a count ran, where
    '\u00b2' and 'x' were refused. Each is now a count no run can use, in the words of the others."""
    for parse, least in ((positive_count, 1), (non_negative_count, 0), (bounded_count(0, 10_000), None)):
        words = f"must be a whole number >= {least}" if least is not None else "must be a whole number from 0 to 10000"
        with pytest.raises(argparse.ArgumentTypeError, match=f"{words}, got {text!r}"):
            parse(text)
    with pytest.raises(argparse.ArgumentTypeError, match=f"comma-separated whole numbers >= 0, got '0,{text}'"):
        seed_list(f"0,{text}")
    with pytest.raises(argparse.ArgumentTypeError, match=f"comma-separated whole numbers >= 1, got '1,{text}'"):
        positive_count_list(f"1,{text}")
    with pytest.raises(argparse.ArgumentTypeError, match=f"WIDTHxHEIGHT in pixels, each >= 1 .*, got '{text}x480'"):
        image_size(f"{text}x480")


def test_a_seed_or_size_past_the_digits_int_reads_is_refused_in_words():
    """int() refuses more than 4300 digits with a ValueError, which argparse said as "invalid seed_list value"."""
    long = "1" * 5000
    with pytest.raises(argparse.ArgumentTypeError, match="comma-separated whole numbers >= 0, got '0,1111"):
        seed_list(f"0,{long}")
    with pytest.raises(argparse.ArgumentTypeError, match="WIDTHxHEIGHT in pixels, each >= 1 .*, got '1111"):
        image_size(f"{long}x480")
    with pytest.raises(argparse.ArgumentTypeError, match="must be a whole number >= 1, got '1111"):
        positive_count(long)


def test_counts_take_whole_numbers_at_their_least():
    assert positive_count("1") == 1 and positive_count(" 12 ") == 12
    assert non_negative_count("0") == 0
    with pytest.raises(argparse.ArgumentTypeError, match=r">= 0, got '-1'"):
        non_negative_count("-1")


def test_an_ascii_integer_is_a_whole_number_of_any_sign_and_size():
    """The reading behind ``config_field`` and ``training.cli.at_least``, which say their own bounds: below -2**63 it
    was refused as "not a whole number" (it was ``whole_number``'s with that least), so ``--rest-every`` of such a
    value was said as no number rather than in the config's words."""
    assert ascii_integer(" -12 ") == -12 and ascii_integer(str(-2 ** 70)) == -2 ** 70
    for text in ("\u0663", "1_0", "x", "1.5", ""):
        with pytest.raises(ValueError, match=f"not a whole number, got {text!r}"):
            ascii_integer(text)


def test_a_model_folder_option_is_a_folder_that_is_there(tmp_path):
    (tmp_path / "model.onnx").write_bytes(b"")
    assert model_folder_option(str(tmp_path)) == str(tmp_path)
    with pytest.raises(argparse.ArgumentTypeError, match="model.onnx is not a folder"):
        model_folder_option(str(tmp_path / "model.onnx"))


def test_a_model_folder_option_holds_graph_files_where_the_session_looks(tmp_path):
    """Only the files' presence: the session finds graphs by name or by metadata, and checks what they hold."""
    with pytest.raises(argparse.ArgumentTypeError, match=f"{tmp_path} holds no model: no .onnx graph file"):
        model_folder_option(str(tmp_path))
    (tmp_path / "ghnerf").mkdir()
    (tmp_path / "ghnerf" / "encoder.onnx").write_bytes(b"")
    assert model_folder_option(str(tmp_path)) == str(tmp_path)  # its ghnerf/ subfolder
    shipped = tmp_path / "shipped"
    (shipped / "baseline").mkdir(parents=True)
    (shipped / "baseline" / "encoder.onnx").write_bytes(b"")
    assert model_folder_option(str(shipped)) == str(shipped)  # its one subfolder holding graphs (models/<variant>)
    (shipped / "other").mkdir()
    (shipped / "other" / "encoder.onnx").write_bytes(b"")
    with pytest.raises(argparse.ArgumentTypeError, match="holds no model"):  # two: the session would take neither
        model_folder_option(str(shipped))


@pytest.mark.parametrize("text", ["1,²", "x", "1,,2", "-1", ""])
def test_a_seed_list_refuses_what_is_not_whole_numbers(text):
    """"²" is a digit to str.isdigit() and no number to int(): it was int()'s ValueError traceback."""
    with pytest.raises(argparse.ArgumentTypeError, match="comma-separated whole numbers >= 0"):
        seed_list(text)


def test_a_seed_list_takes_whole_numbers():
    assert seed_list("0, 1,2") == [0, 1, 2]


#: script -> the arguments of a run that reads no model folder (docs/runtime.md, the scripts' docstrings)
RUNS_WITHOUT_A_MODEL = {"compare_3d_methods": ("--oracle",),
                        "measure_prior_out_of_range": ("--prior", "skeleton_prior.onnx"),
                        "measure_cold_tiles": ("--wake-margin",)}


@pytest.mark.parametrize("script", sorted(RUNS_WITHOUT_A_MODEL))
def test_a_run_that_reads_no_model_is_not_refused_for_the_default_model_folder(script, tmp_path, monkeypatch):
    """argparse runs ``type=`` on a string default: ``--model-dir``'s check of its default ``models`` refused these
    runs, which need no model, where there is none (a checkout before ``make model``)."""
    monkeypatch.chdir(tmp_path)  # no models/ here
    _parse_only(monkeypatch)
    monkeypatch.setattr(sys, "argv", [str(BENCH / f"{script}.py"), *RUNS_WITHOUT_A_MODEL[script]])
    with pytest.raises(_Parsed):
        runpy.run_path(str(BENCH / f"{script}.py"), run_name="__main__")


@pytest.mark.parametrize("script", sorted(RUNS_WITHOUT_A_MODEL))
def test_a_run_that_reads_a_model_still_refuses_a_default_model_folder_holding_none(script, tmp_path, monkeypatch,
                                                                                  capsys):
    monkeypatch.chdir(tmp_path)  # no models/ here
    assert "argument --model-dir: models" in usage_error(monkeypatch, capsys, script)


@pytest.mark.parametrize("folder", ["no-such-model-folder", NO_MODEL])
def test_the_prior_measure_refuses_a_model_folder_it_reads_before_it_measures(folder, monkeypatch, capsys):
    """measure_prior_out_of_range reads --model-dir only without --prior (a folder given beside --prior is not
    read: tests/ghnerf_runtime/test_skeleton_prior.py), so it checks it once parsed, before any scene."""
    err = usage_error(monkeypatch, capsys, "measure_prior_out_of_range", "--model-dir", folder)
    assert f"argument --model-dir: {folder}" in err
