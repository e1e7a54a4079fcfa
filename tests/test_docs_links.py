"""Every link into a doc's sections lands on a heading that is there.

The long docs pages open with a Contents list of ``[Title](#anchor)`` links (session 61), and a few pages link to
another's section (``[protocol.md](protocol.md#6-bandwidth)``). GitHub makes a heading's anchor from its text, so a
heading renamed or renumbered leaves such a link pointing at the page's top without a word: ``#vmc-output`` in
docs/protocol.md pointed at nothing since the heading became ``## 8. VMC output`` (anchor ``8-vmc-output``).

This test reads README.md and docs/**/*.md, and checks each Markdown link outside code (fenced blocks and
backtick spans): an in-page ``(#anchor)`` must be the anchor of one of the page's headings; a relative
``(file.md#anchor)`` must name a file that exists and, where it has an anchor, one of that file's headings; a
relative link without an anchor must name a file that exists. Web links (``https:``, ``mailto:``) are not followed.
The long pages with a Contents list (``CONTENTS_PAGES``) must link each of their ``##`` sections from it, so a
section added later is not left out of the list.

GitHub's anchor of a heading (:func:`github_anchor`): the heading's text as rendered (backticks, emphasis marks and
link targets gone), lower case, every character that is not a letter, a digit, ``_``, ``-`` or a space dropped,
each space made ``-``; a second heading with the same anchor gets ``-1``, a third ``-2``. An HTML ``<a id="x">``
(or ``name=``) in the page is an anchor too.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: the pages whose links are checked (globs, relative to the repository)
DOC_GLOBS = ("README.md", "docs/**/*.md")

_FENCE = re.compile(r"^\s*(```|~~~)")
_HEADING = re.compile(r"^ {0,3}#{1,6}\s+(?P<title>.+?)\s*#*\s*$")
_HTML_ANCHOR = re.compile(r"""<a\s+(?:id|name)\s*=\s*["'](?P<anchor>[^"']+)["']""", re.IGNORECASE)
_CODE_SPAN = re.compile(r"(`+).*?\1")
# ](target) or ](target "title"): the target has no space or closing parenthesis
_LINK_TARGET = re.compile(r"\]\((?P<target><[^>]*>|[^)\s]*)(?:\s+\"[^\"]*\")?\)")
_INLINE_LINK = re.compile(r"!?\[(?P<text>[^\]]*)\]\([^)]*\)")
_HTML_TAG = re.compile(r"<[^>]+>")
_NOT_IN_ANCHOR = re.compile(r"[^\w\- ]")
_EXTERNAL = re.compile(r"^[a-z][a-z0-9+.-]*:", re.IGNORECASE)


def github_anchor(title: str) -> str:
    """The anchor GitHub gives a heading of this text (before a repeat's ``-N`` suffix)."""
    text = _INLINE_LINK.sub(lambda m: m.group("text"), title)
    text = _HTML_TAG.sub("", text).replace("`", "").replace("*", "")
    return _NOT_IN_ANCHOR.sub("", text.strip().lower()).replace(" ", "-")


def _outside_fences(text: str):
    """(line number, line) of each line of ``text`` that is not inside a fenced code block."""
    in_fence = False
    for number, line in enumerate(text.splitlines(), 1):
        if _FENCE.match(line):
            in_fence = not in_fence
        elif not in_fence:
            yield number, line


def anchors(text: str) -> set[str]:
    """Every anchor a Markdown page has: its headings' (repeats numbered) and its HTML ``<a id=...>``."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    for _, line in _outside_fences(text):
        m = _HEADING.match(line)
        if m:
            anchor = github_anchor(m.group("title"))
            repeat = seen.get(anchor, 0)
            seen[anchor] = repeat + 1
            found.add(anchor if repeat == 0 else f"{anchor}-{repeat}")
        found.update(a.group("anchor") for a in _HTML_ANCHOR.finditer(line))
    return found


def link_targets(text: str) -> list[tuple[int, str]]:
    """(line, target) of each Markdown link in ``text``, outside fenced blocks and backtick spans."""
    found = []
    for number, line in _outside_fences(text):
        for m in _LINK_TARGET.finditer(_CODE_SPAN.sub("", line)):
            found.append((number, m.group("target").strip("<>")))
    return found


def broken_links(page: Path, root: Path) -> list[str]:
    """One line per link of ``page`` whose file or anchor is not there."""
    problems = []
    where = page.relative_to(root).as_posix()
    own = page.read_text(encoding="utf-8")
    for line, target in link_targets(own):
        if not target or _EXTERNAL.match(target):
            continue
        path_part, _, anchor = target.partition("#")
        linked = (page.parent / path_part).resolve() if path_part else page
        if not linked.exists():
            problems.append(f"{where}:{line}: ({target}): no file {path_part}")
        elif anchor and linked.suffix == ".md" and anchor not in anchors(linked.read_text(encoding="utf-8")):
            problems.append(f"{where}:{line}: ({target}): {linked.name} has no heading with the anchor #{anchor}")
    return problems


def _pages(root: Path) -> list[Path]:
    return sorted({p for pattern in DOC_GLOBS for p in root.glob(pattern)})


def test_every_section_link_in_the_docs_lands_on_a_heading():
    problems = [p for page in _pages(REPO) for p in broken_links(page, REPO)]
    assert not problems, f"{len(problems)} links to sections or files that are not there:\n" + "\n".join(problems)


def test_the_links_are_found():
    # the check holds only if it sees the links: the Contents lists and the cross-page ones
    targets = [t for page in _pages(REPO) for _, t in link_targets(page.read_text(encoding="utf-8"))]
    assert sum(t.startswith("#") for t in targets) > 80
    assert "protocol.md#6-bandwidth" in targets


#: the long pages that open with a Contents list (session 61); a ## section added later must be listed too
CONTENTS_PAGES = ("docs/runtime.md", "docs/training.md", "docs/turn-search.md", "docs/two-people.md")


def contents_list(text: str) -> str:
    """The page's Contents list: the first list after its ``**Contents**`` lead, up to the blank line ending it
    ("" where the page has none)."""
    lines = text.splitlines()
    start = next((n for n, line in enumerate(lines) if line.startswith("**Contents**")), len(lines))
    first = next((n for n in range(start, len(lines)) if lines[n].startswith("- ")), len(lines))
    end = next((n for n in range(first, len(lines)) if not lines[n].strip()), len(lines))
    return "\n".join(lines[first:end])


def unlisted_sections(text: str) -> list[str]:
    """The ## headings of a page that its Contents list does not link (a link elsewhere on the page, "see
    [Limits](#limits) below", does not list a section)."""
    linked = {target[1:] for _, target in link_targets(contents_list(text)) if target.startswith("#")}
    headings = [m.group("title") for _, line in _outside_fences(text)
                if line.startswith("## ") and (m := _HEADING.match(line))]
    return [title for title in headings if github_anchor(title) not in linked]


@pytest.mark.parametrize("page", CONTENTS_PAGES)
def test_the_contents_list_links_every_section(page):
    missing = unlisted_sections((REPO / page).read_text(encoding="utf-8"))
    assert not missing, f"{page}: add these ## sections to the Contents list at its top: {missing}"


@pytest.mark.parametrize("heading, anchor", [
    ("8. VMC output", "8-vmc-output"),
    ("STATUS (0x02) — 16 bytes", "status-0x02--16-bytes"),
    ("Choosing GHJ_MAX_JOINTS", "choosing-ghj_max_joints"),
    ("The skeleton prior (`joints3d.skeleton_prior`, on with the shipped model)",
     "the-skeleton-prior-joints3dskeleton_prior-on-with-the-shipped-model"),
    ("Where a pair's time goes (session 58, a 2-core AVX2 host)",
     "where-a-pairs-time-goes-session-58-a-2-core-avx2-host"),
    ("The novel view (docs/novel-view.md)", "the-novel-view-docsnovel-viewmd"),
    ("See [the spec](protocol.md) **now**", "see-the-spec-now"),
])
def test_github_anchor(heading, anchor):
    assert github_anchor(heading) == anchor


def test_a_repeated_heading_is_numbered_and_fences_are_skipped():
    text = "# Page\n\n## Results\n\n```\n## Results\n```\n\n## Results\n\n<a id=\"kept\"></a>\n"
    assert anchors(text) == {"page", "results", "results-1", "kept"}


def test_made_up_broken_links_are_caught(tmp_path):
    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "other.md").write_text("# Other\n\n## 2. Bandwidth\n", encoding="utf-8")
    (docs / "page.md").write_text(
        "# Page\n\n## Known gaps\n\n"
        "[ok](#known-gaps) [ok](other.md#2-bandwidth) [ok](other.md) [web](https://example.com/#x)\n"
        "[gone](#bandwidth) [gone](other.md#bandwidth) [gone](missing.md#x)\n"
        "`[code](#not-a-link)`\n\n```\n[fenced](#not-a-link)\n```\n", encoding="utf-8")
    problems = broken_links(docs / "page.md", tmp_path)
    assert [p.split(": (")[1].split(")")[0] for p in problems] == ["#bandwidth", "other.md#bandwidth", "missing.md#x"]
    assert all(p.startswith("docs/page.md:6: ") for p in problems)


def test_a_section_missing_from_the_contents_is_named():
    text = "# Page\n\n**Contents**\n\n- [Results](#results)\n\n## Results\n\n## Known gaps\n\n### Detail\n"
    assert unlisted_sections(text) == ["Known gaps"]


def test_a_section_linked_from_the_body_but_not_the_contents_is_named():
    # any in-page link counted as listing it: a section added later and pointed at from a paragraph passed
    text = ("# Page\n\n**Contents** (a lead\nover two lines)\n\n- [Results](#results)\n  - [Results](#results)\n\n"
            "## Results\n\nSee [Known gaps](#known-gaps) below.\n\n## Known gaps\n")
    assert unlisted_sections(text) == ["Known gaps"]
    assert unlisted_sections("# Page\n\n## Results\n\n[Results](#results)\n") == ["Results"]  # no Contents at all


#: paths of the development host that a clone of the repository does not have, by what they are: its work tree and
#: design notes (``/work/...``: ``git clone /work/main``, ``/work/mm/runs``, ``/work/shared/design``), the review
#: worktrees (``/tmp/wt_*``) and its users' home folders; a placeholder such as ``/home/<user>/`` is not one
_REST_OF_PATH = r"[^\s`'\"()\[\]]*"
HOST_ONLY_PATHS = (("/work/", re.compile(r"(?<![\w.~-])/work/" + _REST_OF_PATH)),
                   ("/tmp/wt_", re.compile(r"(?<![\w.~-])/tmp/wt_" + _REST_OF_PATH)),
                   ("a home folder", re.compile(r"(?<![\w.~-])(?:/root/|/home/[A-Za-z0-9_.-]+/)" + _REST_OF_PATH)))


def host_only_references(page: Path, root: Path) -> list[str]:
    """One line per mention in ``page`` of a path only the development host has: a reader of a clone can neither
    open it nor run a command that names it."""
    where = page.relative_to(root).as_posix()
    return [f"{where}:{number}: {name} is not in the repository: {match.group(0)!r}" for number, line in
            enumerate(page.read_text(encoding="utf-8").splitlines(), 1) for name, pattern in HOST_ONLY_PATHS
            for match in pattern.finditer(line)]


def test_no_doc_sends_the_reader_to_the_development_host():
    # docs/model.md sent the reader to /work/shared/design/MODEL.md for its background; docs/training.md's
    # commands cloned /work/main and wrote to /work/mm/models until session 62
    problems = [p for page in [*_pages(REPO), REPO / "models" / "MODEL_CARD.md"]
                for p in host_only_references(page, REPO)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("line, name", [
    ("Background: `/work/shared/design/MODEL.md`.", "/work/"),
    ("git clone /work/main /tmp/mm39 && ln -s /work/main/.venv .venv", "/work/"),
    ("python -m training.pipeline --out /work/mm/models", "/work/"),
    ("cd /tmp/wt_K && make test", "/tmp/wt_"),
    ("BindReadOnlyPaths=/home/me/models", "a home folder"),
    ("ls /root/.cache/ghnerf-bench", "a home folder"),
])
def test_a_made_up_host_only_reference_is_caught(tmp_path, line, name):
    (tmp_path / "README.md").write_text(f"# R\n\n{line}\n", encoding="utf-8")
    found = host_only_references(tmp_path / "README.md", tmp_path)
    assert found and all(f.startswith(f"README.md:3: {name} is not in the repository") for f in found), found


@pytest.mark.parametrize("line", [
    "git clone /path/to/clone /tmp/mm39 && ln -s /path/to/clone/.venv .venv",  # a named placeholder
    "python -m training.pipeline --out out/fresh/models --data out/fresh/data",  # the clone's own folders
    "BindReadOnlyPaths=/home/<user>/models",  # a placeholder for the reader's home folder
    "the bench's cache, `~/.cache/ghnerf-bench`; scratch in /tmp/priorpose/d0",  # the reader's own folders
    "models/work/x, runs/work/y and src/tmp/wt_z",  # a folder named work or wt_ inside the repository
])
def test_a_path_every_clone_or_reader_has_is_not_flagged(tmp_path, line):
    (tmp_path / "README.md").write_text(f"# R\n\n{line}\n", encoding="utf-8")
    assert host_only_references(tmp_path / "README.md", tmp_path) == []
