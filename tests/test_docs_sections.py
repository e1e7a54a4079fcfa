"""Every reference to a doc section names a section that is there.

Code, error messages and docs send the reader to a section as ``docs/runtime.md, "Section title"`` or
``docs/runtime.md ("Section title")`` (error messages use single quotes:
``docs/recording-format.md, 'Image sizes'``), to one of the README's as ``README, "Section title"`` or
``README.md, "Section title"``, and a doc (the README included) to one of its own sections as
``"Section title" below`` or ``above``. A section is a markdown heading or a bold paragraph lead (``**Title.**``,
``**Title** (session N).``), or a paragraph that opens with the title and a stop (``Frame check (per camera``,
``Errors: a failed start``, ``Checked at load, each``). Nothing tied the two together, so a section renamed or
moved to another doc left its references pointing nowhere (session 59: ``"Quantisation"`` and ``"calibration"``).

How a quoted title is matched (``_norm``): case, backticks, runs of white space, trailing ``.:;,``, a trailing
``(session N)`` / ``(sessions N, M)`` and a heading's number (``## 8. VMC output``) are ignored on both sides.
A quoted title may also be the start of a longer one, ending at a word's end (``"Between the cameras"`` for
``## Between the cameras: a line or an orbit (...)``), as long as no other section of that doc starts the same
way; an exact match wins over starts. A paragraph opening matches only in full: the title, then ``:``, ``,``,
``.``, ``;`` or `` (``. A doc's ``"Title" below`` / ``above`` is checked only where the quoted text starts with a
capital, a digit or a backtick, as titles do (``the rows "before the runner-up in a region" above`` quotes a
table's rows); that the section is on the side named is not checked.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# The files that hold such references; Makefile and the systemd units have no suffix to go by.
SCANNED_SUFFIXES = (".py", ".md", ".sh", ".service")
SCANNED_NAMES = ("Makefile",)
# Ignored folders: the venv, git's own, and build output (clients/c/build) that copies the sources.
# this file: its examples of dangling references are made up on purpose
SELF = "tests/test_docs_sections.py"
SKIPPED_DIRS = {".venv", ".git", "__pycache__", "build", "dist", "node_modules", ".pytest_cache", ".hypothesis"}

# docs/<name>.md, "<title>" or 'title' (README, "<title>" and README.md, "<title>" too: the README's sections, which
# the docs send the reader to as often); the title may run onto the next lines (a comment or docstring wrapped).
# Also docs/<name>.md ("<title>"), and with the line broken after the comma (the next line's comment marker
# skipped); a Python string may end just before the title's quote and the next start with it (usb_select.py).
_DOC_REF = re.compile(r"""(?:docs/(?P<doc>[A-Za-z0-9_-]+\.md)|\b(?P<readme>README)(?:\.md)?)"""
                      r"""(?:,(?: |[ \t]*\n[ \t]*(?:(?:#+:?|//|\*)[ \t]*)?)| \()"""
                      r"""(?:"[ \t]*\n[ \t]*")?(?P<q>["'])""")
# "<title>" below / above, inside one doc; a wrapped title has at most one line break.
_LOCAL_REF = re.compile(r'"(?P<title>[A-Z0-9`][^"\n]*(?:\n[^"\n]+)?)" (?P<dir>below|above)\b')
_HEADING = re.compile(r"^#{1,6}\s+(?P<title>.+?)\s*#*\s*$")
# a bold lead: at a line's start, after an optional list marker or quote mark
_BOLD_LEAD = re.compile(r"^\s*(?:[-*+]\s+|\d+\.\s+|>\s*)?\*\*(?P<title>[^*]+?)\*\*")
# a paragraph's opening words up to a stop: "Frame check (per camera", "Errors: a failed start"
_OPENING_STOP = re.compile(r"[:,.;]| \(")
_FENCE = re.compile(r"^\s*(```|~~~)")
_SESSION_SUFFIX = re.compile(r"\s*\(sessions? [0-9][0-9, and-]*\)$")
_HEADING_NUMBER = re.compile(r"^[0-9]+[a-z]?\.\s+")
# a line break inside a title, with what the next line starts with: a comment marker (Python/shell, ``#:``, C), or
# the closing and opening quotes of a Python string continued on the next line
_WRAP_PREFIX = re.compile(r"""["']?[ \t]*\n[ \t]*(?:#+:?|//|\*(?!\*)|["'])?[ \t]*""")
MAX_TITLE_CHARS = 200


#: the repository's front page, referred to as ``README, "Title"`` or ``README.md, "Title"``
README = "README.md"


def _shown(doc: str) -> str:
    """A doc as its references name it: docs/<name>.md, or README.md."""
    return doc if doc == README else f"docs/{doc}"


def _norm(title: str) -> str:
    """A title as compared: no backticks, no case, one space between words, no closing punctuation."""
    text = re.sub(r"\s+", " ", title.replace("`", "")).strip().lower()
    text = _HEADING_NUMBER.sub("", _SESSION_SUFFIX.sub("", text).rstrip(" .:;,"))
    return text


@dataclass(frozen=True)
class Sections:
    """A doc's section titles (headings, bold leads) and its paragraphs' first lines, normalised."""
    titles: tuple[str, ...]
    openings: tuple[str, ...]


def doc_sections(text: str) -> Sections:
    """The sections of a markdown text, outside code fences."""
    titles, openings, in_fence, previous = [], [], False, ""
    for line in text.splitlines():
        if _FENCE.match(line):
            in_fence = not in_fence
        elif not in_fence:
            m = _HEADING.match(line) or _BOLD_LEAD.match(line)
            if m:
                titles.append(_norm(m.group("title")))
            elif not previous.strip() and line.strip() and not line.lstrip().startswith("|"):
                openings.append(re.sub(r"\s+", " ", line.replace("`", "")).strip().lower())
        previous = line
    return Sections(tuple(titles), tuple(openings))


def find_section(title: str, sections: Sections) -> str | None:
    """Why ``title`` names no single one of ``sections`` (None: it does)."""
    want = _norm(title)
    if not want:
        return "an empty title"
    if want in sections.titles:
        return None
    starts = sorted({s for s in sections.titles if s.startswith(want) and not s[len(want)].isalnum()})
    if len(starts) == 1:
        return None
    if starts:
        return f"it starts {len(starts)} sections ({'; '.join(starts)}): quote more of the one meant"
    if any(o.startswith(want) and _OPENING_STOP.match(o, len(want)) for o in sections.openings):
        return None
    return "no heading, bold lead or paragraph opens with that title"


def _title_after(text: str, start: int, quote: str) -> str | None:
    """The quoted title from ``start`` (just past the opening quote) to its closing quote, wrapped lines joined;
    None where no closing quote comes within MAX_TITLE_CHARS."""
    end = text.find(quote, start, start + MAX_TITLE_CHARS + 40)
    if end < 0:
        return None
    title = _WRAP_PREFIX.sub(" ", text[start:end])
    return title if len(title) <= MAX_TITLE_CHARS else None


def references(text: str) -> list[tuple[int, str, str]]:
    """(line, doc name, title) of each ``docs/<name>.md, "<title>"`` in ``text``."""
    found = []
    for m in _DOC_REF.finditer(text):
        title = _title_after(text, m.end(), m.group("q"))
        line = text.count("\n", 0, m.start()) + 1
        doc = m.group("doc") or README
        found.append((line, doc, title if title is not None else ""))
    return found


def local_references(text: str) -> list[tuple[int, str]]:
    """(line, title) of each ``"<title>" below`` / ``above`` in a doc's own text."""
    found = []
    for m in _LOCAL_REF.finditer(text):
        title = _WRAP_PREFIX.sub(" ", m.group("title"))
        found.append((text.count("\n", 0, m.start()) + 1, title))
    return found


def _scanned_files(root: Path):
    for folder, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if d not in SKIPPED_DIRS and not d.endswith(".egg-info"))
        for name in sorted(files):
            if name.endswith(SCANNED_SUFFIXES) or name in SCANNED_NAMES:
                yield Path(folder, name)


def dangling(root: Path) -> list[str]:
    """One line per reference under ``root`` that names a missing doc or a section its doc does not have."""
    sections: dict[str, Sections | None] = {}

    def sections_of(doc: str) -> Sections | None:
        if doc not in sections:
            path = root / doc if doc == README else root / "docs" / doc
            sections[doc] = doc_sections(path.read_text(encoding="utf-8")) if path.is_file() else None
        return sections[doc]

    problems = []
    for path in _scanned_files(root):
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        where = path.relative_to(root).as_posix()
        if where == SELF:
            continue
        for line, doc, title in references(text):
            known = sections_of(doc)
            if known is None:
                problems.append(f'{where}:{line}: {_shown(doc)}, "{title}": no such doc')
                continue
            why = find_section(title, known) if title else "no closing quote within reach"
            if why:
                problems.append(f'{where}:{line}: {_shown(doc)}, "{title}": {why}')
        if (path.parent == root / "docs" and path.suffix == ".md") or path == root / README:
            own = doc_sections(text)
            for line, title in local_references(text):
                why = find_section(title, own)
                if why:
                    problems.append(f'{where}:{line}: "{title}" below/above: {why}')
    return problems


def test_no_section_reference_dangles():
    problems = dangling(REPO)
    assert not problems, f"{len(problems)} references to doc sections that are not there:\n" + "\n".join(problems)


def test_the_references_are_found():
    # the check holds only if it sees the references: the wrapped and the single-quoted forms included
    refs = [r for path in _scanned_files(REPO) for r in references(path.read_text(encoding="utf-8"))]
    assert len(refs) > 250
    text = ('x (docs/runtime.md, "A person at\n    # the frame\'s edge") y docs/recording-format.md, \'Image sizes\''
            ' docs/runtime.md,\n  # "Smoothing" and docs/runtime.md ("Output"; docs/daemon.md, "\n   "\'udev\'')
    assert references(text) == [(1, "runtime.md", "A person at the frame's edge"),
                                (2, "recording-format.md", "Image sizes"), (2, "runtime.md", "Smoothing"),
                                (3, "runtime.md", "Output"), (3, "daemon.md", "udev")]


def _fake_repo(tmp_path: Path, code: str, doc: str) -> Path:
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "runtime.md").write_text(doc, encoding="utf-8")
    (tmp_path / "tool.py").write_text(code, encoding="utf-8")
    return tmp_path


DOC = """# Runtime

## Between the cameras: a line or an orbit (`novel_view.path`)

**Smoothing** (session 12). Text, and "Frame check" below.

```
## not a heading: inside a fence
```

**Frame check.** Text; "Smoothing" above.

## Two people in the working volume

## Two people 0.6 m apart
"""


def test_a_made_up_reference_is_caught(tmp_path):
    code = ('# docs/runtime.md, "Between the cameras"; docs/runtime.md, "`smoothing`"\n'
            'raise ValueError("see docs/runtime.md, \'Frame check\'")\n'
            '# docs/runtime.md, "Matting out the\n#   fog"\n'
            '# docs/runtime.md, "not a heading"\n'
            '# docs/runtime.md, "Two people"; docs/novel-view.md, "Frame check"\n')
    problems = dangling(_fake_repo(tmp_path, code, DOC))
    assert [p.split(": ", 1)[0] for p in problems] == ["tool.py:3", "tool.py:5", "tool.py:6", "tool.py:6"]
    assert "Matting out the fog" in problems[0] and "no heading, bold lead or paragraph" in problems[0]
    assert "inside a fence" not in problems[1] and "no heading, bold lead or paragraph" in problems[1]
    assert "it starts 2 sections" in problems[2]
    assert "no such doc" in problems[3]


def test_a_made_up_local_reference_is_caught(tmp_path):
    root = _fake_repo(tmp_path, "", DOC + '\nSee "Recolouring from the body proxy" above.\n')
    assert dangling(root) == ['docs/runtime.md:17: "Recolouring from the body proxy" below/above: '
                              "no heading, bold lead or paragraph opens with that title"]


@pytest.mark.parametrize("quoted, heading", [
    ("The painter", "## The painter (`novel_view.painter`, since session 30)"),
    ("Lanes that share the cores (session 40)", "**Lanes that share the cores** (session 40)."),
    ("Image sizes", "### Image sizes:"),
    ("VMC output", "## 8. VMC output"),
    ("Frame check", "Text.\n\nFrame check (per camera, on the model input): ..."),
    ("Errors", "Errors: a failed start is ..."),
    ("Frames of another size", "1. Step.\n   **Frames of another size than the rig file's** (since session 58)."),
])
def test_title_normalisation(quoted, heading):
    assert find_section(quoted, doc_sections(heading)) is None


@pytest.mark.parametrize("quoted, doc", [
    ("Frame", "Frame check (per camera)"),           # a paragraph's opening matches only in full
    ("Frame check", "Text\nFrame check (per camera)"),  # not a paragraph's first line
    ("Painter", "## The painter"),
])
def test_what_is_no_section(quoted, doc):
    assert find_section(quoted, doc_sections(doc)) is not None


def test_a_reference_to_the_readme_is_checked_like_a_docs_page(tmp_path):
    # "README, ..." and "README.md, ..." were passed over: a README section renamed left the docs' references dangling
    root = _fake_repo(tmp_path, '# README, "Rig URLs"; README.md, "Pointing it at real\n#   cameras", step 5\n'
                                '# README.md, "Running it on a robot"; README, "The two"\n', DOC)
    (root / "README.md").write_text("# Project\n\n## Pointing it at real cameras\n\n## The two commands\n\n"
                                    "Rig URLs (each backend documents its options).\n\n"
                                    'See "Streaming joints" below.\n', encoding="utf-8")
    problems = dangling(root)
    assert [p.split(": ", 1)[0] for p in problems] == ["README.md:9", "tool.py:3"], problems
    assert '"Streaming joints" below/above: no heading' in problems[0]
    assert 'README.md, "Running it on a robot": no heading' in problems[1]
    assert references('see README, "Rig URLs" and README.md ("Layout")') == [(1, "README.md", "Rig URLs"),
                                                                            (1, "README.md", "Layout")]
