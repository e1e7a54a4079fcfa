"""Hand freed heap back to the system after a model is replaced.

A reload that loads the model again frees the old onnxruntime sessions, but glibc keeps the freed
pages in its arenas: each such reload left the daemon's resident memory some megabytes higher
(docs/daemon.md, "Reloaded again and again"). ``malloc_trim(0)`` returns what is free at the top of
every arena (:func:`return_freed_memory`).

That is not enough on its own: glibc serves a block past its mmap threshold (128 KiB) with a mapping
of its own, given back whole when freed, but raises the threshold to the size of each such block
freed (up to 32 MiB). Freeing the first model's weights and arena chunks (a few MiB each) so put the
next model's in the heap, amid the pairs' small arrays, where once freed they are left as holes the
trim cannot hand back while live blocks sit around them: the heap's free space grew with every load
(``benchmarks/measure_reload_memory.py``). :func:`pin_mmap_threshold` fixes the threshold (a fixed one
is never raised), so every model's big blocks are mapped and go back to the system when freed.
Elsewhere (musl, macOS) there are no such calls and nothing is done.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import logging
import os

log = logging.getLogger(__name__)

__all__ = ["MMAP_THRESHOLD", "pin_mmap_threshold", "return_freed_memory"]

#: Blocks of this size or more get a mapping of their own. 1 MiB and not glibc's 128 KiB: the pairs' images
#: and crops (a 320x240 RGB image is 225 KiB) stay in the heap, as they did once the threshold had risen,
#: rather than being mapped and unmapped on every pair (128 KiB cost time, docs/daemon.md); the model's
#: weights and onnxruntime's arena chunks are larger.
MMAP_THRESHOLD = 1 << 20
_M_MMAP_THRESHOLD = -3  # glibc's malloc.h


def _libc_function(name: str):
    lib = ctypes.util.find_library("c")
    if lib is None:
        return None
    try:
        return getattr(ctypes.CDLL(lib), name, None)
    except OSError:
        return None


def _malloc_trim():
    return _libc_function("malloc_trim")


def pin_mmap_threshold(nbytes: int = MMAP_THRESHOLD) -> bool:
    """Fix glibc's mmap threshold at ``nbytes`` (before a model loads), unless the environment sets malloc's
    tunables. Returns whether it was set."""
    # glibc read these at start: a threshold the environment chose (the unit, an operator) is kept
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "malloc.mmap_threshold" in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    mallopt = _libc_function("mallopt")
    if mallopt is None:
        return False
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    return bool(mallopt(_M_MMAP_THRESHOLD, nbytes))


def return_freed_memory() -> bool:
    """Collect Python's cycles, then ask glibc to return free heap pages. Returns whether glibc did trim."""
    gc.collect()
    trim = _malloc_trim()
    if trim is None:
        return False
    trim.argtypes = [ctypes.c_size_t]
    return bool(trim(0))
