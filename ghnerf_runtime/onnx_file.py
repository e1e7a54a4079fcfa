"""Opening a small auxiliary ONNX file (the skeleton prior, the novel-view painter) on the CPU.

The model's own graphs go through :class:`ghnerf_runtime.session.ModelSession`, which shares one
thread pool between them; these files are one small network each, loaded beside them with a pool of
their own whose workers do not spin.
"""
from __future__ import annotations

from pathlib import Path

from ghnerf_runtime.errors import ModelLoadError

__all__ = ["open_onnx_file"]


def open_onnx_file(path: str | Path, threads: int, what: str):
    """``(onnxruntime.InferenceSession, custom metadata dict)`` of ``path``; ``what`` names the file in the
    error when it is missing (``ModelLoadError``, also when onnxruntime cannot load it)."""
    import onnxruntime as ort

    path = Path(path)
    if not path.is_file():
        raise ModelLoadError(f"no such {what} file", path=str(path))
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    except Exception as e:  # onnxruntime's own exception types
        raise ModelLoadError(f"onnxruntime cannot load it ({path.stat().st_size} bytes; truncated or corrupt?): "
                             f"{type(e).__name__}: {str(e).strip()[:200]}", path=str(path)) from e
    return sess, dict(sess.get_modelmeta().custom_metadata_map)
