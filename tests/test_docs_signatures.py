"""Every function signature or call the docs quote, `name(a, b, *, c=None)` or `level_rig(rig, pitch_deg=...)`, fits
the code: each keyword it names is a parameter of that function, and a signature (a span with a bare ``*``) names
the positional parameters before the ``*`` and all of them in the code's order, the keyword-only ones after it.

docs/metrics.md heads its sections with the metric's signature, docs/rig-file.md lists the import and export
functions', docs/geometry.md the triangulation's, docs/runtime.md the keywords of ``Estimator.estimate``; a reader
calls them as written, and a renamed parameter leaves the doc's call raising ``TypeError``.
tests/test_docs_commands.py checks what a doc's commands pass a program; this checks what its spans pass a function
(session 64).

A span counts when it is ``name(...)`` (``Class.name`` or ``module.name`` too) holding a ``*`` or a ``name=value``;
its name is looked up among the functions and methods the project's packages define (read with :mod:`ast`, nothing
imported): one defined by none of them (``DataLoader``, depthai's) is another library's and skipped, as is a name
defined more than once unless the span's ``Class.`` prefix picks one. Without a ``*`` the span may be a call, whose
bare items are values (``estimate(pair, ...)``), so only its keywords are checked. ``**kw``, ``...`` and argument
expressions (``ZjuConfig(...)``) are not checked by name. About 1 s.
"""
from __future__ import annotations

import ast
import functools
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.test_docs_commands import code_spans, doc_files

REPO = Path(__file__).resolve().parents[1]
#: the packages whose functions the docs quote
PACKAGES = ("ghnerf_runtime", "drivers", "calibration", "firmware_host", "training")
_SIGNATURE = re.compile(r"^(?:(?P<owner>[\w.]+)\.)?(?P<name>\w+)\((?P<params>.*)\)$")
_IDENTIFIER = re.compile(r"^[A-Za-z_]\w*$")


@dataclass(frozen=True)
class Defined:
    """A function as the code defines it: where, its owner (class or module), its parameters by kind."""

    where: str
    owner: str
    positional: tuple[str, ...]  # may be passed by position (self/cls left out)
    keyword_only: tuple[str, ...]
    takes_kwargs: bool

    @property
    def order(self) -> tuple[str, ...]:
        return self.positional + self.keyword_only


def _defined(node: ast.FunctionDef | ast.AsyncFunctionDef, where: str, owner: str) -> Defined:
    args = node.args
    positional = [a.arg for a in args.posonlyargs + args.args]
    if owner[:1].isupper() and positional and positional[0] in ("self", "cls"):
        positional = positional[1:]
    return Defined(where, owner, tuple(positional), tuple(a.arg for a in args.kwonlyargs), args.kwarg is not None)


@functools.lru_cache(maxsize=1)
def project_functions(repo: Path = REPO) -> dict[str, list[Defined]]:
    """name -> every top-level function and class method of that name in the project's packages."""
    found: dict[str, list[Defined]] = {}
    for package in PACKAGES:
        for path in sorted((repo / package).rglob("*.py")):
            module = ".".join(path.relative_to(repo).with_suffix("").parts)
            for node in ast.parse(path.read_text(encoding="utf-8")).body:
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    found.setdefault(node.name, []).append(_defined(node, f"{module}:{node.lineno}", module))
                elif isinstance(node, ast.ClassDef):
                    for item in node.body:
                        if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                            found.setdefault(item.name, []).append(
                                _defined(item, f"{module}:{item.lineno}", node.name))
    return found


def _items(params: str) -> list[str]:
    """The span's comma-separated items, commas inside brackets and quotes kept."""
    items, depth, quote, current = [], 0, "", ""
    for char in params:
        if quote:
            quote = "" if char == quote else quote
        elif char in "\"'":
            quote = char
        elif char in "([{":
            depth += 1
        elif char in ")]}":
            depth -= 1
        elif char == "," and depth == 0:
            items.append(current.strip())
            current = ""
            continue
        current += char
    if current.strip():
        items.append(current.strip())
    return items


