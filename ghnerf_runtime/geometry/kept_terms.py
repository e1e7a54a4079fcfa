"""Terms a caller computes once from its projection matrices and passes back on later calls (the two-view solver's,
the skeleton prior's): read-only, reused only for the very matrices they were computed from. The caller owns them;
the functions that take them keep nothing between calls."""
from __future__ import annotations

from typing import Callable, Protocol, TypeVar

import numpy as np

from ghnerf_runtime.errors import GeometryError

__all__ = ["read_only", "same_bits", "terms_of"]


def read_only(*arrays: np.ndarray) -> None:
    """Mark arrays read-only: they are shared by every later call that reuses them."""
    for a in arrays:
        a.setflags(write=False)


def same_bits(kept: np.ndarray, given) -> bool:
    """Whether ``given`` holds the same float64 values as ``kept`` to the bit (shape included): the test for
    reusing terms or a solve, where values equal by ``==`` (0.0 and -0.0) may still be other inputs."""
    given = np.asarray(given, dtype=np.float64)
    return given.shape == kept.shape and given.tobytes() == kept.tobytes()


class _Terms(Protocol):
    P: np.ndarray

    def is_for(self, P) -> bool: ...


T = TypeVar("T", bound=_Terms)


def terms_of(P: np.ndarray, given: T | None, compute: Callable[[np.ndarray], T], what: str) -> T:
    """``given`` where given (they must be ``P``'s), else ``compute(P)``.

    Raises:
        GeometryError: ``given`` were computed from other matrices (named ``what`` in the message).
    """
    if given is None:
        return compute(P)
    if not given.is_for(P):
        raise GeometryError(f"the {what} given are those of other matrices than P = {np.asarray(P).tolist()} "
                            f"(they were computed for {given.P.tolist()})")
    return given
