"""Running a command where file permissions bind, for the tests of folders and files a user may not read.

The service runs as its own user (``systemd/ghnerf.service``: ``User=ghnerf``, ``ProtectHome=yes``), so a
model folder it may not read is a real case; but the tests often run as root, who reads everything. As
root the command runs without the two capabilities that override permission bits (``setpriv``, util-linux),
so ``chmod 000`` means what it says; a test skips where neither is possible (a container that may not
drop capabilities).
"""
from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Sequence

import pytest

_DROP = ["--bounding-set", "-dac_override,-dac_read_search", "--"]


def unprivileged_prefix() -> list[str]:
    """The words to put before a command so that permission bits bind to it (skips the test when none do)."""
    if os.geteuid() != 0:
        return []
    setpriv = shutil.which("setpriv")
    if setpriv is None:
        pytest.skip("running as root without setpriv: permission bits cannot be made to bind")
    probe = subprocess.run([setpriv, *_DROP, "true"], capture_output=True, timeout=30)
    if probe.returncode != 0:
        pytest.skip(f"setpriv cannot drop capabilities here: {probe.stderr.decode(errors='replace').strip()}")
    return [setpriv, *_DROP]


def run_unprivileged(args: Sequence[str], **kwargs) -> subprocess.CompletedProcess:
    """``subprocess.run(args, capture_output=True, text=True, **kwargs)`` with permission bits binding."""
    return subprocess.run([*unprivileged_prefix(), *args], capture_output=True, text=True, **kwargs)
