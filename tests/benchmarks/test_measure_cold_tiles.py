"""``benchmarks/measure_cold_tiles.py``: its command line runs and prints both configs and their ratios (the tiny test
export, random weights: the figures mean nothing)."""
from __future__ import annotations

from tests.benchmarks.test_bench_smoke import run_script, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


def test_the_command_line_runs(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_cold_tiles", "--model-dir", str(tiny_model_dir), "--precision", "fp32",
                     "--sequences", "1", "--frames", "2", "--rooms", "1", "--pairs", "2",
                     "--rigs", "docs/examples/rig.json", capsys=capsys, monkeypatch=monkeypatch)
    rows = [line for line in out.splitlines() if line.startswith("| docs/examples/rig.json |")]
    assert [r.split("|")[2].strip() for r in rows] == ["tiles (default)", "no tiles", "ratio"], out
    # the example rig's cold crop draws a person at 0.40 of its side: every empty-room pair searches a tile
    assert rows[0].rstrip(" |").endswith("/ 2") and rows[1].rstrip(" |").endswith("0 / 0"), out
    assert " of 2 | " in rows[0] and " of 2 | " in rows[1], out
