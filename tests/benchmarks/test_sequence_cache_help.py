"""Where the bench's sequences are cached, as every ``--cache`` help says it: ``default_cache_dir`` follows
``XDG_CACHE_HOME``, and the helps said ``~/.cache/ghnerf-bench`` whatever the environment (one wording now,
``simdata.SEQUENCE_CACHE_HELP``)."""
from __future__ import annotations

from pathlib import Path

import pytest

from ghnerf_runtime.cli.bench import build_parser
from ghnerf_runtime.cli.simdata import SEQUENCE_CACHE_HELP, default_cache_dir

REPO = Path(__file__).resolve().parents[2]


def _scripts_caching_the_bench_sequences() -> list[Path]:
    """The benchmark scripts whose ``--cache`` is where ``load_sequences`` caches."""
    return sorted(p for p in (REPO / "benchmarks").glob("*.py") if "cache_dir=args.cache" in p.read_text())


def test_the_help_names_the_folder_default_cache_dir_picks_with_and_without_xdg_cache_home(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache_dir() == tmp_path / "xdg" / "ghnerf-bench"
    assert "default $XDG_CACHE_HOME/ghnerf-bench when XDG_CACHE_HOME is set" in SEQUENCE_CACHE_HELP
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_cache_dir() == tmp_path / "home" / ".cache" / "ghnerf-bench"
    assert "else ~/.cache/ghnerf-bench" in SEQUENCE_CACHE_HELP


def test_every_script_caching_the_bench_sequences_says_so_in_the_shared_words() -> None:
    scripts = _scripts_caching_the_bench_sequences()
    assert scripts, "no benchmark script hands --cache to load_sequences: the search is stale"
    off = [p.name for p in scripts if 'add_argument("--cache", help=SEQUENCE_CACHE_HELP)' not in p.read_text()]
    assert not off, f"--cache help not SEQUENCE_CACHE_HELP in {off}"


def test_ghnerf_bench_runtime_help_says_it_too(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["runtime", "--help"])
    shown = "".join(capsys.readouterr().out.split())  # argparse wraps the help, also at a hyphen (ghnerf-|bench)
    assert "".join(SEQUENCE_CACHE_HELP.split()) in shown
