"""``benchmarks/measure_edge_padding.py``: its fills and the fade's reach get through its command line to the
runtime's config and its table (the tiny test export, random weights: the figures mean nothing), so that the
commands docs/runtime.md names beside its figures ("A person at the frame's edge") keep running."""
from __future__ import annotations

import re

from tests.benchmarks.test_bench_smoke import run_script, run_script_failing, scratch_cache  # noqa: F401
from tests.ghnerf_runtime.test_session import tiny_model_dir  # noqa: F401  (session fixture)


def test_the_fade_fill_and_its_reach_reach_the_table(tiny_model_dir, scratch_cache, capsys, monkeypatch):  # noqa: F811
    out = run_script("measure_edge_padding", "--model-dir", str(tiny_model_dir), "--sequences", "1", "--frames", "2",
                     "--outside", "0.5", "--pad-fill", "fade", "--pad-fade", "0.05", capsys=capsys,
                     monkeypatch=monkeypatch)
    # the crop turn search as the estimator runs it (on by default since session 57 where the model has encoder
    # heatmaps): the header said "runtime defaults" alone, the same before and after the default changed
    from ghnerf_runtime.config import EstimatorConfig, SessionConfig
    from ghnerf_runtime.estimator import load_session

    heat = load_session(EstimatorConfig(session=SessionConfig(model_dir=str(tiny_model_dir)))).contract.encoder_heatmaps
    assert f"roi.pad_fill 'fade' (pad_fade 0.05), roi.turn_search {'on' if heat else 'off'}:" in out, out
    assert re.search(r"^\| uncut \(reference\) \|", out, re.M) and re.search(r"^\| 50% \| \d+\.\d%", out, re.M), out
    err = run_script_failing("measure_edge_padding", "--pad-fill", "mirror", capsys=capsys, monkeypatch=monkeypatch)
    assert "mirror" in err and "fade" in err  # argparse names the value and the fills it takes
