"""A daemon's reopens of its rig, for the tests of its rig warnings: one new source per open, all handed one
``log_rig_warnings_once`` set (drivers.base.RigSource)."""
from __future__ import annotations

from collections.abc import Callable

from drivers import RigSource


def open_sources_sharing_a_logged_set(make_source: Callable[[int], RigSource], opens: int) -> set[str]:
    """Create ``opens`` sources with ``make_source(k)``, each handed the same logged set, and open and close each,
    as a daemon does at each reopen after a lost camera; returns the set (the warnings logged)."""
    logged: set[str] = set()
    for k in range(opens):
        source = make_source(k)
        source.log_rig_warnings_once(logged)
        with source.open():
            pass
    return logged
