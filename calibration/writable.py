"""Can ``ghcal`` write where it was told to? Asked before the work, not found out after it.

A solve detects the board in every image and solves for seconds (minutes on a large capture) before it
writes; a capture opens the cameras first. An output it cannot write was reported only then.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["unwritable_reason", "existing_ancestor"]


def unwritable_reason(folder: Path) -> str | None:
    """Why no file can be made in ``folder`` (None: one can), found by making and removing one.

    Tried rather than read from the permission bits: ``os.access`` says yes to root everywhere,
    also on sysfs and similar mounts that refuse the file, and says nothing of a full inode table.
    """
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".ghcal-write-test-", suffix=".tmp")
    except OSError as e:
        return e.strerror or str(e)
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:  # made but not removable: writable enough, and nothing to do about the leftover
        pass
    return None


def existing_ancestor(path: Path) -> Path:
    """``path`` itself if it exists, else its nearest existing parent (where ``mkdir -p`` starts)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path
