"""Calls checked against depthai's own type stubs, for the parts of the backend no host can run.

depthai 3.12 refuses to create a device node (``Camera``) in a pipeline without a device ("Pipeline is
host only, cannot create device node"), and a ``dai.Device`` cannot be made without one attached. The
stand-ins here take their place, and every call the production code makes on them is checked against
the ``.pyi`` stubs shipped inside the installed depthai wheel (generated from its pybind11 bindings):
the method must exist on the real class, the arguments must bind to one of its overloads (names,
count) with values of the annotated types, and each canned answer must have the annotated return type.
So a misspelt method or keyword, or an argument of the wrong type, fails here as it would on a device.

Test-only: lives in tests/, never in production code.
"""
from __future__ import annotations

import ast
import collections.abc
import datetime
import functools
import inspect
import os
import types
import typing
from pathlib import Path
from typing import Any

import depthai as dai
import numpy as np

STUB_ROOT = Path(dai.__file__).parent / "depthai"


class StubMismatch(AssertionError):
    """A call, or a stand-in's answer, that depthai's stubs do not allow."""


@functools.cache
def _stub_tree(module: str) -> ast.Module:
    """The parsed stub of ``depthai`` or one of its submodules (``depthai.node``)."""
    parts = module.split(".")[1:]
    path = STUB_ROOT.joinpath(*parts, "__init__.pyi")
    if not path.exists():
        raise StubMismatch(f"no depthai stub for module {module}: {path} is missing")
    return ast.parse(path.read_text())


def _stub_class(cls: type) -> ast.ClassDef | None:
    """The stub's ``class`` statement of a real depthai class (nested ones by qualified name)."""
    body: list[ast.stmt] = _stub_tree(cls.__module__).body
    found = None
    for name in cls.__qualname__.split("."):
        found = next((s for s in body if isinstance(s, ast.ClassDef) and s.name == name), None)
        if found is None:
            return None
        body = found.body
    return found


def _signature(function: ast.FunctionDef) -> inspect.Signature:
    """An ``inspect.Signature`` of a stub function; annotations stay source text. ``self`` is dropped."""
    args = function.args
    static = any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in function.decorator_list)
    positional = args.posonlyargs + args.args
    defaults = [None] * (len(positional) - len(args.defaults)) + list(args.defaults)
    params = []
    for index, (arg, default) in enumerate(zip(positional, defaults)):
        if index == 0 and not static:
            continue  # self
        kind = (inspect.Parameter.POSITIONAL_ONLY if arg in args.posonlyargs
                else inspect.Parameter.POSITIONAL_OR_KEYWORD)
        params.append(inspect.Parameter(arg.arg, kind, default=inspect.Parameter.empty if default is None else ...,
                                        annotation=_text(arg.annotation)))
    if args.vararg:
        params.append(inspect.Parameter(args.vararg.arg, inspect.Parameter.VAR_POSITIONAL))
    for arg, default in zip(args.kwonlyargs, args.kw_defaults):
        params.append(inspect.Parameter(arg.arg, inspect.Parameter.KEYWORD_ONLY,
                                        default=inspect.Parameter.empty if default is None else ...,
                                        annotation=_text(arg.annotation)))
    if args.kwarg:
        params.append(inspect.Parameter(args.kwarg.arg, inspect.Parameter.VAR_KEYWORD))
    return inspect.Signature(params, return_annotation=_text(function.returns))


def _text(node: ast.expr | None) -> Any:
    return inspect.Parameter.empty if node is None else ast.unparse(node)


def overloads(cls: type, method: str) -> list[inspect.Signature]:
    """Every stub signature of ``cls.method``, looked up along the real class's bases (``Device`` ->
    ``DeviceBase``).

    Raises:
        StubMismatch: the real class has no such attribute, or no stub defines it.
    """
    if not hasattr(cls, method):
        raise StubMismatch(f"depthai {cls.__module__}.{cls.__qualname__} has no attribute {method!r}")
    for base in cls.__mro__:
        if not base.__module__.startswith("depthai"):
            continue
        stub = _stub_class(base)
        functions = [s for s in (stub.body if stub else []) if isinstance(s, ast.FunctionDef) and s.name == method]
        if functions:
            return [_signature(f) for f in functions]
    raise StubMismatch(f"no stub signature for depthai {cls.__qualname__}.{method}")


