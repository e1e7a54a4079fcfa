"""The error that ended a tool's run, said in place of a Ctrl-C or SIGTERM landing as it leaves: one helper for
``ghnerf-demo`` and ``ghcal capture``.

A run that fails (a camera gone, a sink's link) closes its rig and take on the error's way out, then says the
take's failure if it had one (:mod:`ghnerf_runtime.cli.recorded_take`). A stop landing there (a second Ctrl-C
pressed while the cameras close, ``timeout``'s SIGTERM as the take's failure is said) was raised in the error's
place: "stopped", 130 or 143, the error's words lost, and a script read "the user ended a run that worked". The run
had failed before the stop came: the error is said, exit 2. The run notes its error with :meth:`ErrorLeaving.held`
as it leaves the reading, which also holds stops until the run's close is done; :func:`status_keeping_the_error`
raises that error where a stop escapes the run after it.
"""
from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass

from ghnerf_runtime.cli.sigterm import stop_signals_deferred


@dataclass
class ErrorLeaving:
    """The error on its way out of one run; None while the run has none."""

    error: Exception | None = None

    def held(self, error: Exception, stops: contextlib.ExitStack) -> None:
        """``error`` noted as the run's, and Ctrl-C and SIGTERM held (noted, dropped) in ``stops`` from now on: the
        run leaves ``stops`` once its rig and take are closed, which a stop landing before the close skipped."""
        self.error = error  # first: a stop landing as the holding begins is then still said as this error
        stops.enter_context(stop_signals_deferred(then_raise=False))


def status_keeping_the_error(run: Callable[[ErrorLeaving], int]) -> int:
    """``run(leaving)``'s exit status; an error it noted in ``leaving`` is raised (the tool says it, exit 2) also
    where a Ctrl-C or SIGTERM took its place on the way out, or a failed take's status 2 came back in its place."""
    leaving = ErrorLeaving()
    try:
        status = run(leaving)
    except KeyboardInterrupt:
        if leaving.error is None:  # a stop of a run that had not failed: the tool says it (130, 143)
            raise
    else:
        if leaving.error is None:
            return status
    raise leaving.error
