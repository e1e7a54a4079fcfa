"""``ghnerf-daemon`` as systemd runs it: a separate process, a notify socket, SIGTERM, exit statuses."""
from __future__ import annotations

import contextlib
import json
import logging
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from firmware_host.daemon import cli
from tests.framing_note import framing_notes

REPO = Path(__file__).resolve().parents[3]
MODELS = REPO / "models"
needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                 reason="no trained model yet: models/model_card.json does not exist")


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "daemon.json"
    path.write_text(json.dumps(data))
    return path


def test_validate_config_prints_the_full_tree(tmp_path, capsys):
    path = _write(tmp_path, {"rig": {"url": "sim://?fps=15"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.main(["--config", str(path), "--validate-config"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["rig"]["url"] == "sim://?fps=15" and printed["rig"]["stall_s"] == 10.0
    assert printed["estimator"]["joints3d"]["method"]  # the runtime's defaults spelled out


def test_validate_config_keeps_what_a_rig_library_prints_out_of_the_json(tmp_path, monkeypatch, capfd):
    """``depthai://`` loads depthai, whose logger writes to the process's stdout (file descriptor 1) on import (in a
    container without USB: ``[depthai] [warning] USB protocol not available ...``): ``--validate-config > full.json``
    then held that line before the JSON. It goes to stderr now; stdout is the config alone."""
    import drivers

    real = drivers.create_rig_source

    def chatty(url, **kwargs):
        os.write(1, b"[depthai] [warning] USB protocol not available\n")  # below Python, as a C++ logger writes
        return real(url, **kwargs)

    monkeypatch.setattr(drivers, "create_rig_source", chatty)
    path = _write(tmp_path, {"rig": {"url": "sim://?fps=15"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    captured = capfd.readouterr()
    assert json.loads(captured.out)["rig"]["url"] == "sim://?fps=15"
    assert "[depthai] [warning] USB protocol not available" in captured.err
    print("after", flush=True)  # stdout is stdout again once the checks are over
    assert capfd.readouterr().out == "after\n"


@pytest.mark.parametrize("data, message", [
    ({"sinks": ["udp://127.0.0.1:9870"], "rig": {"url": "sim://", "stall": 3}}, "rig.stall: unknown key"),
    ({"sinks": ["udp://127.0.0.1:9870?fps=fast"], "rig": {"url": "sim://"}}, "sinks[0]: "),
    # these two left as tracebacks, exit 1, which systemd restarts
    ({"sinks": ["memory://", "udp://127.0.0.1:9870?send_2d=1&send_2d=0"], "rig": {"url": "sim://"}}, "sinks[1]: "),
    ({"sinks": ["udp://[::1:9870"], "rig": {"url": "sim://"}}, "sinks[0]: "),
])
def test_bad_config_is_one_line_and_exit_2(tmp_path, capsys, data, message):
    path = _write(tmp_path, data)
    assert cli.main(["--config", str(path), "--validate-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err.startswith(f"ghnerf-daemon: error: {path}: {message}")


def test_usage_errors(capsys):
    assert cli.main([]) == 2
    assert "--config is required" in capsys.readouterr().err
    assert cli.main(["--config", "x.json", "--max-seconds", "0"]) == 2
    assert "--max-seconds must be" in capsys.readouterr().err
    for endless in ("inf", "nan", "1e12"):  # inf killed the stop timer's thread: the run had no bound
        assert cli.main(["--config", "x.json", "--max-seconds", endless]) == 2
        assert "--max-seconds must be > 0 and at most" in capsys.readouterr().err
    assert cli.main(["--print-example-config"]) == 0
    assert json.loads(capsys.readouterr().out) == cli.EXAMPLE_CONFIG
    assert cli.main(["--config", "x.json", "--no-model"]) == 2  # the daemon itself cannot run without its model
    assert "--no-model goes with --validate-config" in capsys.readouterr().err


BASELINE = MODELS / "baseline"  # a model without encoder heatmaps (docs/runtime.md, "Heatmap sources")
needs_baseline = pytest.mark.skipif(not (BASELINE / "encoder.onnx").is_file(), reason="no models/baseline")


@needs_baseline
@pytest.mark.parametrize("estimator, message", [
    # heatmaps.source 'encoder' (the default) needs encoder heatmaps, which the baseline has not
    ({"session": {"model_dir": str(BASELINE)}},
     f"estimator: the settings do not fit the model in {BASELINE}: heatmaps.source = 'encoder' needs a model"),
    # a resolution the model's graphs are not exported at
    ({"session": {"model_dir": str(BASELINE), "expected_resolution": 96}, "heatmaps": {"source": "rendered"}},
     f"estimator.session: cannot load the model in {BASELINE}: {BASELINE / 'encoder.int8.onnx'}: ghnerf.resolution: "
     "model resolution is 128x128, the runtime is configured for 96x96 (session.expected_resolution)"),
    # a variant other than the folder's
    ({"session": {"model_dir": str(BASELINE), "expected_variant": "ghnerf"}, "heatmaps": {"source": "rendered"}},
     f"estimator.session: cannot load the model in {BASELINE}: {BASELINE / 'encoder.int8.onnx'}: ghnerf.variant: "
     "model variant is 'baseline', configured 'ghnerf'"),
])
def test_validate_config_refuses_settings_the_model_cannot_serve(tmp_path, capsys, estimator, message):
    """These passed --validate-config (which read the folder's file names only), then the start loaded the model
    and exited 2 before READY: install.sh and a CI check took them for good. The model is loaded now, as at
    start, and the one line names the file, the key and what does not fit; --no-model still passes them."""
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"], "estimator": estimator})
    assert cli.main(["--config", str(path), "--validate-config"]) == 2
    out, err = capsys.readouterr()
    assert out == ""  # no config printed for one that fails
    assert "\n" not in err.strip()
    assert err.strip().startswith(f"ghnerf-daemon: error: {path}: {message}"), err
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    assert "model: not loaded (--no-model)" in capsys.readouterr().err


@needs_baseline
def test_validate_config_passes_what_the_model_serves_and_says_what_it_checked(tmp_path, capsys):
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(BASELINE)},
                                           "heatmaps": {"source": "rendered"}}})
    assert cli.main(["--config", str(path), "--validate-config"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["estimator"]["heatmaps"]["source"] == "rendered"  # stdout stays the config alone
    assert err == (f"ghnerf-daemon: {path}: ok; model: {BASELINE} (baseline, fp32+int8, 128x128; encoder, volume, "
                   "render_heat) loaded, the estimator settings fit it (roi.pad_fill fade, roi.turn_search off)\n")
    # the crop turn search, on by default (session 57), is off for a model without the encoder heatmaps it needs;
    # the shipped model has them
    if (MODELS / "ghnerf" / "model_card.json").is_file() or (MODELS / "model_card.json").is_file():
        path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                                 "estimator": {"session": {"model_dir": str(MODELS)}}})
        assert cli.main(["--config", str(path), "--validate-config"]) == 0
        assert capsys.readouterr().err.endswith("(roi.pad_fill fade, roi.turn_search on)\n")


@needs_baseline
def test_validate_config_refuses_novel_views_from_a_folder_without_their_graph(tmp_path, capsys):
    """novel_view.enabled runs render_rgb, which this copy of the baseline lacks: found when the start loaded it."""
    models = tmp_path / "models"
    shutil.copytree(BASELINE, models, ignore=shutil.ignore_patterns("render_rgb.*"))
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": "models"}, "heatmaps": {"source": "rendered"},
                                           "novel_view": {"enabled": True}}})
    assert cli.main(["--config", str(path), "--validate-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"ghnerf-daemon: error: {path}: estimator.session: cannot load the model in {models}: "
                          f"{models}: no file for graph 'render_rgb'"), err


@needs_baseline
def test_validate_config_names_a_corrupt_graph_file(tmp_path, capsys):
    """One graph file of a good model cut short (a copy that stopped half-way): the folder still holds *.onnx
    files, which was all the check looked at."""
    models = tmp_path / "models"
    shutil.copytree(BASELINE, models)
    broken = models / "render_heat.onnx"  # fp32 under precision 'auto': loaded after encoder and volume
    broken.write_bytes(broken.read_bytes()[: broken.stat().st_size // 2])
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": "models"}, "heatmaps": {"source": "rendered"}}})
    assert cli.main(["--config", str(path), "--validate-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err.startswith(f"ghnerf-daemon: error: {path}: estimator.session: cannot load the model in {models}: "
                          f"{broken}: onnxruntime cannot load the graph file"), err


def test_a_corrupt_model_exits_2_naming_it(tmp_path):
    broken = tmp_path / "models"
    broken.mkdir()
    (broken / "encoder.onnx").write_bytes(b"\x08\x07garbage")
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(broken)}}})
    proc = subprocess.run([sys.executable, "-m", "firmware_host.daemon.cli", "--config", str(path)],
                          capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 2, proc.stderr
    assert f"ghnerf-daemon: error: estimator.session: cannot load the model in {broken}" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.skipif(not (MODELS / "baseline").is_dir(), reason="no models/baseline")
def test_settings_the_model_cannot_serve_exit_2_at_start_naming_the_key(tmp_path):
    """The baseline has no encoder heatmaps, which heatmaps.source 'encoder' (the default) needs: the daemon sent
    READY and waited for the rig (here one that never comes, until --max-seconds: exit 0). Refused right after the
    model loads now, exit 2, naming the key; --validate-config refuses it too (the tests below)."""
    path = _write(tmp_path, {"rig": {"url": f"replay://{tmp_path / 'never'}"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS / "baseline"), "warmup": False}}})
    proc = subprocess.run([sys.executable, "-m", "firmware_host.daemon.cli", "--config", str(path),
                           "--max-seconds", "20"], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "ghnerf-daemon: error: estimator: the settings do not fit the model in" in proc.stderr
    assert "heatmaps.source = 'encoder'" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("mode", [0o000, 0o111, 0o444], ids=["none", "enter-only", "list-only"])
def test_a_model_folder_the_service_user_may_not_read_exits_2_naming_it(tmp_path, mode):
    """The unit runs as User=ghnerf: a folder it may not read was a PermissionError traceback and exit 1 (which
    systemd restarts), from --validate-config and from the start alike (list-only passed the check)."""
    from tests.unprivileged import run_unprivileged

    models = tmp_path / "models"
    models.mkdir()
    (models / "encoder.onnx").write_bytes(b"\x08\x07not read")
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(models)}}})
    models.chmod(mode)
    try:
        for extra in (["--validate-config"], ["--max-seconds", "30"]):
            proc = run_unprivileged([sys.executable, "-m", "firmware_host.daemon.cli", "--config", str(path), *extra],
                                    timeout=120, cwd=REPO)
            assert proc.returncode == 2, proc.stderr[-2000:]
            assert "Traceback" not in proc.stderr
            assert f"estimator.session.model_dir: {models}: cannot read the model folder: permission denied" \
                in proc.stderr
    finally:
        models.chmod(0o755)


