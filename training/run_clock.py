"""Wall time of a training run that may be stopped and resumed, one segment per invocation.

A resumed run's ``summary.json`` used to carry only its last invocation's wall time and threads, so a
24000-step pretraining resumed at 12000 steps reported half its time. The checkpoint carries the
finished segments; the summary reports their sum and each one.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field


@dataclass
class RunClock:
    """Segments before this invocation (from the checkpoint) plus the one running now."""

    first_step: int
    threads: int
    before: list[dict] = field(default_factory=list)
    t0: float = field(default_factory=time.monotonic)

    @classmethod
    def resumed(cls, checkpoint: dict | None, step: int, threads: int) -> "RunClock":
        """``checkpoint``'s segments (none for a fresh run or a checkpoint made before they were kept)."""
        return cls(step, threads, list((checkpoint or {}).get("segments", [])))

    def elapsed(self) -> float:
        """Seconds of this invocation."""
        return time.monotonic() - self.t0

    def segments(self, step: int) -> list[dict]:
        """Every segment so far, this one up to ``step``: what a checkpoint at ``step`` stores."""
        now = {"steps": step - self.first_step, "wall_s": round(self.elapsed(), 1), "threads": self.threads}
        return [*self.before, now]

    def summary(self, step: int) -> dict:
        """``wall_s`` summed over the segments, and the segments (when there was more than one)."""
        seg = self.segments(step)
        out = {"wall_s": round(sum(s["wall_s"] for s in seg), 1)}
        if len(seg) > 1:
            out["segments"] = seg
        return out
