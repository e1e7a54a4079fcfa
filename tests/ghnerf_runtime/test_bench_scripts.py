"""The benchmark scripts time the estimator on frames in RAM, as a driver delivers them.

The bench's sequences come from a cache of ``.npy`` files opened as memory maps. A view of the map
handed to ``Estimator.estimate`` is read inside the timed call: the page faults (disk reads when the
page cache is cold) land in the pair's wall time and its ``preprocess`` stage, of whichever row or
method touches the pages first. The scripts copy each pair out first, as ``ghnerf-bench runtime`` does.
"""
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def _mapped_sequence(tmp_path: Path, frames: int = 3):
    """A sequence whose images are a memory map of a ``.npy`` file, as ``load_sequences`` reads the cache."""
    from ghnerf_runtime.cli.simdata import Sequence

    images = np.lib.format.open_memmap(tmp_path / "images.npy", mode="w+", dtype=np.uint8,
                                       shape=(frames, 2, 4, 6, 3))
    images[:] = 7
    images.flush()
    images = np.load(tmp_path / "images.npy", mmap_mode="r")
    return Sequence(None, images, np.zeros((frames, 25, 3)), np.zeros((frames, 2, 25, 2)),
                    np.ones((frames, 2, 25), bool), {"fps": 30.0})


class _FakeEstimator:
    """Records the frames each ``estimate`` is handed."""

    received: list = []

    def __init__(self, session, rig, config):
        self.config = config
        self.tracker = SimpleNamespace(track=None)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass

    def estimate(self, images, **kwargs):
        _FakeEstimator.received.extend(images)
        return SimpleNamespace(joints_3d=np.zeros((25, 3)), missing=np.zeros(25, bool), confidence=np.ones(25),
                               tracked=True, novel_view=None,
                               timing_ms={"total": 1.0, "joints_3d": 0.1, "render_heat": 0.1})


def _assert_in_ram(seq) -> None:
    assert _FakeEstimator.received
    assert not any(np.shares_memory(image, seq.images) for image in _FakeEstimator.received)


def test_compare_3d_methods_hands_the_estimator_frames_in_ram(tmp_path, monkeypatch):
    from benchmarks import compare_3d_methods
    from ghnerf_runtime.config import Joints3DConfig

    seq = _mapped_sequence(tmp_path)
    monkeypatch.setattr(compare_3d_methods, "Estimator", _FakeEstimator)
    monkeypatch.setattr(_FakeEstimator, "received", [])
    compare_3d_methods.run_method(None, [seq], Joints3DConfig(), None)
    _assert_in_ram(seq)


def test_bench_runtime_regions_times_frames_in_ram(tmp_path, monkeypatch, capsys):
    from benchmarks import bench_runtime_regions

    seq = _mapped_sequence(tmp_path)
    monkeypatch.setattr(bench_runtime_regions, "Estimator", _FakeEstimator)
    monkeypatch.setattr(_FakeEstimator, "received", [])
    bench_runtime_regions.end_to_end(SimpleNamespace(has=lambda graph: True), [seq], warmup=0)
    _assert_in_ram(seq)


def test_measure_novel_overlap_times_frames_in_ram(tmp_path, monkeypatch, capsys):
    from benchmarks import measure_novel_overlap

    seq = _mapped_sequence(tmp_path)
    monkeypatch.setattr(measure_novel_overlap, "Estimator", _FakeEstimator)
    monkeypatch.setattr(measure_novel_overlap, "load_session", lambda cfg: None)
    monkeypatch.setattr(measure_novel_overlap, "load_sequences", lambda *a, **k: [seq])
    monkeypatch.setattr(_FakeEstimator, "received", [])
    assert measure_novel_overlap.main(["--precisions", "int8", "--warmup", "0"]) == 0
    _assert_in_ram(seq)


def test_the_runtime_vs_eval_psnr_counts_scenes_without_a_view():
    """Path C's mean used to skip the scenes where the estimator made no novel view (flattering it) and a NaN
    (empty mask) made a path's mean NaN; now both are left out by name and counted."""
    from benchmarks.bench_runtime_vs_eval import PSNR_CAP_DB, psnr_summary

    p = psnr_summary([18.0, None, 22.0, float("nan"), None])
    assert (p["mean"], p["median"]) == (20.0, 20.0)  # by hand: (18 + 22) / 2
    assert (p["scored"], p["no_view"], p["nonfinite"]) == (2, 2, 1)
    assert psnr_summary([float("inf"), 20.0])["mean"] == (PSNR_CAP_DB + 20.0) / 2  # capped as ghnerf-eval caps it
    none = psnr_summary([None])
    assert np.isnan(none["mean"]) and none["no_view"] == 1 and none["scored"] == 0