def _notes_until(sock: socket.socket, proc: subprocess.Popen, notes: list[dict[str, str]], done, what: str,
                 timeout: float = 120) -> None:
    """Read systemd notifications into ``notes`` until ``done(notes)``; fail naming ``what``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            data = sock.recv(4096).decode()
        except socket.timeout:
            assert proc.poll() is None, proc.communicate()[1]
            continue
        notes.append(dict(line.split("=", 1) for line in data.splitlines()))
        if done(notes):
            return
    pytest.fail(f"{what}: not seen in {notes}")


@contextlib.contextmanager
def _under_a_notify_socket(tmp_path: Path, config: Path, *python_args: str, stdout: int = subprocess.PIPE,
                           **env: str) -> Iterator[tuple[socket.socket, subprocess.Popen]]:
    """``python *python_args --config config`` (the daemon's module by default) started as systemd starts the
    service: ``NOTIFY_SOCKET`` names a datagram socket bound here, read with a 1 s timeout (for :func:`_notes_until`),
    ``env`` added to the environment; stderr piped. On the way out the process is killed (if it still runs) and
    reaped, and the socket closed."""
    sock_path = tmp_path / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    try:
        sock.bind(str(sock_path))
        sock.settimeout(1.0)
        proc = subprocess.Popen([sys.executable, *(python_args or ("-m", "firmware_host.daemon.cli")),
                                 "--config", str(config)], stdout=stdout, stderr=subprocess.PIPE, text=True,
                                cwd=REPO, env={**os.environ, "NOTIFY_SOCKET": str(sock_path), **env})
        try:
            yield sock, proc
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
    finally:
        sock.close()


def _estimated_in(status: str) -> int:
    """The pairs a daemon's ``running: ... pairs/s, N estimated`` STATUS counts; 0 for any other STATUS."""
    found = re.search(r"(\d+) estimated$", status) if status.startswith("running:") else None
    return int(found.group(1)) if found else 0


@needs_model
def test_runs_under_a_notify_socket_and_stops_on_sigterm(tmp_path):
    status = tmp_path / "status.json"
    cache = tmp_path / "sim-cache"
    path = _write(tmp_path, {
        "rig": {"url": f"sim://?fps=30&width=320&height=240&cache={cache}"},
        "sinks": [f"file://{tmp_path / 'joints.jsonl'}"],
        "estimator": {"session": {"model_dir": str(MODELS)}},
        "health": {"status_file": str(status), "status_every_s": 0.2},
    })
    notes: list[dict[str, str]] = []
    with _under_a_notify_socket(tmp_path, path, WATCHDOG_USEC="2000000", JOURNAL_STREAM="8:1") as (sock, proc):
        # a running status counting an estimated pair: the first one may count none yet on a loaded host
        _notes_until(sock, proc, notes, lambda ns: any(_estimated_in(n.get("STATUS", "")) > 0 for n in ns)
                     and any("WATCHDOG" in n for n in ns), "a running status with a pair estimated and a watchdog ping")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
        while True:  # the notes sent up to its exit
            try:
                data = sock.recv(4096).decode()
            except (socket.timeout, OSError):
                break
            notes.append(dict(line.split("=", 1) for line in data.splitlines()))
    assert proc.returncode == 0, err
    assert notes[0]["READY"] == "1" and notes[0]["MAINPID"] == str(proc.pid)
    assert "STOPPING" in notes[-1]
    assert "SIGTERM received: stopping" in err
    assert "Traceback" not in err
    assert not any(line[:4].isdigit() for line in err.splitlines())  # the journal stamps lines itself
    report = json.loads(status.read_text())
    assert report["state"] == "stopping" and report["pairs"]["estimated"] > 0
    rows = [json.loads(line) for line in (tmp_path / "joints.jsonl").read_text().splitlines()]
    assert sum(r["type"] == "JOINTS" for r in rows) == report["pairs"]["estimated"]


@needs_model
def test_sighup_reloads_the_config_file_and_refuses_a_broken_one(tmp_path):
    status = tmp_path / "status.json"
    config = {
        "rig": {"url": f"sim://?fps=30&width=320&height=240&cache={tmp_path / 'sim-cache'}"},
        "sinks": [f"file://{tmp_path / 'first.jsonl'}"],
        "estimator": {"session": {"model_dir": str(MODELS)}},
        "health": {"status_file": str(status), "status_every_s": 0.2},
    }
    path = _write(tmp_path, config)
    notes: list[dict[str, str]] = []
    with _under_a_notify_socket(tmp_path, path, JOURNAL_STREAM="8:1") as (sock, proc):
        _notes_until(sock, proc, notes, lambda ns: ns[-1].get("STATUS", "").startswith("running:"), "running")
        # systemctl reload: a second sink and debug logging, applied without a restart.
        _write(tmp_path, {**config, "sinks": config["sinks"] + [f"file://{tmp_path / 'second.jsonl'}"],
                          "log_level": "debug"})
        proc.send_signal(signal.SIGHUP)
        _notes_until(sock, proc, notes, lambda ns: "RELOADING" in ns[-1], "RELOADING=1", timeout=30)
        _notes_until(sock, proc, notes, lambda ns: ns[-1].get("READY") == "1", "READY=1 after the reload", timeout=30)
        # A file broken mid-edit: refused, the daemon runs on with the config it had.
        path.write_text('{"rig": {"url": ')
        proc.send_signal(signal.SIGHUP)
        _notes_until(sock, proc, notes, lambda ns: "reload refused" in ns[-1].get("STATUS", ""), "the refusal",
                     timeout=30)
        assert notes[-1]["READY"] == "1"
        # It runs on, and STATUS keeps the refusal (systemctl reload returned before the file was read).
        _notes_until(sock, proc, notes, lambda ns: ns[-1].get("STATUS", "").startswith("running:")
                     and "reload refused: " in ns[-1]["STATUS"] and "READY" not in ns[-1], "running after the refusal",
                     timeout=30)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "config reloaded: sinks, log_level" in err
    assert f"reload refused: {path}: " in err and "running on with the config loaded before" in err
    assert "DEBUG ghnerf.daemon: the config now: " in err  # the reloaded log level took effect
    assert "Traceback" not in err
    report = json.loads(status.read_text())
    assert report["config"]["reloads"] == 1 and report["config"]["reload_failures"] == 1
    assert report["rig"]["opens"] == 1
    second = [json.loads(line) for line in (tmp_path / "second.jsonl").read_text().splitlines()]
    assert sum(r["type"] == "JOINTS" for r in second) > 0


def test_the_start_runs_the_checks_a_reload_runs(tmp_path, capsys):
    """A rig file whose id the stream cannot announce: refused at start (exit 2), as a reload refuses it, rather
    than waiting for an OAK and failing once it is plugged in."""
    from ghnerf_runtime.geometry.rig import Rig
    from ghnerf_runtime.rig_file import load_rig, save_rig

    rig = load_rig(REPO / "docs/examples/rig.json")
    long_id = tmp_path / "rig.json"
    save_rig(Rig(rig.cameras, rig.volume, rig_id="a rig id far longer than the streams 32 characters"), long_id)
    size = f"width={rig.pair[0].width}&height={rig.pair[0].height}"
    path = _write(tmp_path, {"rig": {"url": f"depthai://?rig={long_id}&{size}"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.main(["--config", str(path)]) == 2
    assert f"ghnerf-daemon: error: {path}: rig.url: " in capsys.readouterr().err


def test_validate_config_prints_the_rig_file_s_note_as_it_prints_its_warnings(tmp_path, capsys):
    """Loading notes at INFO a rig whose pair shows a person at the volume's centre under 97 % of their height
    (``rig_file.rig_notes``, session 67); ``--validate-config``, which opens no rig and prints the rig's warnings,
    set up no logging, so Python showed WARNING and over only and the note was dropped."""
    from calibration.render import example_rig  # ghcal synth's rig until session 68: 84 % in view, noted
    from ghnerf_runtime.rig_file import save_rig

    rig = tmp_path / "synth_rig.json"
    save_rig(example_rig(), rig)
    path = _write(tmp_path, {"rig": {"url": f"opencv://?first=/dev/video0&second=/dev/video2&rig={rig}"},
                             "sinks": ["udp://127.0.0.1:9870"]})
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    err = capsys.readouterr().err
    assert err.count(f"{rig}: a 1.8 m person standing at the working volume's centre") == 1, err
    assert [note for note in framing_notes(err) if "(under 97%, " in note], err


@contextlib.contextmanager
def _a_root_handler_as_a_caller_sets_up() -> Iterator[None]:
    """A handler on the root logger while inside, as a caller's ``logging.basicConfig`` adds one, printing on
    sys.stderr as capsys holds it, in a format of its own: a line passed on to it shows twice."""
    root = logging.getLogger()
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)


def test_validate_config_prints_the_rig_s_note_once_where_the_root_logger_has_a_handler(tmp_path, capsys):
    """``--validate-config``'s handler printed the rig file's lines on stderr, and passed them on too: where the root
    logger has a handler (a caller's ``logging.basicConfig``, pytest's), each line came out a second time in that
    handler's format (session 68)."""
    from calibration.render import example_rig
    from ghnerf_runtime.rig_file import save_rig

    rig = tmp_path / "synth_rig.json"
    save_rig(example_rig(), rig)
    path = _write(tmp_path, {"rig": {"url": f"opencv://?first=/dev/video0&second=/dev/video2&rig={rig}"},
                             "sinks": ["udp://127.0.0.1:9870"]})
    with _a_root_handler_as_a_caller_sets_up():
        assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    err = capsys.readouterr().err
    assert err.count("a 1.8 m person standing at the working volume's centre") == 1, err
    assert f"\n{rig}: a 1.8 m person" in "\n" + err, err  # bare, as the warnings are


@pytest.mark.parametrize("options, words", [
    ("distance=1", "sim:// rig 'sim': a 1.8 m person standing at the working volume's centre"),  # 89 %: a note
    ("baseline=0.05", "sim:// rig 'sim': cameras 'left' and 'right' are 50 mm apart"),  # a warning
])
def test_validate_config_prints_a_sim_rig_s_note_and_warnings_once(tmp_path, capsys, options, words):
    """A ``sim://`` rig is built in memory: no rig file is loaded and ``--validate-config`` opens no source, so it
    printed neither the note nor the warnings the start logs of it (session 68). Now each once, bare on stderr, in
    the start's words (``INFO drivers.base: sim:// rig 'sim': ...`` there), also where the root logger has a handler."""
    path = _write(tmp_path, {"rig": {"url": f"sim://?width=48&height=36&cache=off&{options}"},
                             "sinks": ["udp://127.0.0.1:9870"]})
    with _a_root_handler_as_a_caller_sets_up():
        assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0
    out, err = capsys.readouterr()
    assert err.count(words.split(": ", 1)[1]) == 1 and f"\n{words}" in "\n" + err, err
    assert words not in out


@needs_model
def test_the_start_logs_the_rig_s_note_once_at_the_default_log_level(tmp_path):
    """The daemon's rig source notes a rig that cuts a standing person at INFO, once over its reopens; the default
    ``log_level`` (info) shows it in the journal at the start, with no setting (session 68 checked: no change
    needed there, unlike ``ghcal`` and ``ghnerf-run``). ``sim://?distance=1`` shows 89 % of the person.
    Stopped once it streams (systemd's ``running:`` status, sent after the rig's open): a 2 s --max-seconds ran out
    before the rig was opened on a loaded host (the imports and the model load; review 75), and nothing was noted."""
    path = _write(tmp_path, {"rig": {"url": "sim://?width=48&height=36&cache=off&distance=1"}, "sinks": ["memory://"],
                             "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
                             "health": {"status_every_s": 0.2}})
    with _under_a_notify_socket(tmp_path, path, stdout=subprocess.DEVNULL) as (sock, proc):
        _notes_until(sock, proc, [], lambda ns: ns[-1].get("STATUS", "").startswith("running:"), "streaming")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]
    noted = framing_notes(err)
    assert len(noted) == 1 and "INFO drivers.base: sim:// rig 'sim': a 1.8 m person standing" in noted[0], noted


@pytest.mark.parametrize("scheme", ["depthai", "opencv"])
def test_validate_config_refuses_a_rig_file_whose_volume_the_model_cannot_sweep(tmp_path, capsys, scheme):
    """A working volume reaching 20 km passed --validate-config and the start, then every pair failed on the
    model's near/far bound (MAX_DEPTH_M). The rig loader refuses it now, and --validate-config says so."""
    data = json.loads((REPO / "docs/examples/rig.json").read_text())
    data["working_volume"] = {"min": [-1.0, -2.0, 1.0], "max": [1.0, 0.0, 20000.0]}
    rig = tmp_path / "rig.json"
    rig.write_text(json.dumps(data))
    size = f"width={data['cameras'][0]['width']}&height={data['cameras'][0]['height']}"
    url = (f"depthai://?rig={rig}&{size}" if scheme == "depthai"
           else f"opencv://?first=/dev/video0&second=/dev/video2&rig={rig}")
    path = _write(tmp_path, {"rig": {"url": url}, "sinks": ["udp://127.0.0.1:9870"]})
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 2
    err = capsys.readouterr().err
    assert f"ghnerf-daemon: error: {path}: rig.url: " in err
    assert f"file {rig}, field 'working_volume': from [-1.0, -2.0, 1.0] to [1.0, 0.0, 20000.0] reaches" in err
    assert "(MAX_DEPTH_M)" in err


def test_the_stop_signal_handler_never_waits_on_the_stop_events_lock(tmp_path, monkeypatch):
    """SIGTERM's handler runs on the main thread between two bytecodes, maybe inside ``stop.wait()`` while
    that thread holds the Event's lock (a plain Lock): a handler taking it would wait for ever. Here the
    daemon holds the lock while the handler runs on another thread, so such a handler fails, not hangs."""
    from firmware_host.daemon import daemon_config_from_dict

    seen: dict[str, bool] = {}

    class HoldsTheStopLock:
        def __init__(self, config, **_kw) -> None:
            pass

        def request_reload(self) -> None:
            pass

        def run(self, stop: threading.Event) -> int:
            handler = signal.getsignal(signal.SIGTERM)
            with stop._cond:  # as Event.wait holds it around its inner wait
                caller = threading.Thread(target=handler, args=(signal.SIGTERM, None), daemon=True)
                caller.start()
                caller.join(timeout=5)
                seen["handler returned"] = not caller.is_alive()
            seen["stopped"] = stop.wait(timeout=5)  # the stop still arrives, without the lock held
            return 0

    config = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                      "estimator": {"session": {"model_dir": str(tmp_path)}}})
    monkeypatch.setattr(cli, "read_checked_config", lambda path: config)
    monkeypatch.setattr(cli, "Daemon", HoldsTheStopLock)
    monkeypatch.setattr(cli, "_setup_logging", lambda level: None)  # leave pytest's logging alone
    monkeypatch.setattr(cli.faulthandler, "enable", lambda: None)
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)}
    try:
        assert cli.main(["--config", str(tmp_path / "daemon.json")]) == 0
        assert seen == {"handler returned": True, "stopped": True}
        assert {s: signal.getsignal(s) for s in before} == before  # put back once the daemon returns
    finally:
        for signum, handler in before.items():
            signal.signal(signum, handler)


