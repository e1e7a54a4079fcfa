"""A ``#:`` doc comment documents the assignment on the line after it; above anything else (a ``def``, a blank
line) documentation tools attach it to nothing, and the constant it was written for goes undocumented."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("calibration", "drivers", "firmware_host", "ghnerf_runtime", "training")


def _assignment_lines(tree: ast.AST) -> set[int]:
    return {node.lineno for node in ast.walk(tree) if isinstance(node, (ast.Assign, ast.AnnAssign))}


def doc_comments_attached_to_nothing(path: Path) -> list[int]:
    """Line numbers (1-based) of the last line of each ``#:`` block in ``path`` not followed by an assignment."""
    text = path.read_text()
    lines = text.splitlines()
    assigned = _assignment_lines(ast.parse(text, str(path)))
    return [n for n, line in enumerate(lines, 1)
            if line.lstrip().startswith("#:") and n + 1 not in assigned
            and not (n < len(lines) and lines[n].lstrip().startswith("#:"))]


@pytest.mark.parametrize("package", PACKAGES)
def test_each_doc_comment_sits_above_the_assignment_it_documents(package):
    orphans = [f"{path.relative_to(ROOT)}:{n}" for path in sorted((ROOT / package).rglob("*.py"))
               for n in doc_comments_attached_to_nothing(path)]
    assert not orphans, f"#: comments attached to nothing (move each above its assignment): {orphans}"
