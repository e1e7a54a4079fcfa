"""Fixtures shared by the firmware_host tests."""
from __future__ import annotations

import pytest

from ghnerf_runtime.estimator import Estimator


@pytest.fixture
def recorded(monkeypatch):
    """Every PairResult an Estimator returns while the test runs (the demo's, the daemon's), in order."""
    results = []
    original = Estimator.estimate

    def estimate(self, *args, **kwargs):
        result = original(self, *args, **kwargs)
        results.append(result)
        return result

    monkeypatch.setattr(Estimator, "estimate", estimate)
    return results
