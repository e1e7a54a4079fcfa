"""A daemon's reopens of its rig, for the tests of its rig warnings: one new source per open, all handed one
``log_rig_warnings_once`` set (drivers.base.RigSource)."""
from __future__ import annotations

import logging
from collections.abc import Callable

from drivers import RigSource, create_rig_source, open_rig

#: What the narrow-pair warning says (ghnerf_runtime.rig_file): the tests' narrow rigs are told by it
PAIR_ANGLE_WORDS = "MIN_PAIR_ANGLE_DEG"


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


def warnings_shared_and_alone(caplog, url: str, words: str = PAIR_ANGLE_WORDS, opens: int = 3,
                               level: int = logging.WARNING) -> tuple[list[str], list[str]]:
    """The warnings saying ``words`` logged (with any already in ``caplog``) over ``opens`` sources of ``url``
    sharing one logged set, as a daemon's reopens, then by one :func:`open_rig` of it alone, as a one-shot tool's;
    ``level`` ``logging.INFO`` counts the rig's notes too (``rig_file.rig_notes``)."""
    with caplog.at_level(level):
        open_sources_sharing_a_logged_set(lambda _: create_rig_source(url), opens)
        shared = [r.getMessage() for r in caplog.records if words in r.getMessage()]
        caplog.clear()
        with open_rig(url):
            pass
        alone = [r.getMessage() for r in caplog.records if words in r.getMessage()]
    return shared, alone