@contextlib.contextmanager
def _daemon_waiting_for_an_absent_rig(tmp_path: Path, *python_args: str
                                      ) -> Iterator[tuple[socket.socket, subprocess.Popen, Path]]:
    """The daemon (``python *python_args``, its module by default) :func:`_under_a_notify_socket`, on a rig that
    never appears (it waits in 300 s backoffs): ``(socket, process, status file)``."""
    status = tmp_path / "status.json"
    path = _write(tmp_path, {
        "rig": {"url": f"replay://{tmp_path / 'never'}", "reopen_min_s": 300, "reopen_max_s": 300},
        "sinks": [f"file://{tmp_path / 'joints.jsonl'}"],
        "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
        "health": {"status_file": str(status), "status_every_s": 0.2},
    })
    with _under_a_notify_socket(tmp_path, path, *python_args, JOURNAL_STREAM="8:1") as (sock, proc):
        yield sock, proc, status


@needs_model
def test_sigterm_while_waiting_for_the_rig_stops_at_once(tmp_path):
    """The loop waits for an absent rig in short ``stop.wait`` calls (where a signal may land): SIGTERM
    still stops it long before its backoff ends, with the final status written."""
    notes: list[dict[str, str]] = []
    with _daemon_waiting_for_an_absent_rig(tmp_path) as (sock, proc, status):
        _notes_until(sock, proc, notes, lambda ns: any(n.get("STATUS", "").startswith("waiting") for n in ns),
                     "waiting for the rig")
        time.sleep(0.5)  # a few of its stop.wait calls
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)  # not after the 300 s backoff, nor never
    assert proc.returncode == 0, err
    assert "SIGTERM received: stopping" in err and "Traceback" not in err
    assert json.loads(status.read_text())["state"] == "stopping"


