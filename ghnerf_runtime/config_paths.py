"""Relative paths written in a config file are read from the file's own folder.

The convention of systemd drop-ins and docker compose: a config names its model folder or status
file the same way wherever the program is started from. Read from the current directory instead,
the example config's ``"models"`` worked only from the folder that held it, and a daemon started
from anywhere else was told its model folder did not exist. A default (a key the file leaves out)
is not in the file, so it stays relative to the current directory. Paths inside URLs are the
backends' own syntax, as on the command line, and are left as written.
"""
from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

__all__ = ["config_folder", "paths_from_file"]


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
    folder = config_folder(path)
    for key in keys:
        data = _replace(data, key, folder)
    return data


def _replace(node: Any, key: tuple[str, ...], folder: Path) -> Any:
    if not isinstance(node, Mapping) or key[0] not in node:
        return node
    value = node[key[0]]
    if len(key) > 1:
        new = _replace(value, key[1:], folder)
    elif isinstance(value, str) and value and not os.path.isabs(value):
        new = str(folder / value)
    else:
        return node
    return {**node, key[0]: new}
