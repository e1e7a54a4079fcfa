"""One status file, one daemon: a second ``ghnerf-daemon`` given the same ``health.status_file`` is refused.

Two daemons on one config (the service, and one started by hand on ``/etc/ghnerf/daemon.json`` to look at
something) replaced each other's report at every beat: ``cat /run/ghnerf/status.json`` read the service's
counters and the other's ``waiting`` (its rig busy in the service) in turn, and the second one's stop left its
``stopping`` there. Neither said a word of the other.

The claim is a Linux abstract unix socket whose name is made of the status file's folder (device and inode, so
the service's private ``/tmp`` is not a shell's ``/tmp``) and file name. The kernel frees it when its process
ends, however it ends (no stale lock file, no permissions: the service's user and root meet on it), and a
connection to it tells the holder's pid (``SO_PEERCRED``) for the message. Abstract names belong to the network
namespace, which the unit shares with the host (it sets no ``PrivateNetwork=``).

Standard library only.
"""
from __future__ import annotations

import errno
import hashlib
import os
import socket
import struct
from pathlib import Path
from typing import Optional

from firmware_host.errors import FirmwareHostError

__all__ = ["StatusFileTaken", "StatusFileClaim", "claim_name", "names_one_file"]

#: How long finding the holder's pid may take: it only words the message.
_ASK_TIMEOUT_S = 0.5


class StatusFileTaken(FirmwareHostError):
    """Another process holds the claim on ``path``; ``pid`` is that process's, when it could be learnt."""

    def __init__(self, path: str, pid: Optional[int]) -> None:
        who = "another ghnerf-daemon" + (f" (pid {pid})" if pid else "")
        super().__init__(f"{path} is written by {who}: two daemons would replace each other's report at every "
                         "beat; stop that one first (sudo systemctl stop ghnerf, if it is the service), or give this "
                         "one another health.status_file")
        self.path, self.pid = path, pid


def claim_name(path: str) -> Optional[bytes]:
    """The abstract socket name claiming ``path``; None when its folder is not there (the write will fail and
    say so: there is nothing to share)."""
    target = Path(path)
    try:
        folder = os.stat(target.parent)
    except OSError:
        return None
    digest = hashlib.sha256(os.fsencode(target.name)).hexdigest()[:24]
    return f"\0ghnerf-daemon-status:{folder.st_dev}:{folder.st_ino}:{digest}".encode()


def names_one_file(first: Optional[str], second: Optional[str]) -> bool:
    """Whether two status file paths name one file (the same claim): spelled alike, or through a link or ``..``
    to the same folder. A reload from one to the other keeps this daemon's claim: taken again, it was refused as
    another daemon's, naming this one's pid."""
    if first == second:
        return True
    name = claim_name(first) if first and second else None
    return name is not None and name == claim_name(second)


def _holder_pid(name: bytes) -> Optional[int]:
    """The pid of the process listening on ``name``, from a connection's peer credentials; None if not learnt."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.settimeout(_ASK_TIMEOUT_S)
        try:
            probe.connect(name)
            creds = probe.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
        except OSError:  # its backlog full, or it ended meanwhile
            return None
    pid, _uid, _gid = struct.unpack("3i", creds)
    return pid or None


class StatusFileClaim:
    """This process's claim on one status file, held until :meth:`release` (or the process ends)."""

    def __init__(self, path: str, sock: Optional[socket.socket]) -> None:
        self.path = path
        self._sock = sock

    @classmethod
    def take(cls, path: str) -> "StatusFileClaim":
        """Claim ``path``. A claim that cannot be made for another reason than a holder (its folder is missing,
        no unix sockets) holds nothing and refuses nothing.

        :raises StatusFileTaken: another process holds it.
        """
        name = claim_name(path)
        if name is None:
            return cls(path, None)
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.bind(name)
            sock.listen(8)  # a second daemon's connection asks for the pid; closed by let_askers_go
            sock.setblocking(False)
        except OSError as e:
            sock.close()
            if e.errno == errno.EADDRINUSE:
                raise StatusFileTaken(path, _holder_pid(name)) from None
            return cls(path, None)
        return cls(path, sock)

    def let_askers_go(self) -> None:
        """Close the connections other daemons made to learn this one's pid (:func:`_holder_pid`), without
        waiting. Left queued, the listen backlog filled after nine refused starts, and every later one was told
        of "another ghnerf-daemon" without its pid. The daemon calls it at each status write."""
        sock = self._sock
        while sock is not None:
            try:
                asker, _ = sock.accept()
            except OSError:  # none waiting (BlockingIOError), or released meanwhile
                return
            asker.close()

    def release(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()
