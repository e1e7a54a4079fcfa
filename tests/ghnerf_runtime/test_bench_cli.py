"""``ghnerf-bench runtime``'s argument errors and Ctrl-C, without a model or a rendered sequence."""
from __future__ import annotations

import json
import os
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from ghnerf_runtime.cli import bench, simdata
from ghnerf_runtime.config import EstimatorConfig
from ghnerf_runtime.metrics import strict_json


@pytest.fixture
def no_render(monkeypatch):
    """Fails the test if the bench renders (or loads) its sequences: minutes on a cold cache."""
    def load_sequences(*args, **kwargs):
        raise AssertionError("the sequences were rendered before the error was found")

    monkeypatch.setattr(simdata, "load_sequences", load_sequences)


@pytest.mark.parametrize(("extra", "words"), [
    (["--model-dir", "NOWHERE"], "model folder does not exist"),
    (["--threads", "0"], "SessionConfig.threads: must be an integer in [1, 64], got 0"),
    # checked as its rows are built, after the model folder's graphs load (the shipped models/)
    (["--novel-interior-strides", "3"], "NovelViewConfig.interior_stride: must be one of"),
])
def test_a_model_or_config_error_is_said_before_the_sequences_are_rendered(tmp_path, capsys, no_render, extra,
                                                                            words):
    extra = [str(tmp_path / a) if a == "NOWHERE" else a for a in extra]
    rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                     "--precisions", "fp32", *extra])
    assert rc == 2
    assert words in capsys.readouterr().err


@pytest.mark.parametrize(("make", "said"), [(lambda p: p.write_text("{}"), "is not a folder"),
                                             (lambda p: None, "model folder does not exist")])
def test_a_model_dir_that_is_no_model_folder_is_named_by_the_option(tmp_path, capsys, no_render, make, said):
    """It said "m.json: is not a folder (session.model_dir names ...)": a key the bench has no way to set."""
    folder = tmp_path / "m.json"
    make(folder)
    assert bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                       "--precisions", "fp32", "--model-dir", str(folder)]) == 2
    assert f"ghnerf-bench: error: --model-dir {folder}: {said}" in capsys.readouterr().err


@pytest.mark.parametrize("modes", ["keypoints", "keypoints,novel"])
def test_an_invalid_interior_stride_is_refused_whatever_the_modes(capsys, no_render, monkeypatch, modes):
    """``--modes keypoints --novel-interior-strides 3`` ran, the 3 (not a stride the runtime takes) unseen."""
    monkeypatch.setattr(bench, "load_session", lambda cfg: pytest.fail("the model was loaded"))
    rc = bench.main(["runtime", "--modes", modes, "--novel-interior-strides", "0,3", "--cache", "off"])
    assert rc == 2
    assert ("--novel-interior-strides 3: NovelViewConfig.interior_stride: must be one of [0, 1, 2, 4, 8], got 3"
            in capsys.readouterr().err)


@pytest.mark.parametrize("option", [["--novel-stride", "2"], ["--novel-interior-strides", "2"],
                                    ["--proxy-blends", "on,off"], ["--painters", "off"],
                                    ["--novel-pipelines", "on"], ["--novel-lanes", "on,off"]])
def test_a_novel_only_option_without_the_novel_mode_is_refused(capsys, no_render, monkeypatch, option):
    """Each was accepted with ``--modes keypoints`` and ignored: no novel row, no word said (ghnerf-run refuses
    its novel options without --novel-view alike)."""
    monkeypatch.setattr(bench, "load_session", lambda cfg: pytest.fail("the model was loaded"))
    assert bench.main(["runtime", "--modes", "keypoints", *option, "--cache", "off"]) == 2
    assert (f"{option[0]} without the novel mode (--modes keypoints): there is no novel row"
            in capsys.readouterr().err)


def test_novel_stride_left_out_is_the_configs():
    args = bench.build_parser().parse_args(["runtime"])
    assert args.novel_stride is None and bench.novel_option_error(args) is None
    cfg = bench.row_base_config(args, "fp32", "encoder")
    assert cfg.novel_view.stride == EstimatorConfig().novel_view.stride


def test_ctrl_c_exits_130_without_a_traceback_or_a_report(tmp_path, capsys, monkeypatch):
    def interrupted(cfg):
        raise KeyboardInterrupt

    monkeypatch.setattr(bench, "load_session", interrupted)
    try:
        rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                         "--json", str(tmp_path / "r.json")])
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped ghnerf-bench: the user saw a traceback")
    assert rc == 130 and "stopped (Ctrl-C)" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()


