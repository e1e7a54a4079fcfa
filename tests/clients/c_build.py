"""Compile the C decoder and its tools for the tests (gcc or cc into a temp dir)."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import warnings
from pathlib import Path
from typing import Optional

import pytest

ROOT = Path(__file__).resolve().parents[2]
C_DIR = ROOT / "clients" / "c"
VECTOR_DIR = ROOT / "tests" / "vectors" / "joint_stream"
C_DECODER_DOC = ROOT / "docs" / "c-decoder.md"
STRICT = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Wpedantic", "-Wconversion", "-Wsign-conversion",
          "-Wshadow", "-Wcast-qual", "-Werror"]


def c_compiler() -> Optional[str]:
    for cc in ("gcc", "cc", "clang"):
        if shutil.which(cc):
            return cc
    return None


#: Set (to anything but 0) where the C client must be tested: a missing compiler or sanitizer then fails the
#: run instead of skipping or building without them (.ci/run sets it; a fresh machine without gcc still passes).
REQUIRE_ENV = "GHJ_REQUIRE_CC"


def _required() -> bool:
    return os.environ.get(REQUIRE_ENV, "0") not in ("", "0")


def require_compiler() -> str:
    cc = c_compiler()
    if cc is None:
        if _required():
            pytest.fail(f"no C compiler (gcc, cc or clang) on PATH, and {REQUIRE_ENV} says the C client must be tested")
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
    proc = subprocess.run([cc, *flags, str(probe), "-o", str(tmp / "probe")], capture_output=True, text=True)
    if proc.returncode == 0:
        return flags
    if _required():
        pytest.fail(f"{cc} cannot link AddressSanitizer/UBSan here, and {REQUIRE_ENV} says the C client must be tested "
                    f"with them: {proc.stderr.strip()[:300]}")
    warnings.warn(f"{cc} cannot link AddressSanitizer/UBSan here: the C tests run without them", stacklevel=2)
    return []


def doc_code_blocks(lang: str) -> list[str]:
    """The ```lang code blocks of docs/c-decoder.md, in order (the tests compile and run them)."""
    return re.findall(rf"```{lang}\n(.*?)```", C_DECODER_DOC.read_text(), re.S)
