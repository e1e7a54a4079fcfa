"""A close() from another thread while ``sim://``'s open() loads its loop from the disk cache, or writes it there,
stops that at its next chunk. Before, only the render stopped early: the cache's checksum check read every file to
its end, and the write stored the whole entry, for a source already closed. A cancelled write leaves nothing in the
cache (its temporary entry removed, never renamed into place); a cancelled load leaves the entry, intact."""
from __future__ import annotations

import types
import zlib

import pytest

from drivers import ManualClock, RigInitializationError, create_rig_source, open_rig
from drivers.backends import sim_loop

SMALL = "width=48&height=36"


def test_a_close_during_the_cache_write_stops_it_and_stores_nothing(tmp_path, monkeypatch):
    url = f"sim://?{SMALL}&seed=11&cache={tmp_path}"
    source = create_rig_source(url, clock=ManualClock())
    writes_after_the_close = []
    real_writer = sim_loop._Crc32Writer

    class ClosingOnTheFirstWrite(real_writer):
        """The store's first write closes the source (as another thread's close would land), then counts what
        the store goes on to write."""

        def write(self, data) -> int:
            if not source._closed:
                source.close()
            written = super().write(data)
            writes_after_the_close.append(written)
            return written

    monkeypatch.setattr(sim_loop, "_Crc32Writer", ClosingOnTheFirstWrite)
    with pytest.raises(RigInitializationError, match="closed while open"):
        source.open()
    assert writes_after_the_close == []  # stopped before the chunk it was about to write
    assert list(tmp_path.iterdir()) == []  # no entry, no temporary one left to be read as a cache
    assert (source._loop, source._loop_alone, source.is_open) == (None, None, False)
    monkeypatch.setattr(sim_loop, "_Crc32Writer", real_writer)
    with open_rig(url, clock=ManualClock()) as again:
        assert again.fill_report.source == "rendered"
    with open_rig(url, clock=ManualClock()) as third:
        assert third.fill_report.source == "disk"  # the entry the uncancelled open stored is whole


def test_a_close_during_the_cache_load_stops_it_and_keeps_the_entry(tmp_path, monkeypatch):
    url = f"sim://?{SMALL}&seed=12&cache={tmp_path}"
    open_rig(url, clock=ManualClock()).close()  # renders and stores the entry
    (entry,) = tmp_path.iterdir()
    source = create_rig_source(url, clock=ManualClock())
    chunks_after_the_close = []

    def closing_on_the_first_chunk(data, value=0):
        """The checksum check's first chunk closes the source, then counts the chunks it goes on to sum."""
        if source._closed:
            chunks_after_the_close.append(len(data))
        else:
            source.close()
        return zlib.crc32(data, value)

    monkeypatch.setattr(sim_loop, "_CHUNK", 4096)  # several chunks in every file
    monkeypatch.setattr(sim_loop, "zlib", types.SimpleNamespace(crc32=closing_on_the_first_chunk))
    with pytest.raises(RigInitializationError, match="closed while open"):
        source.open()
    assert chunks_after_the_close == []
    assert (source._loop, source._loop_alone, source.is_open) == (None, None, False)
    monkeypatch.undo()
    assert list(tmp_path.iterdir()) == [entry]  # a cancelled load is no damaged entry: kept
    with open_rig(url, clock=ManualClock()) as again:
        assert again.fill_report.source == "disk"
