"""training/learnt_fill_gpu.sh, the learnt fill's measurement in one command: its plumbing, with every stage
stubbed (the stages themselves are tests/training/test_learnt_fill.py's)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "training" / "learnt_fill_gpu.sh"


def test_folders_and_a_python_with_spaces_and_quotes_in_their_names_are_used_as_given(tmp_path):
    np.savez(tmp_path / "cache.npz", angle=np.zeros(6, np.float32))
    python = tmp_path / "my venv" / "python"
    python.parent.mkdir()
    # the stages write what the script copies; the view count is read by the real python
    python.write_text(f"""#!/usr/bin/env bash
out=""; prev=""
for a in "$@"; do [ "$prev" = --out ] && out=$a; prev=$a; done
case "$*" in
  *training.data.generate*) exit 0;;
  *"training.learnt_fill cache"*) cp "{tmp_path / 'cache.npz'}" "$out";;
  *"training.learnt_fill train"*) mkdir -p "$out"; for f in fill_net.pt score.json; do echo > "$out/$f"; done
                                  echo "$*" > "$out/score.md";;
  *) exec "{sys.executable}" "$@";;
esac
""")
    python.chmod(0o755)
    work, report = tmp_path / "it's work", tmp_path / "the report"
    done = subprocess.run(["bash", str(SCRIPT), str(work), str(report), "3", "4"], cwd=REPO,
                          env={**os.environ, "PYTHON": str(python), "WORKERS": "1"}, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert (report / "fill_net_all.pt").is_file() and "max_seconds=4" in (report / "score_all.md").read_text()
    half = (report / "score_half.md").read_text()
    assert "--train-views 3" in half and "max_seconds=2" in half
    assert "total:" in done.stdout
