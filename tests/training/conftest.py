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


@pytest.fixture(scope="module", params=["batch", "scene"])
def tiny_each_norm(request):
    """The tiny preset with its image feature network normalised by BatchNorm, then by scene statistics."""
    from training.configs import preset

    cfg = preset("tiny")
    cfg.features.norm = request.param
    return cfg


@pytest.fixture(scope="session")
def data64(tmp_path_factory):
    """A 64 px synthetic dataset (3 train, 2 val scenes): the ``tiny`` preset's resolution."""
    from training.data.generate import main as generate

    out = tmp_path_factory.mktemp("data64")
    generate(["--out", str(out), "--train", "3", "--val", "2", "--val-seen-motions", "0", "--res", "64",
              "--workers", "1"])
    return out


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
