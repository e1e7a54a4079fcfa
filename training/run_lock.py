"""A run folder's ``train.pid``: which live process holds it, if any (torch-free: the pipeline reads it too).

The trainer and the human-encoder pretraining write it when they start and remove it on the way out; a
``kill -9`` or a power cut leaves it behind. Such a stale file names a number the system may since have given
to another process, which is alive: the number alone then read as "in use" and refused the folder until the
file was deleted by hand. So the holder records, on a second line, who it is: its start time since boot (in
clock ticks) and the boot's id, ``start=<ticks>@<boot id>`` (Linux ``/proc``). A live process of that number
with another start or boot is not the holder: the lock is stale. Where ``/proc`` cannot be read (another
system), or for a file written before the record existed, the number alone decides, as before.

The first line stays the number alone; the record is one word that is not a number (a ``kill $(cat train.pid)``
still stops the holder and no other process).

A dataset folder's ``dataset.lock`` (``training.data.cache.writer_lock``) records its holder the same way, on the
second line of its file, and :func:`is_recorded_process` judges it.
"""
from __future__ import annotations

import os
from pathlib import Path


def process_identity(pid: int) -> str | None:
    """``start=<ticks since boot>@<boot id>`` of process ``pid``: what no later process of that number shares.
    None where ``/proc`` does not say (not Linux, no such process)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        boot = Path("/proc/sys/kernel/random/boot_id").read_text().strip()
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces: count the fields after its last ")"
    after_name = stat[stat.rfind(")") + 1:].split()
    if len(after_name) < 20:
        return None
    return f"start={after_name[19]}@{boot}"  # field 22, starttime


def lock_text(pid: int) -> str:
    """What a holder writes into ``train.pid``: its number, then its identity where it has one."""
    identity = process_identity(pid)
    return f"{pid}\n{identity}\n" if identity else f"{pid}\n"


def lock_holder(path: Path) -> int | None:
    """The live process that holds the lock file ``path``; None where there is no file, it does not read, or it is
    stale (its process is gone, or the number now belongs to another process: see the module's docstring)."""
    try:
        words = path.read_text().split()
        pid = int(words[0])
        os.kill(pid, 0)
    except (OSError, ValueError, IndexError):  # PermissionError too: another user's process, not a run of ours
        return None
    recorded = words[1] if len(words) > 1 else None
    if not is_recorded_process(pid, recorded):
        return None  # the number was given to another process since the holder wrote it
    return pid


def is_recorded_process(pid: int, recorded: str | None) -> bool:
    """Whether the live process ``pid`` is the one whose :func:`process_identity` a holder recorded as
    ``recorded``. With no record (an older file) or no ``/proc`` to compare against, the number alone decides:
    True."""
    if recorded is None:
        return True
    now = process_identity(pid)
    return now is None or now == recorded
