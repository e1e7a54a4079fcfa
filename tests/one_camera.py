"""A person seen by one camera of the pair alone, as the oracle (``benchmarks.bench_runtime_common.OracleSession``)
takes it: the ``(2, J)`` visibility its ``set_truth`` reads. One helper for every test of a one-camera pair."""
from __future__ import annotations

import numpy as np


def seen_by(visible: np.ndarray, k: int) -> np.ndarray:
    """``visible`` (``(2, J)``, a camera's row per source: the truth's, or all True) with camera ``k``'s row kept and
    the other camera's all False: a person camera ``k`` sees as ``visible`` says and the other does not see."""
    one = np.array(visible, bool)  # a copy: the caller's truth stays whole
    if one.ndim != 2 or one.shape[0] != 2:
        raise ValueError(f"visible: expected (2, J) per camera, got shape {one.shape}")
    one[1 - k] = False
    return one
