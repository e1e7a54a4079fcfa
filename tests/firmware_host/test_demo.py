"""``python -m firmware_host.demo`` (``make demo``): the main job on the simulated rig, run briefly.

The estimate tests use the shipped model (models/) and skip until it exists
(models/model_card.json); the error and ``--truth-only`` tests need no model.
"""
from __future__ import annotations

import dataclasses
import errno
import json
import os
import re
import time
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

import drivers
from firmware_host import demo
from ghnerf_runtime import rig_file
from ghnerf_runtime.cli.sigterm import Terminated
from ghnerf_runtime.estimator import Estimator
from tests.firmware_host.joint_stream_helpers import record_take
from tests.stops import stop_around

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                 reason="no trained model yet: models/model_card.json does not exist")


@pytest.fixture(scope="module")
def sim_url(tmp_path_factory) -> str:
    """The demo's default rig, with the pre-rendered loop cached for this module only."""
    cache = tmp_path_factory.mktemp("sim-cache")
    return f"{demo.DEFAULT_URL}&cache={cache}"


def _small_take(tmp_path: Path) -> tuple[Path, str]:
    """A take's folder under ``tmp_path`` and the ``record+`` URL of a small simulated rig recording into it."""
    take = tmp_path / "take"
    return take, f"record+sim://?width=40&height=30&seed=8&cache={tmp_path / 'cache'}&out={take}"


def _joints_rows(path: Path) -> list[dict]:
    return [m for m in map(json.loads, path.read_text().splitlines()) if m["type"] == "JOINTS"]


def _summary(out: str) -> tuple[int, int, int]:
    m = re.search(r"^pairs: (\d+) delivered, (\d+) estimated .*?, (\d+) skipped", out, re.M)
    assert m, out
    return int(m[1]), int(m[2]), int(m[3])


