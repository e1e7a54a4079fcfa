"""Config base class, nerfstudio style: one dataclass per component, nested, each building its module.

No global config singleton: a preset (``training/configs.py``) is a plain tree of these dataclasses.
:meth:`Config.from_dict` validates once and names unknown or mistyped keys.
"""
from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import dataclass, fields
from typing import Any, ClassVar, Mapping


class ConfigError(ValueError):
    """A config dict has an unknown key or a value of the wrong type; the message names the key path."""


@dataclass
class Config:
    """Base of every component config. ``setup(**kw)`` builds ``_target(self, **kw)``."""

    _target: ClassVar[type | None] = None

    def setup(self, **kwargs: Any) -> Any:
        if self._target is None:
            raise NotImplementedError(f"{type(self).__name__} has no _target to set up")
        return self._target(self, **kwargs)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], _path: str = "") -> "Config":
        """Build from a (possibly partial) nested dict; unknown keys raise :class:`ConfigError`."""
        if not isinstance(data, Mapping):
            raise ConfigError(f"{_path or cls.__name__}: expected a mapping, got {type(data).__name__}")
        hints = typing.get_type_hints(cls)
        known = {f.name: f for f in fields(cls)}
        kwargs = {}
        for key, value in data.items():
            path = f"{_path}.{key}" if _path else key
            if key not in known:
                raise ConfigError(f"{path}: unknown key for {cls.__name__}; known keys: {sorted(known)}")
            hint = hints[key]
            kwargs[key] = _convert(hint, value, path)
        return cls(**kwargs)


def _convert(hint: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(hint)
    if origin is typing.Literal:
        if value not in typing.get_args(hint):
            raise ConfigError(f"{path}: expected one of {list(typing.get_args(hint))}, got {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        errors = []
        for a in args:
            if a is type(None):
                continue
            try:
                return _convert(a, value, path)
            except ConfigError as e:
                errors.append(str(e))
        raise ConfigError("; ".join(errors))
    if isinstance(hint, type) and issubclass(hint, Config):
        return hint.from_dict(value, path)
    if origin is tuple:
        args = typing.get_args(hint)
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{path}: expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{path}: expected {len(args)} items, got {len(value)}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    if hint is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true/false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {value!r}")
        return value
    return value
