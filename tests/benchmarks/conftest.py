"""Shared fixtures of the benchmark tests."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def train_only(tmp_path_factory):
    """A dataset of one training scene and no held-out split (32 px, no novel views: made in a second)."""
    from training.data.generate import main as generate

    out = tmp_path_factory.mktemp("train_only")
    assert generate(["--out", str(out), "--train", "1", "--res", "32", "--novel-views", "0", "--workers", "1"]) == 0
    return out
