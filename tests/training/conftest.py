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
