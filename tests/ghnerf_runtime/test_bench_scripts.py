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
    from benchmarks.bench_runtime_vs_eval import psnr_summary
    from ghnerf_runtime.metrics import PSNR_CAP_DB

    p = psnr_summary([18.0, None, 22.0, float("nan"), None])
    assert (p["mean"], p["median"]) == (20.0, 20.0)  # by hand: (18 + 22) / 2
    assert (p["scored"], p["no_view"], p["nonfinite"]) == (2, 2, 1)
    assert psnr_summary([float("inf"), 20.0])["mean"] == (PSNR_CAP_DB + 20.0) / 2  # capped as ghnerf-eval caps it
    none = psnr_summary([None])
    assert np.isnan(none["mean"]) and none["no_view"] == 1 and none["scored"] == 0


class _LanedSession:
    """A session with the lanes' doors (``run_on_lane``, ``on_lanes``, ``run_both``), each answering its own
    ``acc`` so a test can tell which door a recorded run came through."""

    contract = SimpleNamespace(graph=lambda graph: SimpleNamespace(input_names=("ray_uv",)))

    def run(self, graph, feeds):
        return {"acc": np.full((1, 2), 0.1, np.float32)}

    def run_on_lane(self, graph, feeds):
        return {"acc": np.full((1, 2), 0.2, np.float32)}

    def on_lanes(self):
        from ghnerf_runtime.session import LaneRunner

        return LaneRunner(self)

    def run_both(self, graph, first, second):
        return {"acc": np.full((1, 2), 0.3, np.float32)}, {"acc": np.full((1, 2), 0.4, np.float32)}


def _ray_feeds(x: float) -> dict:
    return {"ray_uv": np.full((1, 2, 2), x, np.float32)}


def test_the_session_taps_record_the_runs_on_the_lanes():
    """A tracked pair's novel view renders through ``session.on_lanes()`` (and the flip test's second run through
    ``run_on_lane`` / ``run_both``): the taps overrode ``run`` alone and let those pass unseen, so
    measure_novel_quality/measure_novel_rays lost every tracked pair's opacity and bench_graph_threads said
    ``render_rgb`` was "not run by the estimator" (the shipped model, --sequences 1 --pairs 4)."""
    from benchmarks.bench_graph_threads import _FeedTap
    from benchmarks.bench_runtime_common import RenderTap

    render = RenderTap(_LanedSession())
    render.run("render_rgb", _ray_feeds(1))
    render.on_lanes().run("render_rgb", _ray_feeds(2))  # the estimator's worker, novel view on the lanes
    render.run_on_lane("render", _ray_feeds(3))
    render.run_both("render_rgb", _ray_feeds(4), _ray_feeds(5))
    render.run_on_lane("human", _ray_feeds(6))  # not a colour render: not kept
    assert [(float(uv[0, 0]), float(acc[0])) for uv, acc in render.runs] == [
        (1, np.float32(0.1)), (2, np.float32(0.2)), (3, np.float32(0.2)), (4, np.float32(0.3)),
        (5, np.float32(0.4))]

    feeds: dict = {}
    tap = _FeedTap(_LanedSession(), feeds)
    tap.on_lanes().run("volume", _ray_feeds(1))
    tap.run_both("human", _ray_feeds(2), _ray_feeds(3))
    tap.run("render_heat", _ray_feeds(4))
    assert {g: [float(f["ray_uv"][0, 0, 0]) for f in calls] for g, calls in feeds.items()} == {
        "volume": [1.0], "human": [2.0, 3.0], "render_heat": [4.0]}
