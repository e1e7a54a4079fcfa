"""SOMEONE_ELSE (header bit 6, since session 65): the estimator's scan for others (``presence.scan_every_s``) on the
joint stream, and the HELLO mask that says whether the sender scans (docs/protocol.md, "Scene flags")."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from firmware_host import listen
from firmware_host.errors import SinkConfigError
from firmware_host.joint_frames import announced_scene_flags, scene_flags
from firmware_host.protocol import ALL_SCENE_FLAGS, SCENE_FLAGS, Flags, decode_stream, encode, hello_scene_flags
from firmware_host.protocol.from_frame import joints2d_messages, joints_message
from firmware_host.sinks.memory_sink import MemorySink
from ghnerf_runtime.config import EstimatorConfig, PresenceConfig
from tests.firmware_host.joint_stream_helpers import make_frame, messages_of

REPO = Path(__file__).resolve().parents[2]
MODELS = REPO / "models"
SCANNING = EstimatorConfig(presence=PresenceConfig(scan_every_s=0.5))


def test_the_bit_is_six_and_the_masks_with_and_without_the_scan():
    assert int(Flags.SOMEONE_ELSE) == 0x40
    assert SCENE_FLAGS == 0x3C and ALL_SCENE_FLAGS == 0x7C
    assert hello_scene_flags(False) == 0x3C and hello_scene_flags(True) == 0x7C
    assert announced_scene_flags(EstimatorConfig()) == 0x3C  # the scan is off by default: "nobody looked"
    assert announced_scene_flags(SCANNING) == 0x7C


def test_a_frame_flagged_someone_else_round_trips_on_joints_and_joints_2d():
    """JointFrame refused bit 6 as a reserved bit before; now it travels on the frame's JOINTS and JOINTS_2D,
    beside the link's DROPPED, and decodes as sent. Bit 7 is still refused."""
    uv = np.column_stack([np.full((25, 2), 100.0), np.ones(25)])
    frame = replace(make_frame(7, joints_2d={0: uv, 1: uv}), scene_flags=int(Flags.SOMEONE_ELSE | Flags.SEVERAL_PEOPLE))
    messages = [joints_message(frame, 1_000, int(Flags.DROPPED))]
    messages += joints2d_messages(frame, 1_000, ("left", "right"), 0)
    events, stats = decode_stream(b"\x00".join(encode(m) for m in messages))
    assert all(e.message is not None for e in events) and len(events) == len(messages)
    flags = [e.message.header.flags for e in events]
    assert flags[0] == 0x40 | 0x04 | 0x02
    assert flags[1:] == [0x44, 0x44], flags
    with pytest.raises(ValueError, match="0x80 sets bits other than the scene flags 0x7c"):
        replace(make_frame(7), scene_flags=0x80)


@pytest.mark.parametrize("answer, flagged", [(True, True), (False, False), (None, False)])
def test_a_pair_s_held_answer_sets_the_flag(answer, flagged):
    """The estimator holds the latest scan's answer on every pair until the next scan; None (no scan this track,
    or the scan off) leaves the bit clear."""
    result = SimpleNamespace(several_people=False, prior_fallback=False, single_view=None, someone_else=answer)
    assert scene_flags(result) == (int(Flags.SOMEONE_ELSE) if flagged else 0)


def _hello_flags(sink: MemorySink) -> list[int]:
    return [m.header.flags for m in messages_of(sink.read()) if type(m).__name__ == "Hello"]


def test_hello_announces_someone_else_only_from_a_sender_that_scans():
    """A receiver tells "nobody else seen" from "nobody looked" by HELLO: 0x3C by default, 0x7C when the producer
    says its estimator scans (``scene_flags=``), and the mask can change on a running link (a reload)."""
    plain = MemorySink.from_url("memory://").start()
    plain.send(make_frame(0))
    plain.close()
    assert set(_hello_flags(plain)) == {0x3C}

    scanning = MemorySink.from_url("memory://?status_s=0.01", scene_flags=hello_scene_flags(True)).start()
    scanning.send(replace(make_frame(0), scene_flags=int(Flags.SOMEONE_ELSE)))
    scanning.close()
    assert set(_hello_flags(scanning)) == {0x7C}

    turned = MemorySink.from_url("memory://", scene_flags=ALL_SCENE_FLAGS)
    turned.announce_scene_flags(SCENE_FLAGS)  # before start: the first HELLO says it already
    turned.start().close()
    assert set(_hello_flags(turned)) == {0x3C}


