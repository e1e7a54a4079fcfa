"""Smoke runs of the benchmark scripts: each cheap script's main path, run as its command line runs it
(``runpy`` as ``__main__``, so its own ``sys.path`` set-up and exit status count), at its smallest sizes.

The model is the tiny test export (``tests/ghnerf_runtime/test_session.py``, random weights: it finds no
joints, so the figures mean nothing); what is checked is that each script gets through to its table and
prints the rows its arguments ask for, so that an API change of the runtime, the drivers or the calibration
cannot break one silently (most are tools nobody runs for weeks). The simulator sequences render once into a
scratch cache (``XDG_CACHE_HOME``), never the user's ``~/.cache/ghnerf-bench``. About 30 s on two cores
(``.venv/bin/python -m pytest tests/benchmarks``, the tiny export included: the folder's 70 tests in 28.9 s, session 64).

Left out, as too slow for every CI run or needing what CI does not have: ``measure_calibration`` (9 s at one
seed of four views), ``time_lanes`` (a minute or more a measurement), ``time_train_step`` and
``time_pretrain_step`` (training steps of seconds each; tests/training/test_trainer.py runs the former),
``measure_body_proxy`` and ``tune_proxy_matte`` (a trained torch checkpoint), ``measure_prior_outliers`` and
``measure_prior_peak_shape`` (a skeleton prior; tests/training/test_skeleton_prior_cli.py runs them).
"""
from __future__ import annotations

import json
import re
import runpy
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from ghnerf_runtime.body25 import JOINT_NAMES
from tests.firmware_host.daemon.test_daemon_memory import glibc_only_reason
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
#: One sequence of three pairs for every script that takes the sizes (rendered once, then read from the cache).
SIZES = ("--sequences", "1", "--frames", "3")