def _namespace(cls: type) -> dict[str, Any]:
    """Names a stub annotation of ``cls`` may use: its own module's classes first (``Camera`` in depthai.node)."""
    module = dai.node if cls.__module__ == "depthai.node" else dai
    space: dict[str, Any] = {name: getattr(typing, name) for name in typing.__all__}  # Type[T], Optional...
    space.update({"depthai": dai, "datetime": datetime, "typing": typing, "numpy": np, "os": os,
                  "T": typing.TypeVar("T"), "Callable": collections.abc.Callable})
    space.update({name: getattr(dai, name) for name in dir(dai) if not name.startswith("_")})
    space.update({name: getattr(module, name) for name in dir(module) if not name.startswith("_")})
    return space


def _annotation(text: Any, cls: type) -> Any:
    if text is inspect.Parameter.empty:
        return Any
    try:
        return eval(text, _namespace(cls))  # noqa: S307 - the installed wheel's own stub text
    except Exception as e:  # noqa: BLE001
        raise StubMismatch(f"cannot read the stub annotation {text!r} of {cls.__qualname__}: {e}") from e


def conforms(value: Any, annotation: Any) -> bool:
    """Whether pybind11 would accept ``value`` for a parameter annotated ``annotation`` (the cases depthai's
    stubs use: its classes and enums, builtins, ``X | None``, ``tuple[...]``, ``list[...]``, callables)."""
    if annotation is Any or annotation is inspect.Parameter.empty:
        return True
    if annotation is None or annotation is type(None):
        return value is None
    origin = typing.get_origin(annotation)
    if origin in (types.UnionType, typing.Union):
        return any(conforms(value, member) for member in typing.get_args(annotation))
    if origin is tuple:
        items = typing.get_args(annotation)
        return (isinstance(value, (tuple, list)) and len(value) == len(items)
                and all(conforms(v, a) for v, a in zip(value, items)))
    if origin is list:
        (item,) = typing.get_args(annotation)
        return isinstance(value, (list, tuple)) and all(conforms(v, item) for v in value)
    if origin is collections.abc.Callable or annotation is collections.abc.Callable:
        return callable(value)
    if annotation is float:
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    if annotation is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if annotation is os.PathLike:
        return isinstance(value, (str, os.PathLike))
    if isinstance(annotation, type):
        stands_for = getattr(type(value), "stands_for", None)
        return isinstance(value, annotation) or (isinstance(stands_for, type) and issubclass(stands_for, annotation))
    return True  # a form the stubs do not use for the calls checked here


def check_call(cls: type, method: str, args: tuple = (), kwargs: dict | None = None) -> inspect.Signature:
    """The stub overload of ``cls.method`` that ``args``/``kwargs`` fit, by names, count and types.

    Raises:
        StubMismatch: none fits; the message lists the call and every overload.
    """
    kwargs = kwargs or {}
    signatures = overloads(cls, method)
    for signature in signatures:
        try:
            bound = signature.bind(*args, **kwargs)
        except TypeError:
            continue
        params = signature.parameters
        if all(conforms(value, _annotation(params[name].annotation, cls))
               for name, value in bound.arguments.items()
               if params[name].kind not in (inspect.Parameter.VAR_POSITIONAL, inspect.Parameter.VAR_KEYWORD)):
            return signature
    shown = ", ".join([repr(a) for a in args] + [f"{k}={v!r}" for k, v in kwargs.items()])
    raise StubMismatch(f"depthai {cls.__qualname__}.{method}({shown}) fits none of its stub overloads: "
                       + "; ".join(str(s) for s in signatures))


def check_answer(cls: type, method: str, signature: inspect.Signature, value: Any) -> Any:
    """``value``, after checking it has the return type ``signature`` (the overload called) declares."""
    if not conforms(value, _annotation(signature.return_annotation, cls)):
        raise StubMismatch(f"stand-in answer {value!r} for depthai {cls.__qualname__}.{method} is not a "
                           f"{signature.return_annotation}")
    return value


class StandIn:
    """An object standing for an instance of the depthai class ``stands_for``: calls to the methods named in
    ``answers`` are checked (:func:`check_call`), recorded in ``calls`` and answered (a value, or a callable
    given the call's arguments); any other attribute is an error, so nothing goes unchecked."""

    stands_for: type = object

    def __init__(self, answers: dict[str, Any]) -> None:
        self._answers = answers
        self.calls: list[tuple[str, tuple, dict]] = []

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in self._answers:
            raise AttributeError(f"stand-in for {self.stands_for.__qualname__} has no answer for {name!r}")

        def method(*args: Any, **kwargs: Any) -> Any:
            signature = check_call(self.stands_for, name, args, kwargs)
            self.calls.append((name, args, kwargs))
            answer = self._answers[name]
            value = answer(*args, **kwargs) if callable(answer) else answer
            return check_answer(self.stands_for, name, signature, value)

        return method

    def called(self, name: str) -> list[tuple[tuple, dict]]:
        return [(args, kwargs) for called, args, kwargs in self.calls if called == name]
