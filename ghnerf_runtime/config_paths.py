"""Relative paths written in a config file are read from the file's own folder.

The convention of systemd drop-ins and docker compose: a config names its model folder or status
file the same way wherever the program is started from. Read from the current directory instead,
the example config's ``"models"`` worked only from the folder that held it, and a daemon started
from anywhere else was told its model folder did not exist. A default (a key the file leaves out)
is not in the file, so it stays relative to the current directory. Paths inside URLs follow the
same rule, through a converter that knows the URL's syntax (:func:`values_from_file`; the daemon's
rig URL: ``drivers.url_paths``); given on a command line, paths and URLs stay as written.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ghnerf_runtime.path_check import path_problem, shown

__all__ = ["config_folder", "impossible_path", "paths_from_file", "values_from_file"]


def config_folder(path: str | os.PathLike) -> Path:
    """The folder relative paths in the config file ``path`` are read from (absolute; links not followed,
    so ``/etc/ghnerf/daemon.json`` linked elsewhere still reads from ``/etc/ghnerf``)."""
    return Path(os.path.abspath(path)).parent


def paths_from_file(data: Any, keys: Sequence[tuple[str, ...]], path: str | os.PathLike) -> Any:
    """``data``, a config file's JSON, with each relative path string at ``keys`` (key paths, e.g.
    ``("session", "model_dir")``) made absolute against the folder of ``path``; ``data`` is not changed.

    A key that is absent, or a value that is not a non-empty string, is left for validation to report.

    >>> paths_from_file({"session": {"model_dir": "models"}}, [("session", "model_dir")], "/etc/ghnerf/a.json")
    {'session': {'model_dir': '/etc/ghnerf/models'}}
    """
    return values_from_file(data, keys, path, _plain_path)


def values_from_file(data: Any, keys: Sequence[tuple[str, ...]], path: str | os.PathLike,
                     convert: Callable[[str, Path], str]) -> Any:
    """``data`` with each non-empty string at ``keys`` replaced by ``convert(value, folder)``, ``folder``
    being :func:`config_folder` of ``path`` (for a URL naming files: its relative paths read from there);
    ``data`` is not changed, and anything else is left for validation to report."""
    folder = config_folder(path)
    for key in keys:
        data = _replace(data, key, folder, convert)
    return data


def impossible_path(data: Any, keys: Sequence[tuple[str, ...]]) -> tuple[str, str] | None:
    """The first path string at ``keys`` in ``data`` (a config file's JSON, as written) that no file can have
    (:func:`ghnerf_runtime.path_check.path_problem`), as ``(dotted key, "value: why")``; None when there is none.
    Checked before :func:`paths_from_file` joins a relative one to the file's folder, so that a ``~`` is seen as
    written, and before anything touches it (a NUL byte raised ``ValueError`` from ``os.path.realpath``)."""
    for key in keys:
        node: Any = data
        for part in key:
            node = node.get(part) if isinstance(node, Mapping) else None
        problem = path_problem(node) if isinstance(node, str) and node else None
        if problem is not None:
            return ".".join(key), f"{shown(node)}: {problem}"
    return None


def _plain_path(value: str, folder: Path) -> str:
    return value if os.path.isabs(value) else str(folder / value)


def _replace(node: Any, key: tuple[str, ...], folder: Path, convert: Callable[[str, Path], str]) -> Any:
    if not isinstance(node, Mapping) or key[0] not in node:
        return node
    value = node[key[0]]
    if len(key) > 1:
        new = _replace(value, key[1:], folder, convert)
    elif isinstance(value, str) and value:
        new = convert(value, folder)
    else:
        return node
    return {**node, key[0]: new}
