"""JSON objects that remember the keys given more than once (``json.loads(..., object_pairs_hook=)``).

JSON keeps a repeated key's last value; a file that sets ``"method"`` twice loses the first without a word.
The rig file, the config files and a take's manifest refuse such a key, naming it: this is the hook they parse
with, and :func:`loads_remembering` the one parse they share (each says its errors in its own words).
"""
from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

__all__ = ["JsonTextError", "KeysObject", "MAX_JSON_DEPTH", "first_repeat", "loads_remembering", "nested_deeper_than",
           "remember_repeats"]

#: Deepest nesting of objects and arrays :func:`loads_remembering` takes (the outermost is level 1). The files read
#: with it (rig, configs, a take's manifest) are a few levels deep, a rig's free-form ``metadata`` at most 100 more
#: (``rig_file.MAX_METADATA_DEPTH``). Python's parser takes up to about 1000, but the readers walk what it returns
#: recursively (:func:`first_repeat`, the copies into plain dicts): from about 500 levels a bare RecursionError,
#: naming no file, came out of them.
MAX_JSON_DEPTH = 128


class JsonTextError(ValueError):
    """Text that is not JSON Python reads: ``reason`` says why, ``line`` and ``column`` where (``None`` for text
    nested too deeply or an integer past Python's digit limit, which have no one place)."""

    def __init__(self, reason: str, line: int | None = None, column: int | None = None) -> None:
        super().__init__(f"invalid JSON at line {line}, column {column}: {reason}" if line is not None
                         else f"invalid JSON: {reason}")
        self.reason, self.line, self.column = reason, line, column


class KeysObject(dict):
    """A parsed JSON object; ``duplicates`` the keys it was given more than once."""

    duplicates: tuple[str, ...] = ()


def remember_repeats(pairs: list[tuple[str, Any]]) -> KeysObject:
    """The ``object_pairs_hook``: the object (last value of each key, as JSON keeps) and its repeated keys.

    Example:
        >>> import json
        >>> obj = json.loads('{"a": 1, "b": 2, "a": 3}', object_pairs_hook=remember_repeats)
        >>> dict(obj), obj.duplicates
        ({'a': 3, 'b': 2}, ('a',))
    """
    obj = KeysObject()
    repeated = []
    for key, value in pairs:
        if key in obj:
            repeated.append(key)
        obj[key] = value
    obj.duplicates = tuple(repeated)
    return obj


def first_repeat(value: Any, where: str = "") -> str | None:
    """The path (``rig.cameras[0].K``) of the first key given twice anywhere in ``value`` (parsed with
    :func:`remember_repeats`), or ``None``."""
    if isinstance(value, dict):
        repeated = getattr(value, "duplicates", ())
        if repeated:
            return f"{where}.{repeated[0]}" if where else repeated[0]
        items = ((f"{where}.{k}" if where else str(k), v) for k, v in value.items())
    elif isinstance(value, list):
        items = ((f"{where}[{i}]", v) for i, v in enumerate(value))
    else:
        return None
    return next((found for path, v in items if (found := first_repeat(v, path)) is not None), None)


def loads_remembering(text: str, *, object_pairs_hook: Callable[[list[tuple[str, Any]]], Any] = remember_repeats
                      ) -> Any:
    """``text`` parsed with :func:`remember_repeats` (every object a :class:`KeysObject`), or with
    ``object_pairs_hook`` in its place: one that refuses a repeated key itself (the board file names both values).
    What the hook raises goes through as it is.

    Raises:
        JsonTextError: invalid JSON (with its line and column), JSON nested too deeply (past
            :data:`MAX_JSON_DEPTH`, or a RecursionError from the parser) or an integer of more digits than Python
            converts (4300): each was a traceback from a reader that caught only the first.
    """
    try:
        value = json.loads(text, object_pairs_hook=object_pairs_hook, parse_int=_int_or_refuse)
    except json.JSONDecodeError as e:
        raise JsonTextError(e.msg, e.lineno, e.colno) from e
    except RecursionError as e:
        raise JsonTextError("nested too deeply") from e
    if nested_deeper_than(value, MAX_JSON_DEPTH):
        raise JsonTextError(f"nested too deeply (objects and arrays more than {MAX_JSON_DEPTH} levels deep, "
                            "MAX_JSON_DEPTH)")
    return value


def _int_or_refuse(digits: str) -> int:
    """A JSON integer; past Python's digit limit (4300) a :class:`JsonTextError`, told from the ValueError a hook
    may raise (the board file's, a repeated key)."""
    try:
        return int(digits)
    except ValueError as e:
        raise JsonTextError(str(e)) from e


def nested_deeper_than(value: Any, limit: int) -> bool:
    """Whether objects (dicts) and arrays (lists) nest in ``value`` more than ``limit`` levels deep (``value`` itself
    is level 1); iterative, so no depth is too deep to measure."""
    pending = [(value, 1)]
    while pending:
        item, level = pending.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        if level > limit:
            return True
        pending.extend((child, level + 1) for child in children)
    return False
