"""Shared fixtures of the training tests (tiny configs, a synthetic two-camera rig)."""
from __future__ import annotations

import pytest


@pytest.fixture(autouse=True, scope="session")
def _two_threads():
    try:
        import torch
    except ImportError:
        yield
        return
    torch.set_num_threads(2)
    yield


@pytest.fixture(autouse=True)
def _no_flush_denormal_afterwards():
    """The trainers set the process-wide flush-denormal mode (a CLI runs alone); a test that calls them in
    process leaves subnormals off for every later test (hypothesis refuses float strategies then)."""
    yield
    try:
        import torch
    except ImportError:
        return
    torch.set_flush_denormal(False)
