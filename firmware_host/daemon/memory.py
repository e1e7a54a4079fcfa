"""Hand freed heap back to the system after a model is replaced.

A reload that loads the model again frees the old onnxruntime sessions, but glibc keeps the freed
pages in its arenas: each such reload left the daemon's resident memory some megabytes higher
(docs/daemon.md, "Reloaded again and again"). ``malloc_trim(0)`` returns what is free at the top of
every arena. Elsewhere (musl, macOS) there is no such call and nothing is done.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging

log = logging.getLogger(__name__)

__all__ = ["return_freed_memory"]


def _malloc_trim():
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        return getattr(ctypes.CDLL(name), "malloc_trim", None)
    except OSError:
        return None


def return_freed_memory() -> bool:
    """Collect Python's cycles, then ask glibc to return free heap pages. Returns whether glibc did trim."""
    gc.collect()
    trim = _malloc_trim()
    if trim is None:
        return False
    trim.argtypes = [ctypes.c_size_t]
    return bool(trim(0))
