"""JSON objects that remember the keys given more than once (``json.loads(..., object_pairs_hook=)``).

JSON keeps a repeated key's last value; a file that sets ``"method"`` twice loses the first without a word.
The rig file and the config files refuse such a key, naming it: this is the hook both parse with.
"""
from __future__ import annotations

from typing import Any

__all__ = ["KeysObject", "first_repeat", "remember_repeats"]


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
