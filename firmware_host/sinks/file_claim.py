"""One writer per file: a ``file://`` sink holds an exclusive ``flock`` on the regular file it appends to.

Two daemons on a rig that no camera makes exclusive (``sim://``, ``replay://``), each with its own status file and
the same ``file://`` sink, both appended, their HELLOs, STATUS lines and frames interleaved in one file that no
reader could take for one stream. The claim is an advisory ``flock`` on the open descriptor: it belongs to that
open file (two sinks in one process conflict too), the kernel drops it when the descriptor is closed or its process
ends, however it ends (no stale lock file), and it stays with the file's inode: logrotate's ``copytruncate`` keeps
it, and a file renamed away keeps it until the sink sees the rename and opens the new file at the path, which it
then claims.

Who holds it is read from ``/proc/locks`` (flock locks carry the pid that took them), for the message only.

"""
from __future__ import annotations

import errno
import fcntl
import os
from typing import Optional

from firmware_host.errors import FirmwareHostError
from ghnerf_runtime.path_check import shown

__all__ = ["FileTaken", "claim_file", "holder_pid", "holder_text"]

#: ``flock`` errors that mean the file system keeps no such locks (some FUSE and network ones): no claim is made.
_NO_LOCKS = (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL)


class FileTaken(FirmwareHostError):
    """Another open file (another sink, in this process or another) holds the claim on ``path``."""

    def __init__(self, path: str, pid: Optional[int]) -> None:
        super().__init__(f"{shown(path)} is being written by {holder_text(pid)}: two writers would interleave their "
                         "lines in it; stop that one, or give this sink another file (retried until that one lets go)")
        self.path, self.pid = path, pid


def claim_file(fd: int, path: str) -> bool:
    """Take the exclusive claim on the regular file open as ``fd`` (``path`` names it, for the message), held
    until ``fd`` is closed. False when the file system keeps no locks: then nothing is claimed or refused.

    :raises FileTaken: another open file holds it.
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        st = os.fstat(fd)
        raise FileTaken(path, holder_pid(st.st_dev, st.st_ino)) from None
    except OSError as e:
        if e.errno in _NO_LOCKS:
            return False
        raise
    return True


def holder_pid(st_dev: int, st_ino: int) -> Optional[int]:
    """The pid that holds a ``flock`` on the file (``st_dev``, ``st_ino``), from ``/proc/locks``; None if not
    learnt. Its device field is the file system's, which is not ``stat``'s on every one (a btrfs subvolume): where
    none matches, a holder of that inode number is taken if it has the file open (``/proc/PID/fd``)."""
    entries = _flock_entries(st_ino)
    device = f"{os.major(st_dev):02x}:{os.minor(st_dev):02x}"
    for pid, dev in entries:
        if dev == device:
            return pid
    for pid, _ in entries:
        if _has_open(pid, st_dev, st_ino):
            return pid
    return None


def _flock_entries(st_ino: int) -> list[tuple[int, str]]:
    """(pid, "MAJ:MIN") of the held FLOCK locks on an inode numbered ``st_ino``, as ``/proc/locks`` lists them."""
    try:
        with open("/proc/locks", encoding="ascii", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError:
        return []
    entries = []
    for line in lines:
        # "1: FLOCK  ADVISORY  WRITE 1234 08:01:5678 0 EOF"; a waiter's line has "->" after its number
        fields = line.split()
        if len(fields) < 6 or fields[1] != "FLOCK":
            continue
        dev, _, ino = fields[5].rpartition(":")
        if ino == str(st_ino) and fields[4].isdigit() and int(fields[4]) > 0:
            entries.append((int(fields[4]), dev))
    return entries


def _has_open(pid: int, st_dev: int, st_ino: int) -> bool:
    """Whether process ``pid`` has the file open (False where its descriptors cannot be read: another user's)."""
    folder = f"/proc/{pid}/fd"
    try:
        names = os.listdir(folder)
    except OSError:
        return False
    for name in names:
        try:
            st = os.stat(os.path.join(folder, name))
        except OSError:
            continue
        if (st.st_dev, st.st_ino) == (st_dev, st_ino):
            return True
    return False


def holder_text(pid: Optional[int]) -> str:
    """"pid 1234 (ghnerf-daemon)", "another sink of this process", or "another program" when not learnt."""
    if pid is None:
        return "another program"
    if pid == os.getpid():
        return f"another sink of this process (pid {pid})"
    try:
        with open(f"/proc/{pid}/comm", encoding="utf-8", errors="replace") as f:
            name = f.read().strip()
    except OSError:
        name = ""
    # any program sets its own name (prctl, /proc/self/comm): an ESC in it reached the log and STATUS line raw
    return f"pid {pid} ({shown(name)})" if name else f"pid {pid}"