def _signalled_until_it_exits(tmp_path, first: signal.Signals | None, repeated: signal.Signals):
    """The daemon, waiting for an absent rig, sent ``first`` once (None: not), then ``repeated`` every millisecond
    until it has exited (60 s at most): how many were repeated, its exit status, its stderr, its status file's
    state."""
    notes: list[dict[str, str]] = []
    sent = 0
    with _daemon_waiting_for_an_absent_rig(tmp_path) as (sock, proc, status):
        _notes_until(sock, proc, notes, lambda ns: any(n.get("STATUS", "").startswith("waiting") for n in ns),
                     "waiting for the rig")
        if first is not None:
            proc.send_signal(first)
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(repeated)
            sent += 1
            time.sleep(0.001)
        _, err = proc.communicate(timeout=60)
    return sent, proc.returncode, err, json.loads(status.read_text())["state"]


@needs_model
@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_stop_signals_repeated_until_it_exits_still_end_it_with_status_0(tmp_path, signum):
    """A second stop signal (``systemctl stop`` then ``kill``, Ctrl-C twice) may land after the daemon put back the
    handlers it replaced, as the process exits: SIGTERM's default action then killed it (status 143 where the
    docs say 0) and SIGINT raised KeyboardInterrupt in the interpreter's exit. Signals sent until it has exited."""
    sent, returncode, err, state = _signalled_until_it_exits(tmp_path, None, signum)
    assert sent >= 2  # (one alone is test_sigterm_while_waiting_for_the_rig_stops_at_once)
    assert returncode == 0, err
    assert f"{signal.Signals(signum).name} received: stopping" in err and "Traceback" not in err
    assert state == "stopping"


