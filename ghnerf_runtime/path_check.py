"""Paths no file can have, refused where the user gives them: one line naming the option or key, not a traceback.

A path holding a NUL byte makes ``os.path.realpath`` and ``open`` raise ``ValueError`` (not ``OSError``, so a
tool's ``except OSError`` lets it through); a name past 255 bytes or a path past 4095 raises ``ENAMETOOLONG`` from
wherever it is first touched; a path that is not UTF-8 (bytes Python keeps as surrogates in ``sys.argv``) crashes
OpenCV outright (a segmentation fault in ``cv2.imread``, ``cv2.VideoCapture``, ``cv2.haveImageWriter``) and cannot
be written into a JSON report or a URL; and a leading ``~`` that no shell expanded (a config file, a quoted
argument, a URL) names a folder called ``~`` in the current one. :func:`path_problem` says which, before any of it
is touched; :func:`shown` writes the value so that odd bytes can be read back (``repr``).
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["NAME_MAX", "NOT_UTF8", "PATH_MAX", "is_utf8", "name_max_at", "path_problem", "shown", "user_path",
           "user_path_as_path"]

#: Linux's limits (``<linux/limits.h>``), in bytes: a name (one component) and a whole path with its NUL. A name
#: is refused past ``NAME_MAX`` only where its file system allows no longer one (:func:`name_max_at`).
NAME_MAX = 255
PATH_MAX = 4096
#: What :func:`path_problem` says of a path that is not UTF-8 (URL parsers say it of a %XX escape that decodes to one).
NOT_UTF8 = "is not UTF-8 (give the path in UTF-8, or rename the file)"


def is_utf8(value: str) -> bool:
    """Whether ``value`` encodes in UTF-8: not a name whose bytes are not UTF-8, which Python keeps as surrogates
    (``sys.argv``, a folder listing) and OpenCV crashes on."""
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def path_problem(value: str) -> str | None:
    """Why ``value`` cannot name a file here (None: it can, whether or not one exists).

    >>> path_problem("models/ghnerf")
    >>> path_problem("a\\x00b")
    'holds a NUL byte'
    """
    if "\x00" in value:
        return "holds a NUL byte"
    if not is_utf8(value):
        return NOT_UTF8
    encoded = os.fsencode(value)
    if len(encoded) >= PATH_MAX:
        return f"is {len(encoded)} bytes long; a path has at most {PATH_MAX - 1}"
    longest = max(encoded.split(b"/"), key=len)
    if len(longest) > NAME_MAX:
        limit = name_max_at(value)
        if len(longest) > limit:
            return f"has a name of {len(longest)} bytes; a file or folder name has at most {limit}"
    if _unexpanded_home(value):
        return "starts with '~', which is not expanded here: write the home folder in full (or ./~ for a folder " \
               "named ~)"
    return None


def _unexpanded_home(value: str) -> bool:
    """Whether ``value`` starts with a home folder a shell would have expanded: ``~``, ``~/``, or ``~USER`` of a
    user this system has (``~pi/models`` on a Raspberry Pi); ``~take/x`` with no user ``take`` is a name."""
    return value == "~" or value.startswith("~/") or (value.startswith("~") and os.path.expanduser(value) != value)


def name_max_at(value: str) -> int:
    """The longest name in bytes the file system holding ``value`` (its deepest folder that exists) takes, at
    least :data:`NAME_MAX`: 255 is ext4's, but a USB stick's FAT or exFAT and an NTFS or SMB share count 255
    UTF-16 units (``pathconf`` says 1530 bytes there), so 100 CJK characters (300 bytes) name a file there."""
    folder = os.path.dirname(value) or "."
    while not os.path.isdir(folder):
        parent = os.path.dirname(folder) or "."
        if parent == folder:
            return NAME_MAX
        folder = parent
    try:
        return max(NAME_MAX, os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):  # (no pathconf here, or no answer: Linux's figure)
        return NAME_MAX


def shown(value: str) -> str:
    """``value`` as a message shows it: as written, or ``repr`` when it holds bytes a terminal would hide or
    mangle (a NUL, a control character, a byte that is not UTF-8)."""
    if value.isprintable() and is_utf8(value):
        return value
    return repr(value)


def user_path(value: str) -> str:
    """An argparse ``type=`` for an option naming a file or folder: a value :func:`path_problem` refuses ends the
    tool as argparse ends it (``argument --out: ...``, exit status 2). An empty value is refused too: it names no
    file, yet tools read it as the option left out (``ghnerf-run --novel-view ''`` rendered nothing and exited 0,
    ``--config ''`` ran on the defaults) or as the current folder (``ghnerf-demo --out ''`` wrote there), as a
    ``"$UNSET"`` in a script gives it."""
    if value == "":
        raise argparse.ArgumentTypeError("is empty: give a path, or leave the option out")
    problem = path_problem(value)
    if problem is not None:
        raise argparse.ArgumentTypeError(f"{shown(value)}: {problem}")
    return value


def user_path_as_path(value: str) -> Path:
    """:func:`user_path`, as a :class:`pathlib.Path` (for an option read as one)."""
    return Path(user_path(value))