def signature_problems(span: str, functions: dict[str, list[Defined]]) -> list[str]:
    """What a quoted signature says that its function does not have; [] for a span that is none or is right."""
    match = _SIGNATURE.match(span)
    if not match or not re.search(r"\*|\w=", match.group("params")):
        return []
    owner, name = match.group("owner"), match.group("name")
    candidates = functions.get(name, [])
    if owner:
        last = owner.rsplit(".", 1)[-1]
        candidates = [d for d in candidates if d.owner == last or d.owner == owner
                      or d.owner.endswith("." + last)] or candidates
    if len(candidates) != 1:
        return []  # another library's, or several of that name with nothing to pick one
    defined = candidates[0]
    items = _items(match.group("params"))
    signature = "*" in items  # else possibly a call: its bare items are values, not parameter names
    problems, keyword_only, shown = [], False, []
    for item in items:
        if item == "*":
            keyword_only = True
            continue
        param, keyword = item.split("=", 1)[0].strip(), "=" in item
        if not _IDENTIFIER.match(param) or not (keyword or signature):
            continue  # **kw, ..., an argument expression, a call's value
        if param not in defined.order:
            if not defined.takes_kwargs:
                problems.append(f"{param!r}: no such parameter (it has {', '.join(defined.order)})")
            continue
        if signature and not keyword_only and param in defined.keyword_only:
            problems.append(f"{param!r} is keyword-only in the code: the signature needs `*,` before it")
        shown.append(param)
    if signature and shown != sorted(shown, key=defined.order.index):
        problems.append(f"parameters out of order: the code's order is {', '.join(defined.order)}")
    return [f"{span} ({defined.where}): {p}" for p in problems]


def quoted_signatures() -> list[tuple[str, str]]:
    return [(f"{doc.relative_to(REPO)}:{line}", span) for doc in doc_files() for line, span in
            code_spans(doc.read_text(encoding="utf-8")) if _SIGNATURE.match(span)]


def test_every_signature_a_doc_quotes_is_the_code_s():
    functions = project_functions()
    problems = [f"{where}: {p}" for where, span in quoted_signatures() for p in signature_problems(span, functions)]
    assert not problems, "\n".join(problems)


def test_the_docs_quote_signatures_of_project_functions():
    """The check has something to check: the metrics page's and the rig file page's signatures are found."""
    functions = project_functions()
    checked = {span.split("(", 1)[0] for _, span in quoted_signatures()
               if _SIGNATURE.match(span) and len(functions.get(_SIGNATURE.match(span).group("name"), [])) == 1}
    assert {"acceleration_error", "masked_psnr", "read_opencv_rig", "write_anipose_toml"} <= checked


@pytest.mark.parametrize("span, says", [
    ("acceleration_error(pred_3d, true_3d, valid, pred_valid=None, *, consecutive=None)", "keyword-only"),
    ("acceleration_error(pred_3d, true_3d, valid, *, pred_vald=None)", "no such parameter"),
    ("level_rig(rig, camera_height=1.4)", "no such parameter"),  # a call's keyword
    ("acceleration_error(pred_3d, valid, true_3d, *, consecutive=None)", "out of order"),
    ("masked_psnr(pred, target, mask, data_rang=1.0)", "no such parameter"),
])
def test_a_drifted_signature_is_named(span, says):
    problems = signature_problems(span, project_functions())
    assert problems and says in problems[0], problems


@pytest.mark.parametrize("span", [
    "acceleration_error(pred_3d, true_3d, valid, *, pred_valid=None, consecutive=None)",
    "acceleration_error(pred_3d, true_3d, valid, pred_valid=None, consecutive=None)",  # a call: keywords by name
    "Estimator.estimate(pair, novel_view=NovelViewRequest(...))",  # `pair` is the call's value
    "DataLoader(ds, batch_size=None, ...)",  # torch's
    "mpjpe(pred_3d, true_3d, valid)",  # no default and no *: a call, not a signature
    "open_sink(url, **kw)",
])
def test_a_right_or_foreign_signature_passes(span):
    assert signature_problems(span, project_functions()) == []
