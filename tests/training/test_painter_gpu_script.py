"""training/painter_gpu.sh, the painter's GPU recipe, end to end at a tiny size on the CPU.

A lent GPU machine is held for minutes, so the script must not fail there for a reason a CPU run finds:
this runs every stage (data, the device's joints, the caches, a net per width) on a few scenes."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "training" / "painter_gpu.sh"


def _run(tmp_path: Path, report: str = "report", **env: str) -> subprocess.CompletedProcess:
    full = {**os.environ, "PYTHON": sys.executable, "VAL": "4", "WORKERS": "2", "WIDTHS": "8", **env}
    return subprocess.run(["bash", str(SCRIPT), str(tmp_path / "work"), str(tmp_path / report), "6", "2"],
                          cwd=REPO, env=full, capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("report", ["report", "work"])  # `make painter-gpu` reports into the work folder
def test_the_gpu_recipe_makes_a_scored_net_per_width_and_the_val_joints(tmp_path, report):
    from training.learnt_fill import load_net

    done = _run(tmp_path, report)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    report = tmp_path / report
    net = load_net(report / "fill_net_w8.pt")
    assert net.cfg.width == 8 and net.cfg.shown_input and not net.cfg.relit_input
    assert net.steps_trained >= 1 and net.trained["config"]["batch"] == 32
    assert net.trained["config"]["around_weight"] == pytest.approx(0.03)
    assert "| novel, all |" in (report / "score_w8.md").read_text()
    with np.load(report / "joints_val.npz") as z:
        assert z["joints"].shape == (4, 25, 3)
    assert "total:" in done.stdout


def test_a_stage_that_fails_in_the_background_stops_the_script(tmp_path):
    # the joints of both splits run side by side; only the train split's fails here, and the script must
    # stop there (a plain `wait` would let it go on with the val split's joints alone)
    python = tmp_path / "python"
    python.write_text(f"""#!/usr/bin/env bash
case "$*" in *training.device_joints*--split\\ train*) echo "train joints failed" >&2; exit 7;; esac
exec {sys.executable} "$@"
""")
    python.chmod(0o755)
    done = _run(tmp_path, PYTHON=str(python))
    assert done.returncode == 7, done.stdout[-2000:] + done.stderr[-2000:]
    assert "train joints failed" in done.stderr
    assert "joints:" not in done.stdout and not (tmp_path / "work" / "fill_val.npz").exists()


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_make_painter_without_its_dataset_says_what_makes_one(tmp_path):
    # `make painter` trains on the dataset `make model` makes: from a clean clone it must say so, not fail
    # with a traceback from the first stage
    done = subprocess.run(["make", "-s", "painter", "DEV_STAMP=", f"PY={sys.executable}",
                           f"PAINTER_DATA={tmp_path / 'none'}", f"PAINTER_RUNS={tmp_path / 'runs'}"],
                          cwd=REPO, capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert "no dataset in" in done.stderr and "`make model`" in done.stderr and "no GPU needed" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "runs").exists()


def test_a_python_whose_path_has_a_space_is_run(tmp_path):
    # PYTHON=<a venv's python>: a folder with a space in its name is an ordinary place for one
    python = tmp_path / "my venv" / "python"
    python.parent.mkdir()
    python.write_text('#!/usr/bin/env bash\necho "ran $2" >&2; exit 7\n')
    python.chmod(0o755)
    done = _run(tmp_path, PYTHON=str(python))
    assert done.returncode == 7 and "ran training.data.generate" in done.stderr, done.stderr[-2000:]


def test_views_trains_each_width_on_all_and_on_the_first_n_training_views(tmp_path):
    from training.learnt_fill import load_net

    done = _run(tmp_path, VIEWS="all 3")
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    report = tmp_path / "report"
    every, few = load_net(report / "fill_net_w8.pt"), load_net(report / "fill_net_w8_v3.pt")
    assert few.trained["train_views"] == 3 and every.trained["train_views"] > 3
    assert "fill net trained on 3 views" in (report / "score_w8_v3.md").read_text()
    assert "training views 3" in done.stdout and "training views all" in done.stdout


@pytest.mark.parametrize("views", ["0", "some", "all -1"])
def test_a_views_entry_that_is_not_a_count_stops_the_script_before_any_work(tmp_path, views):
    done = _run(tmp_path, VIEWS=views)
    assert done.returncode == 2 and "VIEWS:" in done.stderr, done.stderr[-2000:]
    assert not (tmp_path / "work").exists()
