"""The training tools answer ``--help`` and usage errors without importing torch (about 3 s here): the parsers
live in ``training.cli`` and the tools' modules parse before they import it."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: ``python -m`` module, an argv that is a usage error.
TOOLS = (
    ("training.train", ["--out", "r", "--preset", "nope"]),
    ("training.evaluate", ["--data", "d"]),  # --model is required
    ("training.pretrain_human", ["--iterations", "x"]),
    ("training.convert_norm", ["only-src"]),
    ("training.learnt_fill", ["cache", "--data", "d", "--out", "c.npz", "--workers", "0"]),
    ("training.export", ["--out", "m", "--opset", "3"]),
)


def _run(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-X", "importtime", *args], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=120)


def _imported_torch(importtime_log: str) -> bool:
    """Whether ``-X importtime``'s log (stderr) lists the torch package."""
    return any(line.rsplit("|", 1)[-1].strip() == "torch" for line in importtime_log.splitlines())


@pytest.mark.parametrize(("module", "usage_error"), TOOLS, ids=[m for m, _ in TOOLS])
def test_help_and_usage_errors_come_before_torch(module, usage_error):
    r = _run("-m", module, "--help")
    assert r.returncode == 0 and r.stdout.startswith("usage:"), r.stderr[-2000:]
    assert not _imported_torch(r.stderr), f"python -m {module} --help imported torch"
    r = _run("-m", module, *usage_error)
    assert r.returncode == 2 and "error:" in r.stderr, r.stderr[-2000:]
    assert not _imported_torch(r.stderr), f"python -m {module} {' '.join(usage_error)} imported torch"


def test_the_console_scripts_parse_before_torch():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for name in ("ghnerf-train", "ghnerf-eval"):
        module, _, func = scripts[name].partition(":")
        code = (f"import sys\nfrom {module} import {func}\ntry:\n    {func}(['--help'])\nexcept SystemExit as e:\n"
                "    assert e.code == 0, e.code\nassert 'torch' not in sys.modules, 'torch imported'\n")
        r = _run("-c", code)
        assert r.returncode == 0 and "usage: " + name in r.stdout, (name, r.stderr[-2000:])


def test_the_console_scripts_still_run_the_tool():
    """After parsing, the tool's own main runs (here ``--validate-config``, which prints the config)."""
    pytest.importorskip("torch")
    r = _run("-m", "training.train", "--preset", "tiny", "--validate-config", "--out", "unused")
    assert r.returncode == 0 and '"preset": "tiny"' in r.stdout, r.stderr[-2000:]


def test_the_export_help_states_the_limits_it_checks():
    """``--opset`` and ``--calib-npz`` say in ``--help`` what the export refuses (docs/model.md): the help named
    neither the opset range nor the calibration file's minimum."""
    from training.export.calibration import MIN_FRAMES
    from training.export.cli import build_parser
    from training.export.opsets import MAX_OPSET, MIN_OPSET

    helps = {a.option_strings[0]: " ".join(a.help.split()) for a in build_parser()._actions if a.help}
    assert f"{MIN_OPSET} to {MAX_OPSET}" in helps["--opset"]
    assert f"at least {MIN_FRAMES} frame pairs" in helps["--calib-npz"]


@pytest.mark.parametrize("module", ["training.convert_norm", "training.learnt_fill", "training.pretrain_human",
                                    "training.export"])
def test_a_tool_without_a_console_script_names_the_command_the_docs_give(module):
    """docs/training.md runs these as ``python -m MODULE``; their usage line said ``convert_norm.py`` and
    ``learnt_fill.py`` (argparse's file name), a command that does not run from the repository root."""
    r = _run("-m", module, "--help")
    assert r.returncode == 0 and r.stdout.startswith(f"usage: python -m {module} "), r.stdout[:200]


@pytest.mark.parametrize("module", ["training.cli.train", "training.cli.evaluate", "training.cli.pretrain_human",
                                    "training.cli.convert_norm", "training.cli.learnt_fill"])
def test_the_modules_pyproject_names_run_the_tool_through_python_m(module):
    """``python -m training.cli.train`` (the module behind ``ghnerf-train`` in pyproject) exited 0 having run
    nothing: no usage line, no error, no run."""
    r = _run("-m", module, "--help")
    assert r.returncode == 0 and r.stdout.startswith("usage:"), (r.returncode, r.stdout[:200])
