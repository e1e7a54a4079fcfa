"""The C decoder (clients/c) against the shared vectors and against the Python decoder."""
from __future__ import annotations

import json
import random
import subprocess
from pathlib import Path

import pytest

from firmware_host.protocol import decode_stream
from firmware_host.protocol.vectors import VECTORS
from tests.clients.c_build import C_DIR, VECTOR_DIR, compile_c, require_compiler


def run_dump(exe: Path, path: Path, chunk: int = 4096) -> tuple[list[dict], dict]:
    proc = subprocess.run([str(exe), "-c", str(chunk), str(path)], capture_output=True, text=True, check=True)
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    assert "stats" in lines[-1]
    return lines[:-1], lines[-1]["stats"]


@pytest.mark.parametrize("name", sorted(VECTORS))
@pytest.mark.parametrize("chunk", [1, 7, 4096])
def test_c_decoder_passes_vector(ghj_dump: Path, name: str, chunk: int) -> None:
    expected = json.loads((VECTOR_DIR / f"{name}.json").read_text())
    events, stats = run_dump(ghj_dump, VECTOR_DIR / f"{name}.bin", chunk)
    assert events == expected["events"]
    assert stats == expected["stats"]


def _mutations(rng: random.Random, clean: bytes) -> bytes:
    data = bytearray(clean)
    for _ in range(rng.randint(1, 12)):
        kind = rng.random()
        pos = rng.randrange(len(data) + 1)
        if kind < 0.35 and data:  # bit flip
            i = min(pos, len(data) - 1)
            data[i] ^= 1 << rng.randrange(8)
        elif kind < 0.55:  # inserted garbage, zeros included
            data[pos:pos] = bytes(rng.choice([0, rng.randrange(256)]) for _ in range(rng.randint(1, 40)))
        elif kind < 0.8 and data:  # lost bytes
            del data[pos : pos + rng.randint(1, 30)]
        else:  # a delimiter lost or a spurious one
            zeros = [i for i, b in enumerate(data) if b == 0]
            if zeros and rng.random() < 0.5:
                del data[rng.choice(zeros)]
            else:
                data.insert(pos, 0)
    return bytes(data)


def test_c_and_python_agree_on_random_corruptions(ghj_dump: Path, tmp_path: Path) -> None:
    rng = random.Random(20240601)
    clean = b"".join((VECTOR_DIR / f"{n}.bin").read_bytes() for n in ("session", "joints_2d", "limits"))
    for case in range(120):
        data = _mutations(rng, clean) if case % 10 else bytes(rng.randrange(256) for _ in range(3000))
        path = tmp_path / f"case{case}.bin"
        path.write_bytes(data)
        py_events, py_stats = decode_stream(data)
        c_events, c_stats = run_dump(ghj_dump, path, chunk=rng.choice([1, 3, 64, 4096]))
        assert c_events == [e.to_json() for e in py_events], f"case {case}: {path}"
        assert c_stats == py_stats.to_json(), f"case {case}"


def test_small_joint_budget_build(tmp_path: Path) -> None:
    """GHJ_MAX_JOINTS=25 saves RAM: BODY_25 still decodes, larger sets are 'malformed'."""
    cc = require_compiler()
    exe = compile_c(cc, tmp_path / "ghj_dump25", [C_DIR / "ghjoints.c", C_DIR / "tools" / "ghj_dump.c"],
                    ["-DGHJ_MAX_JOINTS=25"])
    events, _ = run_dump(exe, VECTOR_DIR / "session.bin")
    assert events == json.loads((VECTOR_DIR / "session.json").read_text())["events"]
    events, _ = run_dump(exe, VECTOR_DIR / "long_block.bin")
    assert events == [{"error": "malformed"}]
    # 0 joints fit any budget; the protocol's 64 do not fit 25 (each packet refused alone, the stream goes on)
    events, _ = run_dump(exe, VECTOR_DIR / "joints_empty.bin")
    assert events == json.loads((VECTOR_DIR / "joints_empty.json").read_text())["events"]
    events, _ = run_dump(exe, VECTOR_DIR / "joints_max.bin")
    assert events == [{"error": "malformed"}, {"error": "malformed"}]


@pytest.mark.parametrize("name, counts", [("joints_empty", [0, 0, 25]), ("joints_max", [64, 64])])
def test_c_decoder_takes_the_smallest_and_largest_joint_counts(ghj_dump: Path, name: str, counts: list[int]) -> None:
    """Count 0 (no mask byte, no joint) and count 64 (an 8-byte mask) decode in C as in Python, whatever the
    chunking: the vectors firmware ports check against (session 53)."""
    expected = json.loads((VECTOR_DIR / f"{name}.json").read_text())["events"]
    assert [len(e["joints"]) for e in expected] == counts
    for chunk in (1, 3, 4096):
        events, stats = run_dump(ghj_dump, VECTOR_DIR / f"{name}.bin", chunk)
        assert events == expected and stats["malformed"] == 0


def test_header_compiles_as_cpp(tmp_path: Path) -> None:
    import shutil

    cxx = shutil.which("g++") or shutil.which("clang++")
    if cxx is None:
        pytest.skip("no C++ compiler to check the extern \"C\" header")
    src = tmp_path / "use.cpp"
    src.write_text('#include "ghjoints.h"\nint f() { ghj_decoder d; ghj_init(&d); return (int)d.stats.frames; }\n')
    proc = subprocess.run([cxx, "-std=c++11", "-Wall", "-Werror", f"-I{C_DIR}", "-c", str(src), "-o",
                           str(tmp_path / "use.o")], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
