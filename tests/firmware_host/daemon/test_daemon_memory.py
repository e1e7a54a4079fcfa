"""firmware_host.daemon.memory: freed heap goes back to the system, and a model's big blocks stay out of the heap."""
from __future__ import annotations

import ctypes.util
import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

from firmware_host.daemon import memory
from firmware_host.daemon.memory import return_freed_memory

REPO = Path(__file__).resolve().parents[3]


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


#: Run in a fresh interpreter (the threshold is process-wide, and this one's has moved already): after
#: ``SETUP``, an 8 MiB block is allocated and freed (a model's weights, dropped by a reload), then a 2 MiB
#: one (the next model's); prints whether glibc mapped the second (its mapped bytes grew by it).
_PROBE = """
import ctypes, ctypes.util, sys
sys.path.insert(0, {repo!r})
class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]
libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.malloc.restype, libc.malloc.argtypes, libc.free.argtypes = ctypes.c_void_p, [ctypes.c_size_t], [ctypes.c_void_p]
libc.mallinfo2.restype = MallInfo2
{setup}
libc.free(libc.malloc(8 << 20))
before = libc.mallinfo2().hblkhd
block = libc.malloc(2 << 20)
print("mapped" if libc.mallinfo2().hblkhd - before >= 2 << 20 else "heap")
"""


def probe_big_block(setup: str, env: dict | None = None) -> str:
    """Where glibc puts a 2 MiB block after an 8 MiB one was freed, in a fresh process run after ``setup``."""
    out = subprocess.run([sys.executable, "-c", _PROBE.format(repo=str(REPO), setup=setup)], cwd=REPO,
                         capture_output=True, text=True, timeout=120, env={**os.environ, **(env or {})})
    assert out.returncode == 0, out.stderr
    return out.stdout.split()[-1]


def glibc_only_reason() -> str:
    """Why the mmap threshold cannot be probed here ("" where it can)."""
    if platform.system() != "Linux" or "musl" in (ctypes.util.find_library("c") or ""):
        return "the mmap threshold and mallinfo2 are glibc's"
    return ""


glibc_only = pytest.mark.skipif(bool(glibc_only_reason()), reason=glibc_only_reason() or "glibc")


@glibc_only
def test_a_pinned_threshold_keeps_mapping_big_blocks_after_one_is_freed():
    # Left to glibc, freeing the mapped 8 MiB block raises the threshold past 2 MiB: the next block goes to
    # the heap, where, once freed amid live blocks, its pages stay with the process (what each reload added).
    assert probe_big_block("") == "heap"
    assert probe_big_block("from firmware_host.daemon.memory import pin_mmap_threshold\n"
                           "assert pin_mmap_threshold()") == "mapped"


@glibc_only
def test_a_threshold_the_environment_sets_is_kept(monkeypatch):
    calls = []
    monkeypatch.setattr(memory, "_libc_function", lambda name: calls.append(name))
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "4194304")
    assert memory.pin_mmap_threshold() is False
    monkeypatch.delenv("MALLOC_MMAP_THRESHOLD_")
    monkeypatch.setenv("GLIBC_TUNABLES", "glibc.malloc.mmap_threshold=4194304")
    assert memory.pin_mmap_threshold() is False
    assert calls == []  # mallopt never called
    # glibc reads the variable at start: a 16 MiB threshold keeps a 2 MiB block in the heap, pin or not
    assert probe_big_block("from firmware_host.daemon.memory import pin_mmap_threshold\n"
                           "assert not pin_mmap_threshold()", env={"MALLOC_MMAP_THRESHOLD_": str(16 << 20)}) == "heap"