@needs_model
def test_streams_estimated_joints_and_prints_the_summary(tmp_path, capsys, sim_url, recorded):
    rc = demo.main(["--url", sim_url, "--seconds", "1.5", "--out", str(tmp_path), "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0, out

    delivered, estimated, skipped = _summary(out)
    assert estimated == len(recorded) >= 3
    assert delivered == estimated + skipped
    assert re.search(r"estimator latency \(timing_ms total\): median [\d.]+ ms, p99 [\d.]+ ms", out), out
    assert re.search(r"estimated joints found: [\d.]+%", out), out
    assert re.search(r"accuracy of the estimate vs ground truth: MPJPE \d+ mm over the \d+ joints found", out), out
    # the jitter needs a joint found in three pairs in a row (the demo skips pairs it cannot keep up with)
    seqs, found = [r.sequence for r in recorded], [~np.asarray(r.missing) for r in recorded]
    chained = any(s1 == s0 + 1 and s2 == s1 + 1 and (f0 & f1 & f2).any()
                  for s0, s1, s2, f0, f1, f2 in zip(seqs, seqs[1:], seqs[2:], found, found[1:], found[2:]))
    assert bool(re.search(r"; jitter \d+\.\d mm per pair\^2", out)) == chained, out
    assert ("; jitter not measured: no joint found in three pairs in a row" in out) != chained, out
    assert "2D PCK@0.2" in out
    assert (tmp_path / "sim_pair.png").stat().st_size > 0

    # What was streamed is the estimate, joint for joint (mm on the wire), missing joints flagged.
    rows = _joints_rows(tmp_path / "joints.jsonl")
    assert [r["seq"] for r in rows] == list(range(len(recorded)))  # the frames sent, not the rig's pair numbers
    for msg, result in zip(rows, recorded):
        joints = np.array(msg["joints"], dtype=float)
        assert joints.shape == (25, 5) and np.all(np.isfinite(joints))
        missing = joints[:, 4] == 1
        assert set(np.unique(joints[:, 4])) <= {0.0, 1.0}
        np.testing.assert_array_equal(missing, result.missing)
        assert np.all(joints[missing, :4] == 0)  # missing: zeros, confidence 0
        assert np.all(joints[~missing, 3] >= 1)  # found: confidence 1..255
        np.testing.assert_allclose(joints[~missing, :3], 1000 * result.joints_3d[~result.missing], atol=0.51)
    assert sum(r.num_found for r in recorded) > 0  # the shipped model finds about half the joints
    # The true simulated rig: the calibration check never flags it (judged or not in so short a run).
    assert re.search(r"^calibration check: (fits|not judged)", out, re.M), out
    assert not any(r["flags"] & 0x20 for r in rows)  # CALIBRATION_SUSPECT


@needs_model
def test_a_slow_estimator_skips_to_the_newest_pair(tmp_path, capsys, sim_url, monkeypatch):
    original, open_rig, estimates = Estimator.estimate, drivers.create_rig_source, []

    def slow(self, *args, **kwargs):
        time.sleep(0.1)  # three frame periods at 30 fps
        estimates.append(original(self, *args, **kwargs))
        return estimates[-1]

    def ending_after_five_estimates(url):
        # the run ends on a count, not on --seconds: 1 s gave a loaded host two estimates, too few to judge
        source = open_rig(url)
        read = source.read

        def read_until_five(timeout_s):
            if len(estimates) >= 5:
                raise drivers.EndOfStream("five estimates")
            return read(timeout_s=timeout_s)

        source.read = read_until_five
        return source

    monkeypatch.setattr(Estimator, "estimate", slow)
    monkeypatch.setattr(drivers, "create_rig_source", ending_after_five_estimates)
    rc = demo.main(["--url", sim_url, "--seconds", "120", "--out", str(tmp_path), "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0, out
    delivered, estimated, skipped = _summary(out)
    assert estimated > 0 and skipped > 0 and delivered == estimated + skipped
    rows = _joints_rows(tmp_path / "joints.jsonl")
    seqs = [r["seq"] for r in rows]
    # The pairs skipped were never frames: no gap in the stream's seq, where a gap means lost on the link
    # (docs/protocol.md section 3); the summary counts them instead.
    assert seqs == list(range(estimated))
    # Each estimate takes the newest pair: while one runs (>= 0.1 s, three periods at 30 fps) at least
    # three pairs arrive, so consecutive frames are >= ~3 periods apart in capture time. An estimator that
    # took the pairs in turn (skipping only what overflowed) would step one period at a time. A loaded
    # machine only makes the estimates, and so the steps, longer; 2.5 periods leaves room for capture jitter.
    period_us = 1e6 / 30
    steps = np.diff([r["capture_us"] for r in rows])
    assert len(steps) >= 2, rows
    assert np.median(steps) >= 2.5 * period_us, steps.tolist()


@needs_model
def test_a_suspect_calibration_is_streamed_printed_and_drawn(tmp_path, capsys, sim_url, monkeypatch):
    # The demo ran no calibration check: a rig whose camera was knocked since ghcal streamed and printed as if
    # all fitted, where the daemon flags CALIBRATION_SUSPECT. Here every estimate's views miss by 2 px.
    original = Estimator.estimate
    results = []

    def drifted(self, *args, **kwargs):
        result = dataclasses.replace(original(self, *args, **kwargs), reprojection_px_median=2.0,
                                     lowest_foot_m=0.03)  # the feet stay on the floor: one symptom only
        results.append(result)
        return result

    monkeypatch.setattr(Estimator, "estimate", drifted)
    monkeypatch.setattr(demo, "CALIBRATION_WINDOW", 3)  # the daemon's 30 pairs would need a longer run
    # 3 s, not the other tests' 1.5 s: a full window of 3 estimates must fit even on a loaded 2-core host
    # STATUS every 50 ms: the file sink's STATUS lines must say it too, as the daemon's do
    sink = (tmp_path / "joints.jsonl").as_uri() + "?status_s=0.05"
    rc = demo.main(["--url", sim_url, "--seconds", "3", "--out", str(tmp_path), "--model-dir", str(MODELS),
                    "--sink", sink])
    out = capsys.readouterr().out
    assert rc == 0, out
    estimated = _summary(out)[1]
    assert estimated == len(results) >= 3, out
    rows = _joints_rows(tmp_path / "joints.jsonl")
    # judged from the third estimate on (a full window), as the daemon would: every frame from there is flagged
    assert [bool(r["flags"] & 0x20) for r in rows] == [False, False] + [True] * (estimated - 2)
    lines = [json.loads(line) for line in (tmp_path / "joints.jsonl").read_text().splitlines()]
    first = next(k for k, m in enumerate(lines) if m["type"] == "JOINTS" and m["flags"] & 0x20)
    later = [m for m in lines[first + 1:] if m["type"] == "STATUS"]
    # (before: the demo flagged its JOINTS only, its STATUS said the calibration fitted throughout)
    assert later and all(m["flags"] & 0x20 for m in later), [m["flags"] for m in later]
    changes = re.findall(r"^pair (\d+): CALIBRATION SUSPECT \(2\.00 px > 0\.8\): the frames streamed from here "
                         r"carry CALIBRATION_SUSPECT; recalibrate \(ghcal", out, re.M)
    assert changes == [str(results[2].sequence)], out
    assert re.search(rf"^calibration check: SUSPECT \(2\.00 px > 0\.8\): recalibrate \(ghcal\) \(docs/calibration.md\); "
                     rf"views' agreement: peaks 2\.00 px apart \(median of the last 3 pairs, limit 0\.8 px\); feet: "
                     rf"feet 0\.03 m above the floor .*; {estimated - 2} of the {estimated} frames streamed carry "
                     rf"CALIBRATION_SUSPECT$", out, re.M), out
    assert "marked CALIBRATION SUSPECT" in out
    band = cv2.imread(str(tmp_path / "sim_pair.png"))[-demo.SUSPECT_BAND_PX:]
    red = np.all(band == demo.SUSPECT_BGR, axis=-1).mean()
    assert red > 0.8, red  # the red band across both views' foot (white words on it)


def test_the_calibration_check_says_when_it_changes_and_how_it_stands():
    check = demo._CalibrationCheck(window=3)
    assert check.report(0).startswith("calibration check: not judged (too few pairs measured; run longer")
    pair = lambda px, foot: SimpleNamespace(reprojection_px_median=px, lowest_foot_m=foot, handedness=None)  # noqa
    assert [check.add(k, pair(0.3, 0.02)) for k in range(3)] == [None] * 3
    assert check.report(3) == ("calibration check: fits; views' agreement: peaks 0.30 px apart (median of the last 3 "
                               "pairs, limit 0.8 px); feet: feet 0.02 m above the floor (median of the last 3 pairs, "
                               "limit 0.05 m); mirror image: 0 of the 3 pairs it needs, not judged")
    # a pan: the views still meet, the feet sink below the floor (the floor check's symptom, in its words)
    lines = [check.add(k, pair(0.3, -0.2)) for k in range(3, 6)]
    assert lines[0] is None and lines[2] is None
    assert lines[1] is not None and lines[1].startswith(
        "pair 4: CALIBRATION SUSPECT (feet 0.20 m below the floor > 0.05 m): the frames streamed from here")
    assert check.suspect and check.flagged == 2
    assert check.report(6).startswith("calibration check: SUSPECT (feet 0.20 m below the floor > 0.05 m): recalibrate")
    assert check.report(6).endswith("; 2 of the 6 frames streamed carry CALIBRATION_SUSPECT")
    # None (feet out of view) does not count; back on the floor it clears
    lines = [check.add(k, pair(0.3, None if k == 6 else 0.01)) for k in range(6, 10)]
    assert lines == [None, None, "pair 8: the calibration fits again", None]
    assert not check.suspect and check.flagged == 4  # pairs 4 to 7


def test_the_demo_s_calibration_check_says_when_the_cameras_look_exchanged():
    """A mirror-image skeleton (the cameras' inputs exchanged on a symmetric rig): the views meet and the feet stand on
    the floor, and the demo's stream is flagged as the daemon's is (since session 65)."""
    check = demo._CalibrationCheck(window=3)
    pair = lambda hand: SimpleNamespace(reprojection_px_median=0.3, lowest_foot_m=0.01, handedness=hand)  # noqa
    lines = [check.add(k, pair(-0.7)) for k in range(3)]
    assert lines[:2] == [None, None] and lines[2].startswith(
        "pair 2: CALIBRATION SUSPECT (cameras look exchanged (mirror image: handedness -0.70 < -0.2))")
    assert check.suspect and check.flagged == 1


def test_the_demo_s_verdict_shows_the_handedness_check_and_a_full_window_of_it_alone_is_judged():
    """The summary line named the views' agreement and the feet only, and said "not judged" while the handedness
    window alone was full (until session 65's second review): a subject whose feet were out of view and whose peaks
    gave no px figure got no word on the check that was judging."""
    check = demo._CalibrationCheck(window=3)
    pair = lambda hand: SimpleNamespace(reprojection_px_median=None, lowest_foot_m=None, handedness=hand)  # noqa
    assert [check.add(k, pair(0.8)) for k in range(3)] == [None] * 3
    assert check.report(3) == ("calibration check: fits; views' agreement: 0 of the 3 pairs it needs, not judged; "
                               "feet: 0 of the 3 pairs it needs, not judged; mirror image: handedness +0.80 (median of "
                               "the last 3 pairs, limit -0.2)")


def test_the_demo_names_the_fix_for_exchanged_cameras_not_a_recalibration():
    """Exchanged cameras need their plugs or names swapped; a new calibration would be solved from the exchanged views
    (since session 65's follow-up the line, the verdict and the picture's band say so; they said recalibrate)."""
    check = demo._CalibrationCheck(window=3)
    pair = lambda hand: SimpleNamespace(reprojection_px_median=0.3, lowest_foot_m=0.01, handedness=hand)  # noqa
    line = [check.add(k, pair(-0.7)) for k in range(3)][2]
    assert "swap the cameras' plugs or names in rig.url" in line and "recalibrate" not in line, line
    verdict = check.report(3)
    assert "SUSPECT" in verdict and "swap the cameras' plugs or names in rig.url" in verdict, verdict
    assert "recalibrate" not in verdict, verdict
    assert check.band() == ("CALIBRATION SUSPECT: swap the cameras' plugs or names in rig.url",
                            "cameras look exchanged (mirror image: handedness -0.70 < -0.2)")


@pytest.mark.parametrize("make", [False, True], ids=["absent", "empty"])
def test_no_model_is_a_one_line_error(tmp_path, capsys, make):
    folder = tmp_path / "no-model"
    if make:
        folder.mkdir()
    rc = demo.main(["--model-dir", str(folder), "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2
    assert captured.out == ""  # stopped before opening the rig
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert str(folder) in lines[0] and f"python -m training.pipeline --out {folder}" in lines[0]
    assert "--truth-only" in lines[0]


def test_a_file_given_as_the_model_folder_is_named_by_the_option_or_key(tmp_path, capsys):
    """It said "no model in m.json: the folder does not exist" of a file that exists, naming no option."""
    model = tmp_path / "m.json"
    model.write_text("{}")
    assert demo.main(["--model-dir", str(model), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert f"no model in --model-dir {model}: is not a folder" in err
    assert "training.pipeline" not in err  # no advice to build a model into a file's path
    config = tmp_path / "runtime.json"
    config.write_text(json.dumps({"session": {"model_dir": str(model)}}))
    assert demo.main(["--config", str(config), "--out", str(tmp_path / "out")]) == 2
    assert f"no model in session.model_dir in {config} ({model}): is not a folder" in capsys.readouterr().err


def test_default_model_folder_error_names_make_model(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./models here
    assert demo.main(["--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "no model in models" in err and "`make model`" in err
    assert "python -m training.pipeline --out models" in err


def test_bad_config_is_a_one_line_error(tmp_path, capsys):
    config = tmp_path / "runtime.json"
    config.write_text(json.dumps({"joints3d": {"metod": "triangulate"}}))
    assert demo.main(["--config", str(config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "joints3d.metod" in err and str(config) in err


@pytest.mark.parametrize(("args", "words"), [
    (["--url", "bogus://x"], ["bogus"]),
    (["--url", "replay:///nonexistent/take"], ["/nonexistent/take"]),
])
def test_a_wrong_url_or_sink_is_a_one_line_error(tmp_path, capsys, sim_url, args, words):
    argv = ["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out")]
    if "--url" not in args:
        argv += ["--url", sim_url]
    assert demo.main(argv + args) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and all(w in err for w in words), err


RTSP_PAIR = ("opencv://?first=rtsp%3A%2F%2Fuser%3As3cret%40127.0.0.1%3A1%2Fs"
             "&second=rtsp%3A%2F%2Fuser%3As3cret%40127.0.0.1%3A1%2Fs")  # refused (one camera twice) before a connect


@pytest.mark.parametrize(("url", "shown"), [
    ("replay:///nonexistent/take?token=s3cret", "opening replay:///nonexistent/take?token=***"),
    (RTSP_PAIR, "opening opencv://?first=rtsp%3A%2F%2Fuser%3A***%40127.0.0.1"),
])
def test_a_camera_url_is_printed_without_its_password(tmp_path, capsys, url, shown):
    assert demo.main(["--truth-only", "--url", url, "--seconds", "0.2", "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert shown in captured.out and "s3cret" not in captured.out + captured.err


def test_a_sink_url_is_printed_without_its_password(tmp_path, capsys, sim_url):
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(tmp_path),
                    "--sink", "memory://viewer:s3cret@here"])  # memory:// takes any location, user info too
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    assert "sink memory://viewer:***@here: " in captured.out and "s3cret" not in captured.out + captured.err


def test_truth_only_streams_ground_truth_without_a_model(tmp_path, capsys, sim_url, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./models (a --model-dir with --truth-only is refused: it would be ignored)
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.5", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "GROUND TRUTH" in out and "estimated" not in out
    assert (tmp_path / "sim_pair.png").stat().st_size > 0
    rows = _joints_rows(tmp_path / "joints.jsonl")
    assert len(rows) >= 5 and [r["seq"] for r in rows] == list(range(len(rows)))
    for msg in rows:
        joints = np.array(msg["joints"])
        assert joints.shape == (25, 5) and np.all(joints[:, 4] == 0) and np.all(joints[:, 3] == 255)


def test_hello_names_the_rig_as_the_daemon_does(tmp_path, capsys, sim_url):
    """The demo's stream says which rig it is (HELLO's rig_id was empty, the daemon's says ``sim``); a
    rig_id= in the sink URL wins."""
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(tmp_path)])
    assert rc == 0, capsys.readouterr().out
    hellos = [m for m in map(json.loads, (tmp_path / "joints.jsonl").read_text().splitlines())
              if m["type"] == "HELLO"]
    assert hellos and {(m["rig_id"], tuple(m["cameras"])) for m in hellos} == {("sim", ("left", "right"))}
    own = tmp_path / "own.jsonl"
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(tmp_path),
                    "--sink", f"{own.as_uri()}?rig_id=bench-7"])
    assert rc == 0, capsys.readouterr().out
    assert {m["rig_id"] for m in map(json.loads, own.read_text().splitlines()) if m["type"] == "HELLO"} == {"bench-7"}


def test_the_counters_of_a_recording_are_those_of_the_finished_take(tmp_path, capsys, sim_url, monkeypatch):
    # printed before the recorder closed: frames_written=41 where the take's manifest says 106
    from drivers.backends import record

    real = record.encode_image

    def slow(*args, **kwargs):  # a writer slower than the rig: frames are still queued when the run ends
        time.sleep(0.1)
        return real(*args, **kwargs)

    monkeypatch.setattr(record, "encode_image", slow)
    take = tmp_path / "take"
    rc = demo.main(["--truth-only", "--url", f"record+{sim_url}&out={take}", "--seconds", "0.5",
                    "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert rc == 0, out
    counters = json.loads((take / "manifest.json").read_text())["counters"]
    m = re.search(r"frames_written=(\d+), writes_dropped=(\d+)", out)
    assert m, out
    assert (int(m[1]), int(m[2])) == (counters["frames_written"], counters["writes_dropped"])
    assert counters["frames_written"] == len((take / "frames.jsonl").read_text().splitlines())


@needs_model
def test_a_replay_prints_no_capture_latency_and_no_loop_note(tmp_path, capsys, sim_url):
    # a replay printed "capture to joints: median 78955.2 ms" (the recorded capture times against this
    # run's clock) and "the first open pre-renders the motion loop", which only sim:// does
    take = tmp_path / "take"
    assert demo.main(["--truth-only", "--url", f"record+{sim_url}&out={take}&lossless=1", "--seconds", "0.4",
                      "--out", str(tmp_path / "rec")]) == 0
    assert "pre-renders the motion loop" in capsys.readouterr().out
    rc = demo.main(["--url", f"replay://{take}?speed=free", "--out", str(tmp_path / "out"),
                    "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "pre-renders" not in out
    assert "capture to joints: not measured (a replay" in out and not re.search(r"capture to joints: median", out)
    # At the recorded pace the replay stamps its frames with the time they play (drivers' replay
    # backend, keep_time=0): capture to joints is this run's, and measured.
    rc = demo.main(["--url", f"replay://{take}", "--out", str(tmp_path / "out"), "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0, out
    m = re.search(r"capture to joints: median ([\d.]+) ms", out)
    assert m and 0 <= float(m[1]) < 5000, out


def test_the_default_sink_writes_into_an_out_folder_with_a_space_and_a_hash(tmp_path, capsys, sim_url):
    # file://{path} unescaped: the "#" began a fragment and the joints went to a file called "my run"
    out = tmp_path / "my run#2"
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(out)])
    printed = capsys.readouterr().out
    assert rc == 0, printed
    assert _joints_rows(out / "joints.jsonl") and not (tmp_path / "my run").exists()


def test_a_sink_that_sent_nothing_fails_the_run(tmp_path, capsys, sim_url):
    # a named pipe no program reads: it retried, sent nothing, and the demo exited 0 (a sink folder that does not
    # exist, this test's case until session 74, is refused before the run now)
    fifo = tmp_path / "j.fifo"
    os.mkfifo(fifo)
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.5", "--out", str(tmp_path / "out"),
                    "--sink", fifo.as_uri()])
    err = capsys.readouterr().err
    assert rc == 2 and "sent none of the" in err and "a named pipe with no reader" in err


@pytest.mark.parametrize(("where", "said"), [
    ("folder", "{path} is a folder, not a file; name a file in it ({path_uri}/joints.jsonl)"),
    ("folder/", "{path}/ is a folder, not a file; name a file in it ({path_uri}/joints.jsonl)"),
    ("nowhere/j.jsonl", "its folder {tmp}/nowhere does not exist (the sink makes the file, not its folder)"),
    ("a.txt/j.jsonl", "its folder {tmp}/a.txt is a file, not a folder (the sink makes the file, not its folder)"),
])
def test_a_file_sink_that_can_never_be_written_is_refused_before_the_run(tmp_path, capsys, sim_url, where, said):
    """Session 74: the file sink tries again what it cannot open (a daemon's USB stick mounted later), so the demo
    loaded the model and ran its seconds against a sink that never opened, then failed: 'sent none of the frames'."""
    (tmp_path / "folder").mkdir()
    (tmp_path / "a.txt").write_text("")
    url = f"file://{tmp_path}/{where}"
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path / "out"),
                    "--sink", url], capsys)
    path = f"{tmp_path}/folder"
    assert f"error: --sink {url}: " + said.format(path=path, path_uri=Path(path).as_uri(), tmp=tmp_path) in err
    assert not (tmp_path / "out").exists()  # refused before anything is opened or written


@pytest.mark.parametrize(("url", "said"), [
    ("bogus://x", "bogus://x: invalid scheme='bogus': known schemes: file, memory, serial, udp, usb, vmc"),
    ("udp://", "udp://: invalid host='': missing host"),
    ("udp://127.0.0.1:99999", "udp://127.0.0.1:99999: invalid port='99999'"),
    ("serial:///dev/ttyS0?baud=fast", "serial:///dev/ttyS0?baud=fast: invalid baud='fast'"),
    ("memory://?colour=red", "memory://?colour=red: invalid colour='red': unknown parameter"),
    ("file:///tmp/j.jsonl?queue=0", "file:///tmp/j.jsonl?queue=0: invalid queue='0'"),
    ("udp://u:s3cret@127.0.0.1:9870", "udp://u:***@127.0.0.1:9870: invalid user info='u:***'"),
])
def test_a_sink_url_its_parser_refuses_is_refused_before_the_run(tmp_path, capsys, sim_url, url, said):
    """Session 74: the sink's open said it, after the rig's open and the model's load (seconds on a small host);
    the parse is the daemon's config check, which opens no device (a serial port busy now may be free later)."""
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path / "out"),
                    "--sink", url], capsys)
    assert f"error: --sink {said}" in err and "s3cret" not in err
    assert not (tmp_path / "out").exists()  # refused before anything is opened or written


def test_a_serial_sink_is_not_opened_by_the_check(tmp_path, capsys, monkeypatch):
    """The check builds the sink without starting it: a port that is not there (or busy) passes it, and the run's
    own open says what it meets."""
    def no_rig(url):
        raise drivers.RigConfigError("stop here: the sink's check is passed")

    monkeypatch.setattr(drivers, "create_rig_source", no_rig)
    rc = demo.main(["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out"),
                    "--sink", "serial:///dev/ghnerf-no-such-port?baud=921600"])
    assert rc == 2 and "stop here: the sink's check is passed" in capsys.readouterr().err


@pytest.mark.parametrize(("where", "said"), [
    ("locked/j.jsonl", "its folder {tmp}/locked is not writable here (no permission, or a read-only file system)"),
    ("locked.jsonl", "{tmp}/locked.jsonl is not writable here (no permission, or a read-only file system)"),
])
def test_a_file_sink_this_user_may_not_write_is_refused_before_the_run(tmp_path, capsys, sim_url, monkeypatch,
                                                                        where, said):
    """EACCES (a folder of another user's) or EROFS: the sink retried its open for the whole run, which then failed
    'sent none of the frames'. Simulated through os.access: the tests run as root, whom a mode does not stop."""
    (tmp_path / "locked").mkdir()
    (tmp_path / "locked.jsonl").write_text("")
    real = os.access
    monkeypatch.setattr(os, "access", lambda path, mode, **kw: "locked" not in str(path) and real(path, mode, **kw))
    url = f"file://{tmp_path}/{where}"
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path / "out"),
                    "--sink", url], capsys)
    assert f"error: --sink {url}: " + said.format(tmp=tmp_path) in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("refused", [(errno.EACCES, "Permission denied"), (errno.EPERM, "Operation not permitted")])
@pytest.mark.parametrize("where", ["locked/sub/j.jsonl", "locked/sub/deeper/j.jsonl"])
def test_a_file_sink_in_a_folder_this_user_may_not_look_up_is_not_said_missing(tmp_path, capsys, sim_url,
                                                                               monkeypatch, where, refused):
    """A folder on the way this user may not search (EACCES from the stat of what lies in it; EPERM from a security
    policy) was said 'does not exist' of a folder that may well be there (here it is), sending the user to make it.
    Simulated through os.stat and os.lstat: the tests run as root, whom a mode does not stop."""
    (tmp_path / "locked" / "sub" / "deeper").mkdir(parents=True)
    locked = f"{tmp_path}/locked/"
    number, words = refused

    def refused_under_locked(real):
        def look_up(path, *args, **kwargs):
            if os.fspath(path).startswith(locked):
                raise PermissionError(number, words, os.fspath(path))
            return real(path, *args, **kwargs)
        return look_up

    monkeypatch.setattr(os, "stat", refused_under_locked(os.stat))
    monkeypatch.setattr(os, "lstat", refused_under_locked(os.lstat))
    url = f"file://{tmp_path}/{where}"
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path / "out"),
                    "--sink", url], capsys)
    folder = os.path.dirname(f"{tmp_path}/{where}")
    assert (f"error: --sink {url}: its folder {folder} cannot be looked up: {tmp_path}/locked/sub: {words} "
            f"({errno.errorcode[number]}: this user may not search a folder on its path)") in err, err
    assert "does not exist" not in err and not (tmp_path / "out").exists()