@needs_model
def test_a_sighup_as_it_exits_does_not_kill_it(tmp_path):
    """A SIGHUP after the stop (``systemctl reload`` as the daemon stops, or exits at its replay's end) found SIGHUP's
    default action put back: the interpreter's finalization resets a Python handler (the recording one) to it. The
    daemon died of SIGHUP in place of exit 0, a death the unit's RestartForceExitStatus=SIGHUP restarts."""
    sent, returncode, err, state = _signalled_until_it_exits(tmp_path, signal.SIGTERM, signal.SIGHUP)
    assert sent >= 2
    assert returncode == 0, err
    assert "SIGTERM received: stopping" in err and "Traceback" not in err
    assert state == "stopping"


_NOTE_THE_MEASURE = '''
import os, sys
sys.argv[0] = os.path.join(os.path.dirname(sys.executable), "ghnerf-daemon")  # as the console script
from firmware_host.daemon import cli

_measure = cli.measure_floor_of_config

def _noted(*args, **kwargs):
    open(os.environ["MEASURE_STARTED"], "w").close()  # the stop handlers are in place from here on
    return _measure(*args, **kwargs)

cli.measure_floor_of_config = _noted
sys.exit(cli.main(sys.argv[1:]))
'''


@needs_model
def test_a_second_ctrl_c_as_measure_floor_exits_prints_no_traceback(tmp_path):
    """``--measure-floor`` put back SIGINT's default handler once stopped: a second Ctrl-C as it exited raised
    KeyboardInterrupt in the print or the interpreter's exit, a traceback (and no status 130 of its own). Ignored
    there now, as the daemon's exit ignores it. SIGINT sent once the measurement began, then every millisecond until
    it has exited."""
    path = _write(tmp_path, {
        "rig": {"url": f"sim://?fps=30&seed=0&motion=wave&width=320&height=240&cache={tmp_path / 'sim'}"},
        "sinks": ["memory://"], "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}}})
    started = tmp_path / "started"
    proc = subprocess.Popen([sys.executable, "-c", _NOTE_THE_MEASURE, "--config", str(path), "--measure-floor",
                             "100000"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
                            env={**os.environ, "MEASURE_STARTED": str(started)})
    sent = 0
    try:
        deadline = time.monotonic() + 120
        while not started.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert started.exists(), proc.communicate(timeout=60)[1] if proc.poll() is not None else "not started"
        deadline = time.monotonic() + 60
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(signal.SIGINT)
            sent += 1
            time.sleep(0.001)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert sent >= 2
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert proc.returncode == 130, err
    assert out == "" and "SIGINT received: --measure-floor stopped before 100000 pairs" in err


# ------------------------------------------------------------------ SIGHUP during the start
# SIGHUP's default action kills, and systemd (Restart=on-failure) counts a death by SIGHUP as clean: a
# reload landing while the daemon still imports, reads its config or loads its model must not kill it.

_HUP_ON_IMPORT = '''
import os, signal, sys

class _HupOnImport:
    """Sends this process SIGHUP as the package's first heavy module is imported."""
    def find_spec(self, name, path=None, target=None):
        if name == "firmware_host.daemon.config":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGHUP)
        return None

sys.meta_path.insert(0, _HupOnImport())
'''


@pytest.mark.parametrize("how", ["console script", "-m"])
def test_a_sighup_during_the_imports_does_not_kill_it(tmp_path, how):
    script = Path(sys.executable).parent / "ghnerf-daemon"
    if how == "console script" and not script.is_file():
        pytest.skip(f"{script} is not installed")
    (tmp_path / "hook").mkdir()
    (tmp_path / "hook/sitecustomize.py").write_text(_HUP_ON_IMPORT)
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    command = [str(script)] if how == "console script" else [sys.executable, "-m", "firmware_host.daemon.cli"]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path / "hook"), str(REPO),
                                                                      os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([*command, "--config", str(path), "--validate-config"], capture_output=True, text=True,
                          timeout=120, env=env, cwd=REPO)
    assert proc.returncode != -signal.SIGHUP, "killed by the SIGHUP"
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["rig"]["url"] == "sim://"


_STOP_ON_IMPORT = '''
import os, signal, sys

class _StopOnImport:
    """Sends this process the signal named in GHNERF_TEST_STOP as the package's first heavy module is imported."""
    def find_spec(self, name, path=None, target=None):
        if name == "firmware_host.daemon.config":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), getattr(signal, os.environ["GHNERF_TEST_STOP"]))
        return None

sys.meta_path.insert(0, _StopOnImport())
'''


def _stopped_during_the_imports(tmp_path: Path, signum: signal.Signals, *args: str) -> subprocess.CompletedProcess:
    """``python -m firmware_host.daemon.cli *args``, sent ``signum`` as the package's first heavy module is imported
    (after the package's first lines), with the journal's log format; run to its end."""
    (tmp_path / "hook").mkdir()
    (tmp_path / "hook/sitecustomize.py").write_text(_STOP_ON_IMPORT)
    env = {**os.environ, "GHNERF_TEST_STOP": signum.name, "JOURNAL_STREAM": "8:1",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path / "hook"), str(REPO),
                                                       os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "firmware_host.daemon.cli", *args], capture_output=True, text=True,
                          timeout=120, env=env, cwd=REPO)


