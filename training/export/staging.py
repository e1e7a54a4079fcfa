"""Replace a model folder's graphs only with checked ones: write them in ``<folder>.staging``, check them there,
then move them in (``make model``'s export and quantize stages, and ``python -m training.export``).

A failed export or parity check leaves the folder as it was and the rejected files in the staging folder. Moving
new graphs in also drops what no longer describes them: the ``<graph>.int8.onnx`` quantized from a replaced fp32
graph (the runtime's ``auto`` precision would load it beside the new graphs as one model), and a model card (with
its metrics) whose recorded sha256 no longer match the folder's files; the card is set aside as
``model_card.stale.json`` (the pipeline's card stage writes a new one and reads the painter's section from it).

The move itself is one ``os.replace`` per file, so it cannot be one step; what keeps a folder from holding some new
graphs beside old ones (same contract, other weights) is that a Ctrl-C or SIGTERM during it is held until the
last file is in, and that a move cut short by a crash is finished by the next :func:`staging_dir` of the folder
(the staging folder lists what it was moving, :data:`MOVING`). Until then (a power cut in the move) the folder
is mixed, and the runtime refuses it: every graph of one export carries the same weights id
(``ghnerf_runtime.contract.WEIGHTS_ID_KEY``), which ``ModelSession.load`` compares.
"""
from __future__ import annotations

import json
import logging
import os
import shutil
import signal
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterable, Mapping

from training.model_card import sha256

log = logging.getLogger(__name__)

#: ``<folder>`` + this: where new files are written and checked before they replace the folder's (beside it, so on
#: the same file system for ``os.replace``).
STAGING_SUFFIX = ".staging"
CARD = "model_card.json"
#: What a stale card is moved to (and its companions: ``MODEL_CARD.md``, the metrics it was made from).
STALE_CARD = "model_card.stale.json"
_CARD_COMPANIONS = ("MODEL_CARD.md", "metrics.json")


#: Written into the staging folder before its files move into the model folder: their names (JSON). Found by the
#: next :func:`staging_dir`, it means a move was cut short (a crash, a kill), and the files still staged go in.
MOVING = "moving.json"


def staging_dir(folder: Path) -> Path:
    """An empty ``<folder>.staging`` (a failed attempt's files, kept for inspection, go now; a move into ``folder``
    cut short is finished first, :func:`finish_interrupted_move`)."""
    staging = folder.with_name(folder.name + STAGING_SUFFIX)
    finish_interrupted_move(staging, folder)
    if staging.exists():
        log.info("removing %s (the rejected files of an earlier attempt)", staging)
        shutil.rmtree(staging)
    staging.mkdir(parents=True)
    return staging


def rejected(folder: Path, staging: Path, e: BaseException) -> None:
    """Say that a failure left ``folder`` as it was, and where its files are; a failed parity check is raised
    again with that said (the caller prints it as the error)."""
    from training.export.parity import ParityError

    where = f"{folder} is left as it was; the rejected files are kept in {staging}"
    if isinstance(e, ParityError):
        raise ParityError(f"{e} ({where})") from e
    log.error("%s", where)


def drop_stale_int8(folder: Path, fresh: Mapping[str, Path]) -> list[Path]:
    """Before fp32 graphs that differ from the folder's replace them: remove the ``<graph>.int8.onnx`` quantized
    from the old ones, which the runtime would load beside the new graphs as one model (``auto`` precision mixes
    int8 and fp32 files) until they are quantized again; a missing one falls back to the fp32 file. Returns the
    removed files."""
    removed = []
    for graph, new in fresh.items():
        old, int8 = folder / new.name, folder / f"{graph}.int8.onnx"
        if int8.exists() and not (old.exists() and sha256(old) == sha256(new)):
            log.info("removing %s: quantized from the %s being replaced (quantize again to remake it)",
                     int8, old.name)
            int8.unlink()
            removed.append(int8)
    return removed


def move_into(staging: Path, folder: Path, files: Iterable[Path], removed: Iterable[Path] = ()) -> list[Path]:
    """Move ``files`` (in ``staging``, checked) over the folder's, one ``os.replace`` each, then remove ``staging``;
    returns their paths in ``folder``. Before the first one moves, a card that records another version of any of
    them (or of a ``removed`` file) is set aside (:func:`set_aside_stale_cards`): from then on it would lie."""
    files = list(files)
    folder.mkdir(parents=True, exist_ok=True)
    set_aside_stale_cards(folder, {f.name: sha256(f) for f in files}, [p.name for p in removed])
    # the list first (whole: a temporary file, then os.replace), so a crash among the moves below is finished by the
    # next staging_dir; the moves themselves with Ctrl-C held, so one cannot leave half the files in
    marker = staging / MOVING
    tmp = marker.with_name(MOVING + ".tmp")
    tmp.write_text(json.dumps({"folder": str(folder), "files": [f.name for f in files]}))
    os.replace(tmp, marker)
    moved = []
    with _signals_held():
        for f in files:
            os.replace(f, folder / f.name)
            moved.append(folder / f.name)
        marker.unlink()
    shutil.rmtree(staging)
    return moved


