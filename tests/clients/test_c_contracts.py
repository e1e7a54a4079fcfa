"""What ghjoints.h promises beyond the shared vectors: a GHJ_MAX_JOINTS mismatch is refused,
joints beyond count are missing, only GHJ_PACKET writes *out, out = NULL counts the same,
`make check` fails on a wrong decode, and the memory figures in docs/c-decoder.md are measured."""
from __future__ import annotations

import json
import os
import platform
import re
import shutil
import struct
import subprocess
from pathlib import Path

import pytest

from firmware_host.protocol.encoder import frame_packet, seal
from firmware_host.protocol.vectors import VECTORS
from tests.clients.c_build import C_DIR, ROOT, STRICT, VECTOR_DIR, compile_c, require_compiler, sanitizer_flags

HERE = Path(__file__).resolve().parent
DOC = ROOT / "docs" / "c-decoder.md"


def _frame(msg_type: int, payload: bytes, seq: int = 1) -> bytes:
    return frame_packet(seal(struct.pack("<BBBIQQ", 1, msg_type, 0, seq, 1000, 2000) + payload))


def _joints(count: int, value: int, seq: int, joint_set: int = 0) -> bytes:
    payload = bytes([joint_set, count]) + bytes((count + 7) // 8)
    payload += b"".join(struct.pack("<hhhB", value, value, value, 200) for _ in range(count))
    return _frame(0x10, payload, seq)


def _joints2d(count: int, seq: int) -> bytes:
    payload = bytes([1, 0, count]) + bytes((count + 7) // 8)
    payload += b"".join(struct.pack("<hhB", 40, 80, 200) for _ in range(count))
    return _frame(0x11, payload, seq)


def _status(seq: int) -> bytes:
    return _frame(0x02, struct.pack("<HIIIH", 3000, 42000, 3, 120, 1), seq)


def _run(exe: Path, data: bytes, *args: str) -> list[dict]:
    proc = subprocess.run([str(exe), *args], input=data, capture_output=True)
    assert proc.returncode == 0 and proc.stderr == b"", proc.stderr.decode(errors="replace")
    return [json.loads(line) for line in proc.stdout.decode().splitlines()]


# --- GHJ_MAX_JOINTS mismatch ------------------------------------------------------------------


@pytest.mark.parametrize(("app_joints", "lib_joints"), [(25, 64), (64, 25), (21, 20)])
def test_mismatched_max_joints_is_refused_not_overflowed(tmp_path: Path, app_joints: int, lib_joints: int) -> None:
    """The caller (ghj_dump, static ghj_packet) and ghjoints.c compiled apart, as an Arduino sketch
    with a #define does: every frame is GHJ_ERR_CONFIG and nothing is written (ASan would report
    the 64-joint write into a 25-joint packet that this used to be). 21 vs 20 joints gives
    packets of one size on x86-64 (HELLO is the union's largest member), so the size alone
    would not tell them apart."""
    cc = require_compiler()
    san = sanitizer_flags(cc, tmp_path)
    lib = compile_c(cc, tmp_path / "lib.o", [C_DIR / "ghjoints.c"], ["-c", f"-DGHJ_MAX_JOINTS={lib_joints}", *san])
    app = compile_c(cc, tmp_path / "app.o", [C_DIR / "tools" / "ghj_dump.c"],
                    ["-c", f"-DGHJ_MAX_JOINTS={app_joints}", *san])
    exe = compile_c(cc, tmp_path / "ghj_dump_mixed", [app, lib], san)
    data = _joints(64, 7, 1) + _joints(25, 7, 2) + _status(3) + _joints(3, 7, 4) + b"\x01\x00"
    lines = _run(exe, data, "-c", "1", "-")
    assert lines[:-1] == [{"error": "config"}] * 5
    assert lines[-1]["stats"]["frames"] == 5 and lines[-1]["stats"]["config"] == 5
    # The same objects without a mismatch decode normally (the test is not refusing everything).
    same = compile_c(cc, tmp_path / "app_same.o", [C_DIR / "tools" / "ghj_dump.c"],
                     ["-c", f"-DGHJ_MAX_JOINTS={lib_joints}", *san])
    exe_same = compile_c(cc, tmp_path / "ghj_dump_same", [same, lib], san)
    assert _run(exe_same, _joints(3, 7, 4), "-")[0]["type"] == "JOINTS"


def test_counters_only_mode_works_whatever_the_capacity(tmp_path: Path) -> None:
    """out = NULL writes nothing, so a mismatch does not matter there."""
    cc = require_compiler()
    lib = compile_c(cc, tmp_path / "lib.o", [C_DIR / "ghjoints.c"], ["-c"])
    app = compile_c(cc, tmp_path / "app.o", [C_DIR / "tools" / "ghj_dump.c"], ["-c", "-DGHJ_MAX_JOINTS=25"])
    exe = compile_c(cc, tmp_path / "ghj_dump_mixed", [app, lib])
    expected = json.loads((VECTOR_DIR / "session.json").read_text())["stats"]
    assert _run(exe, (VECTOR_DIR / "session.bin").read_bytes(), "-n", "-") == [{"stats": expected}]


# --- what *out holds ---------------------------------------------------------------------------


@pytest.fixture(scope="module", params=[64, 25], ids=["64", "25"])
def driver(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    cc = require_compiler()
    tmp = tmp_path_factory.mktemp("driver")
    return compile_c(cc, tmp / "contract_driver", [C_DIR / "ghjoints.c", HERE / "contract_driver.c"],
                     [f"-DGHJ_MAX_JOINTS={request.param}", *sanitizer_flags(cc, tmp)])


def test_joints_beyond_count_are_missing(driver: Path) -> None:
    """A BODY_25 packet with 3 joints after one with 25: joints[3..] must not be the old ones."""
    data = _joints(25, 111, 1) + _joints(3, -5, 2) + _joints(0, 0, 3) + _joints2d(20, 4) + _joints2d(2, 5)
    ev = _run(driver, data)
    assert [e["result"] for e in ev] == ["packet"] * 5
    assert [e["count"] for e in ev] == [25, 3, 0, 20, 2]
    assert all(e["tail_missing"] == 1 for e in ev)
    assert ev[0]["j0x"] == 111 and ev[1]["j0x"] == -5


def _hello(cameras: list[str], seq: int) -> bytes:
    payload = bytes([1, 0, 25, 0, 0, 3]) + b"rig" + bytes([len(cameras)])
    payload += b"".join(bytes([len(c)]) + c.encode() for c in cameras)
    return _frame(0x01, payload, seq)


def test_camera_names_beyond_n_cameras_are_empty(driver: Path) -> None:
    """A HELLO shares the union with JOINTS: after a JOINTS packet, the name slots a HELLO does not fill held
    joint bytes without a NUL, which a caller scanning every slot with strcmp read past."""
    data = _joints(25, 0x4141, 1) + _hello([], 2) + _joints(25, 0x4141, 3) + _hello(["left", "right"], 4)
    ev = _run(driver, data)
    assert [(e["type"], e["count"], e["tail_missing"]) for e in ev] == [(16, 25, 1), (1, 0, 1), (16, 25, 1),
                                                                         (1, 2, 1)]


def test_only_a_packet_writes_out(driver: Path) -> None:
    """GHJ_SKIPPED and errors leave the caller's packet byte-for-byte as it was; the skipped type
    is in the decoder (it used to be written into the packet's header, beside the old payload)."""
    good = _joints(25, 111, 1)
    bad_crc = bytearray(_joints(25, 5, 2))
    bad_crc[10] ^= 0x40
    data = good + _frame(0x7F, b"xyz", 999) + bytes(bad_crc) + b"\x04\x01\x02\x03\x00" + _frame(0x10, b"\x00", 3)
    ev = _run(driver, data)
    assert ev[0] == {"result": "packet", "type": 16, "count": 25, "tail_missing": 1, "j0x": 111}
    assert ev[1] == {"result": "skipped", "skipped_type": 127, "untouched": 1}
    assert [e["result"] for e in ev[2:]] == ["crc", "short", "malformed"]
    assert all(e["untouched"] == 1 for e in ev[2:])


def test_ghj_dump_reports_the_skipped_type_from_the_decoder(ghj_dump: Path) -> None:
    lines = _run(ghj_dump, _status(1) + _frame(0x42, b"", 2) + _frame(0x7F, b"abc", 3), "-")
    assert lines[1:3] == [{"skipped": "unknown", "msg_type": 0x42}, {"skipped": "unknown", "msg_type": 0x7F}]


@pytest.mark.parametrize("name", sorted(VECTORS))
def test_null_out_counts_like_a_full_decode(ghj_dump: Path, name: str) -> None:
    """ghj_dump -n passes out = NULL and result = NULL to ghj_feed()."""
    expected = json.loads((VECTOR_DIR / f"{name}.json").read_text())["stats"]
    assert _run(ghj_dump, (VECTOR_DIR / f"{name}.bin").read_bytes(), "-n", "-c", "1", "-") == [{"stats": expected}]


@pytest.mark.parametrize("args", [["-c", "0"], ["-c", "4097"], ["-c", "abc"], ["-c", "-1"], ["-c", "7x"],
                                  ["-x"], ["two", "files"], ["-c"]])
def test_ghj_dump_refuses_bad_arguments(ghj_dump: Path, args: list[str]) -> None:
    """A CHUNK outside 1..4096 used to become 4096 without a word, so a run asked to feed 0 or 5000 bytes at a
    time tested another chunking than it said; like an unknown option, it is a usage error (status 2)."""
    path = VECTOR_DIR / "status.bin"
    proc = subprocess.run([str(ghj_dump), *args, *([] if "files" in args else [str(path)])], capture_output=True,
                          text=True)
    assert proc.returncode == 2 and proc.stdout == "", proc.stdout
    assert "CHUNK" in proc.stderr


def test_ghj_dump_accepts_every_chunk_in_range(ghj_dump: Path) -> None:
    expected = json.loads((VECTOR_DIR / "session.json").read_text())["stats"]
    for chunk in ("1", "4096"):
        lines = _run(ghj_dump, (VECTOR_DIR / "session.bin").read_bytes(), "-n", "-c", chunk, "-")
        assert lines == [{"stats": expected}]


# --- make check --------------------------------------------------------------------------------


@pytest.mark.parametrize("make", ["make", "bmake"])
def test_make_check_compares_with_the_vectors(tmp_path: Path, make: str) -> None:
    """`make check` passes on the real vectors and fails when one expectation is wrong.
    bmake (BSD make) checks that the Makefile needs no GNU extensions."""
    if not shutil.which(make):
        pytest.skip(f"{make} not installed")
    cc = require_compiler()
    build = tmp_path / "build"
    ok = subprocess.run([make, "-C", str(C_DIR), "check", f"CC={cc}", f"BUILD={build}"], capture_output=True,
                        text=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    n = len(VECTORS)  # each fed 1, 7 and 4096 bytes at a time
    assert f"{3 * n} runs ({n} vectors" in ok.stdout and "all contracts held" in ok.stdout

    bad = tmp_path / "vectors"
    shutil.copytree(VECTOR_DIR, bad)
    text = (bad / "unknown_type.json").read_text()
    (bad / "unknown_type.json").write_text(text.replace('"msg_type":127', '"msg_type":126'))
    fail = subprocess.run([make, "-C", str(C_DIR), "check", f"CC={cc}", f"BUILD={build}", f"VECTORS={bad}"],
                          capture_output=True, text=True)
    assert fail.returncode != 0
    assert "FAIL unknown_type" in fail.stdout


def test_check_vectors_fails_when_the_decoder_fails(tmp_path: Path) -> None:
    failing = tmp_path / "dump"
    failing.write_text("#!/bin/sh\necho '{\"stats\":{}}'\nexit 3\n")
    failing.chmod(0o755)
    proc = subprocess.run([str(C_DIR / "tools" / "check_vectors.sh"), str(failing), str(VECTOR_DIR)],
                          capture_output=True, text=True)
    assert proc.returncode == 1
    assert "exited with status 3" in proc.stdout


def test_check_vectors_stops_on_a_signal(tmp_path: Path) -> None:
    """A TERM (or Ctrl-C) ends check_vectors.sh at once with 143 and its temporary directory gone; its trap used
    to remove the directory and carry on, printing a FAIL for each of the remaining runs and exiting 1."""
    calls = tmp_path / "calls"
    dump = tmp_path / "dump"
    dump.write_text(f"#!/bin/sh\necho x >> {calls}\nkill -TERM $PPID\necho '{{\"stats\":{{}}}}'\n")
    dump.chmod(0o755)
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    proc = subprocess.run([str(C_DIR / "tools" / "check_vectors.sh"), str(dump), str(VECTOR_DIR)],
                          capture_output=True, text=True, env={**os.environ, "TMPDIR": str(scratch)}, timeout=60)
    assert proc.returncode == 143, proc.stdout
    assert "FAIL" not in proc.stdout
    assert calls.read_text().count("x") == 1
    assert list(scratch.iterdir()) == []


# --- memory figures in docs/c-decoder.md -------------------------------------------------------


def test_host_size_figures_in_docs(tmp_path: Path) -> None:
    """The sizes the doc quotes for a 64-bit host are what tools/ghj_sizes.c prints (`make sizes`)."""
    if platform.machine() not in ("x86_64", "AMD64") or platform.system() != "Linux":
        pytest.skip("the doc quotes x86-64 Linux sizes")
    cc = require_compiler()
    doc = DOC.read_text()
    for joints in (64, 25):
        exe = compile_c(cc, tmp_path / f"sizes{joints}", [C_DIR / "tools" / "ghj_sizes.c"],
                        [f"-DGHJ_MAX_JOINTS={joints}"])
        line = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.strip()
        assert line in doc, f"docs/c-decoder.md does not quote `make sizes`: {line}"


def test_avr_build_and_ram_figures() -> None:
    """Where avr-gcc is installed: ghjoints.c builds warning-free with the project's flags for a
    16-bit-int target, and the SRAM figures in the doc are what tools/avr_ram.sh measures."""
    if not shutil.which("avr-gcc"):
        pytest.skip("avr-gcc not installed (apt-get install gcc-avr avr-libc)")
    obj = subprocess.run(["avr-gcc", "-mmcu=atmega328p", *STRICT, "-Os", f"-I{C_DIR}", "-c",
                          str(C_DIR / "ghjoints.c"), "-o", os.devnull], capture_output=True, text=True)
    assert obj.returncode == 0 and obj.stderr == "", obj.stderr
    proc = subprocess.run([str(C_DIR / "tools" / "avr_ram.sh")], capture_output=True, text=True)
    if proc.returncode == 77:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.strip().splitlines()
    doc = DOC.read_text()
    figures = [ln for ln in lines if ln.startswith("GHJ_MAX_JOINTS=")]
    assert len(figures) == 4
    # Struct sizes and "decoding only" do not depend on the compiler version; the strings and
    # switch tables ghj_result_name() adds may, so those are compared only with the doc's compiler.
    for ln in figures:
        if "decoding only" in ln or lines[0] in doc:
            assert ln in doc, f"docs/c-decoder.md does not quote `make avr-ram`: {ln}"
        assert re.search(r"decoding only: \d+ bytes = .* \+ other 0$", ln) or "ghj_result_name" in ln, ln


def test_ci_fails_rather_than_skips_without_a_compiler(monkeypatch: pytest.MonkeyPatch) -> None:
    from tests.clients import c_build

    monkeypatch.setattr(c_build, "c_compiler", lambda: None)
    monkeypatch.setenv(c_build.REQUIRE_ENV, "0")
    with pytest.raises(pytest.skip.Exception):
        c_build.require_compiler()
    monkeypatch.setenv(c_build.REQUIRE_ENV, "1")
    with pytest.raises(pytest.fail.Exception, match="GHJ_REQUIRE_CC says the C client must be tested"):
        c_build.require_compiler()
