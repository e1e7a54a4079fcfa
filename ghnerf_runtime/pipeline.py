"""``NovelViewPipeline``: a pair's novel view finished while the next pair is estimated.

With a novel view, the end of a pair is the view's last steps: waiting for its rendering, the body proxy's
painter, blend and matte, the overlay (:meth:`Estimator.estimate_then_view`'s second step). They run on one
core, mostly in numpy, while the next pair's crops and encoder graph could use the other. The pipeline runs
that second step of pair N in a thread of its own while pair N+1's first step runs in the caller's thread.

* The results are those of :meth:`Estimator.estimate`, number for number: the second step reads only its own
  pair's data, and everything the next pair reads (the track, the smoothing) was settled in the first step.
* One pair at most is in flight: each result comes out of the next call (or :meth:`flush`), so a pair's
  joints and view arrive one pair later than :meth:`Estimator.estimate` would give them, for more pairs per
  second (measured in docs/runtime.md, "The novel view alongside the keypoints").

numpy only; the estimator is passed in.
"""
from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, Sequence

import numpy as np

from ghnerf_runtime.novel_view import NovelViewRequest

__all__ = ["NovelViewPipeline"]


class NovelViewPipeline:
    """Pairs through an :class:`~ghnerf_runtime.estimator.Estimator`, each novel view finished beside the next
    pair's estimate.

    Args:
        estimator: the estimator (not closed by the pipeline; one pipeline per estimator at a time).

    Use::

        with NovelViewPipeline(est) as pipe:
            for pair in pairs:
                for result in pipe.submit(pair, novel_view=request, timestamp_s=t):
                    show(result)
            for result in pipe.flush():
                show(result)
    """

    def __init__(self, estimator: Any) -> None:
        self.estimator = estimator
        self._finisher = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ghnerf-novel-finish")
        self._pending: Future | None = None

    def submit(self, images: Sequence[np.ndarray], *, sequence: int | None = None,
               novel_view: NovelViewRequest | None = None, timestamp_s: float | None = None) -> list:
        """Estimate one pair (arguments as :meth:`Estimator.estimate`'s) and return the results finished
        meanwhile, oldest first: the previous pair's once its view is done, and this pair's too when it has no
        view to finish (none requested, a pair whose frames failed the check, or one that found nobody).

        Raises:
            what :meth:`Estimator.estimate` raises, for this pair or (its view) for the previous one; the
            pair whose view is being finished stays in flight either way, for the next call.
        """
        result, finish = self.estimator.estimate_then_view(images, sequence=sequence, novel_view=novel_view,
                                                           timestamp_s=timestamp_s)
        if finish is None:
            now: Future = Future()
            now.set_result(result)
        else:
            now = self._finisher.submit(finish)  # after the previous pair's, in the one thread
        previous, self._pending = self._pending, now  # this pair is not lost to an error of the previous one
        done = [] if previous is None else [previous.result()]
        if finish is None:
            done.append(result)
            self._pending = None
        return done

    def flush(self) -> list:
        """The result still in flight (its view finished), if any: ``[]`` or one result."""
        previous, self._pending = self._pending, None
        return [] if previous is None else [previous.result()]

    def close(self) -> None:
        """Wait for the pair in flight (its result is dropped) and stop the thread."""
        if self._pending is not None:
            self._pending.exception()
            self._pending = None
        self._finisher.shutdown(wait=True)

    def __enter__(self) -> "NovelViewPipeline":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