def finish_interrupted_move(staging: Path, folder: Path) -> list[Path]:
    """Move into ``folder`` the files a cut-short :func:`move_into` left in ``staging`` (its :data:`MOVING` list
    names them), so the folder holds the new set whole, not some new graphs beside old ones; returns them (none
    when no move was cut short)."""
    marker = staging / MOVING
    try:
        names = json.loads(marker.read_text())["files"]
    except FileNotFoundError:
        return []
    except (OSError, ValueError, KeyError, TypeError) as e:  # the list is written whole: this is not ours to guess
        raise RuntimeError(f"{marker}: cannot read the list of a cut-short move into {folder} ({e}); move the "
                           f"files in {staging} into {folder} by hand, or remove {staging} and export again") from e
    left = [staging / n for n in names if (staging / n).is_file()]
    log.warning("%s: a move into %s was cut short; moving its %d remaining file(s) in now (%s)", staging, folder,
                len(left), ", ".join(p.name for p in left) or "none")
    with _signals_held():
        for f in left:
            os.replace(f, folder / f.name)
        marker.unlink()
    return [folder / f.name for f in left]


@contextmanager
def _signals_held():
    """Hold SIGINT and SIGTERM until the block ends, then deliver them to the handlers they would have met (a
    Ctrl-C still stops the program, after the block). Python runs signal handlers in the main thread only, so
    elsewhere nothing is held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {s: signal.signal(s, lambda n, _frame: got.append(n)) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)  # None: one set outside Python
        for s in dict.fromkeys(got):
            signal.raise_signal(s)


def set_aside_stale_cards(folder: Path, incoming: Mapping[str, str], gone: Iterable[str] = ()) -> list[Path]:
    """Set aside each model card (``folder``'s own, or its parent's, the pipeline's layout) whose ``files`` record
    one of ``incoming`` (name -> new sha256) with another hash, or one of ``gone``; returns the stale cards."""
    gone = set(gone)
    stale = []
    for card_dir in (folder, folder.parent):
        card = card_dir / CARD
        why = _card_is_stale(card, folder.relative_to(card_dir), incoming, gone)
        if why:
            _set_aside(card_dir, why)
            stale.append(card_dir / STALE_CARD)
    return stale


def _card_is_stale(card: Path, sub: Path, incoming: Mapping[str, str], gone: set[str]) -> str | None:
    """Why ``card`` no longer describes the folder ``sub`` (relative to the card) once ``incoming`` moves in
    and ``gone`` is removed; None while it still does (or records none of it: another folder's card)."""
    try:
        files = json.loads(card.read_text()).get("files") or {}
    except (OSError, ValueError, AttributeError):
        return None  # no card (an unreadable one is its writer's to redo)
    if not isinstance(files, dict):  # unreadable as well ("files" a list, say): was an AttributeError before the move
        return None
    for name, new_hash in sorted(incoming.items()):
        rec = files.get(str(sub / name))
        if rec is not None and (rec.get("sha256") if isinstance(rec, dict) else None) != new_hash:
            return f"it records another {sub / name}"
    for name in sorted(gone):
        if str(sub / name) in files:
            return f"it records {sub / name}, which is removed"
    return None


def _set_aside(card_dir: Path, why: str) -> None:
    os.replace(card_dir / CARD, card_dir / STALE_CARD)
    for name in _CARD_COMPANIONS:
        p = card_dir / name
        if p.exists():
            os.replace(p, p.with_name(f"{p.stem}.stale{p.suffix}"))
    log.warning("%s: set aside as %s (with its MODEL_CARD.md and metrics.json): %s, so its hashes and metrics "
                "describe the replaced model; the pipeline's card stage writes a new one", card_dir / CARD,
                STALE_CARD, why)


def drop_stale_leftovers(card_dir: Path) -> None:
    """Remove the set-aside card files once a new card is written."""
    for name in (STALE_CARD, *(f"{Path(n).stem}.stale{Path(n).suffix}" for n in _CARD_COMPANIONS)):
        (card_dir / name).unlink(missing_ok=True)


__all__ = ["STAGING_SUFFIX", "STALE_CARD", "MOVING", "staging_dir", "rejected", "drop_stale_int8", "move_into",
           "finish_interrupted_move",
           "set_aside_stale_cards", "drop_stale_leftovers"]
