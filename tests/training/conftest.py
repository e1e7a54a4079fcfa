"""Shared fixtures of the training tests (tiny configs, a synthetic two-camera rig)."""
from __future__ import annotations

import builtins
import io
from pathlib import Path

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


class _DiskFullAt:
    """Writes to files whose name holds ``name`` (its temporary file's too) stop halfway with ENOSPC, as on a
    full disk: through ``open`` (Path.write_text, write_atomic) and through ``torch.save`` to a path, which
    writes the file from C++, not through ``open``."""

    def __init__(self, monkeypatch, folder: Path, name: str) -> None:
        import torch

        self.folder, self.name, self.real_open, self.real_save = folder, name, builtins.open, torch.save
        monkeypatch.setattr(builtins, "open", self.open)
        monkeypatch.setattr(io, "open", self.open)
        monkeypatch.setattr(torch, "save", self.save)

    def hit(self, file) -> bool:
        return isinstance(file, (str, Path)) and Path(file).parent == self.folder and self.name in Path(file).name

    def open(self, file, mode="r", *args, **kwargs):
        fh = self.real_open(file, mode, *args, **kwargs)
        if not (self.hit(file) and set(mode) & set("wax")):
            return fh

        class HalfThenFull:
            def write(self, data):
                fh.write(data[:len(data) // 2])
                fh.flush()
                raise OSError(28, "No space left on device")

            def __getattr__(self, attr):
                return getattr(fh, attr)

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                fh.close()

        return HalfThenFull()

    def save(self, obj, f, *args, **kwargs):
        if not self.hit(f):
            return self.real_save(obj, f, *args, **kwargs)
        buf = io.BytesIO()
        self.real_save(obj, buf, *args, **kwargs)
        with self.real_open(f, "wb") as fh:
            fh.write(buf.getvalue()[:buf.tell() // 2])
        raise OSError(28, "No space left on device")


@pytest.fixture
def disk_full_at(monkeypatch):
    """``disk_full_at(folder, name)``: from then on in the test, writes to ``folder``'s files named like ``name``
    stop halfway with ENOSPC (:class:`_DiskFullAt`)."""
    return lambda folder, name: _DiskFullAt(monkeypatch, Path(folder), name)


@pytest.fixture
def other_process():
    """A live process that is not this one: the number a stale lock (``train.pid``, ``dataset.lock``) may name now."""
    import subprocess

    proc = subprocess.Popen(["sleep", "60"])
    try:
        yield proc.pid
    finally:
        proc.kill()
        proc.wait()