@needs_model
@pytest.mark.parametrize("signum, mode, status", [(signal.SIGTERM, (), 0), (signal.SIGINT, (), 0),
                                                  (signal.SIGTERM, ("--measure-floor",), 143)])
def test_a_stop_during_the_imports_stops_it_as_the_daemon_stops(tmp_path, signum, mode, status):
    """A SIGTERM (``systemctl stop``) while Python imported the runtime, before the daemon's stop handlers were in
    place, killed it: status 143 where the docs say 0, no log line, the status file unwritten; Ctrl-C there raised
    KeyboardInterrupt, a traceback. Recorded from the package's first import now: the daemon stops once its own
    handlers are in place, with the one line of any stop, no model loaded; ``--measure-floor`` exits 128 + the
    signal's number, as for a stop of its own."""
    status_file = tmp_path / "status.json"
    path = _write(tmp_path, {
        "rig": {"url": f"replay://{tmp_path / 'never'}", "reopen_min_s": 300, "reopen_max_s": 300},
        "sinks": [f"file://{tmp_path / 'joints.jsonl'}"],
        "estimator": {"session": {"model_dir": str(MODELS), "warmup": False}},
        "health": {"status_file": str(status_file)}})
    proc = _stopped_during_the_imports(tmp_path, signum, "--config", str(path), *mode)
    assert proc.returncode != -signum, f"killed by the {signum.name}"
    assert proc.returncode == status, proc.stderr
    assert "Traceback" not in proc.stderr and "loaded" not in proc.stderr, proc.stderr
    if mode:
        assert proc.stderr.strip() == (f"ghnerf-daemon: {path}: {signum.name} received: --measure-floor stopped "
                                       "before 60 pairs measured a foot (0 did, of 0 read): nothing to set")
    else:
        assert proc.stderr.count("received: stopping") == 1 and f"{signum.name} received: stopping" in proc.stderr
        assert json.loads(status_file.read_text())["state"] == "stopping"


def test_validate_config_meets_a_stop_during_the_imports_as_before(tmp_path):
    """``--validate-config`` installs no stop handlers: a SIGTERM recorded during its imports kills it when the
    recording ones are put back, as one did before they were recorded (it does not validate on after a stop)."""
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    proc = _stopped_during_the_imports(tmp_path, signal.SIGTERM, "--config", str(path), "--validate-config")
    assert proc.returncode == -signal.SIGTERM and proc.stdout == "", proc.stderr


@pytest.mark.parametrize("args", [("--print-example-config",), ("--config", "daemon.json", "--no-model"),
                                  ("--config", "no-such-daemon.json")])
def test_a_mode_without_stop_handlers_meets_a_stop_during_the_imports_as_before(tmp_path, args):
    """``--print-example-config``, a usage error and a config the start refuses install no stop handlers either: a
    SIGTERM recorded during their imports was dropped, and the run went on as if none came (the example printed,
    exit 0: a script's ``&&`` ran on after a ``kill``). It kills them on their way out now, as it did before stops
    were recorded."""
    proc = _stopped_during_the_imports(tmp_path, signal.SIGTERM, *args)
    assert proc.returncode == -signal.SIGTERM, (proc.returncode, proc.stderr)


def test_validate_config_off_the_main_thread_leaves_the_stop_recording_as_it_is(tmp_path, capsys):
    """``ghnerf-daemon``'s stop recording put back from a thread other than the main one (``cli.main`` called from
    one, the package imported on the main thread): Python sets handlers on the main thread only, and
    ``--validate-config`` died of the ValueError. It validates there, the recording and a stop it holds left as they
    are (the main thread's to put back)."""
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.early_sighup.install_stop()
    try:
        cli.early_sighup._record_stop(signal.SIGTERM, None)  # a stop recorded as a signal's would be
        statuses: list[object] = []

        def validate() -> None:
            try:
                statuses.append(cli.main(["--config", str(path), "--validate-config", "--no-model"]))
            except Exception as e:  # noqa: BLE001 - said by the assertion below
                statuses.append(e)

        thread = threading.Thread(target=validate)
        thread.start()
        thread.join(timeout=60)
        assert statuses == [0], statuses
        assert signal.getsignal(signal.SIGTERM) is cli.early_sighup._record_stop
        assert cli.early_sighup.take_stop() == signal.SIGTERM
    finally:
        cli.early_sighup.take_stop()  # not raised at this test's process by the put back
        cli.early_sighup.release_stop()
    assert signal.getsignal(signal.SIGTERM) is not cli.early_sighup._record_stop  # put back
    capsys.readouterr()


