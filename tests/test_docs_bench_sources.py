"""Every ``ghnerf-bench runtime`` command the docs quote names its heatmap source.

Until session 62 the bench scored the rendered heatmaps unless ``--heatmap-sources`` said otherwise; it now runs
the runtime's default (``heatmaps.source``, the encoder's). A command quoted without the option gives the figures
of whichever source is the default on the day it is pasted: the figures beside it may be the other source's (a
bare run gave 119.6 mm MPJPE rendered against 32.1 mm encoder, session 62). So each quoted run with options says
its source; a span that only names the program (`ghnerf-bench runtime` in prose), or asks for ``--help``, runs
nothing. The commands are read by tests/test_docs_commands.py's reader (code spans, fences, continuations).
"""
from __future__ import annotations

from tests import test_docs_commands as doc_commands

#: the command lines that run the bench: (kind, program) as the reader gives them, with the subcommand if any
BENCH_RUNS = {("console", "ghnerf-bench"): "runtime", ("module", "ghnerf_runtime.cli.bench"): "runtime",
              ("script", "benchmarks/bench_runtime.py"): None}


def _bench_options(command: doc_commands.Command) -> list[str] | None:
    """The words after ``runtime`` of a bench run (None for any other command)."""
    if (command.kind, command.program) not in BENCH_RUNS:
        return None
    subcommand = BENCH_RUNS[command.kind, command.program]
    if subcommand is None:
        return list(command.args)
    return list(command.args[1:]) if command.args[:1] == (subcommand,) else None


def unsourced_bench_runs(commands: dict[str, list[doc_commands.Command]]) -> list[str]:
    """Each quoted bench run with options that does not name ``--heatmap-sources``."""
    found = []
    for doc_list in commands.values():
        for command in doc_list:
            options = _bench_options(command)
            if not options or "--help" in options or "-h" in options:
                continue
            if not any(word.split("=", 1)[0] == "--heatmap-sources" for word in options):
                found.append(str(command))
    return found


def test_every_quoted_bench_run_names_its_heatmap_source():
    unsourced = unsourced_bench_runs(doc_commands.doc_commands())
    assert not unsourced, ("name --heatmap-sources (rendered for figures from before session 62 without it):\n"
                           + "\n".join(unsourced))


def test_the_check_reads_every_spelling_of_a_bench_run(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "pyproject.toml").write_text((doc_commands.REPO / "pyproject.toml").read_text(encoding="utf-8"),
                                             encoding="utf-8")
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "docs" / "page.md").write_text(
        "Prose names `ghnerf-bench runtime` and `ghnerf-bench runtime --help`; `ghnerf-bench sim-pair --out x`.\n"
        "Named: `ghnerf-bench runtime --sequences 2 --heatmap-sources rendered`.\n"
        "Bare: `ghnerf-bench runtime --sequences 2\n--precisions int8`, `python -m ghnerf_runtime.cli.bench runtime\n"
        "--modes keypoints` and `python benchmarks/bench_runtime.py --model-dir models`.\n", encoding="utf-8")
    unsourced = unsourced_bench_runs(doc_commands.doc_commands(tmp_path))
    assert [line.split(": ", 1)[0] for line in unsourced] == ["docs/page.md:3", "docs/page.md:4", "docs/page.md:5"]
