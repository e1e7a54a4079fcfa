"""The committed vectors are what the generator produces, and the Python decoder passes them."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from firmware_host.protocol import StreamDecoder, decode_stream
from firmware_host.protocol.constants import ALL_SCENE_FLAGS, SCENE_FLAGS, Flags
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


def test_vectors_carry_every_flag_where_it_is_sent() -> None:
    """Each header flag on a JOINTS (the scene flags alone too: a decoder that reads one only next to DROPPED is
    not tested), SINGLE_VIEW and SOMEONE_ELSE on JOINTS_2D, CALIBRATION_SUSPECT on STATUS, both scene-flag masks
    on HELLO (without and with the scan for others), and the reserved bit 7, which every decoder must pass through
    rather than refuse."""
    events = [ev for name in VECTORS for ev in json.loads((VECTOR_DIR / f"{name}.json").read_text())["events"]]
    flags_of = {kind: {ev["flags"] for ev in events if ev.get("type") == kind}
                for kind in ("JOINTS", "JOINTS_2D", "STATUS", "HELLO")}
    for flag in Flags:
        if flag:
            assert int(flag) in flags_of["JOINTS"], f"no vector has a JOINTS flagged {flag!r} alone"
    assert int(Flags.SINGLE_VIEW) in flags_of["JOINTS_2D"]
    assert int(Flags.SOMEONE_ELSE) in flags_of["JOINTS_2D"]
    assert int(Flags.CALIBRATION_SUSPECT) in flags_of["STATUS"]
    assert {SCENE_FLAGS, ALL_SCENE_FLAGS} <= flags_of["HELLO"]
    assert ALL_SCENE_FLAGS | Flags.DROPPED in flags_of["JOINTS"]
    assert any(f & 0x80 for f in flags_of["JOINTS"]), "no vector has the reserved flag bit set"


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