_HUP_AFTER_THE_READ = '''
import os, signal, sys
sys.argv[0] = os.path.join(os.path.dirname(sys.executable), "ghnerf-daemon")  # as the console script
from firmware_host.daemon import cli

_read = cli.read_checked_config
_sent = []

def _read_then_hup(path):
    config = _read(path)
    if not _sent:  # the start's read only, not the reload's
        _sent.append(1)
        os.kill(os.getpid(), signal.SIGHUP)
    return config

cli.read_checked_config = _read_then_hup
sys.exit(cli.main())
'''


@needs_model
def test_a_sighup_after_the_config_was_read_becomes_a_reload_once_running(tmp_path):
    """The file may have changed after the start read it: the recorded SIGHUP is a reload once the loop
    runs (here at once: the loop waits for an absent rig)."""
    notes: list[dict[str, str]] = []
    with _daemon_waiting_for_an_absent_rig(tmp_path, "-c", _HUP_AFTER_THE_READ) as (sock, proc, status):
        _notes_until(sock, proc, notes, lambda ns: any(n.get("STATUS", "").startswith("waiting") for n in ns),
                     "waiting for the rig")
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode != -signal.SIGHUP, "killed by the SIGHUP"
    assert proc.returncode == 0, err
    assert "SIGHUP received while starting" in err and "config reloaded: nothing changed" in err
    assert any("RELOADING" in n for n in notes)
    assert json.loads(status.read_text())["config"]["reloads"] == 1


def test_a_sighup_before_the_config_is_read_is_met_by_the_read(tmp_path, monkeypatch):
    """In process, with a stand-in daemon: a SIGHUP before the read asks nothing more; one after it asks
    one reload; neither kills. The test's own handler stands by in case main() leaves SIGHUP fatal."""
    from firmware_host.daemon import daemon_config_from_dict

    config = daemon_config_from_dict({"rig": {"url": "sim://"}, "sinks": ["memory://"],
                                      "estimator": {"session": {"model_dir": str(tmp_path)}}})
    reloads: list[int] = []

    class Stub:
        def __init__(self, config, **_kw) -> None:
            pass

        def request_reload(self) -> None:
            reloads.append(1)

        def run(self, stop: threading.Event) -> int:
            return 0

    def hup() -> None:
        os.kill(os.getpid(), signal.SIGHUP)
        time.sleep(0.01)  # the Python-level handler runs between two bytecodes

    fell_through: list[int] = []
    before = signal.signal(signal.SIGHUP, lambda *_: fell_through.append(1))
    monkeypatch.setattr(cli, "Daemon", Stub)
    monkeypatch.setattr(cli, "_setup_logging", lambda level: None)
    monkeypatch.setattr(cli.faulthandler, "enable", lambda: None)
    real_parser = cli.build_parser
    try:
        monkeypatch.setattr(cli, "build_parser", lambda: (hup(), real_parser())[1])
        monkeypatch.setattr(cli, "read_checked_config", lambda path: config)
        assert cli.main(["--config", "x.json"]) == 0
        assert reloads == [] and fell_through == []
        monkeypatch.setattr(cli, "build_parser", real_parser)
        monkeypatch.setattr(cli, "read_checked_config", lambda path: (hup(), config)[1])
        assert cli.main(["--config", "x.json"]) == 0
        assert reloads == [1] and fell_through == []
        assert signal.getsignal(signal.SIGHUP) is not cli.early_sighup._record  # put back
    finally:
        signal.signal(signal.SIGHUP, before)


def _fake_models(folder: Path) -> Path:
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "encoder.onnx").write_bytes(b"only globbed by --validate-config")
    return folder / "models"


def test_the_example_config_beside_its_models_validates_from_any_folder(tmp_path, monkeypatch, capsys):
    """The example config names "models" relative: read from the current directory, it worked only from the
    folder holding both (the repository root); run from anywhere else, its model folder did not exist."""
    home = tmp_path / "checkout"
    models = _fake_models(home)
    path = _write(home, cli.EXAMPLE_CONFIG)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    # --no-model: the fake folder's graph file is no graph (loaded by the tests above)
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 0, capsys.readouterr().err
    printed = json.loads(capsys.readouterr().out)
    assert printed["estimator"]["session"]["model_dir"] == str(models)
    assert printed["health"]["status_file"] == str(home / "ghnerf-status.json")
    # a relative --config path too: the file's folder, not the current one
    monkeypatch.chdir(tmp_path)
    assert cli.main(["--config", "checkout/daemon.json", "--validate-config", "--no-model"]) == 0
    assert json.loads(capsys.readouterr().out)["estimator"]["session"]["model_dir"] == str(models)


