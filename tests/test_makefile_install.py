"""The Makefile's editable installs (``make demo``, ``make test``) print no setuptools note a user cannot act on.

pip 26 passes on what a local folder's build backend warns of, and setuptools warns on every editable install of a
flat layout as this one: a box of asterisks on the first screen of ``make demo`` from a fresh clone, "Please be
careful with folders in your working directory with the same name as your package", where those folders are the
packages. The Makefile filters that note out by its text; this runs setuptools' own editable build on a project laid
out as this one is, with and without the environment the Makefile's install lines give pip.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
NOTE = "same name as your package"
BUILD_EDITABLE = "import sys, setuptools.build_meta as b; b.build_editable(sys.argv[1])"


def editable_install_lines(venv: Path) -> list[str]:
    """The ``pip install ... -e`` lines ``make dev`` runs from nothing (``-n``: printed, not run)."""
    printed = subprocess.run(["make", "-n", "-B", "dev", f"VENV={venv}"], cwd=REPO, capture_output=True, text=True,
                             check=True).stdout
    return [line for line in printed.splitlines() if re.search(r"\bpip install\b.* -e ", line)]


def leading_assignments(line: str) -> dict[str, str]:
    """The ``NAME=value`` words a shell line starts with: the environment it gives its command."""
    env = {}
    for word in shlex.split(line):
        if not re.fullmatch(r"[A-Za-z_]\w*=.*", word):
            break
        name, value = word.split("=", 1)
        env[name] = value
    return env


def flat_project(root: Path) -> Path:
    """A one-package project laid out as this repository is (the package folder beside pyproject.toml)."""
    (root / "flatpkg").mkdir(parents=True)
    (root / "flatpkg" / "__init__.py").write_text("")
    (root / "pyproject.toml").write_text('[build-system]\nrequires = ["setuptools>=77"]\n'
                                         'build-backend = "setuptools.build_meta"\n\n'
                                         '[project]\nname = "flatpkg"\nversion = "0"\n\n'
                                         '[tool.setuptools.packages.find]\ninclude = ["flatpkg*"]\n')
    return root


def build_editable_stderr(project: Path, wheels: Path, extra_env: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"} | extra_env
    run = subprocess.run([sys.executable, "-c", BUILD_EDITABLE, str(wheels)], cwd=project, env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return " ".join(run.stderr.split())  # the note is wrapped and indented


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_the_editable_installs_filter_out_setuptools_note_on_the_flat_layout(tmp_path):
    lines = editable_install_lines(tmp_path / "venv")
    assert len(lines) == 2, lines  # the runtime's and the dev set's
    project = flat_project(tmp_path / "project")
    # the note is there to filter: setuptools prints it for this layout (else the test below proves nothing)
    assert NOTE in build_editable_stderr(project, tmp_path / "wheels-plain", {})
    for line in lines:
        stderr = build_editable_stderr(project, tmp_path / f"wheels-{len(line)}", leading_assignments(line))
        assert NOTE not in stderr, f"{line}\n{stderr}"