def test_a_file_sink_under_a_folder_this_user_may_not_search_is_said_so(tmp_path):
    """The same with the permission bits binding (root without the capabilities that override them): a folder of
    mode 0o600, listed but not searched, above the sink's."""
    import subprocess
    import sys

    from tests.unprivileged import run_unprivileged

    (tmp_path / "locked" / "sub").mkdir(parents=True)
    (tmp_path / "locked").chmod(0o600)
    url = f"file://{tmp_path}/locked/sub/j.jsonl"
    try:
        proc = run_unprivileged([sys.executable, "-m", "firmware_host.demo", "--truth-only", "--out",
                                 str(tmp_path / "out"), "--sink", url], cwd=REPO, timeout=120,
                                env={**os.environ, "PYTHONPATH": str(REPO)}, stdin=subprocess.DEVNULL)
    finally:
        (tmp_path / "locked").chmod(0o755)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert (f"--sink {url}: its folder {tmp_path}/locked/sub cannot be looked up: {tmp_path}/locked/sub: Permission "
            "denied (EACCES: this user may not search a folder on its path)") in proc.stderr, proc.stderr[-2000:]


def test_a_file_sink_folder_holding_a_control_character_is_named_escaped(tmp_path, capsys, sim_url):
    """The URL's %1B decoded: the folder was named raw, an ESC sequence reaching the terminal (the URL itself
    refuses a raw one)."""
    url = f"file://{tmp_path}/x%1B%5B31m/j.jsonl"
    err = _refused(["--truth-only", "--url", sim_url, "--out", str(tmp_path / "out"), "--sink", url], capsys)
    assert f"its folder '{tmp_path}/x\\x1b[31m' does not exist" in err and "\x1b" not in err, err


def _sink_check_passed(argv: list[str], capsys, monkeypatch) -> bool:
    """Whether the demo's up-front --sink checks let ``argv`` through (to the rig's open, stopped there)."""
    def no_rig(url):
        raise drivers.RigConfigError("stop here: the sink's check is passed")

    monkeypatch.setattr(drivers, "create_rig_source", no_rig)
    try:
        demo.main(argv)
    except SystemExit:
        pass
    return "stop here: the sink's check is passed" in capsys.readouterr().err


def test_a_file_sink_through_a_symbolic_link_is_checked_where_the_link_leads(tmp_path, capsys, monkeypatch):
    """The sink's open (O_CREAT) makes a dangling link's target: the link's own folder was checked instead, so a
    link in a folder this user may not write, to a file one may make, was refused, and one to a folder that is not
    there passed (the run then failed, 'sent none of the frames')."""
    (tmp_path / "locked").mkdir()
    (tmp_path / "free").mkdir()
    (tmp_path / "locked" / "j.jsonl").symlink_to(tmp_path / "free" / "j.jsonl")
    (tmp_path / "free" / "gone.jsonl").symlink_to(tmp_path / "gone" / "j.jsonl")
    real = os.access  # the tests run as root, whom a mode does not stop
    monkeypatch.setattr(os, "access", lambda path, mode, **kw: "locked" not in str(path) and real(path, mode, **kw))
    argv = ["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out"), "--sink"]
    assert _sink_check_passed(argv + [(tmp_path / "locked" / "j.jsonl").as_uri()], capsys, monkeypatch)
    err = _refused(argv + [(tmp_path / "free" / "gone.jsonl").as_uri()], capsys)
    assert (f"its folder {tmp_path}/gone does not exist (the sink makes the file, not its folder; "
            f"{tmp_path}/free/gone.jsonl is a link to {tmp_path}/gone/j.jsonl)") in err, err