def test_ctrl_c_while_the_report_is_written_leaves_no_half_report(tmp_path, capsys, monkeypatch):
    """The --json report is written as the bench ends: a Ctrl-C landing in that write left the file cut short (an
    earlier report truncated too), while the bench said no report was written."""
    class _PressedNow:
        def __str__(self):  # the JSON writer's default reaches it halfway through the report
            raise KeyboardInterrupt

    monkeypatch.setattr(bench, "run_runtime_bench", lambda args: {"rows": [1.0, 2.0], "late": _PressedNow()})
    report = tmp_path / "r.json"
    report.write_text('{"earlier": true}\n')
    rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                     "--json", str(report)])
    assert rc == 130 and "no report written" in capsys.readouterr().err
    assert report.read_text() == '{"earlier": true}\n' and [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_the_report_is_written_by_the_one_strict_json_writer(tmp_path, monkeypatch):
    """Its own ``json.dumps(..., default=float)`` wrote an int64 count as 3.0 and failed, a traceback after the whole
    bench, on an array of figures; the training side's reports went through another writer."""
    report = {"pairs": np.int64(3), "per_joint_mm": np.array([12.5, np.nan]), "ms": np.float32("inf")}
    monkeypatch.setattr(bench, "run_runtime_bench", lambda args: report)
    out = tmp_path / "r.json"
    assert bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0", "--cache", "off",
                       "--json", str(out)]) == 0
    assert out.read_text() == strict_json(report, indent=2) + "\n"
    assert json.loads(out.read_text()) == {"pairs": 3, "per_joint_mm": [12.5, None], "ms": None}


