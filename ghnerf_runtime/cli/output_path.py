"""Settle where a tool's output goes before the long work that produces it.

A benchmark, an evaluation or a training run that learns only at its last line that its ``--out`` folder
is missing, is a folder where a file was meant, or cannot be written, loses minutes to hours of work. The
tools call :func:`ready_output` right after parsing their arguments: the parent folder is made, and a
path of the wrong kind is refused with the flag and the path named.
"""
from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from ghnerf_runtime.path_check import path_problem, shown


class OutputPathError(ValueError):
    """An output path that cannot take what the tool will write (the message names the flag and path)."""


def ready_output(path: str | os.PathLike, flag: str, kind: Literal["file", "folder"] = "file",
                 suffix: str | None = None) -> Path:
    """``path`` ready to be written: its folder made (for ``kind="folder"``, the folder itself).

    ``suffix`` (e.g. ``".npz"``) is appended when the name lacks it, as ``numpy.savez`` would do, so that the
    checks and a later read see the file that will be written. Returns the path to write.

    Raises:
        OutputPathError: a folder given for a file, a file given for a folder, or a folder that cannot be
            made or written into.
    """
    problem = path_problem(os.fspath(path))  # a NUL byte made the checks below raise ValueError (a traceback)
    if problem is not None:
        raise OutputPathError(f"{flag} {shown(os.fspath(path))}: {problem}")
    p = Path(path)
    if suffix and p.suffix != suffix:
        p = p.with_name(p.name + suffix)
    folder = p if kind == "folder" else p.parent
    if kind == "file" and p.is_dir():
        raise OutputPathError(f"{flag} {p}: is a folder; give the file's path")
    if kind == "folder" and p.exists() and not p.is_dir():
        raise OutputPathError(f"{flag} {p}: is a file; give a folder")
    _refuse_unmakeable(p, flag, kind)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputPathError(f"{flag} {p}: cannot make the folder {folder} ({e.strerror or e})") from e
    reason = unwritable_reason(folder)
    if reason is not None:
        raise OutputPathError(f"{flag} {p}: the folder {folder} is not writable ({reason})")
    if kind == "file" and p.exists() and not os.access(p, os.W_OK):
        raise OutputPathError(f"{flag} {p}: the file exists and is not writable")
    return p


def _refuse_unmakeable(p: Path, flag: str, kind: str) -> None:
    """Say why ``mkdir -p`` cannot make the folder of ``p`` in the user's terms: it said only "File exists" for
    a path through a file (``a.json/x``) and for a folder that is a link to nothing."""
    folder = p if kind == "folder" else p.parent
    dangling = dangling_link_words(folder)
    if dangling is not None:
        raise OutputPathError(f"{flag} {p}: cannot make the folder {folder}: {dangling} or give another path")
    base = existing_ancestor(folder)
    if not base.is_dir():
        raise OutputPathError(f"{flag} {p}: cannot make the folder {folder}: {base} is a file, not a folder")


def dangling_link(path: Path) -> Path | None:
    """The first of ``path`` and its parents that is a symbolic link leading nowhere (None: there is none)."""
    for candidate in (path, *path.parents):
        if candidate.is_symlink() and not candidate.exists():
            return candidate
    return None


def dangling_link_words(path: Path) -> str | None:
    """Why ``mkdir -p path`` fails with "File exists", in the user's terms: the first of ``path`` and its parents
    that is a symbolic link leading nowhere, and its target (None: there is none). One wording for every tool."""
    dangling = dangling_link(path)
    if dangling is None:
        return None
    return f"{dangling} is a symbolic link to {os.readlink(dangling)}, which does not exist; make its target"


def unwritable_reason(folder: Path) -> str | None:
    """Why no file can be made in ``folder`` (None: one can), found by making and removing one.

    Tried rather than read from the permission bits: ``os.access`` says yes to root everywhere,
    also on sysfs and similar mounts that refuse the file, and says nothing of a full inode table.
    """
    try:
        fd, name = tempfile.mkstemp(dir=folder, prefix=".write-test-", suffix=".tmp")
    except OSError as e:
        return e.strerror or str(e)
    os.close(fd)
    try:
        os.unlink(name)
    except OSError:  # made but not removable: writable enough, and nothing to do about the leftover
        pass
    return None


