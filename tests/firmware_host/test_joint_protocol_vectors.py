"""The committed vectors are what the generator produces, and the Python decoder passes them."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from firmware_host.protocol import StreamDecoder, decode_stream
from firmware_host.protocol.vectors import VECTORS, build, default_dir

VECTOR_DIR = Path(__file__).resolve().parents[1] / "vectors" / "joint_stream"


def test_default_dir_is_the_committed_dir() -> None:
    assert default_dir() == VECTOR_DIR


def test_committed_files_match_the_generator() -> None:
    built = build()
    committed = {p.stem for p in VECTOR_DIR.glob("*.bin")}
    assert committed == set(built), "run: python -m firmware_host.protocol.vectors"
    for name, (data, text) in built.items():
        assert (VECTOR_DIR / f"{name}.bin").read_bytes() == data, f"{name}.bin is stale"
        assert (VECTOR_DIR / f"{name}.json").read_text() == text, f"{name}.json is stale"


def test_vectors_cover_the_required_damage() -> None:
    expected = {name: json.loads((VECTOR_DIR / f"{name}.json").read_text()) for name in VECTORS}
    totals = {k: sum(v["stats"][k] for v in expected.values()) for k in next(iter(expected.values()))["stats"]}
    for code in ("oversize", "cobs", "short", "crc", "version", "malformed", "skipped"):
        assert totals[code] > 0, f"no vector exercises {code}"


@pytest.mark.parametrize("name", sorted(VECTORS))
def test_python_decoder_passes_vector(name: str) -> None:
    data = (VECTOR_DIR / f"{name}.bin").read_bytes()
    expected = json.loads((VECTOR_DIR / f"{name}.json").read_text())
    events, stats = decode_stream(data)
    assert [e.to_json() for e in events] == expected["events"]
    assert stats.to_json() == expected["stats"]
    d = StreamDecoder()  # byte at a time gives the same
    one_by_one = [e.to_json() for b in data for e in d.feed(bytes([b]))]
    assert one_by_one == expected["events"]
