"""Every command the docs quote still runs as written: its program exists and takes every option it is given.

The project's rule is that each figure in README.md and docs/ comes from a command named beside it that anyone can
rerun; options get renamed and scripts retired, and a doc quoting the old spelling stays silent until someone
pastes it. This test reads the code spans of the docs (inline `code` and fenced blocks), picks out the commands
that start one of the project's programs, and checks each against the program itself:

* ``python benchmarks/X.py ...`` / ``python -m training.X ...`` (any project package): the script or module
  exists and has a command line (a ``__main__`` guard, or a package's ``__main__.py``);
* the console scripts of pyproject.toml's ``[project.scripts]`` (``ghnerf-bench``, ``ghcal``, ...);
* for all of those: each subcommand and each ``--option`` is one its argparse parser (the subcommand's, after
  one) accepts, by its full name (argparse's unique prefixes are refused: see :func:`_lookup`);
* ``make TARGET VAR=...``: the target is in that Makefile (``-C DIR`` honoured) and the Makefile reads VAR;
* ``bash X.sh ...`` or ``X.sh ...``: the script exists, reads each ``VAR=...`` put before it and names each option;
* ``VAR=1 make test``: something in the project reads VAR;
* a span of options without their program (`--recipe cpu`, `cache --no-relit`): some program of the project
  (some program's ``cache`` subcommand) takes each; a span that is a project file's path (`tests/test_x.py`):
  the file is there;
* the commands the Makefile's recipes and ``training/*.sh`` run, as the docs' are.
* a doc's fenced Python blocks: each ``from PACKAGE.module import name`` of a project package names a module
  and an attribute that exist (docs/training.md's quantize snippet, the runtime's and the README's examples).

The parser is taken from the program's own ``main`` without running it: ``ArgumentParser.parse_args`` is
replaced, for the call, by one that stops with the parser it was called on, so what is checked is exactly what
the program parses (no parser copied here, no ``--help`` subprocess; the training tools parse before torch loads).

Placeholders (``<net>``, ``FILE``, ``$OUT``, ``benchmarks/NAME.py``), ``...``, ``[optional]`` brackets, ``\\``
continuations, a block's shell variables (``P="--out ..."`` then ``python -m training.pipeline $P``), env-var
prefixes, ``/usr/bin/time -v``-style wrappers (``nice -n 5``, ``timeout --preserve-status -s TERM 25``),
``sudo -u USER`` and prose's ``--a/--b``, ``--[no-]x``, ``--novel-*`` are allowed for; a span that only names a
program checks that the program exists. About 4 s on two cores (4.3 s in session 64; 18 s in session 53), most of it importing each program's
module once.
"""
from __future__ import annotations

import argparse
import ast
import contextlib
import functools
import importlib
import importlib.util
import inspect
import re
import shlex
import signal
import sys
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from unittest import mock

import pytest

REPO = Path(__file__).resolve().parents[1]

#: the docs whose commands are checked (globs, relative to the repository)
DOC_GLOBS = ("README.md", "docs/**/*.md", "models/MODEL_CARD.md", "training/**/*.md", "clients/**/README*")
#: fenced blocks in these languages are code or data, not commands
NOT_SHELL = {"python", "py", "json", "jsonc", "toml", "yaml", "yml", "c", "h", "cpp", "ini", "xml", "text"}
#: words that run the rest of the line as the command (`sudo make ...`, `/usr/bin/time -v make model`)
WRAPPERS = {"sudo", "time", "/usr/bin/time", "nohup", "exec", "env", "nice", "command"}
#: a shell operator that ends one command and starts another (or redirects into a file)
SEPARATORS = {"&&", "||", "|", ";", "&", ">", ">>", "<", "2>", "2>&1", "&>", "|&"}
PLACEHOLDER = "PLACEHOLDER"
ELLIPSES = {"...", "\u2026"}
ENV_ASSIGNMENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=")
PYTHON = re.compile(r"(?:^|/)python(?:3(?:\.\d+)?)?$|^\$\{?PY(?:THON)?\}?$|^\$\(PY(?:THON)?\)$")


class DocCommandError(Exception):
    """A program a doc names that cannot be checked: missing, or with no command line to read."""


@dataclass(frozen=True)
class Command:
    """One command a doc quotes: where, which program, and the words after the program's name."""

    where: str  # "docs/model.md:54"
    kind: str  # "module" | "script" | "console" | "make" | "shell" | "file" | "options"
    program: str  # module name, script path, console script, Makefile folder, shell script path, file, subcommand
    args: tuple[str, ...]
    env: tuple[str, ...] = ()  # the VAR=value names put before it

    def __str__(self) -> str:
        return f"{self.where}: {self.kind} {self.program} {' '.join(self.args)}".rstrip()


# ---------------------------------------------------------------------------------------------- the docs' spans

def script_lines(text: str, makefile: bool) -> list[tuple[int, str]]:
    """(line number, text) of each logical line of a shell script, or of each recipe line of a Makefile: the
    commands ``make painter`` or ``bash training/painter_gpu.sh`` run, which the docs name in their place."""
    found: list[tuple[int, str]] = []
    pending: tuple[int, str] | None = None
    for number, line in enumerate(text.splitlines(), start=1):
        if pending is None and (makefile and not line.startswith("\t") or line.lstrip().startswith("#")):
            continue
        start, joined = pending if pending else (number, "")
        joined = f"{joined} {line.strip().lstrip('@')}".strip()
        if joined.endswith("\\"):
            pending = (start, joined[:-1].rstrip())
        else:
            pending = None
            found.append((start, joined))
    return found