def existing_ancestor(path: Path) -> Path:
    """``path`` itself if it exists, else its nearest existing parent (where ``mkdir -p`` starts)."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """``a`` and ``b`` name one file (through links, ``..`` and the current directory), whether or not it exists;
    two existing names of one file (``st_dev``, ``st_ino``) are one too: a hard link has a path of its own, and until
    session 74 an output given as a hard link to an input was not caught."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):  # either one missing (or a path the system refuses): no file shared yet
        return False


@dataclass(frozen=True)
class Clash:
    """An output that is a file already taken: ``output`` (a flag or config key) at ``path`` is ``other`` at
    ``other_path``, an input when ``other_is_input`` (replaced by what the tool writes), else another output."""

    output: str
    path: str | os.PathLike
    other: str
    other_path: str | os.PathLike
    other_is_input: bool


def first_clash(outputs: Iterable[tuple[str, str | os.PathLike | None]],
                inputs: Iterable[tuple[str, str | os.PathLike | None]]) -> Clash | None:
    """The first of ``outputs`` (``(name, path)``; a ``None`` path for one not given) that is one of ``inputs`` or
    an earlier output, however spelled (:func:`same_file`); ``None`` when every output has a file of its own.
    Callers say it in their own words and error type (a CLI's usage error, the daemon's config key)."""
    sources = [(name, path) for name, path in inputs if path is not None]
    written: list[tuple[str, str | os.PathLike]] = []
    for name, path in outputs:
        if path is None:
            continue
        for other, source in sources:
            if same_file(path, source):
                return Clash(name, path, other, source, other_is_input=True)
        for other, other_path in written:
            if same_file(path, other_path):
                return Clash(name, path, other, other_path, other_is_input=False)
        written.append((name, path))
    return None


def output_clash(outputs: dict[str, str | os.PathLike | None],
                 inputs: dict[str, str | os.PathLike | None]) -> str | None:
    """Why one of ``outputs`` (flag -> path; ``None`` for one not given) cannot be written: it is one of ``inputs``
    (replaced by what the tool writes: the rig file by the joints, a captured image by its overlay) or another
    output (one of the two lost); ``None`` when every output has a file of its own."""
    clash = first_clash(outputs.items(), inputs.items())
    if clash is None:
        return None
    if clash.other_is_input:
        return f"{clash.output} {clash.path} is the file {clash.other} reads: writing it would destroy it; give " \
               "another path"
    return f"{clash.output} {clash.path} is where {clash.other} writes too: one of them would be lost; give another path"


def ready_output_arg(ap: argparse.ArgumentParser, path: str | os.PathLike, flag: str,
                     kind: Literal["file", "folder"] = "file", suffix: str | None = None) -> Path:
    """:func:`ready_output` for a parsed argument: a bad path ends the tool as argparse ends it (the usage
    line, the message, exit status 2)."""
    try:
        return ready_output(path, flag, kind, suffix)
    except OutputPathError as e:
        ap.error(str(e))


#: what a model folder is read for: graphs and checkpoints; a ``.json`` is one when an ``.onnx`` of its name is
#: beside it (the skeleton prior's and the painter's settings). A report of the user's own there may be rewritten.
MODEL_FILE_SUFFIXES = (".onnx", ".pt")


def is_model_file(path: str | os.PathLike, model_dir: str | os.PathLike) -> bool:
    """``path`` (through links) is an existing file of the model folder ``model_dir`` (or the subfolder of it that
    a session reads: ``models`` is ``models/ghnerf``) that a session reads."""
    from ghnerf_runtime.errors import ModelError  # local: the path checks import nothing of the model
    from ghnerf_runtime.session import resolve_model_dir

    p = Path(os.path.realpath(path))
    try:
        folder = resolve_model_dir(model_dir)
    except ModelError:  # an unreadable folder: said by the load, which names it
        return False
    if not p.is_file() or p.parent != Path(os.path.realpath(folder)):
        return False
    return p.suffix in MODEL_FILE_SUFFIXES or (p.suffix == ".json" and p.with_suffix(".onnx").is_file())


def model_file_clash(outputs: dict[str, str | os.PathLike | None], model_dir: str | os.PathLike,
                     model_flag: str) -> str | None:
    """Why one of ``outputs`` (flag -> path; ``None`` for one not given) cannot be written: it is a file of the
    model folder (:func:`is_model_file`; ``model_flag``, what named the folder). ``ghnerf-bench --json
    models/ghnerf/encoder.onnx`` replaced the graph with the report."""
    for flag, path in outputs.items():
        if path is not None and is_model_file(path, model_dir):
            return (f"{flag} {path} is a file of the model folder ({model_flag}): writing it would destroy it; "
                    "give another path")
    return None
