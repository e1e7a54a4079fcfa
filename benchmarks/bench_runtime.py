"""Benchmark: per-stage latency and accuracy of the runtime (same as ``ghnerf-bench runtime``).

    .venv/bin/python benchmarks/bench_runtime.py --model-dir models [--precisions fp32,int8,auto] [--json out.json]

Every option of ``ghnerf-bench runtime`` applies (see ``ghnerf_runtime/cli/bench.py``), its defaults too: the
runtime's own config, encoder heatmaps unless ``--heatmap-sources rendered`` (the default before session 62). Not
a test.
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ghnerf_runtime.cli.bench import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["runtime", *sys.argv[1:]]))
