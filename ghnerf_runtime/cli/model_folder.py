"""Errors about the model folder, led by what named it: the option (``--model-dir X``) or the config file's key
(``session.model_dir in FILE``). The session words them as ``session.model_dir`` only (it knows no command line),
so ``ghnerf-run --model-dir m.json`` said ``m.json: is not a folder (session.model_dir names ...)``, naming a key
the user never typed; ``--validate-config`` named the option. ``ghnerf-run``, ``ghnerf-bench`` and
``ghnerf-demo`` word them here, so each says the same.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ghnerf_runtime.config import read_json_file
from ghnerf_runtime.errors import ConfigError, ModelError
from ghnerf_runtime.path_check import shown

__all__ = ["checked_model_folder", "config_names_model_dir", "model_dir_source", "model_folder_option",
           "named_by_source"]


def config_names_model_dir(config_path: str | None) -> bool:
    """Whether the config file at ``config_path`` (None: no ``--config``) names ``session.model_dir``; it was read
    already, so an error reading it again is one ``ConfigError`` naming it."""
    if not config_path:
        return False
    data = read_json_file(config_path, lambda message: ConfigError(message, key=str(config_path)))
    session = data.get("session") if isinstance(data, dict) else None
    return isinstance(session, dict) and "model_dir" in session


def model_dir_source(model_dir_option: str | None, config_path: str | None, model_dir: str) -> str | None:
    """What named the model folder ``model_dir``, as an error should say it: ``--model-dir X`` (the option,
    ``model_dir_option``, wins over the config), ``session.model_dir in FILE (X)``, or None for the default
    ``./models`` that neither names."""
    if model_dir_option:
        return f"--model-dir {shown(model_dir_option)}"
    if config_names_model_dir(config_path):
        return f"session.model_dir in {config_path} ({shown(model_dir)})"
    return None


def named_by_source(where: str, e: ModelError, model_dir: str) -> str:
    """``e`` led by ``where`` (:func:`model_dir_source`), the folder said once: ``--model-dir m.json: is not a
    folder (...)``. A file's error (``e.path`` inside the folder) keeps its path."""
    named = f"{e.path}: " if e.path is not None and Path(e.path) == Path(model_dir) else ""
    return f"{where}: {str(e).removeprefix(named)}"


def model_folder_option(text: str) -> str:
    """An argparse ``type=`` for a benchmark's ``--model-dir``: a folder that is there and holds graph files (the
    folder a session resolves it to, :func:`~ghnerf_runtime.session.resolve_model_dir`, has an ``.onnx`` file),
    refused at parsing (exit 2, the option named). A mistyped folder, or one holding no model (an empty one, a
    checkout's root), was a ModelLoadError traceback, in some scripts only once the sequences were rendered. Whether
    the files make a model the script can run is the session's to check, as it loads."""
    # local: onnxruntime comes with the session, and parsing --help needs none of it
    from ghnerf_runtime.session import resolve_model_dir

    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{shown(text)} is not a folder (make model builds ./models)")
    try:
        folder = resolve_model_dir(text)
    except ModelError as e:  # a folder this user may not read; the message names it
        raise argparse.ArgumentTypeError(str(e)) from None
    if not any(folder.glob("*.onnx")):
        raise argparse.ArgumentTypeError(f"{shown(text)} holds no model: no .onnx graph file in it, in its ghnerf/ "
                                         "subfolder or in a single subfolder (make model builds ./models)")
    return text


def checked_model_folder(parser: argparse.ArgumentParser, folder: str) -> str:
    """``folder``, a benchmark's ``--model-dir`` (its default), checked as :func:`model_folder_option` checks one at
    parsing (a usage error naming the option, exit 2), by a script that reads it only in some runs, once it knows
    the run does. Its ``--model-dir`` defaults to None: argparse runs ``type=`` on a string default, which refused
    the runs that read no model (``--oracle``, ``--prior``, ``--wake-margin``) where the default folder holds none."""
    try:
        return model_folder_option(folder)
    except argparse.ArgumentTypeError as e:
        parser.error(f"argument --model-dir: {e}")
