"""Bounded writes to a non-blocking file descriptor (a tty, a named pipe), shared by serial:// and file://.

A receiver that stops reading fills the kernel's buffer; a blocking ``write()`` would then hold the sink's
worker for as long as the receiver stays away (for ever, for a named pipe whose reader hangs). Here each
write waits for room with ``poll()`` (no CPU spent) at most ``timeout_s`` and returns what went out. (Until
session 72 ``select()``, which refuses a descriptor of 1024 or more with a ValueError: in a process with that many
open, every frame of a full port failed as a backend bug, a traceback in the journal per frame.)
"""
from __future__ import annotations

import math
import os
import select
import time


def write_within(fd: int, data: bytes, timeout_s: float) -> int:
    """Write ``data`` to the non-blocking ``fd`` as far as it takes within ``timeout_s``; returns the bytes
    written (``len(data)`` when all went out). A regular file ignores O_NONBLOCK: its write returns whole.

    :raises OSError: the write failed (EIO after an unplug, EPIPE when a pipe's reader went away).
    """
    view = memoryview(data)
    done = 0
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            done += os.write(fd, view[done:])
        except BlockingIOError:
            pass  # full: wait for room below
        remaining = deadline - time.monotonic()
        if done == len(data) or remaining <= 0:
            return done
        if not _wait_writable(fd, remaining):
            return done


def _wait_writable(fd: int, timeout_s: float) -> bool:
    """Whether ``fd`` took room (or an error, which the next write raises) within ``timeout_s``."""
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return bool(poller.poll(max(1, math.ceil(timeout_s * 1000))))  # milliseconds, rounded up: never a busy loop
