"""Compile the C decoder and its tools for the tests (gcc or cc into a temp dir)."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path
from typing import Optional

import pytest

ROOT = Path(__file__).resolve().parents[2]
C_DIR = ROOT / "clients" / "c"
VECTOR_DIR = ROOT / "tests" / "vectors" / "joint_stream"
STRICT = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wsign-conversion",
          "-Wshadow", "-Wcast-qual", "-Werror"]


def c_compiler() -> Optional[str]:
    for cc in ("gcc", "cc", "clang"):
        if shutil.which(cc):
            return cc
    return None


def require_compiler() -> str:
    cc = c_compiler()
    if cc is None:
        pytest.skip("no C compiler (gcc, cc or clang) on PATH")
    return cc


def compile_c(cc: str, out: Path, sources: list[Path], extra: list[str] = ()) -> Path:  # type: ignore[assignment]
    cmd = [cc, *STRICT, *extra, f"-I{C_DIR}", *map(str, sources), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr}"
    assert proc.stderr == "", proc.stderr  # warnings are errors anyway; nothing else expected
    return out


def sanitizer_flags(cc: str, tmp: Path) -> list[str]:
    """ASan+UBSan flags if this compiler can link them here, else []."""
    flags = ["-fsanitize=address,undefined", "-fno-sanitize-recover=undefined", "-g"]
    probe = tmp / "probe.c"
    probe.write_text("int main(void) { return 0; }\n")
    ok = subprocess.run([cc, *flags, str(probe), "-o", str(tmp / "probe")], capture_output=True).returncode == 0
    return flags if ok else []