def test_a_missing_model_folder_names_the_resolved_path_and_the_config_file(tmp_path, monkeypatch, capsys):
    _fake_models(tmp_path)  # in the current directory, where a relative path used to be read
    monkeypatch.chdir(tmp_path)
    (tmp_path / "etc").mkdir()
    path = _write(tmp_path / "etc", cli.EXAMPLE_CONFIG)
    assert cli.main(["--config", str(path), "--validate-config"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"ghnerf-daemon: error: {path}: estimator.session.model_dir: {tmp_path / 'etc' / 'models'}: "
                   f"no such folder (a relative path in {path} is read from its folder, {tmp_path / 'etc'})")


def test_printing_the_example_config_into_a_closed_pipe_is_no_error():
    # `ghnerf-daemon --print-example-config | head -3` (or --validate-config): a reader that stops early ended in
    # a BrokenPipeError traceback
    read_end, write_end = os.pipe()
    os.close(read_end)  # the reader is gone before anything is written
    try:
        proc = subprocess.run([sys.executable, "-m", "firmware_host.daemon.cli", "--print-example-config"],
                              stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120, cwd=REPO)
    finally:
        os.close(write_end)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr


def test_validate_config_and_the_start_refuse_videos_of_another_size_than_the_rig_file(tmp_path, capsys):
    """opencv:// videos (640x480 here) with a rig file calibrated at another resolution (1280x960): a video's size is
    in its container, so --validate-config and the start say it at once (they passed, and the daemon then retried the
    open for ever); the same videos with a rig file of their size pass."""
    import cv2

    from drivers.sim.placement import RigPlacement
    from ghnerf_runtime.rig_file import save_rig

    videos = []
    for name in ("left", "right"):
        videos.append(tmp_path / f"{name}.avi")
        writer = cv2.VideoWriter(str(videos[-1]), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
        assert writer.isOpened(), "this OpenCV cannot write MJPG"
        writer.write(np.zeros((480, 640, 3), np.uint8))
        writer.release()
    for size, rc in (((1280, 960), 2), ((640, 480), 0)):
        rig = tmp_path / f"rig{size[0]}.json"
        save_rig(RigPlacement(width=size[0], height=size[1]).build(rig_id="desk"), rig)
        path = _write(tmp_path, {"rig": {"url": f"opencv://?first={videos[0]}&second={videos[1]}&rig={rig}"},
                                 "sinks": ["udp://127.0.0.1:9870"],
                                 "estimator": {"session": {"model_dir": str(MODELS)}}})
        assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == rc
        if rc:  # the start reads the config as --validate-config does: stopped before the model loads
            assert cli.main(["--config", str(path)]) == rc
        err = capsys.readouterr().err
        if rc:
            assert (f"ghnerf-daemon: error: {path}: rig.url: camera 'left' ({videos[0]}) delivered 640x480, but "
                    f"its rig camera in {rig} is 1280x960: the same shape at 0.5 times the size, so the rig file was "
                    f"most likely calibrated at another resolution of this camera; calibrate again at 640x480 (ghcal, "
                    f"docs/calibration.md), or use videos recorded at 1280x960") in err
            assert err.count("ghnerf-daemon: error:") == 2  # --validate-config, then the start: one line each


def test_validate_config_and_the_start_refuse_a_still_image_as_an_opencv_video(tmp_path, capsys):
    """A PNG of the rig camera's size named by first=: --validate-config passed it (its container, FFmpeg's image
    reader, states that size), and the daemon played it as one frame. Refused by both, naming the option and
    pointing at replay://, as the open refuses it."""
    import cv2

    from drivers.sim.placement import RigPlacement
    from ghnerf_runtime.rig_file import save_rig

    still, video = tmp_path / "left.png", tmp_path / "right.avi"
    cv2.imwrite(str(still), np.zeros((480, 640, 3), np.uint8))
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    writer.write(np.zeros((480, 640, 3), np.uint8))
    writer.release()
    rig = tmp_path / "rig.json"
    save_rig(RigPlacement(width=640, height=480).build(rig_id="desk"), rig)
    path = _write(tmp_path, {"rig": {"url": f"opencv://?first={still}&second={video}&rig={rig}"},
                             "sinks": ["udp://127.0.0.1:9870"],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == 2
    assert cli.main(["--config", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count(f"ghnerf-daemon: error: {path}: rig.url: opencv:// option first={still} (camera 'left'): a "
                     f"still image, not a video") == 2
    assert "replay://" in err


def test_validate_config_and_the_start_refuse_a_take_of_another_size_than_its_rig(tmp_path, capsys):
    """A replay:// take whose images are all of another size than the rig in its manifest (resized after recording)
    passed --validate-config and the start, then the daemon reopened it for ever (each read failed on an image). A
    take's files never change size, so the check says it at once, keyed rig.url, as for opencv:// videos; the same
    take as recorded passes."""
    import cv2

    import drivers

    takes = {}
    for name in ("resized", "as-recorded"):
        takes[name] = tmp_path / name
        url = f"record+sim://?width=40&height=30&seed=3&cache={tmp_path / 'cache'}&out={takes[name]}&lossless=1"
        with drivers.open_rig(url, clock=drivers.ManualClock()) as source:
            for _ in range(6):
                source.read(timeout_s=5.0)
    for path in sorted((takes["resized"] / "images" / "left").iterdir()):
        cv2.imwrite(str(path), cv2.resize(cv2.imread(str(path)), (80, 60)))
    for name, rc in (("resized", 2), ("as-recorded", 0)):
        path = _write(tmp_path, {"rig": {"url": f"replay://{takes[name]}"}, "sinks": ["udp://127.0.0.1:9870"],
                                 "estimator": {"session": {"model_dir": str(MODELS)}}})
        assert cli.main(["--config", str(path), "--validate-config", "--no-model"]) == rc
        if rc:  # the start reads the config as --validate-config does: stopped before the model loads
            assert cli.main(["--config", str(path)]) == rc
        err = capsys.readouterr().err
        if rc:
            first = min((takes[name] / "images" / "left").iterdir()).relative_to(takes[name]).as_posix()
            assert (f"ghnerf-daemon: error: {path}: rig.url: recording {takes[name]}: camera 'left': 6 of its 6 images "
                    f"are 80x60 ({first}, ") in err
            assert ("read from each image's header at open), but its rig camera in "
                    f"{takes[name] / 'manifest.json'} is 40x30: the take was recorded at another size than the rig it "
                    "carries") in err
            assert err.count("ghnerf-daemon: error:") == 2  # --validate-config, then the start: one line each


def test_a_second_main_in_the_process_records_sighup_after_the_first_left_it_ignored(monkeypatch):
    """A main() run as ghnerf-daemon (by argv[0]) leaves SIGHUP ignored on its way out; a later main() in the same
    process installs the recording handler again (it took the stale 'installed' flag for one in place, and a SIGHUP
    fell through to whatever handler was there)."""
    before = signal.getsignal(signal.SIGHUP)
    try:
        monkeypatch.setattr(sys, "argv", [cli.early_sighup.PROG])
        with pytest.raises(SystemExit):
            cli.main(["--help"])
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        monkeypatch.setattr(sys, "argv", ["python"])
        signal.signal(signal.SIGHUP, signal.SIG_DFL)
        assert cli.early_sighup.install()
        assert signal.getsignal(signal.SIGHUP) is cli.early_sighup._record
        cli.early_sighup.uninstall()
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL
    finally:
        signal.signal(signal.SIGHUP, before)


@pytest.mark.parametrize(("sink", "said"), [
    ("bogus://x", "sinks[1]: bogus://x: invalid scheme='bogus'"),
    ("udp://", "sinks[1]: udp://: invalid host=''"),
    ("serial:///dev/ttyS0?baud=fast", "sinks[1]: serial:///dev/ttyS0?baud=fast: invalid baud='fast'"),
])
def test_a_bad_sink_url_stops_the_start_at_the_config_load(tmp_path, capsys, monkeypatch, sink, said):
    """The start reads the config as --validate-config does (check_config's sink check, which opens nothing):
    a typo in a sink URL is exit 2 naming its key, before the daemon is built or its model loaded."""
    def never(*args, **kwargs):
        raise AssertionError("the daemon was built: the model would load before the sink URL was refused")

    monkeypatch.setattr(cli, "Daemon", never)
    monkeypatch.setattr(cli, "load_model", never)
    path = _write(tmp_path, {"rig": {"url": "sim://"}, "sinks": ["memory://", sink],
                             "estimator": {"session": {"model_dir": str(MODELS)}}})
    assert cli.main(["--config", str(path), "--max-seconds", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"ghnerf-daemon: error: {path}: {said}"), err
