"""No ``except`` clause is shadowed by an earlier one of the same ``try`` that catches its class or a base of it.

Such a clause is dead code that reads as handling its case: ``drivers/base.py`` had ``except EndOfStream``
(flush the pairer) after ``except RigDisconnectedError`` (reset it), and EndOfStream is a RigDisconnectedError,
so the end of a recording always took the disconnect's branch. Each module is imported and its handlers' names
resolved in its namespace; a handler that names no class (a computed tuple) is left out.
"""
from __future__ import annotations

import ast
import builtins
import importlib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: The device's packages (``training`` needs torch, which the device never loads).
PACKAGES = ("drivers", "firmware_host", "ghnerf_runtime", "calibration")


def _modules() -> list[tuple[str, Path]]:
    out = []
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            out.append((".".join(parts[:-1] if parts[-1] == "__init__" else parts), path))
    return out


def _classes(node: ast.expr, namespace: dict, path: Path) -> tuple[type, ...]:
    try:
        value = eval(compile(ast.Expression(node), str(path), "eval"), namespace)  # noqa: S307 - our own source
    except Exception:  # noqa: BLE001 - a name bound only inside a function: not resolvable here
        return ()
    values = value if isinstance(value, tuple) else (value,)
    return values if all(isinstance(v, type) for v in values) else ()


def shadowed_handlers(module: str, path: Path, root: Path = REPO) -> list[str]:
    """``path:line: X is caught earlier by Y (line n)`` for each handler an earlier one of its ``try`` shadows."""
    namespace = {**vars(builtins), **vars(importlib.import_module(module))}
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if not isinstance(node, ast.Try):
            continue
        earlier: list[tuple[type, int]] = []
        for handler in node.handlers:
            classes = _classes(handler.type, namespace, path) if handler.type is not None else ()
            for cls in classes:
                for base, line in earlier:
                    if issubclass(cls, base):
                        found.append(f"{path.relative_to(root)}:{handler.lineno}: {cls.__name__} is caught earlier "
                                     f"by {base.__name__} (line {line})")
            earlier += [(cls, handler.lineno) for cls in classes]
    return found


def test_the_check_finds_a_shadowed_handler(tmp_path, monkeypatch):
    source = ("try:\n    pass\nexcept LookupError:\n    pass\nexcept KeyError:\n    pass\n"
              "except (OSError, ValueError):\n    pass\n")
    (tmp_path / "shadow_sample.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    found = shadowed_handlers("shadow_sample", tmp_path / "shadow_sample.py", root=tmp_path)
    assert found == ["shadow_sample.py:5: KeyError is caught earlier by LookupError (line 3)"]


@pytest.mark.parametrize("module, path", _modules(), ids=lambda v: v if isinstance(v, str) else "")
def test_no_except_clause_is_shadowed(module, path):
    try:
        shadowed = shadowed_handlers(module, path)
    except ImportError as e:  # an optional vendor library missing on this machine: nothing to resolve with
        pytest.skip(f"{module}: {e}")
    assert not shadowed, "\n".join(shadowed)
