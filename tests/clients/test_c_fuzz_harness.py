"""The fuzz harness builds, holds its contracts on the vectors, and run_fuzz.sh works when clang is there."""
from __future__ import annotations

import random
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from firmware_host.protocol import Hello, Joints, MsgType, encode, make_header
from tests.clients.c_build import C_DIR, VECTOR_DIR, compile_c, require_compiler, sanitizer_flags


def test_harness_replays_vectors_and_random_inputs(tmp_path: Path) -> None:
    cc = require_compiler()
    exe = compile_c(cc, tmp_path / "fuzz_replay", [C_DIR / "ghjoints.c", C_DIR / "fuzz" / "fuzz_ghjoints.c"],
                    ["-DGHJ_FUZZ_STANDALONE", *sanitizer_flags(cc, tmp_path)])
    rng = random.Random(7)
    inputs = sorted(VECTOR_DIR.glob("*.bin"))
    for i in range(40):
        p = tmp_path / f"rand{i}.bin"
        p.write_bytes(bytes(rng.choice([0, 1, 0xFF, rng.randrange(256)]) for _ in range(rng.randrange(2000))))
        inputs.append(p)
    proc = subprocess.run([str(exe), *map(str, inputs)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert f"replayed {len(inputs)} inputs" in proc.stdout


def _joints_then_hello() -> bytes:
    """A JOINTS packet whose bytes fill the union, then a HELLO with fewer cameras than slots."""
    xyz = np.full((25, 3), 0x4141, np.int16)
    joints = Joints(make_header(MsgType.JOINTS, 1, 10, 20), 0, xyz, np.full(25, 0x41, np.uint8), np.zeros(25, bool))
    hello = Hello(make_header(MsgType.HELLO, 1, 10, 30), 1, 0, 25, 0, 0, "rig", ("left",))
    return encode(joints) + encode(hello)


def test_harness_checks_camera_names_past_n_cameras(tmp_path: Path) -> None:
    """The decoder clears the HELLO name slots it does not fill (they share the union with the joints); the
    harness holds it to that, so a regression shows up as a crash, not as stale bytes a caller reads."""
    cc = require_compiler()
    exe = compile_c(cc, tmp_path / "fuzz_replay", [C_DIR / "ghjoints.c", C_DIR / "fuzz" / "fuzz_ghjoints.c"],
                    ["-DGHJ_FUZZ_STANDALONE", *sanitizer_flags(cc, tmp_path)])
    case = tmp_path / "joints_then_hello.bin"
    case.write_bytes(_joints_then_hello())
    proc = subprocess.run([str(exe), str(case)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "replayed 1 inputs" in proc.stdout


def _libfuzzer_clang() -> str | None:
    for c in ("clang", "clang-19", "clang-18", "clang-17", "clang-16", "clang-15", "clang-14"):
        if shutil.which(c):
            return c
    return None


@pytest.mark.slow
def test_run_fuzz_script_for_a_few_seconds(tmp_path: Path) -> None:
    if _libfuzzer_clang() is None:
        pytest.skip("no clang: libFuzzer needs clang (apt-get install clang)")
    # A reproducer left by an earlier run must not count as a crash of this one.
    (tmp_path / "crashes").mkdir()
    (tmp_path / "crashes" / "crash-earlier-run").write_bytes(b"\x00")
    proc = subprocess.run([str(C_DIR / "fuzz" / "run_fuzz.sh"), "3"], capture_output=True, text=True,
                          env={"PATH": "/usr/bin:/bin:/usr/local/bin", "OUT": str(tmp_path)}, timeout=120)
    if proc.returncode == 77:
        pytest.skip(proc.stderr.strip())
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "crashes=0" in proc.stdout and "run_fuzz: OK" in proc.stdout
    assert (tmp_path / "crashes.prev" / "crash-earlier-run").exists()


@pytest.mark.parametrize(("fails_on", "status"), [("fuzz_ghjoints.c", 1), ("probe.c", 77)])
def test_run_fuzz_fails_when_the_harness_does_not_build(tmp_path: Path, fails_on: str, status: int) -> None:
    """77 (skip) means "no libFuzzer here" only: a clang that builds a fuzzer but not this harness (a compile
    error in it or in ghjoints.c) fails the run. Every build failure used to give 77, so CI skipped it."""
    cc = tmp_path / "fake-clang"
    cc.write_text(f"""#!/bin/sh
out=
for a in "$@"; do
    case "$a" in *{fails_on}) echo "fake-clang: error in $a" >&2; exit 1 ;; esac
    [ "$prev" = -o ] && out=$a
    prev=$a
done
: > "$out"
""")
    cc.chmod(0o755)
    proc = subprocess.run([str(C_DIR / "fuzz" / "run_fuzz.sh"), "1"], capture_output=True, text=True, timeout=60,
                          env={"PATH": "/usr/bin:/bin", "CC": str(cc), "OUT": str(tmp_path / "out")})
    assert proc.returncode == status, proc.stdout + proc.stderr
    if status == 1:
        assert "fake-clang: error in" in proc.stderr and "harness does not build" in proc.stderr
