"""A ``record+`` take's failure as its source closed, said once by the tool that closed it (``ghnerf-demo``,
``ghcal capture``), wherever a Ctrl-C or SIGTERM lands after the close.

The take's last write (a frame still queued, its last fsync) can fail in the source's close, where no read raises
it: the tool says it, exit 2, after its summary. A stop landing after the close (before the take's check, in the
summary) was raised past that check: ``stopped``, 130 or 143, of a take whose manifest says ``complete: false``.
:func:`status_saying_a_failed_take` runs the tool's reading and summary and says the take's failure, exit 2, where
such a stop escapes them; a whole take leaves the stop its own exit status. An error escaping them (a camera that
failed, the sink's link) is the tool's to say, exit 2: the take's failure is said before it, not left unsaid.
"""
from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass

from ghnerf_runtime.cli.sigterm import stop_signals_deferred


@dataclass
class RecordedTake:
    """The take of a tool's rig source, as the tool closes it: a ``record+`` source's (another source has none: it
    never fails), whether its write failed where no read raised it, said once as ``PROG: error: ...``."""

    source: object  # a drivers.RigSource: a record+ one has unreported_failure()
    prog: str
    said: bool = False

    def failure(self) -> str | None:
        """Why the take failed as it closed (its manifest says ``complete: false``); None: it did not, it is not
        closed yet, or a read raised it (the tool's error said it)."""
        return getattr(self.source, "unreported_failure", lambda: None)()

    def say_failure(self) -> bool:
        """The take's failure said on stderr, one line, unless it was already; whether the take failed (exit 2)."""
        failure = self.failure()
        if failure is not None and not self.said:
            # a stop landing between the line and its note would have it said twice; the tool ends 2 either way
            with stop_signals_deferred(then_raise=False):
                print(f"{self.prog}: error: {failure}", file=sys.stderr)
                self.said = True
        return failure is not None


def status_saying_a_failed_take(run: Callable[[], int], take: RecordedTake) -> int:
    """``run()``'s exit status; ``run`` reads ``take``'s source, closes it however it ends, then says its summary.

    A Ctrl-C or SIGTERM escaping ``run`` came after the close (``run``'s ``finally``): between the close and the
    take's check, or in the summary. It is raised on (the caller says it: 130, 143) unless the take failed, which is
    said instead, exit 2, as the summary would have. An error escaping ``run`` is raised on (the caller says it,
    exit 2) once the take's failure is said: ``run`` closed the take on the error's way out, and no summary came."""
    try:
        return run()
    except KeyboardInterrupt:
        if take.say_failure():
            return 2
        raise
    except Exception:
        take.say_failure()
        raise
