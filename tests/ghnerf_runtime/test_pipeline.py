"""NovelViewPipeline: order, one pair in flight, errors (a stand-in estimator; the shipped model's pictures
through the pipeline are compared with Estimator.estimate's in test_estimator_accuracy)."""
from __future__ import annotations

import threading

import pytest

from ghnerf_runtime.errors import FrameError, ModelRunError
from ghnerf_runtime.pipeline import NovelViewPipeline


class _Estimator:
    """``estimate_then_view`` of a stand-in: the pair's number as its result, ``("view", n)`` once finished; a
    pair numbered in ``no_view`` has no view, one in ``bad_view`` fails in its view, one in ``bad_pair`` at once."""

    def __init__(self, no_view=(), bad_view=(), bad_pair=()) -> None:
        self.no_view, self.bad_view, self.bad_pair = set(no_view), set(bad_view), set(bad_pair)
        self.started: list[int] = []
        self.finished_in: list[str] = []

    def estimate_then_view(self, images, *, sequence=None, novel_view=None, timestamp_s=None):
        if sequence in self.bad_pair:
            raise FrameError(f"pair {sequence}")
        self.started.append(sequence)
        if sequence in self.no_view or novel_view is None:
            return sequence, None

        def finish():
            self.finished_in.append(threading.current_thread().name)
            if sequence in self.bad_view:
                raise ModelRunError(f"view {sequence}")
            return ("view", sequence)

        return sequence, finish


def test_each_result_comes_out_of_the_next_call_in_order():
    est = _Estimator(no_view={2})
    with NovelViewPipeline(est) as pipe:
        out = [pipe.submit(None, sequence=i, novel_view="v") for i in range(5)]
        assert out == [[], [("view", 0)], [("view", 1), 2], [], [("view", 3)]]
        assert pipe.flush() == [("view", 4)] and pipe.flush() == []
    assert est.started == [0, 1, 2, 3, 4]
    assert len(est.finished_in) == 4  # the views, in the pipeline's own thread
    assert all(name.startswith("ghnerf-novel-finish") for name in est.finished_in)


def test_without_a_novel_view_a_pair_comes_out_at_once():
    with NovelViewPipeline(_Estimator()) as pipe:
        assert [pipe.submit(None, sequence=i) for i in range(3)] == [[0], [1], [2]]
        assert pipe.flush() == []


def test_an_error_loses_no_pair():
    """A view that fails raises from the next call, whose own pair stays in flight; a pair that fails at once
    raises at once and leaves the pair in flight where it was."""
    with NovelViewPipeline(_Estimator(bad_view={1}, bad_pair={3})) as pipe:
        assert pipe.submit(None, sequence=0, novel_view="v") == []
        assert pipe.submit(None, sequence=1, novel_view="v") == [("view", 0)]
        with pytest.raises(ModelRunError, match="view 1"):
            pipe.submit(None, sequence=2, novel_view="v")
        with pytest.raises(FrameError, match="pair 3"):
            pipe.submit(None, sequence=3, novel_view="v")
        assert pipe.submit(None, sequence=4, novel_view="v") == [("view", 2)]
        assert pipe.flush() == [("view", 4)]


def test_close_waits_for_the_pair_in_flight():
    est = _Estimator()
    pipe = NovelViewPipeline(est)
    pipe.submit(None, sequence=0, novel_view="v")
    pipe.close()
    assert est.finished_in and pipe.flush() == []
