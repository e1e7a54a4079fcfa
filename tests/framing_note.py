"""The rig file's framing notes, as the tests spot them: loading a rig whose pair shows a person standing at the
working volume's centre under ``PERSON_IN_VIEW_NOTE_SHARE`` of their height notes it at INFO
(``ghnerf_runtime.rig_file.person_partly_in_view_note``), and since session 69 one cut at the volume's near or far
edge too (``rig_file.volume_edge_notes``); the tools show them on stderr. One marker for every test that counts the
notes or leaves them out of what it reads."""
from __future__ import annotations

import logging

#: what the centre's note says and no other message does: the constant it names (the framing warning names
#: MIN_PERSON_IN_VIEW_SHARE, which does not hold these words)
FRAMING_NOTE_WORDS = "PERSON_IN_VIEW_NOTE_SHARE"
#: what an edge's note says and no other message does
EDGE_NOTE_WORDS = ("standing at the working volume's near edge", "standing at the working volume's far edge")


def _is_centre_note(message: str) -> bool:
    return FRAMING_NOTE_WORDS in message


def _is_edge_note(message: str) -> bool:
    return any(words in message for words in EDGE_NOTE_WORDS)


def framing_notes(text: str) -> list[str]:
    """The lines of ``text`` (a tool's stderr or stdout) that are the centre's framing note."""
    return [line for line in text.splitlines() if _is_centre_note(line)]


def edge_notes(text: str) -> list[str]:
    """The lines of ``text`` that are a note of the volume's near or far edge."""
    return [line for line in text.splitlines() if _is_edge_note(line)]


def but_the_framing_notes(text: str) -> str:
    """``text`` without its framing notes' lines (the centre's and the edges'): what a test of a tool's other messages
    reads."""
    return "".join(line for line in text.splitlines(keepends=True)
                   if not (_is_centre_note(line) or _is_edge_note(line)))


def logged_framing_notes(records: list[logging.LogRecord]) -> list[logging.LogRecord]:
    """The centre's framing notes among ``records`` (``caplog.records``)."""
    return [r for r in records if _is_centre_note(r.getMessage())]


def logged_edge_notes(records: list[logging.LogRecord]) -> list[logging.LogRecord]:
    """The edges' framing notes among ``records``."""
    return [r for r in records if _is_edge_note(r.getMessage())]
