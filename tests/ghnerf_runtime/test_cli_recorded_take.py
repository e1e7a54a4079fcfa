"""``RecordedTake`` and ``status_saying_a_failed_take``: the ``record+`` take's failure as its source closed, said
once by ``ghnerf-demo`` and ``ghcal capture`` wherever a stop lands after the close (the tools' own tests land real
signals there: tests/firmware_host/test_demo.py, tests/calibration/test_ghcal_user_flows.py)."""
from __future__ import annotations

import pytest

from ghnerf_runtime.cli.recorded_take import RecordedTake, status_saying_a_failed_take
from ghnerf_runtime.cli.sigterm import Terminated


class _ClosedTake:
    """Stands for a closed record+ source: ``failure`` is what its unreported_failure() says."""

    def __init__(self, failure: str | None) -> None:
        self.failure = failure

    def unreported_failure(self) -> str | None:
        return self.failure


def _stopped_in_the_summary(take: RecordedTake, stop: KeyboardInterrupt, *, summary_says_the_take: bool):
    def run() -> int:
        if summary_says_the_take:
            take.say_failure()
        raise stop
    return run


@pytest.mark.parametrize("stop", [KeyboardInterrupt(), Terminated("SIGTERM")])
def test_a_stop_escaping_the_run_of_a_failed_take_says_the_take_exit_2(capsys, stop):
    take = RecordedTake(_ClosedTake("recording to t failed as it closed: disk full"), "tool")
    assert status_saying_a_failed_take(_stopped_in_the_summary(take, stop, summary_says_the_take=False), take) == 2
    assert capsys.readouterr().err == "tool: error: recording to t failed as it closed: disk full\n"


def test_a_take_the_summary_said_is_not_said_again_when_a_stop_lands_after_it(capsys):
    take = RecordedTake(_ClosedTake("recording to t failed as it closed: disk full"), "tool")
    run = _stopped_in_the_summary(take, KeyboardInterrupt(), summary_says_the_take=True)
    assert status_saying_a_failed_take(run, take) == 2
    assert capsys.readouterr().err.count("failed as it closed") == 1


@pytest.mark.parametrize("source", [_ClosedTake(None), object()], ids=["whole take", "no take"])
def test_a_stop_escaping_the_run_of_a_whole_take_is_raised_on(capsys, source):
    take = RecordedTake(source, "tool")
    with pytest.raises(Terminated):
        status_saying_a_failed_take(_stopped_in_the_summary(take, Terminated("SIGTERM"), summary_says_the_take=False),
                                    take)
    assert capsys.readouterr().err == ""


def test_the_run_s_own_status_is_returned():
    take = RecordedTake(_ClosedTake("recording to t failed as it closed: disk full"), "tool")
    assert status_saying_a_failed_take(lambda: 7, take) == 7


@pytest.mark.parametrize("failure", ["recording to t failed as it closed: disk full", None], ids=["failed", "whole"])
def test_an_error_escaping_the_run_is_raised_on_once_a_failed_take_is_said(capsys, failure):
    """The run closed the take on the error's way out: its failure went unsaid (ghnerf-demo; the caller says the
    error alone, exit 2); it is said first now, and the error raised on for the caller to say."""
    take = RecordedTake(_ClosedTake(failure), "tool")

    def failing_run() -> int:
        raise OSError("the sink's link failed")

    with pytest.raises(OSError, match="the sink's link failed"):
        status_saying_a_failed_take(failing_run, take)
    assert capsys.readouterr().err == ("" if failure is None else f"tool: error: {failure}\n")