@pytest.mark.parametrize(("where", "said"), [
    ("loop", "{tmp}/loop is a loop of symbolic links (ELOOP): no file can be opened there"),
    ("loop/j.jsonl", "{tmp}/loop is a loop of symbolic links (ELOOP): no file can be opened there"),
    ("loop/sub/j.jsonl", "{tmp}/loop is a loop of symbolic links (ELOOP): no file can be opened there"),
    ("to-nowhere/j.jsonl", "its folder {tmp}/to-nowhere does not exist: {tmp}/to-nowhere is a link to {tmp}/nowhere, "
                           "which is not there (the sink makes the file, not its folder)"),
    ("to-nowhere-slash", "{tmp}/to-nowhere-slash is a link to {tmp}/nowhere/, a folder's path (it ends in '/'), not "
                         "a file's"),
    ("a.txt/sub/j.jsonl", "its folder {tmp}/a.txt/sub cannot exist: {tmp}/a.txt is a file (the sink makes the file, "
                          "not its folder)"),
    ("to-a.txt-slash", "{tmp}/to-a.txt-slash is a link to {tmp}/a.txt/, a folder's path (it ends in '/'), not a "
                       "file's"),
])
def test_a_file_sink_path_no_open_can_pass_is_refused_before_the_run_naming_where(tmp_path, capsys, sim_url, where,
                                                                                   said):
    """Session 75: a loop of symbolic links (ELOOP) and a link naming a folder that is not there (EISDIR) passed the
    check, the sink then retrying its open for the whole run; a link to nothing, or a file, further up the folder
    was said 'does not exist' of a folder the user saw there, or could not make."""
    (tmp_path / "loop").symlink_to(tmp_path / "loop-back")
    (tmp_path / "loop-back").symlink_to(tmp_path / "loop")
    (tmp_path / "to-nowhere").symlink_to(tmp_path / "nowhere")
    (tmp_path / "to-nowhere-slash").symlink_to(f"{tmp_path}/nowhere/")
    (tmp_path / "a.txt").write_text("")
    (tmp_path / "to-a.txt-slash").symlink_to("a.txt/")  # relative: said from the link's folder
    url = f"file://{tmp_path}/{where}"
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path / "out"),
                    "--sink", url], capsys)
    assert f"error: --sink {url}: " + said.format(tmp=tmp_path) in err, err
    assert not (tmp_path / "out").exists() and not (tmp_path / "nowhere").exists()


def test_a_file_sink_through_a_link_to_a_file_yet_to_be_made_still_passes_the_check(tmp_path, capsys, monkeypatch):
    """The open (O_CREAT) makes a dangling link's target where its folder is there: not refused as a link to
    nothing (only a link that names a folder, ending in '/', is)."""
    (tmp_path / "j.jsonl").symlink_to(tmp_path / "made-by-the-sink.jsonl")
    argv = ["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out"), "--sink", f"file://{tmp_path}/j.jsonl"]
    assert _sink_check_passed(argv, capsys, monkeypatch)