@pytest.mark.parametrize("value", [0x80, 0x01, 0x7D, -1, True, "0x7C", 0x3C + 0.0])
def test_a_mask_that_is_not_scene_flags_is_refused_naming_the_field(value):
    with pytest.raises(SinkConfigError, match="scene_flags"):
        MemorySink.from_url("memory://", scene_flags=value)
    sink = MemorySink.from_url("memory://")
    with pytest.raises(SinkConfigError, match="scene_flags"):
        sink.announce_scene_flags(value)


def test_a_numpy_mask_counts_as_the_python_int_it_holds():
    """As every keyword of open_sink (docs/protocol.md, "NumPy values")."""
    sink = MemorySink.from_url("memory://", scene_flags=np.int64(0x7C))
    assert type(sink.options.scene_flags) is int and sink.options.scene_flags == 0x7C
    sink.announce_scene_flags(np.uint8(0x3C))
    sink.start().close()
    assert set(_hello_flags(sink)) == {0x3C}


def _listener_line(sink: MemorySink) -> str:
    """``ghnerf-listen``'s summary line of everything ``sink`` wrote."""
    tally = listen.Tally()
    for message in messages_of(sink.read()):
        tally.add(message)
    return tally.line(1.0, {})


def test_the_listener_counts_someone_else_and_says_the_sender_scans():
    sink = MemorySink.from_url("memory://", rig_id="arm", scene_flags=ALL_SCENE_FLAGS).start()
    for seq, flags in ((0, 0), (1, Flags.SOMEONE_ELSE), (2, Flags.SOMEONE_ELSE | Flags.SEVERAL_PEOPLE)):
        sink.send(replace(make_frame(seq), scene_flags=int(flags)))
    sink.close()
    line = _listener_line(sink)
    assert "1 several people; 2 someone else" in line, line
    assert "rig 'arm' cameras [] (scans for someone else)" in line, line

    plain = MemorySink.from_url("memory://", rig_id="arm").start()
    plain.close()
    line = _listener_line(plain)
    assert "scans for someone else" not in line and "(sends no scene flags)" not in line, line


needs_model = pytest.mark.skipif(not (MODELS / "model_card.json").is_file(),
                                 reason="no trained model yet: models/model_card.json does not exist")


@needs_model
def test_the_demo_streams_the_scan_s_answer_on_a_scene_with_a_second_person(tmp_path, capsys, recorded):
    """``ghnerf-demo`` with the scan on (every tracked pair) and a second person a metre beside the subject: its
    HELLO announces 0x7C, and each JOINTS carries SOMEONE_ELSE exactly where the pair's ``someone_else`` is true
    (the shipped model tells this place on 99-100 % of pairs: docs/two-people.md, "Anyone else near?")."""
    from firmware_host import demo

    config = tmp_path / "scan.json"
    config.write_text(json.dumps({"presence": {"scan_every_s": 0.001}}))
    cache = tmp_path / "cache"
    url = f"{demo.DEFAULT_URL}&second=1.0,3.4&cache={cache}"
    rc = demo.main(["--url", url, "--seconds", "2.5", "--out", str(tmp_path / "out"), "--model-dir", str(MODELS),
                    "--config", str(config)])
    out = capsys.readouterr().out
    assert rc == 0, out
    rows = [json.loads(line) for line in (tmp_path / "out" / "joints.jsonl").read_text().splitlines()]
    assert {r["flags"] for r in rows if r["type"] == "HELLO"} == {0x7C}
    joints = [r for r in rows if r["type"] == "JOINTS"]
    assert len(joints) == len(recorded) >= 3
    assert [bool(r["flags"] & 0x40) for r in joints] == [r.someone_else is True for r in recorded]
    assert any(r.someone_else for r in recorded), [r.someone_else for r in recorded]
