"""The int8 calibration frames a user brings (``python -m training.export --int8 --calib-npz FILE``), checked
against the model contract before anything is exported.

Static quantization fixes each activation's range from these frames, so they must be what the runtime feeds the
``encoder`` / ``human`` graphs (``ghnerf_runtime.preprocess``): the two source crops at the contract resolution,
channels first, values in the contract's range (``[0, 1]``: ``uint8 / 255``). Frames in 0..255 would calibrate
ranges 255 times too wide (every real pixel then falls into a few int8 steps) and nothing downstream would say
so; frames ``(H, W, 3)`` or of another size fail deep inside torch or onnxruntime. The colour order (RGB) cannot
be told from the values: the docs say it.
"""
from __future__ import annotations

import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ghnerf_runtime.contract import ModelContract

#: The array of the npz file that holds the frames.
KEY = "images"
#: Fewest frame pairs a file may hold. Static int8 fixes every activation's range at the extremes the calibration
#: frames reach, so the ranges of one or two pairs are one scene's, and a device's other scenes clip against them;
#: nothing after the export would say so but the int8 parity check on other images. A floor, not a measured
#: optimum: ``make model`` calibrates on 16 training scenes, ``python -m training.export`` on 8 random frames
#: (``--calib-frames``, which refuses fewer than this floor too).
MIN_FRAMES = 4
#: What numpy and zipfile raise for a file that is no readable npz: EOFError an empty file; zlib.error a damaged
#: deflate stream; tokenize.TokenError and SyntaxError a damaged array header; KeyError and NotImplementedError a
#: damaged zip directory (each was a traceback of the export).
UNREADABLE = (OSError, ValueError, EOFError, KeyError, NotImplementedError, SyntaxError, zipfile.BadZipFile,
              zlib.error, tokenize.TokenError)


class CalibrationDataError(ValueError):
    """A calibration file that does not hold what the runtime feeds the model; the message names the file,
    the array and the value."""

    def __init__(self, path: str | Path, message: str):
        super().__init__(f"{path}: {message}")
        self.path = str(path)


def load_calibration_npz(path: str | Path, contract: ModelContract) -> list[np.ndarray]:
    """The frames of ``path`` (npz, ``images`` ``(F, S, 3, H, W)``, float, RGB in the contract's value range),
    one float32 ``(S, 3, H, W)`` array each.

    Raises:
        CalibrationDataError: an unreadable file, no ``images`` array, another shape or size, fewer than
            :data:`MIN_FRAMES` frames, integer or non-finite pixels, values outside the contract's range, a
            uniform (blank) view.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            if KEY not in npz.files:
                raise CalibrationDataError(path, f"no {KEY!r} array (it holds {sorted(npz.files)})")
            images = npz[KEY]
    except UNREADABLE as e:
        if isinstance(e, CalibrationDataError):
            raise
        raise CalibrationDataError(path, f"cannot read it as an npz file ({type(e).__name__}: {e})") from e
    S, H, W = contract.num_sources, contract.height, contract.width
    want = f"(F, {S}, 3, {H}, {W})"
    if images.ndim != 5 or images.shape[1:] != (S, 3, H, W) or images.shape[0] < 1:
        raise CalibrationDataError(path, f"{KEY!r} has shape {list(images.shape)}; the model wants {want}: "
                                         f"F frame pairs, channels first, at the contract resolution {W}x{H}")
    if images.shape[0] < MIN_FRAMES:
        raise CalibrationDataError(path, f"{KEY!r} holds {images.shape[0]} frame pair(s); int8 calibration wants at "
                                         f"least {MIN_FRAMES} (its ranges would be one scene's)")
    lo, hi = (float(v) for v in contract.normalisation.value_range)
    if not np.issubdtype(images.dtype, np.floating):
        raise CalibrationDataError(path, f"{KEY!r} is {images.dtype}; the model wants float pixels in [{lo:g}, "
                                         f"{hi:g}] (uint8 / 255, as the runtime feeds it)")
    if not np.all(np.isfinite(images)):
        raise CalibrationDataError(path, f"{KEY!r} holds NaN or infinite values")
    vmin, vmax = float(images.min()), float(images.max())
    if vmin < lo or vmax > hi:
        raise CalibrationDataError(path, f"{KEY!r} values span [{vmin:g}, {vmax:g}]; the model wants [{lo:g}, "
                                         f"{hi:g}] (uint8 / 255, as the runtime feeds it)")
    # a uniform view (all black: a lens cap, a camera not started, a zero-filled buffer) is a capture fault, not a
    # scene: a file of them fixes every range at one value and the int8 graphs clip every real frame; one among
    # real frames says the file is not what it was meant to be
    flat = images.reshape(images.shape[0], S, -1)
    uniform = np.argwhere(flat.max(axis=2) == flat.min(axis=2))
    if len(uniform):
        f, s = (int(v) for v in uniform[0])
        raise CalibrationDataError(path, f"{KEY!r} frame {f} source {s} is uniform (every pixel "
                                         f"{float(images[f, s].flat[0]):g}; {len(uniform)} of the {images.shape[0] * S} "
                                         f"views are): a blank capture, not a scene")
    return [np.ascontiguousarray(f, dtype=np.float32) for f in images]


__all__ = ["CalibrationDataError", "KEY", "MIN_FRAMES", "load_calibration_npz"]
