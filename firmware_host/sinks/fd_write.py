"""Bounded writes to a non-blocking file descriptor (a tty, a named pipe), shared by serial:// and file://.

A receiver that stops reading fills the kernel's buffer; a blocking ``write()`` would then hold the sink's
worker for as long as the receiver stays away (for ever, for a named pipe whose reader hangs). Here each
write waits for room with ``select()`` (no CPU spent) at most ``timeout_s`` and returns what went out.
"""
from __future__ import annotations

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
        _, ready, _ = select.select([], [fd], [], remaining)
        if not ready:
            return done
