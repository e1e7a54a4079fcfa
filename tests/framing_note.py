"""The rig file's framing note, as the tests spot it: loading a rig whose pair shows a person standing at the working
volume's centre under ``PERSON_IN_VIEW_NOTE_SHARE`` of their height notes it at INFO
(``ghnerf_runtime.rig_file.person_partly_in_view_note``), and the tools show it on stderr. One marker for every test
that counts the note or leaves it out of what it reads."""
from __future__ import annotations

import logging

#: what the note says and no other message does: the constant it names (the framing warning names
#: MIN_PERSON_IN_VIEW_SHARE, which does not hold these words)
FRAMING_NOTE_WORDS = "PERSON_IN_VIEW_NOTE_SHARE"


def framing_notes(text: str) -> list[str]:
    """The lines of ``text`` (a tool's stderr or stdout) that are the framing note."""
    return [line for line in text.splitlines() if FRAMING_NOTE_WORDS in line]


def but_the_framing_note(text: str) -> str:
    """``text`` without its framing note's lines: what a test of a tool's other messages reads."""
    return "".join(line for line in text.splitlines(keepends=True) if FRAMING_NOTE_WORDS not in line)


def logged_framing_notes(records: list[logging.LogRecord]) -> list[logging.LogRecord]:
    """The framing notes among ``records`` (``caplog.records``)."""
    return [r for r in records if FRAMING_NOTE_WORDS in r.getMessage()]
