"""A Ctrl-C or SIGTERM landing at an exact point of a tool's run, for the stop tests of ``ghnerf-demo`` and
``ghcal capture``: the signal is sent from inside a patched function, never by timing."""
from __future__ import annotations

import os

import pytest


def stop_around(monkeypatch: pytest.MonkeyPatch, owner: object, name: str, signum: int, *, after: bool = False,
                on_call: int | None = None) -> None:
    """``owner.name`` sends ``signum`` to this process just before it runs (or just after, ``after=True``), on every
    call or on the ``on_call``-th only. The handler runs inside ``os.kill``, in the main thread, at once."""
    real = getattr(owner, name)
    calls = []

    def stopped(*args, **kwargs):
        calls.append(1)
        here = on_call is None or len(calls) == on_call
        if here and not after:
            os.kill(os.getpid(), signum)
        result = real(*args, **kwargs)
        if here and after:
            os.kill(os.getpid(), signum)
        return result

    monkeypatch.setattr(owner, name, stopped)