@pytest.fixture(scope="module")
def scratch_cache(tmp_path_factory):
    """The sequence cache every script reads (``default_cache_dir`` follows ``XDG_CACHE_HOME``)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("xdg-cache")))
        yield


@pytest.fixture(scope="module")
def data64(tmp_path_factory):
    """A 64 px dataset (the tiny model's resolution) of two held-out scenes."""
    pytest.importorskip("torch")
    from training.data.generate import main as generate

    out = tmp_path_factory.mktemp("data64")
    generate(["--out", str(out), "--train", "0", "--val", "2", "--val-seen-motions", "0", "--res", "64",
              "--workers", "1"])
    return out


def run_script(name: str, *args: str, capsys, monkeypatch) -> str:
    """Run ``benchmarks/<name>.py`` with ``args`` as its command line; its standard output."""
    path = BENCH / f"{name}.py"
    monkeypatch.setattr(sys, "argv", [str(path), *args])
    try:
        runpy.run_path(str(path), run_name="__main__")
    except SystemExit as e:
        if e.code not in (0, None):
            captured = capsys.readouterr()
            pytest.fail(f"{name} {' '.join(args)}: exit {e.code}\n{captured.out[-2000:]}\n{captured.err[-2000:]}")
    return capsys.readouterr().out


def run_script_failing(name: str, *args: str, capsys, monkeypatch) -> str:
    """Run ``benchmarks/<name>.py`` with ``args``, expecting a usage error (exit 2); its standard error."""
    path = BENCH / f"{name}.py"
    monkeypatch.setattr(sys, "argv", [str(path), *args])
    with pytest.raises(SystemExit) as info:
        runpy.run_path(str(path), run_name="__main__")
    assert info.value.code == 2
    return capsys.readouterr().err


# ------------------------------------------------------------------------------------------- no model
def test_bench_protocol(capsys, monkeypatch):
    out = run_script("bench_protocol", "--frames", "20", "--repeats", "1", capsys=capsys, monkeypatch=monkeypatch)
    assert "20 frames x 1 runs" in out
    for row in ("encode", "decode", "vmc"):
        assert re.search(rf"^{row} .* frames/s$", out, re.M), out


def test_time_triangulation(capsys, monkeypatch):
    out = run_script("time_triangulation", "--calls", "2", "--rounds", "1", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^(two_views|dlt|midpoint|robust) .* +\d+\.\d$", out, re.M)
    assert rows == ["two_views", "dlt", "dlt", "midpoint", "robust"], out


def test_time_image_read_against_this_tree(capsys, monkeypatch):
    """Its baseline reader is another checkout's image_files.py, loaded by path (this tree's stands in for it)."""
    out = run_script("time_image_read", "--baseline", str(BENCH.parent), "--rounds", "2", "--size", "32x24",
                     capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^ *(jpg|tiff) 32x24: baseline [\d.]+ ms, this tree [\d.]+ ms", out, re.M)
    assert rows == ["jpg", "tiff"], out


def test_bench_sim_render(capsys, monkeypatch):
    out = run_script("bench_sim_render", "--repeats", "1", capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^pair 2x640x480 \(default rig\) +\d+\.\d+ +\d+\.\d+$", out, re.M), out


def test_bench_sim_rig(capsys, monkeypatch):
    out = run_script("bench_sim_rig", "--options", "fps=30&width=160&height=120", "--seconds", "0.5",
                     capsys=capsys, monkeypatch=monkeypatch)
    pairs = int(re.search(r"pairs read in 0.5 s: (\d+)", out)[1])
    assert pairs >= 5, out  # 15 at 30 fps; a loaded host may drop some (policy latest)
    assert "pair skew: median 0.000 ms" in out  # the simulator's two cameras fire together


def test_measure_pairing(capsys, monkeypatch):
    out = run_script("measure_pairing", "--seconds", "2", "--seeds", "1", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^(30 vs \S+ fps.*?) +[\d.]+ (pairer|reference) +(\d+) ", out, re.M)
    assert len(rows) == 10, out  # five scenarios, the pairer and the offline reference each
    by_scenario: dict[str, dict[str, int]] = {}
    for scenario, method, pairs in rows:
        by_scenario.setdefault(scenario, {})[method] = int(pairs)
    assert all(p["pairer"] == p["reference"] > 0 for p in by_scenario.values()), out  # closest-first, as offline


def test_measure_novel_path(capsys, monkeypatch):
    out = run_script("measure_novel_path", "--sim", "aimed,90", "--around", "180", "--alphas", "0.5",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "docs/examples/rig.json: optical axes 0.318 deg apart" in out and "auto takes the line" in out
    assert "around 180 (1.3 m high, aimed 0 cm off): optical axes 166.691 deg apart" in out
    assert "auto takes the orbit" in out
    assert re.search(r"^around 180 .*; pivot \(0\.000, -0\.950, 3\.000\) m, .* 0\.0 mm from the subject;", out, re.M), out
    assert "| 0.5 | 3000.0000 | 0.000000 |" in out  # the orbit 3 m out where the line is at the subject
    # toed in 90 degrees: the axes cross 2.4 m in front of the subject; the orbit goes round the subject, the halfway
    # view as far from it as the cameras (3071.7 mm; 3260.0 round the crossing, before session 55)
    assert re.search(r"^sim 90: .*; pivot \(0\.000, -1\.025, 3\.000\) m, .* 0\.0 mm from the subject;", out, re.M), out
    assert "| 3012.6 / 3071.7 | 0.49 |" in out


def test_measure_pair_outliers(capsys, monkeypatch):
    out = run_script("measure_pair_outliers", "--seeds", "1", capsys=capsys, monkeypatch=monkeypatch)
    assert "good (7)" in out and "bad (3)" in out  # one seed: 10 pairs, 3 unsynchronised
    # calibrate_pair refuses two unsynchronised pairs of five, naming them
    assert len(re.findall(r"now refused: the image pairs '000', '001'", out)) == 6, out
    assert len(re.findall(r"^   2 of [58] moved \d+ cm, seed \d: (solved|refused)", out, re.M)) == 24, out


# ---------------------------------------------------------------------------------- the tiny model
@pytest.fixture
def model(tiny_model_dir, scratch_cache):  # noqa: F811
    return str(tiny_model_dir)


def test_bench_runtime(model, capsys, monkeypatch):
    out = run_script("bench_runtime", "--model-dir", model, *SIZES, "--warmup", "1", "--precisions", "fp32",
                     "--modes", "novel", "--novel-pipelines", "on,off", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^fp32 .*keypoints\+novel (pipelined|one-by-one) ms median/p99: .* \| [\d.]+ pairs/s", out,
                      re.M)
    assert sorted(rows) == ["one-by-one", "pipelined"], out


def test_bench_runtime_regions(model, capsys, monkeypatch):
    out = run_script("bench_runtime_regions", "--model-dir", model, *SIZES, "--warmup", "1", "--repeats", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "end to end over 3 pairs (1 warm-up)" in out
    assert re.search(r"^  encoder heatmaps: \+ novel view stride 1 .* [\d.]+/s$", out, re.M), out


def test_time_demo_stages(model, tmp_path, capsys, monkeypatch):
    # the demo's scene, small and slow (a loop of 6 frames a camera, rendered once into tmp_path)
    url = f"sim://?fps=5&seed=0&motion=wave&policy=all&width=160&height=120&workers=1&cache={tmp_path}"
    out = run_script("time_demo_stages", "--model-dir", model, "--pairs", "3", "--url", url,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert f"3 pairs of {url} through {model} (runtime defaults); load average" in out, out
    rows = set(re.findall(r"^(\w+) +3 +[\d.]+ +[\d.]+$", out, re.M))
    assert {"preprocess", "encoder", "uncovered", "total"} <= rows, out
    assert re.search(r"^wall [\d.]+ s for the estimates \([\d.]+ pairs/s\); CPU per pair [\d.]+ ms, all threads "
                     r"\([\d.]+ ms the calling thread's\); joints checksum -?[\d.]+$", out, re.M), out
    if sys.platform.startswith("linux"):  # each thread's CPU, from /proc
        assert re.search(r"^CPU per pair by thread \(ms; \d+ threads, \d+ ran\): [\d.]+", out, re.M), out


def test_time_demo_stages_counts_what_no_stage_covers():
    from benchmarks.time_demo_stages import summarise

    timings = [{"preprocess": 1.0, "encoder": 10.0, "total": 12.0},
               {"preprocess": 2.0, "encoder": 20.0, "encoder_flip": 5.0, "total": 30.0},
               {"preprocess": 1.0, "encoder": 12.0, "total": 14.5}]
    rows = {key: (count, med) for key, count, med, _ in summarise(timings)}
    assert rows["uncovered"] == (3, 1.5)  # 1.0, 3.0 and 1.5 ms outside the stages
    assert rows["encoder_flip"] == (1, 0.0)  # run on one pair of three: the others count 0 ms
    assert rows["total"] == (3, 14.5)
    assert [key for key, *_ in summarise(timings)][:2] == ["encoder", "preprocess"]  # the stages by median


def test_time_scenes(model, capsys, monkeypatch):
    # the empty room alone: the other scenes read full-size sim:// loops (rendered once per machine)
    out = run_script("time_scenes", "--model-dir", model, "--pairs", "2", "--scenes", "empty",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "2 pairs a scene, keypoints; per-pair medians" in out, out
    assert re.search(r"^empty  total +[\d.]+ ms  CPU +[\d.]+ ms  \| .*preprocess [\d.]+.* \| checksum 0\.000000$", out,
                     re.M), out


def test_compare_3d_methods(model, tmp_path, capsys, monkeypatch):
    run_script("compare_3d_methods", "--model-dir", model, *SIZES, "--methods", "triangulate,depth_centroid",
               "--json", str(tmp_path / "r.json"), capsys=capsys, monkeypatch=monkeypatch)
    report = json.loads((tmp_path / "r.json").read_text())
    assert [row["method"] for row in report["rows"]] == ["triangulate", "depth_centroid"]


def test_measure_foot_spread(model, capsys, monkeypatch):
    out = run_script("measure_foot_spread", "--model-dir", model, *SIZES, capsys=capsys, monkeypatch=monkeypatch)
    assert "1 held-out-like sequences x 3 pairs" in out and "the floor check keeps those within 1)" in out, out
    assert re.search(r"^  dropped by the box gates: \d+: ", out, re.M), out


def test_measure_exchanged_cameras(model, capsys, monkeypatch):
    out = run_script("measure_exchanged_cameras", "--model-dir", model, *SIZES, "--window", "2", "--per-sequence",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "1 held-out-like sequences x 3 pairs" in out and "windows of 2 figures" in out, out
    assert re.search(r"^  sequence +0 \(.*\): as filmed +\d+ figures", out, re.M), out
    assert re.search(r"^  +as filmed \| .*\n  +exchanged \| ", out, re.M), out


def test_measure_exchanged_cameras_per_sequence_windows_and_flag(model, capsys, monkeypatch):
    """--per-sequence gives each sequence's windows and the pair its handedness flag came at (the figures docs/
    calibration.md quotes of single takes, two people beside each other)."""
    out = run_script("measure_exchanged_cameras", "--model-dir", model, *SIZES, "--window", "2", "--per-sequence",
                     capsys=capsys, monkeypatch=monkeypatch)
    setting = r" +\d+ figures, median +(-|-?\d\.\d\d), windows +(- to +-|-?\d\.\d\d to +-?\d\.\d\d), " \
              r"(not flagged|flagged after \d+ pairs);"
    assert re.search(rf"^  sequence +0 \(.*\): as filmed{setting} exchanged{setting}$", out, re.M), out


def test_measure_exchanged_cameras_sequence_windows_text():
    """A sequence's windows are read as the summary's (a short take: one window of all its figures)."""
    text = runpy.run_path(str(BENCH / "measure_exchanged_cameras.py"))["sequence_windows_text"]
    assert text({"hands": [0.5, -0.5, -0.7, -0.9], "flagged_at": 4}, 3) == \
        ", windows -0.70 to -0.50, flagged after 4 pairs"
    assert text({"hands": [0.25], "flagged_at": None}, 30) == ", windows  0.25 to  0.25, not flagged"
    assert text({"hands": [], "flagged_at": None}, 30) == ", windows     - to     -, not flagged"


def test_measure_exchanged_cameras_renders_the_bench_sequence_as_load_sequences_does():
    """Its own rendering (for --heading-deg and --rig) is simdata.render_frames, the bench's: as drawn, on the bench's
    rig, its frames and truth are the bench sequence's (a copy of the render loop kept no 2D truth)."""
    from ghnerf_runtime.cli.simdata import HELD_OUT_MOTIONS, SEED_BASE, _render_sequence

    mod = runpy.run_path(str(BENCH / "measure_exchanged_cameras.py"))
    ours = mod["render_variant"](0, 1, None, "bench")
    bench = _render_sequence(0, 1, 30.0, 640, 480, HELD_OUT_MOTIONS, SEED_BASE)
    assert np.array_equal(ours.images, bench.images) and np.array_equal(ours.joints_3d, bench.joints_3d)
    assert np.array_equal(ours.joints_2d, bench.joints_2d) and np.array_equal(ours.visible, bench.visible)


def test_measure_exchanged_cameras_with_the_person_facing_away_and_the_face_gate(model, capsys, monkeypatch):
    out = run_script("measure_exchanged_cameras", "--model-dir", model, "--sequences", "1", "--frames", "2",
                     "--window", "2", "--heading-deg", "180", "--face-seen", capsys=capsys, monkeypatch=monkeypatch)
    assert "1 held-out-like sequences x 2 pairs, heading 180 deg, pairs with the face seen only" in out, out


def test_measure_exchanged_cameras_one_named_sequence_and_the_heel_peaks(model, capsys, monkeypatch):
    """--only renders just the bench sequences named (a long take of one scene); the heel peaks (what gives no figure
    since session 66) are printed by the true facing."""
    out = run_script("measure_exchanged_cameras", "--model-dir", model, "--only", "25", "--frames", "2", "--window",
                     "2", "--heading-deg", "180", "--per-sequence", capsys=capsys, monkeypatch=monkeypatch)
    assert "1 held-out-like sequences x 2 pairs, heading 180 deg, sequences 25 only" in out, out
    assert re.search(r"^  sequence +25 \(", out, re.M) and not re.search(r"^  sequence +0 \(", out, re.M), out
    assert re.search(r"^ +facing away: +2 pairs, median ", out, re.M), out


def test_measure_exchanged_cameras_lying_and_two_people(model, capsys, monkeypatch):
    """--pose turns every body as measure_lying_rendered's poses do; --second adds a second person and counts the
    several_people pairs, none of which has a handedness figure."""
    out = run_script("measure_exchanged_cameras", "--model-dir", model, "--sequences", "1", "--frames", "2",
                     "--window", "2", "--pose", "lying_z", capsys=capsys, monkeypatch=monkeypatch)
    assert "1 held-out-like sequences x 2 pairs, pose lying_z," in out, out
    out = run_script("measure_exchanged_cameras", "--model-dir", model, "--sequences", "1", "--frames", "2",
                     "--window", "2", "--second", "1.0,0.4", capsys=capsys, monkeypatch=monkeypatch)
    assert "a second person 1 m across and 0.4 m behind" in out, out
    assert re.search(r"^  +as filmed: \d+ of 2 pairs several_people \(0 of them with a figure\)", out, re.M), out


def test_measure_exchanged_cameras_poses_and_second_person_render_the_truth_they_show():
    """--pose: the truth is the turned body's (lying across the view: its head and feet level, at the floor's
    height or above); --second: the subject's truth and room, a second person drawn in (the pictures differ), standing
    towards the centre line."""
    mod = runpy.run_path(str(BENCH / "measure_exchanged_cameras.py"))
    from ghnerf_runtime.body25 import JOINT_INDEX as J

    alone = mod["render_variant"](0, 1, None, "bench")
    lying = mod["render_variant"](0, 1, None, "bench", pose="lying_z")
    head, feet = lying.joints_3d[0, J["Neck"]], lying.joints_3d[0, [J["LAnkle"], J["RAnkle"]]].mean(axis=0)
    assert abs(head[1] - feet[1]) < 0.4 < abs(head[0] - feet[0]) and lying.joints_3d[0, :, 1].max() <= 0
    two = mod["render_variant"](0, 1, None, "bench", second_xz=(1.0, 0.4))
    assert np.array_equal(two.joints_3d, alone.joints_3d) and not np.array_equal(two.images, alone.images)
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene

    scene = bench_rig_and_scene(0)[1]
    other = mod["second_person"](0, scene, (1.0, 0.4))
    (x, z), (x2, z2) = scene.config.position_xz, other.config.position_xz
    assert abs(x2) < abs(x) + 1.0 and abs(abs(x2 - x) - 1.0) < 1e-9 and z2 == pytest.approx(z + 0.4)


@pytest.mark.parametrize("kind", ["higher", "toed-in", "wide"])
def test_measure_exchanged_cameras_rigs_change_the_second_camera_only(kind):
    """--rig: the first camera stays the bench's; ``higher`` raises the second by RAISE_M still aimed at the target,
    ``toed-in`` turns its axis TOE_DEG towards the first's side, ``wide`` is a WIDE_BASELINE_M baseline."""
    mod = runpy.run_path(str(BENCH / "measure_exchanged_cameras.py"))
    from ghnerf_runtime.cli.simdata import bench_rig_and_scene

    rig, _, _, placement = bench_rig_and_scene(0)
    changed = mod["variant_rig"](placement, kind, "r")
    (a0, b0), (a1, b1) = rig.pair, changed.pair
    if kind == "wide":
        assert changed.baseline == pytest.approx(mod["WIDE_BASELINE_M"]) != rig.baseline
        return
    assert np.allclose(a0.R, a1.R) and np.allclose(a0.t, a1.t)
    axis0, axis1 = b0.R[2], b1.R[2]  # the optical axes in the rig frame
    if kind == "higher":
        assert b1.center[1] == pytest.approx(b0.center[1] - mod["RAISE_M"])  # y points down
        aim = placement.target - b1.center
        assert np.allclose(axis1, aim / np.linalg.norm(aim))
    else:
        assert np.allclose(b1.center, b0.center)
        assert np.degrees(np.arccos(np.clip(axis0 @ axis1, -1, 1))) == pytest.approx(mod["TOE_DEG"], abs=0.5)
        assert axis1[0] < axis0[0]  # turned towards -x, the first camera's side


def test_measure_mounting(model, capsys, monkeypatch):
    out = run_script("measure_mounting", "--model-dir", model, "--sequences", "1", "--frames", "2", "--rolls", "0,90",
                     capsys=capsys, monkeypatch=monkeypatch)
    # a camera on its side is turned upright (roi.upright), or not
    assert "roll    90 deg, roi.upright on  (crops rotated [-90.0, -90.0])" in out, out
    assert "roll    90 deg, roi.upright off (crops rotated [0.0, 0.0])" in out, out


def test_measure_novel_overlap(model, capsys, monkeypatch):
    out = run_script("measure_novel_overlap", "--model-dir", model, *SIZES, "--warmup", "1", "--repeats", "1",
                     "--precisions", "fp32", capsys=capsys, monkeypatch=monkeypatch)
    assert "fp32: 2 pairs per variant; joints identical: True" in out, out


def test_bench_graph_threads(model, capsys, monkeypatch):
    out = run_script("bench_graph_threads", "--model-dir", model, "--sequences", "1", "--pairs", "2", "--rounds", "1",
                     "--graphs", "encoder,render_rgb", capsys=capsys, monkeypatch=monkeypatch)
    for graph, calls in (("encoder", r"\d+"), ("render_rgb", "2")):  # one novel view: its coarse and fine passes
        assert re.search(rf"^{graph}\.onnx +{calls} +[\d.]+ +[\d.]+ +[\d.]+ +[\d.]+-[\d.]+$", out, re.M), out


def test_a_tracked_pairs_view_on_the_lanes_reaches_the_render_tap(model):
    """On a tracked pair the novel view renders in the estimator's worker on the one-thread lanes
    (``session.on_lanes()``); the scripts' taps must see those renders too (they saw none: see
    ``test_the_session_taps_record_the_runs_on_the_lanes``). The tiny model tracks nobody: the track is
    placed from the truth, as ``measure_novel_quality --track-from-truth`` does."""
    from benchmarks.bench_runtime_common import RenderTap
    from ghnerf_runtime.cli.simdata import load_sequences
    from ghnerf_runtime.config import EstimatorConfig, NovelViewConfig, PresenceConfig, SessionConfig
    from ghnerf_runtime.estimator import Estimator, load_session
    from ghnerf_runtime.novel_view import NovelViewRequest
    from ghnerf_runtime.tracking import track_from_joints

    # the presence gate off: the random weights find nobody, and a pair with nobody has no novel view
    cfg = EstimatorConfig(session=SessionConfig(model_dir=model, threads=2, thread_pool="per_session"),
                          novel_view=NovelViewConfig(enabled=True, overlap=True, lanes=True),
                          presence=PresenceConfig(enabled=False))
    tap = RenderTap(load_session(cfg))
    seq = load_sequences(1, 3)[0]
    with Estimator(tap, seq.rig, cfg) as est:
        est.tracker.track = track_from_joints(seq.joints_3d[0], np.ones(25), np.ones(25, bool), cfg.tracking, 0)
        r = est.estimate((np.array(seq.images[1, 0]), np.array(seq.images[1, 1])),
                         novel_view=NovelViewRequest(alpha=0.5))
    assert r.novel_view is not None  # (r.tracked is after the pair: the random model lost the track)
    renders = tap.run_counts["render_rgb"]  # counted by the session, on a lane or not
    assert renders >= 1 and len(tap.runs) == renders


@pytest.fixture(scope="module")
def everyone_config(tmp_path_factory):
    """A config with the presence gate off: the random weights find nobody, and a pair with nobody has no novel
    view, so the novel-view scripts would have no pair to measure (the flip test off, as without a config)."""
    path = tmp_path_factory.mktemp("config") / "everyone.json"
    path.write_text(json.dumps({"presence": {"enabled": False}, "heatmaps": {"flip_test": False}}))
    return str(path)


def test_measure_novel_quality(model, everyone_config, capsys, monkeypatch):
    out = run_script("measure_novel_quality", "--model-dir", model, *SIZES, "--every", "1", "--alphas", "0,1",
                     "--strides", "1", "--track-from-truth", "--config", everyone_config,
                     capsys=capsys, monkeypatch=monkeypatch)
    for alpha in (0, 1):
        assert re.search(rf"^\| {alpha} \| 1 \| off \| off \| off \| 3 \| [\d.]+ ", out, re.M), out
    assert "accumulated opacity, coarse-pass rays of the stride-1 views" in out


def test_measure_novel_rays(model, everyone_config, capsys, monkeypatch):
    out = run_script("measure_novel_rays", "--model-dir", model, *SIZES, "--config", everyone_config,
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "3 pairs; novel view 64x64, stride 1" in out, out  # the model's size (it said 128x128 whatever it was)
    assert re.search(r"^  coarse pass +rays median +\d+ ", out, re.M), out


def test_measure_single_view(model, capsys, monkeypatch):
    out = run_script("measure_single_view", "--model-dir", model, *SIZES, "--rooms", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "3 pairs of 1 held-out-like sequences" in out, out
    # the room's other view is a textured room that reaches the model (until session 65 black frames: none passed)
    assert re.search(r"^empty rooms with one camera black: \d+ of 2 report a person \(2 of 2 good views passed the "
                     r"frame check\)$", out, re.M), out


def test_measure_frame_check(model, capsys, monkeypatch):
    out = run_script("measure_frame_check", "--model-dir", model, *SIZES, "--pairs-per-sequence", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    # one pair: each camera's cold crop and its person crop, 4 crops of each kind; the garbage is rejected
    assert re.search(r"^ +bench frame +scene +4 ", out, re.M), out
    # columns: std; fine share; coarse share; rejected flat / noise / noise by the fine share alone
    assert re.search(r"^ +uniform noise +garbage +4 +[\d.]+ / +[\d.]+ +[\d.]+ / [\d.]+ / [\d.]+ +[\d.]+ / [\d.]+ / "
                     r"[\d.]+ +0 / 4 / 4$", out, re.M), out
    assert re.search(r"^ +light x0.005 gain x200 +scene +4 ", out, re.M), out  # the sensor model's kinds


def test_measure_noisy_scenes(model, capsys, monkeypatch):
    out = run_script("measure_noisy_scenes", "--model-dir", model, *SIZES, "--rooms", "1",
                     "--kinds", "bench frame,light x0.005 gain x200", capsys=capsys, monkeypatch=monkeypatch)
    for kind in ("bench frame", "light x0.005 gain x200"):
        for rule in ("fine and coarse", "fine alone"):
            assert re.search(rf"^ +{kind} +{rule} +[\d.]+ +[\d.na]+ +[\d.na]+ +[\d.na]+ \([\d.]+\) +\d of 1 "
                             rf"\(\d of 2\)$", out, re.M), out
    err = run_script_failing("measure_noisy_scenes", "--model-dir", model, "--kinds", "moonlight",
                             capsys=capsys, monkeypatch=monkeypatch)
    assert "unknown kind(s) ['moonlight']" in err, err


def test_time_frame_check(capsys, monkeypatch):
    out = run_script("time_frame_check", "--size", "32", "--repeats", "3", "--rounds", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^ +scene +ok +[\d.]+ +[\d.]+$", out, re.M), out
    assert re.search(r"^ +uniform noise +noise +[\d.]+ +[\d.]+$", out, re.M), out


def test_time_rays_recheck(capsys, monkeypatch):
    """Every pair behind the panel rechecked at ``volume_recheck_every`` 1, one pair in four at 4 (the first of each
    four: 2 of 5); camera 1 passes throughout (the script stops otherwise)."""
    out = run_script("time_rays_recheck", "--width", "320", "--height", "240", "--pairs", "5", "--rounds", "1",
                     "--every", "4", capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^ +1 +[\d.]+ +1\.000$", out, re.M), out
    assert re.search(r"^ +4 +[\d.]+ +0\.400$", out, re.M), out
    assert re.search(r"^ratio \(4 / 1\): [\d.]+$", out, re.M), out


@pytest.mark.parametrize("option, value", [("--pairs", "0"), ("--pairs", "-3"), ("--rounds", "0"), ("--every", "0"),
                                           ("--width", "wide")])
def test_time_rays_recheck_wants_whole_numbers_of_at_least_one(option, value, capsys, monkeypatch):
    """A usage error naming the option (before: --pairs 0 divided by zero, --rounds 0 printed NaN figures, --pairs
    -3 failed on an empty clip, --every 0 raised the config's error after the clip was rendered)."""
    err = run_script_failing("time_rays_recheck", option, value, capsys=capsys, monkeypatch=monkeypatch)
    assert f"argument {option}: " in err and (f"got {value}" in err or f"got {value!r}" in err), err


def test_measure_one_camera(model, capsys, monkeypatch):
    out = run_script("measure_one_camera", "--model-dir", model, *SIZES, "--rooms", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "3 pairs of 1 held-out-like sequences" in out, out
    assert re.search(r"^  camera 1 alone: camera 1 PCK@0.2 ", out, re.M), out
    assert re.search(r"^  camera 1 alone: \d+ of 3 pairs searched the crop turns, [\d.]+ ms per pair", out, re.M), out
    assert "the same rooms without anyone, both cameras: " in out and "1 empty rooms: " in out, out


@pytest.mark.filterwarnings("ignore:Mean of empty slice", "ignore:invalid value encountered")
def test_measure_still_pairs(model, capsys, monkeypatch):
    out = run_script("measure_still_pairs", "--model-dir", model, *SIZES, "--every", "2",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "2 still pairs of 1 held-out-like sequences" in out, out
    assert out.count("refine_cold_start") == 2


def test_tune_runtime_knobs(model, capsys, monkeypatch):
    out = run_script("tune_runtime_knobs", "--model-dir", model, *SIZES, "--precision", "fp32", "--only", "default",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^default +tuning .* \| bench ", out, re.M), out


def test_soak_daemon(model, capsys, monkeypatch):
    out = run_script("soak_daemon", "--model-dir", model, "--minutes", "0.05", "--unplug-every-s", "1",
                     "--sample-s", "1", "--reload-every-s", "1", "--fps", "10", capsys=capsys, monkeypatch=monkeypatch)
    stopped = re.search(r"stopped: (\d+) pairs estimated, (\d+) opens, (\d+) estimate errors, (\d+) reloads "
                        r"\((\d+) refused\)", out)
    assert stopped, out
    pairs, opens, errors, reloads, refused = map(int, stopped.groups())
    assert pairs > 0 and opens >= 2 and errors == 0 and reloads >= 1 and refused == 0, out


def test_measure_reload_memory(model, capsys, monkeypatch):
    # glibc's threshold left as it is (0): the script's default would fix it for this whole test process
    out = run_script("measure_reload_memory", "--model-dir", model, "--loads", "8", "--pairs", "2",
                     "--mmap-threshold", "0", capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^ +(\d+) +([12]) +[\d.]+ +[-+][\d.]+ +(True|False) ", out, re.M)
    assert [(n, t) for n, t, _ in rows] == [(str(n), "21"[n % 2]) for n in range(1, 9)], out
    assert re.search(r"^after 8 loads: [\d.]+ -> [\d.]+ MB", out, re.M), out
    # what tells a leak from a level: RSS at the marks on the last load's threads, the last half's slopes
    assert re.search(r"^RSS at loads 4 / 8 \(2 threads\): [\d.]+ / [\d.]+ MB$", out, re.M), out
    glibc = [] if glibc_only_reason() else [r"glibc in use \(used \+ mmap\)"]  # mallinfo2 is glibc's
    for what in [r"RSS", *glibc]:
        assert re.search(rf"^slope over loads 5-8, {what}: [-+][\d.]+ KB a load at 2 threads \(2 loads\), "
                         r"[-+][\d.]+ KB a load at 1 thread \(2 loads\)$", out, re.M), out


def test_measure_reload_memory_figures():
    script = runpy.run_path(str(BENCH / "measure_reload_memory.py"))  # its functions; main() not run
    assert script["slope_kb_per_load"]([11, 13, 15], [100.0, 101.0, 102.0]) == pytest.approx(512.0)
    assert script["on_last_threads"](10, 301) == 11 and script["on_last_threads"](150, 300) == 150
    rss = {n: 140.0 + (12.0 if n % 2 == 0 else 0.0) + 0.001 * n for n in range(1, 301)}  # levels 12 MB apart
    threads = {n: 2 if n % 2 == 0 else 1 for n in rss}
    assert script["marks_line"](rss, threads) == "RSS at loads 10 / 150 / 300 (2 threads): 152.0 / 152.2 / 152.3 MB"
    assert script["slope_line"]("RSS", rss, threads) == ("slope over loads 151-300, RSS: +1.0 KB a load at 2 threads "
                                                         "(75 loads), +1.0 KB a load at 1 thread (75 loads)")


def test_bench_runtime_vs_eval(model, data64, capsys, monkeypatch):
    out = run_script("bench_runtime_vs_eval", "--model-dir", model, "--data", str(data64), "--split", "val",
                     "--novel", capsys=capsys, monkeypatch=monkeypatch)
    assert "2 scenes" in out
    assert len(re.findall(r"^  [ABC] (rendered|encoder) heatmaps", out, re.M)) == 6, out
    # C: the runtime's own view; the random weights find nobody, and a pair with nobody has none (counted)
    views = re.findall(r"masked PSNR mean .* \((\d+) scenes; (\d+) without a view", out)
    assert len(views) == 3 and all(int(a) + int(b) == 2 for a, b in views), out


def test_measure_novel_ceiling(data64, capsys, monkeypatch):
    out = run_script("measure_novel_ceiling", "--data", str(data64), "--split", "val",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^\| novel, all \| \d+ \| [\d.]+ \|", out, re.M), out


def test_measure_presence(model, capsys, monkeypatch):
    out = run_script("measure_presence", "--model-dir", model, "--rooms", "1", capsys=capsys, monkeypatch=monkeypatch)
    for source in ("rendered", "encoder"):
        assert re.search(rf"^ *{source} heatmaps .*: empty rooms: joints found \d+-\d+, .* \| 40 pairs with a person",
                         out, re.M), out


def test_measure_presence_with_the_flip_test_and_its_timing(model, capsys, monkeypatch):
    """The documented ``--flip-test`` run (its recorder's ``_flip_test`` lacked the estimator's ``beside``
    argument: a TypeError on the first pair) and ``--time --novel-view`` (docs/runtime.md, "Compute only what
    the scene requires"), and ``--time-turn-search-off`` (docs/turn-search.md, "Lying and upside down, rendered")."""
    out = run_script("measure_presence", "--model-dir", model, "--rooms", "1", "--flip-test", "--time",
                     "--novel-view", "--time-turn-search-off", capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^ *encoder heatmaps \(triangulate, flip test\): empty rooms", out, re.M), out
    assert re.search(r"^ *before the mirrored run \(heatmaps.flip_test_skip_below\): empty rooms max [\d.]+", out,
                     re.M), out
    assert re.search(r"^empty rooms, the defaults with a novel view requested on every pair: [\d.]+ ms median per "
                     r"pair, 0 of 10 pairs with a novel view$", out, re.M), out
    # the search is on by default (session 57): the defaults' searches always, --time-turn-search-off times it off
    assert re.search(r"^empty rooms, the defaults \(roi.turn_search on\): \d+ of 11 pairs searched the crop turns, "
                     r"\d+ of 10 reported someone$", out, re.M), out
    assert re.search(r"^empty rooms, the defaults with roi.turn_search off: [\d.]+ ms median per pair \(the defaults "
                     r"[\d.]+x that\)$", out, re.M), out


def test_measure_two_people(capsys, monkeypatch):
    out = run_script("measure_two_people", "--scenes", "1", "--pairs", "2", capsys=capsys, monkeypatch=monkeypatch)
    followed = r"; scenes following the first person \d, the second \d, one person throughout \d of 1$"
    assert re.search(r"^2 pairs of two people \(1 scenes\), .* pick_subject centre_line: [\d.]+ joints reported per "
                     r"pair; of them \d+% at the first person's, \d+% at the second's, \d+% at neither .*; \d+% of "
                     r"pairs flagged several_people" + followed, out, re.M), out
    assert re.search(r"^the second person joining after 3 pairs of the first alone, the next 2 pairs, .* [\d.]+ joints "
                     r"reported per pair; .*; \d+% of pairs flagged several_people" + followed, out, re.M), out
    # the picked person's joints from the first pair (session 54; session 53 reported none without a track)
    assert re.search(r"^2 pairs of two people .*: 2[0-5]\.\d joints reported per pair; of them 100% at the first", out,
                     re.M), out
    # each row's passes: the joints shown twice per view and the people's cell distances (docs/two-people.md, "Two
    # people 0.6 m apart")
    twice = re.findall(r"^  (\d+) passes: joints shown twice at 0\.5 per pass, view 0 [\d.]+, view 1 [\d.]+, both "
                       r"[\d.]+; the people's peaks of a joint [\d.]+-[\d.]+ cells apart in view 0, [\d.]+-[\d.]+ in "
                       r"view 1 \(10th-90th percentile\); a torso of two people \(two_people\.mixed_torso\) on (\d+) "
                       r"passes; roi\.turn_search searches (\d+)$", out, re.M)
    # and the crop turn searches its estimators ran (session 57's review N): two people standing, picked, none; and
    # the passes whose peaks made a torso of two people (session 58), at most every pass
    assert len(twice) == 2 and all(int(n) >= 2 and int(t) <= int(n) and s == "0" for n, t, s in twice), out
    # and each row's torso excess over one body's, as measured and as the rule reads it (docs/two-people.md, "A torso of
    # two people": the figures came from a script outside the repository before session 58's review F)
    assert len(re.findall(TORSO_SPREAD, out, re.M)) == 2, out


def test_measure_two_people_counts_the_scan_s_answers(capsys, monkeypatch):
    # docs/two-people.md, "Anyone else near?" (session 64): --scan-every-s adds each row's pairs with a scan's answer
    # and those saying someone else is there; the oracle's second person a metre beside is told on every pair after
    # the cold start's (which starts the scan clock: no answer); since session 66 also where the scans' crops put the
    # second person: inside the subject's blanked cells or not, and how far from the subject's joints
    out = run_script("measure_two_people", "--scenes", "1", "--pairs", "3", "--alone", "0", "--scan-every-s", "0.001",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^3 pairs of two people .*; someone_else on 2 of 2 pairs with a scan's answer \(100%; 3 pairs\); "
                     r"the second person's joints inside the subject's blanked cells, per scan, view 0 \d+\.\d, view 1 "
                     r"\d+\.\d of 25, each joint \d+\.\d cells from the first's \(median\), with a peak of their own "
                     r"\(within 1\.5 cells of theirs, not of the first's\) view 0 \d+\.\d, view 1 \d+\.\d$",
                     out, re.M), out
    plain = run_script("measure_two_people", "--scenes", "1", "--pairs", "2", "--alone", "0", capsys=capsys,
                       monkeypatch=monkeypatch)
    assert "someone_else" not in plain, plain


def test_measure_two_people_turn_search_off_names_itself_in_each_row(capsys, monkeypatch):
    # docs/two-people.md, "People close together" (session 57's review L): the counts with the crop turn search off
    # come from this option (a script outside the repository gave them before); every row says the search is off
    out = run_script("measure_two_people", "--scenes", "1", "--pairs", "2", "--no-turn-search", capsys=capsys,
                     monkeypatch=monkeypatch)
    rows = re.findall(r"^(2 pairs of two people|the second person joining after 3 pairs) .*, roi\.turn_search off, "
                      r"the defaults, pick_subject \w+: [\d.]+ joints reported per pair", out, re.M)
    assert len(rows) == 2, out
    assert len(re.findall(r"; roi\.turn_search searches 0$", out, re.M)) == 2, out


def test_measure_two_people_turn_search_off_is_refused_where_the_rows_are_not_run(capsys, monkeypatch):
    err = run_script_failing("measure_two_people", "--one-person-model", "models", "--no-turn-search", capsys=capsys,
                             monkeypatch=monkeypatch)
    assert "--no-turn-search sets the two-people rows' estimators" in err, err


def test_measure_two_people_by_joint(capsys, monkeypatch):
    # the joint-by-joint figures of docs/two-people.md ("Fewer, right joints", session 59) come from this option: each
    # row's 25 joints, the pairs reporting each and of them those without a subject's pairing (at most as many)
    out = run_script("measure_two_people", "--scenes", "1", "--pairs", "2", "--alone", "0", "--by-joint",
                     capsys=capsys, monkeypatch=monkeypatch)
    lines = re.findall(r"^  by joint \(pairs reporting it, mean mm from the nearer person's, of them without a "
                       r"subject's pairing\): (.*)$", out, re.M)
    assert len(lines) == 1, out
    joints = re.findall(r"(\w+) (\d+)(?: [\d.]+ \((\d+)\))?(?:, |$)", lines[0])
    assert [name for name, *_ in joints] == list(JOINT_NAMES), lines[0]
    assert all(int(k) <= 2 and int(without or 0) <= int(k) for _, k, without in joints), lines[0]
    assert sum(int(k) for _, k, _ in joints) >= 2 * 20, lines[0]  # the oracle's picked person, nearly whole


class _TwoPasses:
    """A stand-in estimator whose pair runs two passes that each look for the subject's pairings, the first
    reported and the second not (a turn search's candidate that is not kept, say), and a third that does not look
    (a pass not flagged)."""

    def __init__(self):
        self.subject_selector = SimpleNamespace(keep_tracked_subject=self._keep_tracked_subject)

    def _keep_tracked_subject(self, found):
        from ghnerf_runtime.joints3d import Joints3D
        n = len(found)
        return None, None, Joints3D(np.zeros((n, 3)), np.ones(n, np.float32), found, np.zeros((n, 2)))

    def _finish_pass(self, found):
        if found is not None:
            self.subject_selector.keep_tracked_subject(found)
        return SimpleNamespace(conf_2d={})  # a dict of its own, as each pass's

    def estimate(self):
        reported = self._finish_pass(np.array([True, False, True]))
        self._finish_pass(np.array([False, True, True]))
        unflagged = self._finish_pass(None)
        return (SimpleNamespace(sequence=7, confidence_2d=reported.conf_2d),
                SimpleNamespace(sequence=7, confidence_2d=unflagged.conf_2d))


def test_measure_two_people_by_joint_takes_the_reported_pass_s_pairings():
    # --by-joint's "without a subject's pairing" counts are the reported pass's (session 59's review): until then the
    # pair's last keep_tracked_subject call was taken, here the second pass's, not reported
    from benchmarks.measure_two_people import SubjectPairings
    est = _TwoPasses()
    pairings = SubjectPairings(est)
    flagged, unflagged = est.estimate()
    assert pairings.of(flagged).tolist() == [True, False, True]
    assert pairings.of(unflagged) is None  # the pass did not look for the subject's pairings
    pairings.passes.clear()  # the next pair's: this pair's passes are not among them
    with pytest.raises(LookupError, match="pair 7: none of its 0 passes is the one reported"):
        pairings.of(flagged)


#: A row's torso line (``measure_two_people.torso_spread``): the passes, the excess's median, p90 and max, the neck to
#: mid-hip's and the hips' max, and the rule's reading with the passes over the slack (and the margin, with none).
TORSO_SPREAD = (r"^  the torso's largest excess over one body's \(two_people\.torso_excess\) on \d+ passes: median "
                r"[-+][\d.]+, p90 [-+][\d.]+, max [-+][\d.]+ m \(neck to mid-hip max ([-+][\d.]+|none), a hip max "
                r"([-+][\d.]+|none)\); as mixed_torso reads it \(along the line of sight over "
                r"two_people\.depth_scale\): median [-+][\d.]+, max [-+][\d.]+ m, \d+ over the 0\.5 m slack"
                r"(, the least margin under it [\d.]+ m)?$"
                r"|^  the torso's excess over one body's: no pass with a torso limb strong in both views$")


def test_measure_two_people_calibration(capsys, monkeypatch):
    # the two-people calibration figures of docs/calibration.md come from this mode (session 55)
    out = run_script("measure_two_people", "--calibration", "0,2", "--scenes", "1", "--pairs", "2", "--alone", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    lines = re.findall(r"^pan (0|2) deg, 2 pairs of two people \(1 scenes, 1 pairs of the first alone before each\), "
                       r"pick_subject centre_line: 2 flagged; lowest_foot_m on 2 \(the subject alone 2\), \|two - "
                       r"alone\| median [\d.]+, max ([\d.]+) m; reprojection_px_median on 2 \(alone 2\), .*; scene "
                       r"medians of lowest_foot_m: two people ([-+][\d.]+) to [-+][\d.]+ m, (\d) of 1 past 0.05 m, "
                       r"the first alone .*$", out, re.M)
    assert [line[0] for line in lines] == ["0", "2"], out
    assert all(float(line[1]) <= 0.02 for line in lines), out  # the subject's own feet, as alone
    assert [line[3] for line in lines] == ["0", "1"], out  # the 2 degree pan's feet below the floor


@pytest.mark.parametrize("mode, ignored", [
    (("--calibration", "0"), ("--model-dir", "models")),
    (("--calibration", "0"), ("--skeleton-prior", "off")),
    (("--one-person-model", "models"), ("--skeleton-prior", "on")),
    (("--calibration", "0"), ("--swap",)),  # (--places is what it takes)
])
def test_measure_two_people_refuses_options_its_mode_does_not_use(mode, ignored, capsys, monkeypatch):
    # --model-dir and --skeleton-prior (the trained model's rows) came in beside --calibration and
    # --one-person-model, which ran on without them and printed figures that looked like the model's or prior's
    out = run_script_failing("measure_two_people", *mode, *ignored, capsys=capsys, monkeypatch=monkeypatch)
    assert f"{mode[0]} does not use {ignored[0]}" in out, out


def test_measure_two_people_through_a_model(model, capsys, monkeypatch):
    # the trained model's rows of docs/two-people.md ("Two people in the working volume") come from this mode; the tiny
    # model finds nobody, so only the rows and their order are checked
    out = run_script("measure_two_people", "--model-dir", model, "--scenes", "1", "--pairs", "1", "--alone", "1",
                     capsys=capsys, monkeypatch=monkeypatch)
    rows = re.findall(r"^(reference: the first person alone, 1 pairs|1 pairs of two people|the second person joining "
                      r"after 1 pairs of the first alone, the next 1 pairs)[ ,].* on the rendered pairs, the "
                      r"defaults, pick_subject centre_line: [\d.]+ joints reported per pair; .* mm from the nearer "
                      r"person's \(mean; [^)]*\); \d+% of pairs flagged several_people; ", out, re.M)
    assert rows == ["reference: the first person alone, 1 pairs", "1 pairs of two people",
                    "the second person joining after 1 pairs of the first alone, the next 1 pairs"], out


def test_measure_two_people_one_person(model, capsys, monkeypatch):
    # the one-person figures of docs/two-people.md ("Two people in the working volume") come from this mode
    out = run_script("measure_two_people", "--one-person-model", model, *SIZES, capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^one person, .* at the defaults, 1 bench sequences of 3 pairs: \d+ of 3 pairs flagged "
                     r"several_people; joints (identical|DIFFERENT) with the check on and off; "
                     r"(nan|[\d.]+) mm over [\d.]+ % of joints \(against the truth\)$", out, re.M), out
    hist = re.search(r"^passes by joints shown twice in both views at 0\.5: (.*) \((\d+) passes\); a torso of two "
                     r"people \(two_people\.mixed_torso\) on (\d+) of them$", out, re.M)
    assert hist, out
    counts = [int(c) for c in re.findall(r"\d+ joints: (\d+)", hist.group(1))]
    assert counts and sum(counts) == int(hist.group(2)) >= 3, out  # every pass counted, at least one a pair
    assert int(hist.group(3)) <= int(hist.group(2)), out  # (session 58: docs/two-people.md, "A torso of two people")
    assert re.search(TORSO_SPREAD, out, re.M), out


def test_measure_two_people_one_person_at_the_working_volume_s_ends(model, capsys, monkeypatch):
    # docs/two-people.md, "A torso of two people": one person at the ends and corners of the working volume
    # (test_model_extremes' places), each place's flags and torso excess (session 58's review F)
    out = run_script("measure_two_people", "--one-person-model", model, "--ends", "--scenes", "1", "--frames", "2",
                     "--motions", "wave,squat", capsys=capsys, monkeypatch=monkeypatch)
    places = re.findall(r"^one person at \(([-\d.]+), ([\d.]+)\), .* at the defaults, 1 scenes of wave/squat x 2 "
                        r"pairs: \d+ of 4 pairs flagged several_people, [\d.]+ % of joints found; ", out, re.M)
    assert places == [("0", "2"), ("0", "4"), ("-0.8", "2"), ("0.8", "2"), ("-0.8", "4"), ("0.8", "4")], out
    spread = TORSO_SPREAD.replace("^  ", "; ")
    assert len(re.findall(spread, out, re.M)) == 6, out
    out = run_script_failing("measure_two_people", "--ends", capsys=capsys, monkeypatch=monkeypatch)
    assert "--ends places one person through a model: give --one-person-model DIR" in out, out
    out = run_script_failing("measure_two_people", "--one-person-model", model, "--ends", "--motions", "wave,hop",
                             capsys=capsys, monkeypatch=monkeypatch)
    assert "--motions: hop not among stand, walk, wave" in out, out


def test_measure_two_people_behind_and_occluded(capsys, monkeypatch):
    # docs/two-people.md, "One person behind the other" (session 56): --behind places the second person along view 0's
    # line of sight through the first, --occlude hides what is behind a body; the rows say both
    out = run_script("measure_two_people", "--places=0,2.5,0,0", "--behind", "1", "--occlude", "--scenes", "1",
                     "--pairs", "1", "--alone", "0", capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^1 pairs of two people \(1 scenes\) at \(0, 2\.5\) and \(0\.233, 3\.472\), the oracle's "
                     r"heatmaps, each person's joints behind the other's body hidden, ", out, re.M), out
    hidden = re.search(r"the second person's joints hidden per pass, view 0 (\d+)%, view 1 (\d+)%; a torso of two "
                       r"people \(two_people\.mixed_torso\) on \d+ passes; roi\.turn_search searches \d+$", out, re.M)
    assert hidden and int(hidden.group(1)) >= 90 and int(hidden.group(2)) < 90, out  # behind as view 0 sees it
    out = run_script_failing("measure_two_people", "--occlude", "--model-dir", "models", capsys=capsys,
                             monkeypatch=monkeypatch)
    assert "--occlude is the oracle's" in out, out
    out = run_script_failing("measure_two_people", "--behind", "0", capsys=capsys, monkeypatch=monkeypatch)
    assert "--behind needs a distance above 0 m" in out, out


def test_measure_two_people_off_joints_says_where_each_view_read_them(capsys, monkeypatch):
    # docs/two-people.md, "Which joints are off behind the subject" (session 67): --off-joints adds to each row with the
    # second person its joints 5 cm or more from both, by where each view's 2D joint of them lies, and joint by joint;
    # the counts add up to the row's joints at neither person
    out = run_script("measure_two_people", "--places=0,2.5,0,0", "--behind", "1", "--scenes", "1", "--pairs", "2",
                     "--alone", "0", "--off-joints", capsys=capsys, monkeypatch=monkeypatch)
    row = re.search(r"^2 pairs of two people .*: ([\d.]+) joints reported per pair; of them \d+% at the first person's, "
                    r"\d+% at the second's, (\d+)% at neither", out, re.M)
    kinds = re.search(r"^  off joints \(5 cm or more from both people\), (\d+), by where view 0 / view 1's 2D joint "
                      r"lies \(within 8 px of the first person's, the second's, neither's, none reported\): (.*)$",
                      out, re.M)
    joints = re.search(r"^  off joints by joint, pairs not flagged / flagged: (.*)$", out, re.M)
    assert row and kinds and joints, out
    off = int(kinds.group(1))
    assert round(100 * off / (2 * float(row.group(1)))) == pytest.approx(int(row.group(2)), abs=1), out
    each = re.findall(r"(?:^|, )(\w+) (\d+)/(\d+)", joints.group(1))
    assert all(name in JOINT_NAMES for name, _, _ in each), out
    assert sum(int(a) + int(b) for _, a, b in each) == off, out
    if off:
        kind = r"(?:not flagged|flagged) (?:first|second|neither|none) / (?:first|second|neither|none) (\d+) \(\d+%\)"
        assert sum(int(n) for n in re.findall(kind, kinds.group(2))) + sum(
            int(n) for n in re.findall(r"the rest (\d+)", kinds.group(2))) == off, out
    plain = run_script("measure_two_people", "--scenes", "1", "--pairs", "1", "--alone", "0", capsys=capsys,
                       monkeypatch=monkeypatch)
    assert "off joints" not in plain, plain


def test_read_off_names_the_person_whose_projected_joint_a_2d_joint_lies_near():
    from benchmarks.measure_two_people import NEAR_PX, read_off

    first, second = np.array([100.0, 100.0]), np.array([100.0 + 3 * NEAR_PX, 100.0])
    assert read_off(np.array([100.0 + 0.5 * NEAR_PX, 100.0]), first, second) == "first"
    assert read_off(np.array([100.0 + 2.5 * NEAR_PX, 100.0]), first, second) == "second"
    assert read_off(np.array([100.0 + 1.5 * NEAR_PX, 100.0]), first, second) == "neither"  # within NEAR_PX of neither
    assert read_off(None, first, second) == "none"  # no 2D joint reported (a joint the skeleton prior placed)
    # a person's joint that camera does not show (projected NaN) is nobody's reading, and both near: the nearer
    assert read_off(first, np.full(2, np.nan), first + 1.0) == "second"
    assert read_off(first + 0.6 * NEAR_PX, first, first + NEAR_PX) == "second"


# ------------------------------------------------------------------------------- calibration drift
@pytest.mark.parametrize("option, bad", [("--max-floor-m", b) for b in ("0.05,x", "0", "0.05,-0.1", "nan")]
                         + [("--lift-m", b) for b in ("0.01,x", "-0.01", "0.5", "nan")])
def test_measure_calibration_drift_refuses_metres_that_are_not(option, bad, capsys, monkeypatch):
    # --max-floor-m takes several limits since session 56 (a column each): each must be a positive number;
    # --lift-m several heights of the person above the floor, each in [0, 0.3] m
    err = run_script_failing("measure_calibration_drift", option, bad, capsys=capsys, monkeypatch=monkeypatch)
    assert f"{option}: {bad!r}" in err, err


@pytest.mark.skipif(not (BENCH.parent / "models" / "model_card.json").is_file(), reason="no trained model")
def test_measure_calibration_drift_turns_the_camera_asked_and_counts_each_limit(scratch_cache, capsys, monkeypatch):
    # the floor check's table of docs/calibration.md comes from this script, --camera 0 for the first camera's rows
    out = run_script("measure_calibration_drift", "--model-dir", str(BENCH.parent / "models"), "--sequences", "1",
                     "--frames", "2", "--axes", "pan", "--degrees", "1", "--window", "2", "--camera", "0",
                     "--max-floor-m", "0.05,0.1", capsys=capsys, monkeypatch=monkeypatch)
    assert "the first camera's rig entry turned" in out, out
    assert re.search(r"\| past 0\.05 m \| past 0\.1 m$", out, re.M), out
    rows = re.findall(r"^ +(true rig|pan 1 deg) \| +\d+/2 +\|.*\| +(\d+|-)/?\d* +\| +(\d+|-)/?\d* *$", out, re.M)
    assert [r[0] for r in rows] == ["true rig", "pan 1 deg"], out


@pytest.mark.skipif(not (BENCH.parent / "models" / "model_card.json").is_file(), reason="no trained model")
def test_measure_calibration_drift_counts_the_turn_searches_and_sets_the_search_off(scratch_cache, capsys,
                                                                                    monkeypatch):
    # docs/calibration.md, "The crop turn search and these figures": the tables with the search on (the shipped
    # model's default) and off, and the searches each ran, come from this script (a script outside it gave them before)
    common = ("--model-dir", str(BENCH.parent / "models"), "--sequences", "1", "--frames", "2", "--axes", "pan",
              "--degrees", "1", "--window", "2")
    on = run_script("measure_calibration_drift", *common, capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^roi\.turn_search on: \d+ crop turn searches in the 4 pairs$", on, re.M), on
    off = run_script("measure_calibration_drift", *common, "--no-turn-search", capsys=capsys, monkeypatch=monkeypatch)
    assert re.search(r"^roi\.turn_search off: 0 crop turn searches in the 4 pairs$", off, re.M), off
    assert [r for r in re.findall(r"^ +(true rig|pan 1 deg) \|", off, re.M)] == ["true rig", "pan 1 deg"] * 2, off


@pytest.mark.skipif(not (BENCH.parent / "models" / "model_card.json").is_file(), reason="no trained model")
def test_measure_calibration_drift_raises_the_person_through_the_true_rig(scratch_cache, capsys, monkeypatch):
    # docs/calibration.md, "Shoes, mats: the standing foot": a row per lift, the turns not run, and the windows
    # counted again with the standing foot set to the default plus the lift
    out = run_script("measure_calibration_drift", "--model-dir", str(BENCH.parent / "models"), "--sequences", "1",
                     "--frames", "2", "--window", "2", "--lift-m", "0,0.03", "--max-floor-m", "0.05",
                     capsys=capsys, monkeypatch=monkeypatch)
    assert "the person raised above the floor, the true rig" in out, out
    assert re.search(r"\| short \| past 0\.05 m \| set 0\.04\+lift: past 0\.05 m$", out, re.M), out
    rows = re.findall(r"^ +(lifted [\d.]+ m) \| +(\d+)/2 +\| +([-\d.]+) .*\| +(\d+|-)/?\d* +\| +(\d+|-)/?\d* *$",
                      out, re.M)
    assert [r[0] for r in rows] == ["lifted 0 m", "lifted 0.03 m"], out  # the floor table's rows
    assert not re.search(r"^ +(true rig|tilt|pan|roll)\b", out, re.M), out