def doc_files(repo: Path = REPO) -> list[Path]:
    found = {p for pattern in DOC_GLOBS for p in repo.glob(pattern) if p.is_file()}
    return sorted(found)


def code_spans(text: str) -> list[tuple[int, str]]:
    """(line number, text) of each fenced block's logical line (continuations joined), each line of an indented
    code block (four spaces, after a blank line, not a list item's paragraph) and each inline span, in the order of
    the doc."""
    return sorted(_code_spans(text), key=lambda span: span[0])


def _code_spans(text: str) -> Iterator[tuple[int, str]]:
    lines = text.splitlines()
    prose: list[str] = []  # the text outside fences, fenced lines blanked (the line numbers stay right)
    fence: str | None = None
    shell = False
    pending: tuple[int, str] | None = None
    # an indented code block: docs/runtime.md quotes its benchmark commands so, and they went unchecked
    indented = False  # within one
    after_blank = True  # the line before was blank (or there was none)
    in_list = False  # the last prose line was a list item's or its continuation's: its indented lines are prose
    for number, line in enumerate(lines, start=1):
        opening = re.match(r"\s*(`{3,}|~{3,})\s*([\w+-]*)", line)
        if fence is None and opening:
            fence, shell = opening.group(1), opening.group(2).lower() not in NOT_SHELL
            variables: dict[str, str] = {}  # a block's P="--out ..." lines, for the `$P` of the lines after
            prose.append("")
            continue
        if fence is not None:
            prose.append("")
            if line.strip().startswith(fence):
                if pending:
                    yield pending
                fence, pending = None, None
                continue
            if not shell:
                continue
            body = re.sub(r"^\s*\$\s+", "", line)  # a "$ " prompt
            start, joined = pending if pending else (number, "")
            joined = f"{joined} {body.strip()}".strip()
            if joined.endswith("\\"):
                pending = (start, joined[:-1].rstrip())
            else:
                pending = None
                joined = _expand(joined, variables)
                if not _assign(joined, variables):
                    yield start, joined
            continue
        if not line.strip():
            after_blank = True
            prose.append(line)
            continue
        if re.match(r"( {4}|\t)", line) and (indented or (after_blank and not in_list)):
            indented, after_blank = True, False
            prose.append("")
            yield number, re.sub(r"^\$\s+", "", line.strip())
            continue
        indented, after_blank = False, False
        in_list = bool(re.match(r"\s*([*+-]|\d+[.)])\s", line)) or (line[:1].isspace() and in_list)
        prose.append(line)
    # inline spans: within one paragraph, a run of n backticks closed by the next run of exactly n
    paragraph_start = 1
    for block in re.split(r"(\n[ \t]*\n)", "\n".join(prose)):
        if block.strip():
            for match in re.finditer(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", block, flags=re.S):
                line = paragraph_start + block[:match.start()].count("\n")
                yield line, " ".join(match.group(2).split())
        paragraph_start += block.count("\n")


# --------------------------------------------------------------------------------------------- the commands

def _assign(line: str, variables: dict[str, str]) -> bool:
    """Record a line of only ``NAME="value"`` words (a shell variable the block's later lines use)."""
    try:
        words = shlex.split(line, comments=True)
    except ValueError:
        return False
    if not words or not all(ENV_ASSIGNMENT.match(w) for w in words):
        return False
    variables.update(w.split("=", 1) for w in words)
    return True


def _expand(line: str, variables: dict[str, str]) -> str:
    return re.sub(r"\$(?:\{(\w+)\}|(\w+))",
                  lambda m: variables.get(m.group(1) or m.group(2), m.group(0)), line)


def _words(span: str) -> list[str]:
    # <net>, <variant> are placeholders, not redirections; [--opt X] marks an optional part
    span = re.sub(r"<[^<>\s]+>", PLACEHOLDER, span)
    span = re.sub(r"\\\s+", " ", span)  # a continuation inside an inline span (a fenced block's are joined)
    try:
        words = shlex.split(span, comments=True)
    except ValueError:  # an apostrophe of prose in the span: the words are still words
        words = span.split()
    out = []
    for word in words:
        if word in SEPARATORS:
            out.append(word)
            continue
        word = word.strip("[]")
        for ellipsis in ELLIPSES:
            word = word.removesuffix(ellipsis) if word != ellipsis else word
        if word and word != "\\":
            out.append(word)
    return out


def _segments(words: list[str]) -> Iterator[list[str]]:
    current: list[str] = []
    for word in words:
        if word in SEPARATORS:
            yield current
            current = []
        else:
            current.append(word)
    yield current


@dataclass(frozen=True)
class Project:
    """What names a program in this repository: its packages, console scripts and top-level folders."""

    packages: frozenset[str]
    scripts: dict[str, str]  # console script -> "module:function"
    root: Path

    @classmethod
    def read(cls, repo: Path = REPO) -> Project:
        meta = tomllib.loads((repo / "pyproject.toml").read_text(encoding="utf-8"))
        include = meta["tool"]["setuptools"]["packages"]["find"]["include"]
        packages = {name.rstrip("*") for name in include} | {"benchmarks"}
        return cls(frozenset(packages), dict(meta["project"]["scripts"]), repo)

    def is_project_path(self, path: str) -> bool:
        first = path.removeprefix("./").split("/", 1)[0]
        return "/" in path.removeprefix("./") and (self.root / first).is_dir()


def commands_in(span: str, where: str, project: Project) -> list[Command]:
    """The project commands a span runs (a span may hold several: `a && b`, `a | b`)."""
    found = []
    for index, segment in enumerate(_segments(_words(span))):
        command = _command(segment, where, project, head_of_span=index == 0)
        if command is not None:
            found.append(command)
    return found


#: GNU timeout's options that take a value as the next word (``-s TERM``, ``--kill-after 5``)
TIMEOUT_VALUE_OPTIONS = {"-s", "--signal", "-k", "--kill-after"}


def _after_timeout(words: list[str], i: int) -> int:
    """The index of the program ``timeout`` runs, ``words[i:]`` being what follows the word ``timeout``: its options
    (``--preserve-status``, ``-s TERM``, ``--signal=TERM``, ``-k5``), then its duration. The first option was taken
    for the duration and the next word for the program, so such a line went unchecked."""
    while i < len(words) and words[i].startswith("-"):
        i += 2 if words[i] in TIMEOUT_VALUE_OPTIONS else 1
    return i + 1  # past the duration


def _command(words: list[str], where: str, project: Project, head_of_span: bool) -> Command | None:
    env: list[str] = []
    i = 0
    while i < len(words):  # VAR=value prefixes and wrappers before the program
        word = words[i]
        if ENV_ASSIGNMENT.match(word):
            env.append(word.split("=", 1)[0])
        elif word in WRAPPERS:
            pass
        elif word in ("-f", "-o") and i > 0 and words[i - 1] in ("time", "/usr/bin/time"):
            i += 1  # time -f FORMAT, -o FILE
        elif word in ("-u", "-g") and i > 0 and words[i - 1] == "sudo":
            i += 1  # sudo -u ghnerf: the user, not the program (docs/bring-up.md runs the checks as the service's)
        elif word == "-n" and i > 0 and words[i - 1] == "nice":
            i += 1  # its niceness (after `time -v`'s branch below, `nice -n 5` took the 5 for the program)
        elif word.startswith("-") and i > 0 and words[i - 1] in WRAPPERS:
            pass  # time -v, env -i
        elif word == "timeout":
            i = _after_timeout(words, i + 1) - 1  # its options and duration
        elif word == "taskset" and i + 1 < len(words):
            i += 1  # its CPU list
        else:
            break
        i += 1
    if i >= len(words):
        return None
    head, rest = words[i], words[i + 1:]
    name = head.rsplit("/", 1)[-1]
    if PYTHON.search(head) or name == "torchrun":
        while rest and rest[0].startswith("-") and rest[0] != "-m":  # python -u, -X dev; torchrun --nnodes 1
            if rest[0] == "-c":
                return None
            takes_value = rest[0] in ("-X", "-W") or (name == "torchrun" and "=" not in rest[0])
            rest = rest[2:] if takes_value else rest[1:]
        if len(rest) >= 2 and rest[0] == "-m":
            module = rest[1]
            if module.split(".", 1)[0] in project.packages:
                return Command(where, "module", module, tuple(rest[2:]), tuple(env))
            return None  # python -m pytest, pip: not ours
        if rest and re.search(r"(^|/)[A-Z_]+\.py$", rest[0]):
            return None  # benchmarks/NAME.py: a placeholder
        if rest and rest[0].endswith(".py") and project.is_project_path(rest[0]):
            return Command(where, "script", rest[0].removeprefix("./"), tuple(rest[1:]), tuple(env))
        return None
    if name in project.scripts:
        return Command(where, "console", name, tuple(rest), tuple(env))
    if head == "make":
        folder = "."
        targets = []
        j = 0
        while j < len(rest):
            if rest[j] in ("-C", "-f", "-j", "-l", "-o", "-W"):
                if rest[j] == "-C" and j + 1 < len(rest):
                    folder = rest[j + 1]
                j += 2
                continue
            targets.append(rest[j])
            j += 1
        return Command(where, "make", folder, tuple(targets), tuple(env))
    if head in ("bash", "sh") and rest and rest[0].endswith(".sh"):
        return Command(where, "shell", rest[0].removeprefix("./"), tuple(rest[1:]), tuple(env))
    if re.fullmatch(r"[\w./-]+\.sh", head) and project.is_project_path(head):  # not a glob, training/*.sh
        return Command(where, "shell", head.removeprefix("./"), tuple(rest), tuple(env))
    if not head_of_span or env:
        return None
    # a span that starts with a script's path or a module's dotted name: named as a command (`benchmarks/x.py`,
    # `training.pipeline --recipe gpu`)
    has_option = any(w.startswith("-") for w in rest)
    if re.fullmatch(r"(\./)?[\w/]+\.py", head) and project.is_project_path(head):
        # `benchmarks/x.py --seconds 3` runs it; `tests/test_x.py` alone names a file that must still be there
        return Command(where, "script" if has_option else "file", head.removeprefix("./"), tuple(rest))
    if re.fullmatch(r"\w+\.py", head) and has_option:
        # `measure_novel_path.py --sim 90`: a benchmark by its file name, in a paragraph about it
        return Command(where, "script", f"benchmarks/{head}", tuple(rest))
    if re.fullmatch(r"\w+\.sh", head) and has_option:
        scripts = sorted(project.root.glob(f"*/{head}"))  # `install.sh --destdir`
        return Command(where, "shell", scripts[0].relative_to(project.root).as_posix() if scripts else head,
                       tuple(rest))
    if re.fullmatch(r"[a-z]+_\w+", head) and has_option:
        # `learnt_fill train --train-views N`: a project module by its last name (one with an underscore: a
        # plain word, `train --out`, is as likely a subcommand of the program the paragraph is about)
        modules = sorted(project.root.glob(f"*/{head}.py"))
        modules = [m for m in modules if m.parent.name in project.packages]
        if len(modules) == 1:
            return Command(where, "module", f"{modules[0].parent.name}.{head}", tuple(rest))
    if (re.fullmatch(r"[a-z_]+(\.[a-z_0-9]+)+", head) and head.split(".", 1)[0] in project.packages
            and any(w.startswith("--") for w in rest)):
        return Command(where, "module", head, tuple(rest))
    if head.startswith("--"):
        # `--recipe cpu` in prose about a program: some program of the project must take it
        return Command(where, "options", "", tuple(words[i:]))
    if re.fullmatch(r"[a-z][\w-]*", head) and any(w.startswith("--") for w in rest):
        # `cache --no-relit`, `board --dpi`: checked where some program has that subcommand
        return Command(where, "options", head, tuple(rest))
    return None


def doc_commands(repo: Path = REPO, project: Project | None = None) -> dict[str, list[Command]]:
    project = project or Project.read(repo)
    found: dict[str, list[Command]] = {}
    for path in doc_files(repo):
        name = path.relative_to(repo).as_posix()
        found[name] = [command for line, span in code_spans(path.read_text(encoding="utf-8"))
                       for command in commands_in(span, f"{name}:{line}", project)]
    return found


def recipe_commands(repo: Path = REPO, project: Project | None = None) -> dict[str, list[Command]]:
    """The project commands the Makefile's recipes and the training scripts run (what `make painter` runs is as
    much the doc's command as the line that names it)."""
    project = project or Project.read(repo)
    found: dict[str, list[Command]] = {}
    for path in [repo / "Makefile", *sorted(repo.glob("training/*.sh"))]:
        name = path.relative_to(repo).as_posix()
        lines = script_lines(path.read_text(encoding="utf-8"), makefile=path.name == "Makefile")
        found[name] = [command for line, text in lines for command in commands_in(text, f"{name}:{line}", project)
                       if command.kind in ("module", "script", "console", "shell")]
    return found


# --------------------------------------------------------------------------------------------- the programs

class _ParserReached(BaseException):  # BaseException: a main's `except Exception` must not swallow it
    def __init__(self, parser: argparse.ArgumentParser) -> None:
        super().__init__()
        self.parser = parser


@contextlib.contextmanager
def _signal_handlers_kept() -> Iterator[None]:
    kept = {signum: signal.getsignal(signum) for signum in (signal.SIGHUP, signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for signum, handler in kept.items():
            signal.signal(signum, handler)


def parser_of_main(main: Callable[..., object], prog: str) -> argparse.ArgumentParser:
    """The parser ``main`` parses its arguments with, stopped there: nothing after the parse runs."""
    def reached(self: argparse.ArgumentParser, *args: object, **kwargs: object) -> None:
        raise _ParserReached(self)

    takes_argv = bool(inspect.signature(main).parameters)
    with (_signal_handlers_kept(),  # a main run by its program's name (ghnerf-daemon) sets some for its process
          mock.patch.object(argparse.ArgumentParser, "parse_args", reached),
          mock.patch.object(argparse.ArgumentParser, "parse_known_args", reached),
          mock.patch.object(argparse.ArgumentParser, "parse_intermixed_args", reached),
          mock.patch.object(sys, "argv", [prog])):
        try:
            main([]) if takes_argv else main()
        except _ParserReached as reached_it:
            return reached_it.parser
        except SystemExit as e:
            raise DocCommandError(f"{prog}: main exited ({e.code}) before parsing its arguments") from e
    raise DocCommandError(f"{prog}: main returned without parsing its arguments")


def _main_of_module(module: str) -> tuple[str, str]:
    """(module, function) that ``python -m module`` runs, read from its source (a ``__main__`` block may hand over
    to another module's ``main``: ``from training.cli.train import main as _cli_main``)."""
    try:
        spec = importlib.util.find_spec(module)
    except ModuleNotFoundError:
        spec = None
    if spec is None or spec.origin is None:
        raise DocCommandError(f"python -m {module}: no such module")
    if spec.submodule_search_locations is not None:  # a package: its __main__.py runs
        main_file = Path(spec.origin).with_name("__main__.py")
        if not main_file.is_file():
            raise DocCommandError(f"python -m {module}: a package without __main__.py")
        body = ast.parse(main_file.read_text(encoding="utf-8")).body
        this = f"{module}.__main__"
    else:
        tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
        body = next((node.body for node in tree.body if isinstance(node, ast.If) and _is_main_guard(node.test)), [])
        if not body:
            raise DocCommandError(f"python -m {module}: {spec.origin} has no `if __name__ == \"__main__\":` guard")
        this = module
    for node in ast.walk(ast.Module(body=body, type_ignores=[])):
        if isinstance(node, ast.ImportFrom) and node.module and any(a.name == "main" for a in node.names):
            return node.module, "main"
    if this.endswith(".__main__"):
        raise DocCommandError(f"python -m {module}: __main__.py hands over to no `main`")
    return this, "main"


def _is_main_guard(test: ast.expr) -> bool:
    return (isinstance(test, ast.Compare) and isinstance(test.left, ast.Name) and test.left.id == "__name__"
            and any(isinstance(c, ast.Constant) and c.value == "__main__" for c in test.comparators))


@dataclass
class Programs:
    """Each program's parser, built once (a program is imported once however many docs quote it)."""

    project: Project
    parsers: dict[str, argparse.ArgumentParser] = field(default_factory=dict)
    every_built: bool = False
    code: str | None = field(default=None, repr=False)

    def parser(self, command: Command) -> argparse.ArgumentParser:
        key = f"{command.kind}:{command.program}"
        if key not in self.parsers:
            self.parsers[key] = self._build(command)
        return self.parsers[key]

    def _build(self, command: Command) -> argparse.ArgumentParser:
        if command.kind == "console":
            module, function = self.project.scripts[command.program].split(":")
            prog = command.program
        elif command.kind == "script":
            path = self.project.root / command.program
            if not path.is_file():
                raise DocCommandError(f"{command.program}: no such script")
            module, function = _main_of_module(".".join(Path(command.program).with_suffix("").parts))
            prog = command.program
        else:
            module, function = _main_of_module(command.program)
            prog = f"python -m {command.program}"
        main = getattr(importlib.import_module(module), function, None)
        if not callable(main):
            raise DocCommandError(f"{prog}: {module} has no {function}()")
        return parser_of_main(main, prog)


    def every(self) -> list[argparse.ArgumentParser]:
        """The parser of each program in the project: the console scripts, and every module or benchmark with
        a command line (what an option quoted without its program may belong to)."""
        if not self.every_built:
            found = [Command("", "console", name, ()) for name in self.project.scripts]
            for folder in sorted(self.project.packages):
                for path in sorted((self.project.root / folder).rglob("*.py")):
                    text = path.read_text(encoding="utf-8")
                    if ("__main__" in text and "argparse" in text) or path.name == "__main__.py":
                        relative = path.relative_to(self.project.root).with_suffix("")
                        name = ".".join(relative.parts).removesuffix(".__main__")
                        found.append(Command("", "module", name, ()))
            for command in found:
                try:
                    self.parser(command)
                except DocCommandError:
                    continue  # a module whose main is no argparse command line
            self.every_built = True
        return list(self.parsers.values())

    def code_text(self) -> str:
        """Every Python source, shell script and Makefile of the project, tests included: where an environment
        variable a doc sets before `make test` must be read."""
        if self.code is None:
            paths = [p for pattern in ("**/*.py", "**/*.sh", "**/Makefile") for p in self.project.root.glob(pattern)
                     if ".venv" not in p.parts and ".git" not in p.parts]
            self.code = "\n".join(p.read_text(encoding="utf-8", errors="replace") for p in sorted(paths))
        return self.code

    def shell_scripts(self) -> str:
        return "\n".join(p.read_text(encoding="utf-8") for p in sorted(self.project.root.glob("*/*.sh")))


def _lookup(parser: argparse.ArgumentParser, option: str) -> argparse.Action | None:
    """The action ``option`` names in ``parser``, by its full name only: argparse would take a unique prefix
    (`--novel-lane` for `--novel-lanes`), but a doc quoting one stops parsing the day an option sharing the
    prefix is added, and a reader's search for the option does not find it."""
    return parser._option_string_actions.get(option)  # noqa: SLF001 - argparse has no public table of them


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:  # noqa: SLF001
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            return dict(action.choices)
    return {}


def _option_names(word: str) -> list[str]:
    """The options a quoted option word names: `--a=1` one, `--a/--b` two, `--[no-]a` both of its forms."""
    option = word.split("=", 1)[0]
    parts = option.split("/")
    names = parts if all(p.startswith("-") for p in parts) else [option]
    return [form for name in names
            for form in ((name.replace("[no-]", ""), name.replace("[no-]", "no-")) if "[no-]" in name else (name,))]


def _is_value_word(word: str) -> bool:
    return not word.startswith("-") or bool(re.fullmatch(r"-[\d.]+", word))


def argparse_problems(command: Command, parser: argparse.ArgumentParser) -> list[str]:
    """The words of ``command`` that its parser would refuse: unknown options, unknown subcommands."""
    problems = []
    words = list(command.args)
    program = command.program
    i = 0
    while i < len(words):
        word = words[i]
        i += 1
        if word == "--":
            break
        if word in ELLIPSES or PLACEHOLDER in word:
            continue
        if word.startswith("-") and not _is_value_word(word):
            if re.fullmatch(r"--[\w-]*\*", word):  # --novel-* in prose: some option starts so
                prefix = word[:-1]
                if not any(o.startswith(prefix) for o in parser._option_string_actions):  # noqa: SLF001
                    problems.append(f"{command.where}: {program}: no option matches {word}")
                continue
            names = _option_names(word)
            for name in names:
                if _lookup(parser, name) is None:
                    problems.append(f"{command.where}: {program}: unknown option {name}")
            action = _lookup(parser, names[-1])
            if action is None or "=" in word:
                continue
            nargs = action.nargs
            if nargs == 0:
                continue
            if nargs is None:
                i += 1
            elif isinstance(nargs, int):
                i += nargs
            else:  # ?, *, +, ... : the words up to the next option
                while i < len(words) and _is_value_word(words[i]):
                    i += 1
            continue
        subcommands = _subcommands(parser)
        if subcommands:
            if word in subcommands:
                parser, program = subcommands[word], f"{program} {word}"
            else:
                problems.append(f"{command.where}: {program}: unknown subcommand {word!r} "
                                f"(it has {', '.join(sorted(subcommands))})")
                break
    return problems


def option_problems(command: Command, programs: Programs) -> list[str]:
    """Options quoted without their program: each must be one some program takes (the subcommand's, when the
    span starts with a subcommand's name; none of ours has it: another tool's, `enable --now`, not checked)."""
    parsers = programs.every()
    subcommands = [(name, sub) for p in parsers for name, sub in _subcommands(p).items()]
    if command.program:
        parsers = [sub for name, sub in subcommands if name == command.program]
        if not parsers:
            return []
    else:
        parsers += [sub for _, sub in subcommands]
    scripts = programs.shell_scripts()
    problems = []
    for word in command.args:
        if not word.startswith("--") or word == "--" or PLACEHOLDER in word:
            continue
        for name in _option_names(word):
            pattern = name.endswith("*")
            taken = any(
                any(o.startswith(name[:-1]) for o in p._option_string_actions) if pattern  # noqa: SLF001
                else _lookup(p, name) is not None for p in parsers)
            if not taken and not (command.program == "" and re.search(
                    rf"(?<![\w-]){re.escape(name)}(?![\w-])", scripts)):
                where = f"`{command.program} ...`'s subcommand" if command.program else "any program"
                problems.append(f"{command.where}: {name}: not an option of {where}")
    return problems


def _makefile_targets(makefile: str) -> set[str]:
    targets = set()
    for line in makefile.splitlines():
        rule = re.match(r"([A-Za-z0-9_./%-][A-Za-z0-9_./% -]*?)\s*::?(?!=)", line)
        if rule and not line.startswith("\t"):
            targets.update(rule.group(1).split())
    return targets


def make_problems(command: Command, programs: Programs) -> list[str]:
    root = programs.project.root
    makefile = root / command.program / "Makefile"
    if not makefile.is_file():
        return [f"{command.where}: make -C {command.program}: no Makefile there"]
    text = makefile.read_text(encoding="utf-8")
    problems = []
    for variable in command.env:  # GHNERF_TEST_DEPTHAI=1 make test: read by a test, not by the Makefile
        if not re.search(rf"(?<!\w){variable}(?!\w)", text) and not re.search(
                rf"[\"'${{]{variable}\b", programs.code_text()):
            problems.append(f"{command.where}: make: nothing in the project reads {variable}")
    targets = _makefile_targets(text)
    for word in command.args:
        if word.startswith("-") or PLACEHOLDER in word or word in ELLIPSES:
            continue
        if ENV_ASSIGNMENT.match(word):
            variable = word.split("=", 1)[0]
            if not re.search(rf"\$[({{]{variable}[)}}]", text):
                problems.append(f"{command.where}: make: {makefile.relative_to(root)} never reads {variable}")
        elif word not in targets:
            problems.append(f"{command.where}: make: no target {word!r} in {makefile.relative_to(root)}")
    return problems


def shell_problems(command: Command, root: Path = REPO) -> list[str]:
    script = root / command.program
    if not script.is_file():
        return [f"{command.where}: {command.program}: no such script"]
    text = script.read_text(encoding="utf-8")
    problems = []
    for variable in command.env:
        if not re.search(rf"\$\{{?{variable}\b", text):
            problems.append(f"{command.where}: {command.program} never reads {variable}")
    for word in command.args:
        option = word.split("=", 1)[0]
        if option.startswith("--") and PLACEHOLDER not in option and not re.search(
                rf"(?<![\w-]){re.escape(option)}(?![\w-])", text):
            problems.append(f"{command.where}: {command.program}: unknown option {option}")
    return problems


def problems_of(command: Command, programs: Programs) -> list[str]:
    if command.kind == "make":
        return make_problems(command, programs)
    if command.kind == "shell":
        return shell_problems(command, programs.project.root)
    if command.kind == "options":
        return option_problems(command, programs)
    if command.kind == "file":
        exists = (programs.project.root / command.program).is_file()
        return [] if exists else [f"{command.where}: {command.program}: no such file"]
    try:
        parser = programs.parser(command)
    except DocCommandError as e:
        return [f"{command.where}: {e}"]
    return argparse_problems(command, parser)


# ------------------------------------------------------------------------------------------------- the tests

@pytest.fixture(scope="module")
def programs() -> Programs:
    return Programs(Project.read())


@pytest.fixture(scope="module")
def commands() -> dict[str, list[Command]]:
    return doc_commands()


DOCS = [p.relative_to(REPO).as_posix() for p in doc_files()]


@pytest.mark.parametrize("doc", DOCS)
def test_every_command_the_doc_quotes_parses(doc, commands, programs):
    problems = [p for command in commands[doc] for p in problems_of(command, programs)]
    assert not problems, "\n".join(problems)


RECIPES = ["Makefile", *(p.relative_to(REPO).as_posix() for p in sorted(REPO.glob("training/*.sh")))]


@pytest.mark.parametrize("source", RECIPES)
def test_every_command_a_make_target_or_training_script_runs_parses(source, programs):
    found = recipe_commands(REPO, programs.project)[source]
    assert found, f"{source}: no project command found (the reader of its lines broke?)"
    problems = [p for command in found for p in problems_of(command, programs)]
    assert not problems, "\n".join(problems)


def test_the_docs_quote_commands_of_every_kind(commands):
    """The extractor still finds what the docs hold (a broken one would pass every doc with nothing checked)."""
    kinds: dict[str, int] = {}
    for found in commands.values():
        for command in found:
            kinds[command.kind] = kinds.get(command.kind, 0) + 1
    assert set(kinds) == {"module", "script", "console", "make", "shell", "file", "options"}, kinds
    assert kinds["console"] + kinds["module"] + kinds["script"] > 300, kinds


MADE_UP = """\
# A made-up doc

The figure comes from `.venv/bin/python benchmarks/measure_pairing.py --no-such-option 3`, and
`ghcal solve --board b.json --imagez capture/` solved it; `python -m training.train --iterations 64 \\
--bogus` trained it, `ghnerf-run --[no-]refine-cold-start` and `--recipe`/`--no-such-flag` aside.

```sh
WIDTHS="16 32" NOT_READ=1 bash training/painter_gpu.sh runs/a runs/b 2048 270
.venv/bin/python benchmarks/no_such_benchmark.py --seconds 3
make painter-gpu PAINTER_WIDTH=32 NO_SUCH_VAR=1
make no-such-target
GHNERF_TEST_NO_SUCH=1 make test
ghnerf-bench nonsense --out x
ghnerf-bench runtime --novel-lane off,on
S="python -m training.learnt_fill score --val-cache v.npz"
$S --net a.pt --no-such-net
/usr/bin/time -f %e ghnerf-daemon --config d.json --validate-config --no-such-check
```

Well formed: `ghcal board --out board/`, `make model RECIPE=gpu`, `ghnerf-listen udp://:9870 --seconds 8`,
`python -m training.learnt_fill export --net <net> --out $OUT ...`, `ghnerf-bench runtime --novel-*` and
`tests/test_docs_commands.py`; gone: `tests/test_no_such_file.py`, `board --no-such-dpi`.
"""


def test_the_checker_names_each_bad_option_script_target_and_variable(tmp_path, programs):
    (tmp_path / "README.md").write_text(MADE_UP, encoding="utf-8")
    found = [c for cs in doc_commands(tmp_path, programs.project).values() for c in cs]
    problems = [p.split(": ", 1)[1] for command in found for p in problems_of(command, programs)]
    assert problems == [
        "benchmarks/measure_pairing.py: unknown option --no-such-option",
        "ghcal solve: unknown option --imagez",
        "training.train: unknown option --bogus",
        "--no-such-flag: not an option of any program",
        "training/painter_gpu.sh never reads NOT_READ",
        "benchmarks/no_such_benchmark.py: no such script",
        "make: Makefile never reads NO_SUCH_VAR",
        "make: no target 'no-such-target' in Makefile",
        "make: nothing in the project reads GHNERF_TEST_NO_SUCH",
        "ghnerf-bench: unknown subcommand 'nonsense' (it has runtime, sim-pair)",
        "ghnerf-bench runtime: unknown option --novel-lane",  # argparse would take it for --novel-lanes
        "training.learnt_fill score: unknown option --no-such-net",
        "ghnerf-daemon: unknown option --no-such-check",
        "tests/test_no_such_file.py: no such file",
        "--no-such-dpi: not an option of `board ...`'s subcommand",
    ]
    # where each was found: the line the span or the block's line starts on
    assert [c.where for c in found][:3] == ["README.md:3", "README.md:4", "README.md:4"]
    assert len(found) == 23  # the well-formed ones were read too (and passed); S="..." runs nothing itself


def test_code_spans_join_continuations_and_skip_code_blocks():
    text = "a `x --y`\n\n```python\nmake model\n```\n```\nmake \\\n  demo  # the demo\n```\n``with ` tick``\n"
    assert code_spans(text) == [(1, "x --y"), (7, "make demo  # the demo"), (10, "with ` tick")]


def test_code_spans_read_indented_code_blocks_but_not_a_list_item_s_paragraphs():
    text = ("Rerun:\n\n    make demo\n    make `model`\n\nprose `a`\n\n* an item\n\n    its second paragraph, `b`\n"
            "\nmore prose\n    a wrapped line\n")
    assert code_spans(text) == [(3, "make demo"), (4, "make `model`"), (6, "a"), (10, "b")]


def test_a_program_is_found_as_python_runs_it():
    with pytest.raises(DocCommandError, match="no `if __name__"):
        _main_of_module("ghnerf_runtime.config")
    with pytest.raises(DocCommandError, match="no such module"):
        _main_of_module("training.no_such_module")
    assert _main_of_module("training.train") == ("training.cli.train", "main")  # parsed before torch loads
    assert _main_of_module("training.export") == ("training.export.cli", "main")  # a package's __main__.py


def test_a_command_run_as_another_user_is_checked(programs):
    """`sudo -u ghnerf PROGRAM ...` (docs/bring-up.md runs the device's checks as the service's user): the program
    is the word after the user. The user was taken for the program, so the line was passed over unchecked."""
    found = commands_in("sudo -u ghnerf /opt/ghnerf/venv/bin/ghnerf-daemon --config d.json --measure-flor", "x",
                        programs.project)
    assert [(c.kind, c.program) for c in found] == [("console", "ghnerf-daemon")]
    assert problems_of(found[0], programs) == ["x: ghnerf-daemon: unknown option --measure-flor"]


@pytest.mark.parametrize("wrapper", ["timeout 25", "timeout --preserve-status -s TERM 25", "timeout -k 5 -v 1m",
                                     "timeout --signal=INT --foreground 2h", "timeout -sKILL 10",
                                     "nice -n 5 timeout --preserve-status 25", "nice -n 5"])
def test_a_command_run_under_timeout_is_checked(wrapper, programs):
    """``timeout`` with its options runs the rest of the line as ``time`` and ``nice`` do: the program is the word
    after its duration (``--preserve-status`` was taken for the duration, ``-s`` for the program). ``nice -n 5``'s
    5 was taken for the program too."""
    found = commands_in(f"{wrapper} ghnerf-daemon --config d.json --measure-flor", "x", programs.project)
    assert [(c.kind, c.program) for c in found] == [("console", "ghnerf-daemon")]
    assert problems_of(found[0], programs) == ["x: ghnerf-daemon: unknown option --measure-flor"]
    assert commands_in(wrapper, "x", programs.project) == []  # timeout alone, quoted in prose: no program


@functools.lru_cache(maxsize=None)
def _tests_defined(root: Path) -> frozenset[str]:
    """The test functions defined under ``root``/tests and the test files' stems."""
    names = set()
    for path in (root / "tests").rglob("test_*.py"):
        names.add(path.stem)
        names.update(re.findall(r"^\s*def (test_\w+)", path.read_text(encoding="utf-8"), flags=re.M))
    return frozenset(names)


def quoted_test_problems(text: str, where: str, root: Path = REPO) -> list[str]:
    """Every ``test_...`` name the doc quotes in a code span that is neither a test function defined under tests/
    nor a test file's stem: a doc that names the test behind a figure or a rule must not point at one renamed."""
    defined = _tests_defined(root)
    problems = []
    for line, span in code_spans(text):
        for name in re.findall(r"(?<![\w/.])(test_\w+)(?![\w/.])", span):
            if name not in defined:
                problems.append(f"{where}:{line}: {name}: no such test function or file under tests/")
    return problems


@pytest.mark.parametrize("doc", DOCS)
def test_every_test_the_doc_names_is_defined(doc):
    problems = quoted_test_problems((REPO / doc).read_text(encoding="utf-8"), doc)
    assert not problems, "\n".join(problems)


def test_a_renamed_test_the_doc_names_is_caught():
    named = "`test_a_joint_no_view_shows_a_peak_of_is_placed_by_the_subject_s_prior_where_it_hangs_from_a_found_one`"
    assert not quoted_test_problems(f"see {named} and `tests/ghnerf_runtime/test_two_people.py`", "x.md")
    (problem,) = quoted_test_problems(f"see {named.replace('found_one', 'found')}", "x.md")
    assert problem.startswith("x.md:1: test_a_joint_no_view") and "no such test" in problem


# ------------------------------------------------------------------------ the names a doc's Python blocks import

def python_blocks(text: str) -> list[tuple[int, str]]:
    """(line number of its first line, source) of each fenced ``python`` / ``py`` block of a doc."""
    blocks = []
    for match in re.finditer(r"^[ \t]*```(?:python|py)[ \t]*\n(.*?)^[ \t]*```", text, flags=re.M | re.S):
        blocks.append((text.count("\n", 0, match.start(1)) + 1, match.group(1)))
    return blocks


def _project_packages(root: Path) -> frozenset[str]:
    return frozenset(p.parent.name for p in root.glob("*/__init__.py"))


def imported_name_problems(text: str, where: str, root: Path = REPO) -> list[str]:
    """Each ``from PACKAGE.module import name`` of a project package in a doc's Python blocks whose module or name
    is not there: a snippet a user pastes (the shipped model's graphs quantized again, the estimator's example)
    must not stop at its first line because a function was renamed. Only the project's own packages are imported;
    a block that is not whole Python (an excerpt) is read line by line."""
    packages = _project_packages(root)
    problems = []
    for first, source in python_blocks(text):
        try:
            statements = [(first + node.lineno - 1, node) for node in ast.walk(ast.parse(source))
                          if isinstance(node, ast.ImportFrom)]
        except SyntaxError:
            statements = []
            for offset, line in enumerate(source.splitlines()):
                try:
                    statements += [(first + offset, node) for node in ast.parse(line.strip()).body
                                   if isinstance(node, ast.ImportFrom)]
                except SyntaxError:
                    continue
        for line, node in statements:
            if node.level or not node.module or node.module.split(".")[0] not in packages:
                continue
            try:
                module = importlib.import_module(node.module)
            except ImportError as e:
                problems.append(f"{where}:{line}: {node.module}: cannot be imported ({e})")
                continue
            problems += [f"{where}:{line}: {node.module} has no {alias.name}" for alias in node.names
                         if alias.name != "*" and not hasattr(module, alias.name)]
    return problems


@pytest.mark.parametrize("doc", DOCS)
def test_every_name_a_doc_s_python_block_imports_is_there(doc):
    problems = imported_name_problems((REPO / doc).read_text(encoding="utf-8"), doc)
    assert not problems, "\n".join(problems)


def test_a_renamed_function_a_python_block_imports_is_caught():
    block = "text\n\n```python\nfrom pathlib import Path\nfrom training.pipeline import Stages, {}\n```\n"
    assert not imported_name_problems(block.format("stage_quantize"), "x.md")
    (problem,) = imported_name_problems(block.format("stage_quantise"), "x.md")
    assert problem == "x.md:5: training.pipeline has no stage_quantise"
    (problem,) = imported_name_problems(block.format("x").replace("training.pipeline", "training.pipe_line"), "x.md")
    assert problem.startswith("x.md:5: training.pipe_line: cannot be imported")


def console_scripts_unnamed(readme: str, project: Project) -> list[str]:
    """The console scripts of pyproject.toml that ``readme`` never names: a user finds them in .venv/bin with no word
    on what they do."""
    return sorted(name for name in project.scripts if not re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", readme))


def test_the_readme_names_every_console_script():
    # ghnerf-sim-demo was installed beside ghnerf-demo and named on no page
    missing = console_scripts_unnamed((REPO / "README.md").read_text(encoding="utf-8"), Project.read())
    assert not missing, f"README.md names no {missing}: say what each does (the Layout table, or where it is used)"


def test_a_console_script_named_only_as_part_of_another_is_caught():
    project = replace(Project.read(), scripts={"ghnerf-demo": "a:b", "ghnerf-sim-demo": "c:d"})
    assert console_scripts_unnamed("run `ghnerf-demo`, or make demo", project) == ["ghnerf-sim-demo"]
    assert console_scripts_unnamed("`ghnerf-sim-demo --out x.png` draws", project) == ["ghnerf-demo"]