def test_a_camera_that_vanishes_mid_run_fails_the_run_naming_it(tmp_path, capsys, sim_url):
    # a loose cable in the bring-up's camera check: 'stopping: ...' among the summary's lines and exit status 0
    rc = demo.main(["--truth-only", "--url", f"{sim_url}&unplug_after_s=0.3", "--seconds", "3",
                    "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert rc == 2, captured.out
    assert "the rig delivered" in captured.out  # the summary of the pairs before it
    assert re.search(r": error: the rig failed after \d+ pairs: sim camera 'right' unplugged 0.3 s after open",
                     captured.err), captured.err
    assert _joints_rows(tmp_path / "joints.jsonl")  # what came before it was streamed


def test_the_first_pair_is_waited_for_longer_than_the_pairs_after_it(tmp_path, monkeypatch, sim_url):
    # an OAK streams a second or two after its open: a 1 s wait for the first pair failed a healthy camera
    asked = []
    open_rig = drivers.create_rig_source

    def recording_waits(url):
        source = open_rig(url)
        read = source.read

        def read_recording_wait(timeout_s):
            asked.append(timeout_s)
            return read(timeout_s=timeout_s)

        source.read = read_recording_wait
        return source

    monkeypatch.setattr(drivers, "create_rig_source", recording_waits)
    assert demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.5", "--out", str(tmp_path)]) == 0
    assert len(asked) > 2 and asked[0] == demo.FIRST_PAIR_TIMEOUT_S >= 5.0
    assert set(asked[1:]) == {demo.PAIR_TIMEOUT_S}


def test_a_rig_that_gives_no_pair_says_why_as_the_daemon_does(tmp_path, capsys, monkeypatch, sim_url):
    # a camera 10 frames behind the other (a slower USB path) never pairs at max_pending 8: the error named only
    # the timeout, and a lagging webcam at bring-up got no hint of the remedy
    monkeypatch.setattr(demo, "FIRST_PAIR_TIMEOUT_S", 0.5)
    rc = demo.main(["--truth-only", "--url", f"{sim_url}&latency_ms=340", "--seconds", "1", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "the rig failed after 0 pairs" in err, err
    assert "frames came from both cameras" in err and "raise the rig URL's max_pending" in err, err


@needs_model
def test_a_capture_time_the_stream_cannot_carry_is_refused_before_the_model_runs(tmp_path, capsys, recorded):
    """A take's negative stamps kept (``keep_time=1``): the demo ran the model on the first pair, then refused it
    as its frame was made. Now refused before the estimate, as the daemon refuses it."""
    take = tmp_path / "take"
    url = f"record+sim://?fps=30&width=64&height=48&seed=1&policy=all&cache={tmp_path / 'cache'}&out={take}"
    record_take(url, drivers.ManualClock(-10**9), 3)
    rc = demo.main(["--url", f"replay://{take}?keep_time=1", "--seconds", "10", "--out", str(tmp_path / "out"),
                    "--sink", "memory://", "--model-dir", str(MODELS)])
    error = capsys.readouterr().err
    assert rc == 2 and "timestamp_ns=-1000000000" in error, error
    assert recorded == []  # the model never ran


def test_a_stream_that_ends_is_no_failure(tmp_path, capsys, small_take):
    rc = demo.main(["--truth-only", "--url", f"replay://{small_take}", "--seconds", "30", "--out", str(tmp_path)])
    captured = capsys.readouterr()
    assert rc == 0 and "the rig's stream ended" in captured.out and "error" not in captured.err


def test_seconds_and_out_are_checked_by_name(tmp_path, capsys):
    for seconds in ("-1", "nan", "0"):
        with pytest.raises(SystemExit) as e:
            demo.main(["--truth-only", "--seconds", seconds])
        assert e.value.code == 2 and "--seconds: must be a finite number of seconds > 0" in capsys.readouterr().err
    for seconds in ("abc", ""):  # argparse's own words named the parser's function: "invalid _positive_seconds value"
        with pytest.raises(SystemExit) as e:
            demo.main(["--truth-only", "--seconds", seconds])
        err = capsys.readouterr().err
        assert e.value.code == 2 and f"--seconds: must be a finite number of seconds > 0, got {seconds!r}" in err
    (tmp_path / "afile").write_text("")
    assert demo.main(["--truth-only", "--out", str(tmp_path / "afile")]) == 2
    assert f"--out {tmp_path / 'afile'}: is a file" in capsys.readouterr().err


@needs_model
def test_a_run_that_found_no_joint_says_its_mpjpe_is_not_measured(tmp_path, capsys, sim_url):
    """A 16x16 image shows the subject too small for the model: no joint is found, and the accuracy line printed
    "MPJPE nan mm over the 0 joints found"."""
    rc = demo.main(["--url", f"{sim_url}&width=16&height=16", "--seconds", "0.3", "--out", str(tmp_path),
                    "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0 and "estimated joints found: 0.0%" in out
    assert "MPJPE not measured: no joint found" in out and "nan" not in out


def _tally_of_pairs(sequence_numbers: list[int]) -> demo._Tally:
    """A tally of the pairs of one stream with those numbers, every joint found 1 mm off its truth."""
    tally = demo._Tally()
    truth = np.zeros((25, 3))
    for k, number in enumerate(sequence_numbers):
        result = SimpleNamespace(joints_3d=truth + [0.001 * (k % 2), 0.0, 0.0], missing=np.zeros(25, bool),
                                 confidence=np.ones(25), tracked=True)
        tally.totals_ms.append(10.0)
        tally.capture_to_joints_ms.append(20.0)
        tally.found.append(np.ones(25, bool))
        tally.accuracy.add_truth(result, truth, frame=(0, number))
    return tally


def test_a_run_with_no_three_pairs_in_a_row_says_its_jitter_is_not_measured():
    """A host too slow for the rig skipped every other pair (a fresh clone's `make demo` at load 6: 42 of 89 pairs
    estimated): the accuracy line left the jitter out without a word, where the README promises one."""
    accuracy_line = next(line for line in _tally_of_pairs([0, 2, 4, 6]).report() if line.startswith("accuracy"))
    assert accuracy_line.endswith("; jitter not measured: no joint found in three pairs in a row "
                                  "(a skipped pair breaks the chain)"), accuracy_line
    chained_line = next(line for line in _tally_of_pairs([0, 1, 2, 4]).report() if line.startswith("accuracy"))
    assert chained_line.endswith("; jitter 2.0 mm per pair^2"), chained_line


def test_a_picture_that_cannot_be_written_fails_the_run_naming_it_and_keeps_the_earlier_one(tmp_path, capsys,
                                                                                           sim_url, monkeypatch):
    """On a full disk OpenCV's imwrite returned False (libpng printed "Write Error"): the "wrote" line was left out
    and the run exited 0 without a word that OUT/sim_pair.png was not written. imwrite truncated the file first, so
    an earlier run's picture was left cut short: it is now written whole or not at all."""
    (tmp_path / "sim_pair.png").write_bytes(b"an earlier picture")

    def disk_full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(rig_file.os, "fsync", disk_full)  # the disk filled as the new picture was written
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    assert rc == 2 and "BODY_25 joints of that pair" in out  # the rest of the summary still printed
    assert (f"error: could not write {tmp_path / 'sim_pair.png'}: cannot write the image (No space left on device); "
            "an earlier file there is left as it was") in err
    assert (tmp_path / "sim_pair.png").read_bytes() == b"an earlier picture"
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def test_an_empty_sink_is_refused_by_name(tmp_path, capsys):
    """``--sink ''`` (a ``"$UNSET"`` in a script) streamed to the default file sink without a word."""
    with pytest.raises(SystemExit) as e:
        demo.main(["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out"), "--sink", ""])
    assert e.value.code == 2 and "argument --sink: is empty" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("flags, named", [
    (["--config", "CONFIG"], "--config with --truth-only"),  # the config was neither read nor used: exit 0
    (["--model-dir", "nowhere"], "--model-dir with --truth-only"),
    (["--config", "CONFIG", "--model-dir", "nowhere"], "--config and --model-dir with --truth-only"),
])
def test_model_flags_with_truth_only_are_refused(tmp_path, capsys, flags, named):
    (tmp_path / "c.json").write_text('{"joints3d": {"max_prior_error_m": NaN}}')
    flags = [str(tmp_path / "c.json") if f == "CONFIG" else f for f in flags]
    with pytest.raises(SystemExit) as e:
        demo.main(["--truth-only", "--seconds", "0.2", "--out", str(tmp_path / "out"), *flags])
    assert e.value.code == 2 and f"error: {named}: no model runs" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before anything is opened or written


def _refused(argv: list[str], capsys) -> str:
    """The usage error ``argv`` ends in (exit 2, before anything is opened), its stderr."""
    with pytest.raises(SystemExit) as e:
        demo.main(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2, err
    return err


def test_a_file_sink_on_a_file_the_run_reads_is_refused(tmp_path, capsys):
    """As the daemon refuses it (one check, output_path.output_clash): a file:// sink on the rig URL's rig= file or
    the --config file appended joint lines to it; nothing is opened, the file is left as it was."""
    rig, config = tmp_path / "rig.json", tmp_path / "runtime.json"
    rig.write_text("{}")
    config.write_text("{}")
    url = f"opencv://?first=0&second=1&rig={rig}"
    err = _refused(["--url", url, "--sink", f"file://{tmp_path}/sub/../rig.json", "--out", str(tmp_path / "out")],
                   capsys)
    assert f"error: --sink {tmp_path}/sub/../rig.json is the file --url's rig= reads" in err
    err = _refused(["--url", url, "--config", str(config), "--sink", f"file://localhost{config}",
                    "--out", str(tmp_path / "out")], capsys)
    assert f"error: --sink {config} is the file --config reads" in err
    assert rig.read_text() == config.read_text() == "{}" and not (tmp_path / "out").exists()


def test_a_file_sink_on_a_file_a_wrapped_url_reads_is_refused(tmp_path, capsys, monkeypatch):
    """The demo took ``record+`` off the URL's start to find the files it reads: inside another wrapper of the
    registry (``spy+record+...``) the rig= file went unseen, and a --sink on it appended joint lines to the
    calibration. Every wrapper is taken off now (drivers.wrappers.innermost_url)."""
    from drivers import wrappers

    monkeypatch.setitem(wrappers.WRAPPERS, "spy+", wrappers.WRAPPERS[wrappers.RECORD_PREFIX])
    rig = tmp_path / "rig.json"
    rig.write_text("{}")
    url = f"spy+record+opencv://?first=0&second=1&rig={rig}&out={tmp_path / 'take'}"
    err = _refused(["--url", url, "--sink", f"file://{rig}", "--out", str(tmp_path / "out")], capsys)
    assert f"error: --sink {rig} is the file --url's rig= reads" in err
    assert rig.read_text() == "{}" and not (tmp_path / "out").exists()


def test_a_file_sink_on_the_demo_picture_is_refused(tmp_path, capsys, sim_url):
    """The joint lines were replaced by the PNG at the run's end (exit 0)."""
    err = _refused(["--truth-only", "--url", sim_url, "--seconds", "0.3", "--out", str(tmp_path),
                    "--sink", f"file://{tmp_path}/sim_pair.png"], capsys)
    assert f"error: --out's sim_pair.png {tmp_path}/sim_pair.png is where --sink writes too" in err


@pytest.mark.parametrize("argv0, prog", [
    ("/home/me/.venv/bin/ghnerf-demo", "ghnerf-demo"),  # the console script (pyproject.toml [project.scripts])
    ("C:/venv/Scripts/ghnerf-demo.exe", "ghnerf-demo"),
    (str(REPO / "firmware_host" / "demo.py"), "python -m firmware_host.demo"),  # make demo's -m run
])
def test_usage_and_errors_name_the_command_that_was_run(tmp_path, capsys, monkeypatch, argv0, prog):
    monkeypatch.setattr("sys.argv", [argv0])
    with pytest.raises(SystemExit) as e:
        demo.main(["--truth-only", "--seconds", "-1"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.startswith(f"usage: {prog} [-h]") and f"\n{prog}: error: argument --seconds" in err
    (tmp_path / "afile").write_text("")
    assert demo.main(["--truth-only", "--out", str(tmp_path / "afile")]) == 2
    assert capsys.readouterr().err.startswith(f"{prog}: error: --out ")


def test_help_names_the_defaults_and_says_any_rig_runs():
    # a rig's bring-up (docs/bring-up.md, step 2) runs the demo with its own --url and --out: the help must say
    # what it runs without them (README: three seconds of the simulated rig into out/demo)
    text = " ".join(demo.build_parser("ghnerf-demo").format_help().split())
    assert f"default: {demo.DEFAULT_URL}, the simulated rig" in text
    assert "how long to read pairs (default: 3.0)" in text
    assert "(default: out/demo)" in text and "sim_pair.png" in text
    assert "Any rig URL runs the same way" in text and "docs/bring-up.md" in text

def test_python_dash_m_still_runs_and_names_itself():
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "firmware_host.demo", "--help"], cwd=REPO, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.startswith("usage: python -m firmware_host.demo [-h]")


def test_ctrl_c_ends_the_run_with_its_summary(tmp_path, capsys, sim_url, monkeypatch):
    import drivers

    real_read = drivers.RigSource.read
    calls = {"n": 0}

    def read(self, timeout_s=None):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        return real_read(self, timeout_s=timeout_s)

    monkeypatch.setattr(drivers.RigSource, "read", read)
    rc = demo.main(["--truth-only", "--url", sim_url, "--seconds", "5", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 0 and "stopping: Ctrl-C" in out and "the rig delivered 3 pairs" in out
    assert (tmp_path / "sim_pair.png").is_file()


def _main_no_escape(argv: list[str]) -> int:
    """``demo.main``, with a Ctrl-C that escapes it (a traceback for the user) failing the test, not ending the run."""
    try:
        return demo.main(argv)
    except KeyboardInterrupt:
        pytest.fail("Ctrl-C escaped demo.main: the user saw a traceback")


@needs_model
@pytest.mark.parametrize("where", ["calibration", "send"])
def test_ctrl_c_after_an_estimate_streams_it_and_counts_it_once(tmp_path, capsys, sim_url, monkeypatch, where):
    """A Ctrl-C landing after the third estimate, in the calibration check or in the sink's send: the summary said
    "3 estimated" with 2 streamed, or (in the send, outside the loop's catch) the run ended 130 without its
    summary. Now the pair is counted, streamed and drawn whole, then the run stops."""
    import os
    import signal

    owner, name = (demo._CalibrationCheck, "add") if where == "calibration" else (demo.FileSink, "send")
    original = getattr(owner, name)
    calls = {"n": 0}

    def then_ctrl_c(self, *args, **kwargs):
        value = original(self, *args, **kwargs)
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGINT)
        return value

    monkeypatch.setattr(owner, name, then_ctrl_c)
    rc = _main_no_escape(["--url", sim_url, "--seconds", "20", "--out", str(tmp_path), "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0 and "stopping: Ctrl-C" in out
    _, estimated, _ = _summary(out)
    assert estimated == 3 == len(_joints_rows(tmp_path / "joints.jsonl"))
    assert "wrote " in out and "with estimated 2D joints" in out


@needs_model
def test_ctrl_c_in_an_estimate_ends_the_run_with_its_summary(tmp_path, capsys, sim_url, monkeypatch):
    """The estimate is most of a pair's time, so that is where a Ctrl-C mostly lands: it was a traceback."""
    original = Estimator.estimate
    calls = {"n": 0}

    def estimate(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Estimator, "estimate", estimate)
    rc = _main_no_escape(["--url", sim_url, "--seconds", "20", "--out", str(tmp_path), "--model-dir", str(MODELS)])
    out = capsys.readouterr().out
    assert rc == 0 and "stopping: Ctrl-C" in out
    assert _summary(out)[1] == 2  # the two pairs estimated before it
    assert len(_joints_rows(tmp_path / "joints.jsonl")) == 2 and (tmp_path / "sim_pair.png").is_file()


def test_ctrl_c_before_the_first_pair_exits_130_without_a_traceback(tmp_path, capsys, sim_url, monkeypatch):
    import drivers

    def source(url):  # the first open of sim:// renders the motion loop: a Ctrl-C there was a traceback
        raise KeyboardInterrupt

    monkeypatch.setattr(drivers, "create_rig_source", source)
    assert _main_no_escape(["--truth-only", "--url", sim_url, "--out", str(tmp_path)]) == 130
    assert "stopped (Ctrl-C)" in capsys.readouterr().err


@pytest.fixture
def small_take(tmp_path):
    """A 12-pair take of 40x30 images (no truth of another size involved), recorded faster than real time."""
    import drivers

    take = tmp_path / "take"
    url = f"record+sim://?width=40&height=30&seed=8&policy=all&cache={tmp_path / 'cache'}&out={take}&lossless=1"
    with drivers.open_rig(url, clock=drivers.ManualClock()) as source:
        for _ in range(12):
            source.read(timeout_s=5.0)
    return take


def test_one_image_cut_short_in_a_replay_is_skipped_and_counted(tmp_path, capsys, small_take):
    """One image mid-take cut short (its header too) is a corrupt frame: raised once by the read, and the next read
    goes on, as the daemon reads on. It ended the whole run (exit 2) at the first such frame. (An image of another
    size is no longer one: the open measures every image and refuses the take, below.)"""
    cut = sorted((small_take / "images" / "left").iterdir())[5]
    cut.write_bytes(cut.read_bytes()[:12])
    rc = demo.main(["--truth-only", "--url", f"replay://{small_take}?speed=free", "--seconds", "30",
                    "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert rc == 0, out
    assert f"skipped a frame: recording image {cut} is corrupt (OpenCV cannot decode it)" in out
    assert "the rig's stream ended" in out
    assert re.search(r"^1 frame\(s\) the rig could not deliver were skipped, the first: recording image ", out, re.M)


def test_one_image_of_another_size_in_a_replay_is_a_one_line_error_at_open(tmp_path, capsys, small_take):
    """One edited image mid-take (not a camera's first, middle or last): the open sampled those three, so the take
    played and the image was skipped as a corrupt frame; the open reads every image's header now."""
    edited = sorted((small_take / "images" / "left").iterdir())[5]
    cv2.imwrite(str(edited), np.zeros((10, 10, 3), np.uint8))
    rc = demo.main(["--truth-only", "--url", f"replay://{small_take}?speed=free", "--seconds", "30",
                    "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.out
    lines = captured.err.strip().splitlines()
    rel = edited.relative_to(small_take).as_posix()
    assert len(lines) == 1 and f": error: recording {small_take}: camera 'left': 1 of its " in lines[0], lines
    assert f" images is 10x10 ({rel}; read from each image's header at open), but its rig camera in " in lines[0]


def test_a_replay_resized_throughout_is_a_one_line_error_at_open(tmp_path, capsys, small_take):
    """Every image of a camera at another size than the take's rig: refused at open, naming a file and both sizes
    (the run failed on the first read, naming one image, as if that one file were broken)."""
    for path in sorted((small_take / "images" / "right").iterdir()):
        cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), (20, 15)))
    rc = demo.main(["--truth-only", "--url", f"replay://{small_take}?speed=free", "--seconds", "30",
                    "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.out
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and f": error: recording {small_take}: camera 'right': " in lines[0], lines
    assert " images are 20x15 (images/right/" in lines[0]
    assert "is 40x30: the take was recorded at another size than the rig it carries" in lines[0]


def test_a_take_that_cannot_be_written_ends_the_run_and_is_not_counted_as_a_skipped_frame(tmp_path, capsys,
                                                                                         monkeypatch):
    """ghnerf-demo is the documented way to record a take (record+...). Since the demo went past a failed read, the
    recorder's disk-full error (raised once, the frames passing through unrecorded after it) was printed as
    'skipped a frame' and the run streamed on for its --seconds recording nothing, its summary blaming 'the rig'.
    It ends the run again, one error line, exit 2."""
    import drivers.backends.record as record_module

    monkeypatch.setattr(record_module, "encode_image", _full_disk)
    take, url = _small_take(tmp_path)
    rc = demo.main(["--truth-only", "--url", url, "--seconds", "20", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.out
    assert "skipped a frame" not in captured.out and "could not deliver" not in captured.out
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and f"error: recording to {take} failed: [Errno 28] No space left on device" in lines[0]


def test_a_take_that_cannot_be_made_durable_at_close_ends_the_run_with_status_2(tmp_path, capsys, monkeypatch):
    """A write error no read raised (the take's last fsync at close, a frame still queued then) left the take
    complete: false, said in a log line only: the run ended with status 0, as for a whole take."""
    import json

    import drivers.backends.record as record_module

    monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    take, url = _small_take(tmp_path)
    rc = demo.main(["--truth-only", "--url", url, "--seconds", "0.3", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.err
    assert (f"error: recording to {take} failed as it closed: [Errno 28] No space left on device; its manifest "
            "says complete: false") in captured.err
    assert json.loads((take / "manifest.json").read_text())["complete"] is False


# A recorder slower than the rig (frames still queued when the signal comes), then the demo itself, as its console
# script runs it: the test's own process cannot take a real SIGTERM without ending pytest.
_SLOW_RECORDER_DEMO = """
import sys, time
from drivers.backends import record
real = record.encode_image
def slow(*args, **kwargs):
    time.sleep(0.05)
    return real(*args, **kwargs)
record.encode_image = slow
from firmware_host import demo
sys.exit(demo.main(sys.argv[1:]))
"""


def test_sigterm_ends_a_recording_run_with_a_complete_take_its_summary_and_143(tmp_path):
    """``timeout 60 ghnerf-demo --url record+...`` or ``kill``: SIGTERM's default action killed the demo outright, the
    take left ``complete: false`` and the frames queued for the recorder lost, with no summary."""
    import os
    import signal
    import subprocess
    import sys

    take, url = _small_take(tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_RECORDER_DEMO, "--truth-only", "--url", url,
                             "--seconds", "120", "--out", str(tmp_path / "out")], cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    journal = take / "frames.jsonl"
    try:
        deadline = time.monotonic() + 90
        while not (journal.is_file() and len(journal.read_text().splitlines()) >= 10):
            assert proc.poll() is None and time.monotonic() < deadline, "the demo recorded no 10 frames"
            time.sleep(0.1)
        rows_before = len(journal.read_text().splitlines())
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 143, (proc.returncode, err)
    assert "stopping: SIGTERM" in out and "the rig delivered" in out, out  # the summary
    # one line (the prog of a -c run is the module's, as for make demo)
    assert err.strip().splitlines() == [f"{demo.MODULE}: stopped (SIGTERM); the summary above is of the pairs read "
                                        "until then"], err
    manifest = json.loads((take / "manifest.json").read_text())
    assert manifest["complete"] is True
    rows = [json.loads(line) for line in journal.read_text().splitlines()]
    assert len(rows) > rows_before  # the frames still queued at the signal were written as it closed
    assert manifest["counters"]["frames_written"] == len(rows)
    on_disk = {str(p.relative_to(take)) for p in (take / "images").rglob("*.png")}
    assert on_disk == {row["image"] for row in rows}
    assert all((take / row["image"]).stat().st_size > 0 for row in rows)
    m = re.search(r"frames_written=(\d+)", out)
    assert m and int(m[1]) == len(rows), out


class _Escaped(Exception):
    """SIGTERM reached the handler around the demo: the demo left it to the default action, a death without a word."""


def _outer_sigterm_handler(signum, frame):
    raise _Escaped


def _main_under_outer_sigterm(argv: list[str]) -> tuple[int, object]:
    """:func:`_main_no_escape` with :func:`_outer_sigterm_handler` standing for SIGTERM's default action (which would
    end the test run itself): the exit status and the SIGTERM handler the demo left installed."""
    import signal

    previous = signal.signal(signal.SIGTERM, _outer_sigterm_handler)
    try:
        rc = _main_no_escape(argv)
        return rc, signal.getsignal(signal.SIGTERM)
    except _Escaped:
        pytest.fail("SIGTERM was left to the default action: the demo died without a word")
    finally:
        signal.signal(signal.SIGTERM, previous)


def _full_disk(*args, **kwargs):
    """Stands for the recorder's write or fsync on a full disk."""
    raise OSError(errno.ENOSPC, "No space left on device")


def _stop_in_the_recorder_s_close(monkeypatch, signum: int) -> None:
    """The recorder's close sends ``signum`` to this process before it closes the take (a stop landing there)."""
    from drivers.backends import record

    stop_around(monkeypatch, record.RecordingWriter, "close", signum)


def test_sigterm_before_the_first_pair_exits_143_with_one_line_and_restores_the_handler(tmp_path, capsys,
                                                                                      sim_url, monkeypatch):
    # the handler installed here stands for SIGTERM's default action, which would end the test run itself
    import os
    import signal

    import drivers

    def source(url):  # the first open of sim:// renders the motion loop: a while, as the model load is
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)  # the signal's Python handler runs here, in the main thread
        pytest.fail("SIGTERM was not delivered")

    monkeypatch.setattr(drivers, "create_rig_source", source)
    rc, restored = _main_under_outer_sigterm(["--truth-only", "--url", sim_url, "--out", str(tmp_path)])
    assert rc == 143 and capsys.readouterr().err.splitlines() == [f"{demo.prog_name()}: stopped (SIGTERM)"]
    assert restored is _outer_sigterm_handler


def test_a_sigterm_in_the_recorder_s_close_waits_for_the_take_to_be_complete(tmp_path, capsys, monkeypatch):
    """``timeout`` sends its SIGTERM when the run's own --seconds end at about the same time: one that landed in the
    recorder's close (fsyncing the take, rewriting its manifest) tore it, the take left ``complete: false``."""
    import signal

    _stop_in_the_recorder_s_close(monkeypatch, signal.SIGTERM)
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                       str(tmp_path / "out")])
    assert rc == 143 and capsys.readouterr().err.splitlines() == [f"{demo.prog_name()}: stopped (SIGTERM)"]
    manifest = json.loads((take / "manifest.json").read_text())
    assert manifest["complete"] is True
    assert manifest["counters"]["frames_written"] == len((take / "frames.jsonl").read_text().splitlines()) > 0


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_a_take_that_fails_as_it_closes_is_said_when_a_stop_lands_in_the_close_of_a_run_that_read_to_its_end(
        tmp_path, capsys, monkeypatch, stop):
    """A Ctrl-C or SIGTERM (timeout's, as --seconds ran out) landing in the recorder's close of a run that read to
    its end was raised once the take was closed, past its check: a failed take went unsaid, 130 or 143 without the
    summary. Now the summary and the failure are said, exit 2, as for a run that ended any other way."""
    import signal

    from drivers.backends import record

    monkeypatch.setattr(record, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    _stop_in_the_recorder_s_close(monkeypatch, signal.Signals[stop])
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                       str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.err
    said = [line for line in captured.err.splitlines() if "failed as it closed" in line]
    assert said == [f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left "
                    "on device; its manifest says complete: false"], captured.err
    assert "stopped" not in captured.err and "the rig delivered" in captured.out


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_when_a_stop_lands_in_the_sink_s_close_of_a_run_that_read_to_its_end_the_take_is_checked_first(
        tmp_path, capsys, monkeypatch, stop, take_fails):
    """Review 75: a Ctrl-C or SIGTERM (timeout's, as --seconds ran out) landing in the sink's close, the first stop
    of a run that read to its end, was raised there, past the summary and the take's check: a failed take went
    unsaid, 130 or 143. Now it is raised once the take is closed and found whole (130, 143, one line); a failed
    take is said after the summary, exit 2."""
    import signal

    import drivers.backends.record as record_module
    from firmware_host.sinks import base

    real_close, closed = base.Sink.close, []

    def close(self, *args, **kwargs):
        if not closed:  # the handler runs in the main thread at once, inside the close's deferral
            os.kill(os.getpid(), signal.Signals[stop])
        closed.append(1)
        return real_close(self, *args, **kwargs)

    if take_fails:
        monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    monkeypatch.setattr(base.Sink, "close", close)
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                       str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert closed, "the sink was never closed"
    if take_fails:
        assert rc == 2 and captured.err.splitlines() == [
            f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left on device; "
            "its manifest says complete: false"], captured.err
        assert "the rig delivered" in captured.out
    else:  # not swallowed: the stop is the run's end
        words = "SIGTERM" if stop == "SIGTERM" else "Ctrl-C"
        assert (rc, captured.err.splitlines()) == (128 + signal.Signals[stop],
                                                   [f"{demo.prog_name()}: stopped ({words})"]), captured.err
    assert json.loads((take / "manifest.json").read_text())["complete"] is not take_fails


def _stop_after_the_sink_s_close(monkeypatch, signum: int) -> None:
    """A stop lands in the lines between the sink's close (its stops held) and the source's (the take's)."""
    stop_around(monkeypatch, demo, "closed_with_stops_deferred", signum, after=True, on_call=1)


def _stop_in_the_summary(monkeypatch, signum: int) -> None:
    """A stop lands in the summary, the take closed by then: as the last pair's picture is written."""
    stop_around(monkeypatch, demo, "_write_picture", signum)


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("where", ["between the closes", "in the summary"])
def test_a_take_that_failed_is_said_when_a_stop_lands_after_the_sink_s_close(tmp_path, capsys, monkeypatch, stop,
                                                                           take_fails, where):
    """A Ctrl-C or SIGTERM landing between the sink's close and the take's, or in the summary after the take was
    closed, was raised to main past the take's check: "stopped", 130 or 143, of a take whose manifest says
    complete: false. Now a failed take is said (one line, exit 2) wherever the stop lands; a whole one leaves the
    stop its own exit status."""
    import signal

    import drivers.backends.record as record_module

    if take_fails:
        monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    stop_there = _stop_after_the_sink_s_close if where == "between the closes" else _stop_in_the_summary
    stop_there(monkeypatch, signal.Signals[stop])
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                       str(tmp_path / "out")])
    captured = capsys.readouterr()
    if take_fails:
        assert (rc, captured.err.splitlines()) == (2, [
            f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left on device; "
            "its manifest says complete: false"]), captured.err
    else:  # not swallowed: the stop is the run's end
        words = "SIGTERM" if stop == "SIGTERM" else "Ctrl-C"
        assert (rc, captured.err.splitlines()) == (128 + signal.Signals[stop],
                                                   [f"{demo.prog_name()}: stopped ({words})"]), captured.err
    assert json.loads((take / "manifest.json").read_text())["complete"] is not take_fails
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def test_a_take_that_failed_as_a_run_ended_by_an_error_closed_it_is_said_before_the_error(tmp_path, capsys,
                                                                                        monkeypatch):
    """A run ended by an error (here one raised as the third pair is streamed) closes the take on the error's way
    out: a take that failed in that close went unsaid (main said the error alone, the take complete: false), as
    ghcal capture says it. Now both are said, the take first, exit 2."""
    import drivers.backends.record as record_module

    monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    monkeypatch.setattr(demo, "truth_frame",
                        _stopping_at_the_third_pair(lambda: drivers.RigOperationError("the rig failed for good")))
    take, url = _small_take(tmp_path)
    rc = _main_no_escape(["--truth-only", "--url", url, "--seconds", "20", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert (rc, captured.err.splitlines()) == (2, [
        f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left on device; "
        "its manifest says complete: false",
        f"{demo.prog_name()}: error: the rig failed for good"]), captured.err
    assert json.loads((take / "manifest.json").read_text())["complete"] is False


_FIRST_STOPS = {  # the stop that ended the reading: (exception, exit status, stderr)
    "Ctrl-C": (KeyboardInterrupt, 0, []),
    "SIGTERM": (lambda: Terminated("SIGTERM"), 143,
                [f"{demo.prog_name()}: stopped (SIGTERM); the summary above is of the pairs read until then"]),
}


def _stopping_at_the_third_pair(raise_first):
    """``demo.truth_frame`` as it is, but for the third pair's, which raises ``raise_first()`` (the stop)."""
    real_frame, frames = demo.truth_frame, []

    def stopped_at_the_third_pair(*args, **kwargs):
        frames.append(1)
        if len(frames) == 3:
            raise raise_first()
        return real_frame(*args, **kwargs)

    return stopped_at_the_third_pair


@pytest.mark.parametrize("first", sorted(_FIRST_STOPS))
@pytest.mark.parametrize("closing", ["the recorder", "the sink"])
def test_a_second_ctrl_c_while_a_stopped_run_closes_leaves_the_take_whole_and_the_first_stop_reported(
        tmp_path, capsys, monkeypatch, first, closing):
    """The first Ctrl-C (or SIGTERM) ends the reading; a second Ctrl-C pressed while the run closes its outputs
    raised there: in the recorder's close it left the take ``complete: false``, in the sink's (which delivers what
    it holds queued, up to a second) it cut that short, and either way the run ended without its summary, 130 in
    place of the first stop's 0 or 143. Now it waits for the close and the first stop is the one reported."""
    import os
    import signal

    from drivers.backends import record
    from firmware_host.sinks import base

    raise_first, status, err = _FIRST_STOPS[first]
    stopped_at_the_third_pair = _stopping_at_the_third_pair(raise_first)

    pressed = []

    def pressed_again_in(real_close):
        def close(self, *args, **kwargs):
            if not pressed:
                pressed.append(1)
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.3)  # the handler runs here, in the main thread, before the close's work
            return real_close(self, *args, **kwargs)
        return close

    monkeypatch.setattr(demo, "truth_frame", stopped_at_the_third_pair)
    if closing == "the recorder":
        monkeypatch.setattr(record.RecordingWriter, "close", pressed_again_in(record.RecordingWriter.close))
    else:
        monkeypatch.setattr(base.Sink, "close", pressed_again_in(base.Sink.close))
    take, url = _small_take(tmp_path)
    rc = _main_no_escape(["--truth-only", "--url", url, "--seconds", "20", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert pressed == [1]
    assert rc == status and captured.err.splitlines() == err, captured.err
    assert f"stopping: {first}" in captured.out and "the rig delivered" in captured.out  # the summary
    manifest = json.loads((take / "manifest.json").read_text())
    assert manifest["complete"] is True
    assert manifest["counters"]["frames_written"] == len((take / "frames.jsonl").read_text().splitlines()) > 0
    assert len((tmp_path / "out" / "joints.jsonl").read_text().splitlines()) >= 2  # the sink's frames delivered
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def _second_stop_at(monkeypatch, where: str, signum: int) -> list:
    """A second stop, ``signum``, lands at ``where`` as the stopped run closes its sink and its take: in each of the
    sink's closes, just after the sink's close, just before the take's (the source's) close or just after it. The
    list returned counts the stops sent (its handler runs in the main thread, at once)."""
    from firmware_host.sinks import base

    sent = []

    def stop():
        sent.append(1)
        os.kill(os.getpid(), signum)

    if where == "in each of the sink's closes":
        real_close = base.Sink.close

        def close(self, *args, **kwargs):
            stop()
            return real_close(self, *args, **kwargs)

        monkeypatch.setattr(base.Sink, "close", close)
        return sent
    real_closed, closes = demo.closed_with_stops_deferred, []

    def closed_with_a_stop(close, **kwargs):  # the sink's close first, the take's second
        closes.append(1)
        if (len(closes), where) == (2, "before the take's close"):
            stop()
        late_stop = real_closed(close, **kwargs)
        if (len(closes), where) in ((1, "after the sink's close"), (2, "after the take's close")):
            stop()
        return late_stop

    monkeypatch.setattr(demo, "closed_with_stops_deferred", closed_with_a_stop)
    return sent


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("first", sorted(_FIRST_STOPS))
@pytest.mark.parametrize("where", ["in each of the sink's closes", "after the sink's close", "before the take's close",
                                   "after the take's close"])
def test_a_second_stop_between_the_sink_s_close_and_the_take_s_is_dropped_and_the_first_reported(
        tmp_path, capsys, monkeypatch, where, first, take_fails):
    """A second stop landing between the sink's close and the take's, outside the closes' own deferrals, was raised
    there: 130 or 143 without the summary in place of the first stop's 0 or 143; just before the take's close it
    skipped that close, the take left complete: false. Now it is dropped from the first stop until the take is
    closed: the take closed and checked, the summary printed, the first stop reported (a failed take: exit 2). The
    second stop is of the other kind than the first, so the status says which was reported."""
    import signal

    import drivers.backends.record as record_module

    raise_first, status, err = _FIRST_STOPS[first]
    if take_fails:
        monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    monkeypatch.setattr(demo, "truth_frame", _stopping_at_the_third_pair(raise_first))
    sent = _second_stop_at(monkeypatch, where, signal.SIGTERM if first == "Ctrl-C" else signal.SIGINT)
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "20", "--out",
                                       str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert sent, "no second stop was sent"
    if take_fails:
        status, err = 2, [f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space "
                          "left on device; its manifest says complete: false"]
    assert (rc, captured.err.splitlines()) == (status, err), captured.err
    assert f"stopping: {first}" in captured.out and "the rig delivered" in captured.out  # the summary
    assert json.loads((take / "manifest.json").read_text())["complete"] is not take_fails
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def test_an_error_on_its_way_is_reported_when_a_sigterm_lands_in_the_recorder_s_close(tmp_path, capsys,
                                                                                      monkeypatch):
    """A run that failed closes its take on the way out; a SIGTERM landing in that close (timeout's) was raised
    after it in place of the error: "stopped (SIGTERM)", 143, for a run that failed (2, the error said)."""
    import signal

    def failed(*args, **kwargs):
        raise OSError(5, "Input/output error")

    _stop_in_the_recorder_s_close(monkeypatch, signal.SIGTERM)
    monkeypatch.setattr(demo, "truth_frame", failed)
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "20", "--out",
                                       str(tmp_path / "out")])
    assert rc == 2 and capsys.readouterr().err.splitlines() == [
        f"{demo.prog_name()}: error: [Errno 5] Input/output error"]
    assert json.loads((take / "manifest.json").read_text())["complete"] is True


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_an_error_on_its_way_is_reported_when_a_stop_lands_in_the_sink_s_close(tmp_path, capsys, monkeypatch,
                                                                                signum):
    """Review 63: a run stopped by an error closed its sink on the way out without the stop signals held (the
    with's own close): a Ctrl-C or SIGTERM landing there (the sink delivers what it holds queued, up to a second)
    was raised in place of the error, "stopped", 130 or 143, for a run that failed (2, the error said)."""
    import os
    import signal

    from firmware_host.sinks import base

    real_close, closed = base.Sink.close, []

    def close(self, *args, **kwargs):
        if not closed:
            os.kill(os.getpid(), signal.Signals[signum])
            time.sleep(0.3)  # a handler that raises does so here, in the main thread, before the close's work
        closed.append(1)
        return real_close(self, *args, **kwargs)

    def failed(*args, **kwargs):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(base.Sink, "close", close)
    monkeypatch.setattr(demo, "truth_frame", failed)
    url = f"sim://?width=40&height=30&seed=8&cache={tmp_path / 'cache'}"
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "20", "--out",
                                       str(tmp_path / "out")])
    assert rc == 2 and capsys.readouterr().err.splitlines() == [
        f"{demo.prog_name()}: error: [Errno 5] Input/output error"]
    assert len(closed) >= 1


@needs_model
def test_a_second_person_on_the_simulated_rig_reaches_the_stream_flagged(tmp_path, capsys, sim_url, recorded):
    """sim://?second=X,Z puts a second person in front of the rig (the bench's default places' offset, a metre
    beside the subject): the estimates the demo streams carry SEVERAL_PEOPLE where the estimator flagged them, and
    the summary counts them; a one-person run at the same size says nothing of it (a tiny image: at 160x120 the
    shipped model flagged every pair with the second person, none without; the rate is not asserted)."""
    small = sim_url.replace(demo.DEFAULT_URL, "sim://?fps=30&seed=0&motion=wave&width=160&height=120")
    runs = {}
    for name, url in (("one", small), ("two", f"{small}&second=1.0,3.4")):
        recorded.clear()
        out_dir = tmp_path / name
        rc = demo.main(["--url", url, "--seconds", "1.0", "--out", str(out_dir), "--model-dir", str(MODELS)])
        out = capsys.readouterr().out
        assert rc == 0, out
        rows = _joints_rows(out_dir / "joints.jsonl")
        flagged = [bool(r["flags"] & 0x04) for r in rows]  # SEVERAL_PEOPLE
        assert flagged == [bool(r.several_people) for r in recorded]
        runs[name] = (sum(flagged), len(rows), out)
    assert runs["one"][0] == 0 and "several_people" not in runs["one"][2]
    count, estimated, out = runs["two"]
    assert count > 0, out
    assert f"{count} of the {estimated} pairs estimated were flagged several_people" in out


@pytest.mark.parametrize("first", sorted(_FIRST_STOPS))
def test_a_take_that_fails_as_a_stopped_run_closes_it_ends_with_status_2_said_once(tmp_path, capsys, monkeypatch,
                                                                                   first):
    """A Ctrl-C (0) or SIGTERM (143) stop: the take's failed last fsync still ends the run with 2, one error line,
    as a run that read to its end does; a stop is no reason to call an incomplete take whole."""
    import drivers.backends.record as record_module

    raise_first = _FIRST_STOPS[first][0]
    stopped_at_the_third_pair = _stopping_at_the_third_pair(raise_first)

    monkeypatch.setattr(record_module, "_fsync", _full_disk)
    monkeypatch.setattr(demo, "truth_frame", stopped_at_the_third_pair)
    take, url = _small_take(tmp_path)
    rc = _main_no_escape(["--truth-only", "--url", url, "--seconds", "20", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert rc == 2, captured.err
    said = [line for line in captured.err.splitlines() if "failed as it closed" in line]
    assert len(said) == 1 and f"recording to {take} failed as it closed" in said[0], captured.err


def _first_stop_before_the_take_s_close(monkeypatch, where: str, signum: int) -> None:
    """A stop lands after the sink's close of a run that read to its end, before the take's close: as the run
    starts noting stops, or just before the take's close (both outside the close's deferral)."""
    if where == "as the noting begins":
        stop_around(monkeypatch, demo, "stop_signals_noted", signum)
    else:  # the sink's close first, the take's second
        stop_around(monkeypatch, demo, "closed_with_stops_deferred", signum, on_call=2)


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("where", ["as the noting begins", "just before the take's close"])
def test_a_first_stop_just_before_the_take_s_close_of_a_run_that_read_to_its_end_still_closes_the_take(
        tmp_path, capsys, monkeypatch, where, stop, take_fails):
    """A run read to its end with no stop before; a Ctrl-C or SIGTERM (timeout's, as --seconds ran out) landing in
    the finally just before the take's close was raised past that close: the take left complete: false and
    unchecked. Now the take is closed whatever instant the stop lands, then the stop is the run's end as one in the
    close is (130, 143; a failed take said after the summary, exit 2: the summary was skipped where the stop landed
    as the noting began)."""
    import signal

    import drivers.backends.record as record_module

    if take_fails:
        monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    _first_stop_before_the_take_s_close(monkeypatch, where, signal.Signals[stop])
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                       str(tmp_path / "out")])
    captured = capsys.readouterr()
    assert json.loads((take / "manifest.json").read_text())["complete"] is not take_fails  # closed
    assert ("the rig delivered" in captured.out) is take_fails, captured.out  # the summary: a failed take's only
    if take_fails:
        assert rc == 2 and captured.err.splitlines() == [
            f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left on device; "
            "its manifest says complete: false"], captured.err
    else:
        words = "SIGTERM" if stop == "SIGTERM" else "Ctrl-C"
        assert (rc, captured.err.splitlines()) == (128 + signal.Signals[stop],
                                                   [f"{demo.prog_name()}: stopped ({words})"]), captured.err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_a_stop_just_before_the_take_s_close_of_a_run_an_error_ended_still_closes_the_take(
        tmp_path, capsys, monkeypatch, stop):
    """An error ends the reading (one the demo says, exit 2); a Ctrl-C or SIGTERM landing just before the
    take's close, outside its deferral, was raised past that close: the take left complete: false, the error's line
    lost to "stopped". Now stops are held from the error to the take's close: the take closed, the error said, 2."""
    import signal

    def stopped_then_closed(close, **kwargs):  # the take's close: the sink was closed on the error's way out
        os.kill(os.getpid(), signal.Signals[stop])  # its handler runs here, in the main thread, at once
        return real_closed(close, **kwargs)

    real_closed = demo.closed_with_stops_deferred
    monkeypatch.setattr(demo, "truth_frame",
                        _stopping_at_the_third_pair(lambda: demo.DemoError("the third pair went wrong")))
    monkeypatch.setattr(demo, "closed_with_stops_deferred", stopped_then_closed)
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "20", "--out",
                                       str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "the third pair went wrong" in err[0], err
    assert json.loads((take / "manifest.json").read_text())["complete"] is True  # closed


@pytest.mark.parametrize("take_fails", [False, True])
@pytest.mark.parametrize("stop", ["SIGINT", "SIGTERM"])
def test_a_stop_after_the_take_s_close_of_a_run_an_error_ended_does_not_hide_the_error(
        tmp_path, capsys, monkeypatch, stop, take_fails):
    """An error ends the reading (one the demo says, exit 2); a Ctrl-C or SIGTERM landing once the take is closed,
    as the error leaves (a failed take's line said on its way), was raised in the error's place: "stopped", 130 or
    143, the error's line lost. Now the error is said, exit 2 (a failed take said before it), as ghcal capture's."""
    import signal

    import drivers.backends.record as record_module

    from ghnerf_runtime.cli import recorded_take

    real_say = recorded_take.RecordedTake.say_failure

    def said_then_stopped(self):  # on the error's way out to main, the take closed
        failed = real_say(self)
        os.kill(os.getpid(), signal.Signals[stop])  # its handler runs here, in the main thread, at once
        return failed

    if take_fails:
        monkeypatch.setattr(record_module, "_fsync", _full_disk)  # a short take: only the close's fsync runs
    monkeypatch.setattr(recorded_take.RecordedTake, "say_failure", said_then_stopped)
    monkeypatch.setattr(demo, "truth_frame",
                        _stopping_at_the_third_pair(lambda: demo.DemoError("the third pair went wrong")))
    take, url = _small_take(tmp_path)
    rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "20", "--out",
                                       str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    failed = [f"{demo.prog_name()}: error: recording to {take} failed as it closed: [Errno 28] No space left on "
              "device; its manifest says complete: false"] if take_fails else []
    assert (rc, err) == (2, failed + [f"{demo.prog_name()}: error: the third pair went wrong"]), err
    assert json.loads((take / "manifest.json").read_text())["complete"] is not take_fails  # closed
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def test_a_ctrl_c_the_demo_was_started_to_ignore_does_not_stop_it(tmp_path, capsys, monkeypatch):
    """A script's background job (``ghnerf-demo ... &``) starts with Ctrl-C ignored, and the script's own Ctrl-C
    reaches it too. One landing in a pair's send (held there, so that the pair goes out whole) was raised after it:
    "stopping: Ctrl-C", the run cut short. Now it stays ignored: the run reads on to its --seconds."""
    import signal

    real_frame, frames = demo.truth_frame, []

    def ctrl_c_then_frame(*args, **kwargs):  # in the send's hold
        if not frames:
            os.kill(os.getpid(), signal.SIGINT)  # its handler runs here, in the main thread, at once
        frames.append(1)
        return real_frame(*args, **kwargs)

    monkeypatch.setattr(demo, "truth_frame", ctrl_c_then_frame)
    url = f"sim://?width=40&height=30&seed=8&cache={tmp_path / 'cache'}"
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        rc, _ = _main_under_outer_sigterm(["--truth-only", "--url", url, "--seconds", "0.3", "--out",
                                           str(tmp_path / "out")])
    finally:
        signal.signal(signal.SIGINT, previous)
    out = capsys.readouterr().out
    assert frames and rc == 0, out
    assert "stopping: Ctrl-C" not in out and "the rig delivered" in out, out
