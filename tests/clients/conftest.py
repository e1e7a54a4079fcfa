"""Fixtures shared by the C client's tests."""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.clients.c_build import C_DIR, compile_c, require_compiler, sanitizer_flags


@pytest.fixture(scope="session")
def ghj_dump(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tools/ghj_dump.c over ghjoints.c, built once with the sanitizers (they catch out-of-bounds reads the
    comparisons alone would miss)."""
    cc = require_compiler()
    tmp = tmp_path_factory.mktemp("ghj_dump")
    return compile_c(cc, tmp / "ghj_dump", [C_DIR / "ghjoints.c", C_DIR / "tools" / "ghj_dump.c"],
                     sanitizer_flags(cc, tmp))
