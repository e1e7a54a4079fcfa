"""firmware_host.daemon.memory: freed heap pages go back to the system."""
from __future__ import annotations

import ctypes.util
import platform

import pytest

from firmware_host.daemon.memory import return_freed_memory


def _rss_mb() -> float:
    with open("/proc/self/status") as fh:
        return int(fh.read().split("VmRSS:")[1].split()[0]) / 1024


@pytest.mark.skipif(platform.system() != "Linux" or "musl" in (ctypes.util.find_library("c") or ""),
                    reason="malloc_trim is glibc's")
def test_freed_heap_is_returned_to_the_system():
    return_freed_memory()
    base = _rss_mb()
    # 64 KiB blocks sit in the heap (glibc mmaps only blocks past its 128 KiB threshold), so freeing them
    # leaves the pages with the process until a trim.
    blocks = [bytearray(b"x" * 65_000) for _ in range(1500)]
    grown = _rss_mb()
    del blocks
    assert grown - base > 60
    assert return_freed_memory() is True
    assert _rss_mb() - base < (grown - base) / 2