def test_runtime_help_names_the_defaults_the_docs_rely_on(capsys):
    # README's command leaves --precisions and --modes out: the help must say that this makes a row of each
    with pytest.raises(SystemExit):
        bench.build_parser().parse_args(["runtime", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "model folder (default: models)" in text
    assert "(default: fp32,int8,auto)" in text and "(default: keypoints,novel)" in text
    assert "onnxruntime intra-op threads (default: 2)" in text
    # a bare run measures what the device runs: the help says which source that is, read from the config
    assert f"(default: {EstimatorConfig().heatmaps.source}, the runtime's heatmaps.source" in text


class _RowsBuilt(Exception):
    """Raised where the bench would render its sequences: every row's config is built by then."""


def test_the_default_rows_run_what_the_device_runs_by_default(capsys, monkeypatch):
    """A bare ``ghnerf-bench runtime`` scored the rendered heatmaps (119.6 mm MPJPE against 32.1 mm for the
    encoder ones on two sequences, session 62) while the device runs the encoder ones: a new user took the
    device to be that far off. Its rows now start from the runtime's own ``EstimatorConfig()``."""
    built = []

    def recorded_session(cfg):
        built.append(cfg)
        return SimpleNamespace(describe=lambda: {}, contract=SimpleNamespace(encoder_heatmaps=True))

    def rows_built(*args, **kwargs):
        raise _RowsBuilt

    monkeypatch.setattr(bench, "load_session", recorded_session)
    monkeypatch.setattr(simdata, "load_sequences", rows_built)
    with pytest.raises(_RowsBuilt):  # --precisions auto: the runtime's precision too
        bench.main(["runtime", "--precisions", "auto", "--cache", "off"])
    runtime = EstimatorConfig()
    assert [(cfg.heatmaps.source, cfg.joints3d.method) for cfg in built] == \
        [(runtime.heatmaps.source, runtime.joints3d.method)]
    # the rest of the config too, but the novel view's graphs, loaded for the novel rows
    (cfg,) = built
    assert replace(cfg, novel_view=replace(cfg.novel_view, enabled=runtime.novel_view.enabled)) == runtime


def test_a_cache_that_is_a_file_is_named_before_anything_runs(tmp_path, capsys, no_render, monkeypatch):
    monkeypatch.setattr(bench, "load_session", lambda cfg: pytest.fail("the model was loaded"))
    (tmp_path / "afile").write_text("")
    rc = bench.main(["runtime", "--sequences", "1", "--frames", "2", "--warmup", "0",
                     "--cache", str(tmp_path / "afile")])
    # was "[Errno 20] Not a directory: '<it>/seq-...'" after the model had loaded, naming no flag
    assert rc == 2 and f"--cache {tmp_path / 'afile'}: is a file; give a folder" in capsys.readouterr().err


@pytest.mark.parametrize(("option", "value", "repeated"), [
    ("--precisions", "int8,fp32,int8", "int8"), ("--modes", "keypoints,,keypoints", "keypoints"),
    ("--heatmap-sources", "encoder,encoder", "encoder"), ("--smoothing", "on,1", "on"),
    ("--flip-tests", "off,0,on", "off"), ("--novel-interior-strides", "2,2", "2"),
])
def test_a_value_given_twice_in_a_comma_list_is_refused(capsys, no_render, monkeypatch, option, value, repeated):
    """``--precisions int8,int8`` ran every int8 row twice under one label: a table of lookalike rows, twice the
    time, nothing to tell them apart. Refused as the options are parsed, before the model loads."""
    monkeypatch.setattr(bench, "load_session", lambda cfg: pytest.fail("the model was loaded"))
    with pytest.raises(SystemExit) as stop:
        bench.main(["runtime", "--modes", "keypoints,novel", option, value, "--cache", "off"])
    assert stop.value.code == 2
    assert f"argument {option}: {value!r}: {repeated} given twice" in capsys.readouterr().err


def test_empty_items_of_a_comma_list_are_left_out():
    args = bench.build_parser().parse_args(["runtime", "--precisions", "int8,,fp32", "--smoothing", ",off,"])
    assert (args.precisions, args.smoothing) == (["int8", "fp32"], [False])


def test_sequences_that_cannot_fit_are_refused_before_they_are_rendered(capsys, no_render, monkeypatch):
    """``--sequences 10000`` (553 GB of images) rendered in silence for hours, then filled the disk (or, with
    ``--cache off``, memory). Its size and where it goes are said first, and it is refused when it cannot fit."""
    monkeypatch.setattr(bench, "_free_bytes", lambda folder: 10**9)
    rc = bench.main(["runtime", "--sequences", "10000", "--cache", "off", "--precisions", "fp32",
                     "--modes", "keypoints"])
    out, err = capsys.readouterr()
    assert rc == 2
    assert "rendering 10000 of 10000 sequences x 30 pairs first" in out and "about 200.0 min, 552.96 GB in memory" in out
    assert ("--sequences 10000 --frames 30: 553.0 GB of images to render in memory (--cache off), but 1.0 GB is "
            "free there" in err)


def test_memory_free_for_cache_off_counts_the_page_cache_the_kernel_gives_back(tmp_path):
    """``--cache off`` holds every image in memory; the room for them is ``MemAvailable`` (the page cache included),
    not the free pages alone, which a host whose files fill its memory reads as a few hundred MB."""
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:        8000000 kB\nMemFree:          300000 kB\nMemAvailable:    6000000 kB\n")
    assert bench.available_memory_bytes(str(meminfo)) == 6000000 * 1024
    meminfo.write_text("MemTotal:        8000000 kB\nMemFree:          300000 kB\n")  # (an old kernel: no such line)
    assert bench.available_memory_bytes(str(meminfo)) == os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    assert bench._free_bytes(None) == bench.available_memory_bytes()


def test_freshly_rendered_sequences_are_read_back_mapped_not_held(tmp_path):
    """A first run held every rendered sequence's images in memory, cache or not (--sequences 10000: 553 GB);
    a cached one is mapped from its file, as a later run's is."""
    sequences = simdata.load_sequences(2, 2, cache_dir=tmp_path)
    assert all(isinstance(s.images, np.memmap) for s in sequences)
    again = simdata.load_sequences(2, 2, cache_dir=tmp_path)
    assert all(np.array_equal(a.images, b.images) for a, b in zip(sequences, again))


def test_scan_every_s_takes_a_comma_list_of_seconds_and_labels_its_rows(capsys):
    # docs/two-people.md, "Anyone else near?" (session 64): the scan's cost is the rows' encoders column ('scan')
    args = bench.build_parser().parse_args(["runtime", "--scan-every-s", "0,1"])
    assert args.scan_every_s == [0.0, 1.0]
    assert bench.build_parser().parse_args(["runtime"]).scan_every_s is None
    for bad in ("-1", "nan", "x", "inf", "\u0663", "1_0"):  # float() took the last two as 3 and 10
        with pytest.raises(SystemExit):
            bench.build_parser().parse_args(["runtime", "--scan-every-s", bad])
        assert f"--scan-every-s: {bad!r}: " in capsys.readouterr().err


@pytest.mark.parametrize("bad", ["x", "\u0662", "0,\uff12", "1_0", "1.5"])
def test_novel_interior_strides_are_ascii_whole_numbers(bad, capsys):
    """int() took other scripts' digits ('\u0662', full-width '\uff12') and '1_0' as strides."""
    with pytest.raises(SystemExit):
        bench.build_parser().parse_args(["runtime", "--novel-interior-strides", bad])
    assert f"--novel-interior-strides: {bad!r}: expected a comma list of integers" in capsys.readouterr().err
    assert "scan" in bench.STAGE_GROUPS["encoders"]


class _TimedEstimator:
    """Stands in for the estimator in :func:`bench.run_pairs`: each sequence's first pair (cold) 30 ms of
    ``preprocess`` and ``encoder``, the others 1 and 9."""

    def __init__(self, session, rig, config) -> None:
        self.session, self.config = session, config

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def estimate(self, images, *, sequence, novel_view, timestamp_s):
        pre, enc = (10.0, 20.0) if sequence == 0 else (1.0, 9.0)
        return SimpleNamespace(sequence=sequence, timing_ms={"preprocess": pre, "encoder": enc, "total": pre + enc})


class _NoPipeline:
    def __init__(self, est) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass


def test_the_bench_prints_each_sequence_s_first_pair_by_stage_and_the_startup(capsys, monkeypatch):
    """The cold first pair's own stages (session 68: it sets the p99 over every pair) and what the device pays
    before its first pair: the model's load and each estimator's build."""
    monkeypatch.setattr(bench, "Estimator", _TimedEstimator)
    monkeypatch.setattr(bench, "NovelViewPipeline", _NoPipeline)
    sequences = [_Sequence(np.zeros((3, 2, 2, 2, 3), np.uint8)) for _ in range(3)]
    stages, _ = bench.run_pairs(_TimedEstimator(None, None, None), sequences, novel=False, warmup=1)
    assert stages[f"{bench.COLD} total"] == [30.0, 30.0]  # the first sequence's first pair is the warm-up
    assert stages[f"{bench.COLD} preprocess"] == [10.0, 10.0] and stages[bench.STEADY] == [10.0] * 6
    assert len(stages[bench.ESTIMATOR_START]) == 3
    row = {**bench._row(stages, 1.0), "model_load_ms": 123.0, "precision": "int8", "heatmaps": "encoder",
           "method": "triangulate", "mode": "keypoints", "accuracy": {}, "load_average": 1.0}
    assert row[bench.COLD]["total"]["median"] == 30.0 and row[bench.COLD]["preprocess"]["median"] == 10.0
    bench._print_row(row)
    out = capsys.readouterr().out
    assert ("each sequence's first pair past the warm-up, ms median/p99: preprocess 10.00/10.00 encoders "
            "20.00/20.00") in out
    assert "the model loaded in 123 ms" in out and "each sequence's estimator built in" in out


class _Sequence:
    """A bench sequence of blank pairs."""

    def __init__(self, images: np.ndarray) -> None:
        self.images, self.rig, self.info = images, None, {"fps": 30.0}

    def __len__(self) -> int:
        return len(self.images)


@pytest.mark.parametrize("json_report", [False, True])
def test_stdout_closed_by_its_reader_ends_the_bench_without_an_error_unless_a_report_is_lost(tmp_path, json_report):
    """``ghnerf-bench runtime | head -1`` said "error: [Errno 32] Broken pipe" with status 2 (session 73's review);
    a ``--json`` report the early end leaves unwritten is said, and the status is not 0."""
    import subprocess
    import sys

    argv = [sys.executable, "-m", "ghnerf_runtime.cli.bench", "runtime", "--sequences", "1", "--frames", "1",
            "--warmup", "0", "--model-dir", str(tmp_path / "none")]
    if json_report:
        argv += ["--json", str(tmp_path / "r.json")]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader gone before the first line
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == (2 if json_report else 0)
    assert "Broken pipe" not in err and "Traceback" not in err
    assert ("no report written" in err) == json_report and not (tmp_path / "r.json").exists()
