"""Opening a small auxiliary ONNX file (the skeleton prior, the novel-view painter) on the CPU, and
onnxruntime's process-wide thread pool.

The model's own graphs go through :class:`ghnerf_runtime.session.ModelSession`, which shares one
thread pool between them; these files are one small network each, loaded beside them with a pool of
their own whose workers do not spin, or on the global pool once one is installed
(``SessionConfig.thread_pool = "global"``): onnxruntime then refuses any session with its own.
"""
from __future__ import annotations

import functools
import hashlib
import logging
import os
import re
import threading
from pathlib import Path
from typing import Iterable

import numpy as np

from ghnerf_runtime.errors import ModelError, ModelLoadError

__all__ = ["ORT_LOG_SEVERITY", "STALE_INT8_AGE_S", "open_onnx_file", "ensure_global_pool", "global_pool_threads",
           "load_failure", "ort_reason", "non_finite_output", "onnx_metadata", "stale_int8_reason",
           "warn_stale_int8"]

log = logging.getLogger(__name__)

# onnxruntime's global pool is process-wide by nature and cannot be resized once installed.
_global_pool_lock = threading.Lock()
_global_pool_threads: int | None = None


def ensure_global_pool(threads: int) -> None:
    """Install onnxruntime's process-wide pool once (it cannot be resized afterwards)."""
    global _global_pool_threads
    with _global_pool_lock:
        if _global_pool_threads is None:
            try:
                from onnxruntime.capi import _pybind_state
                _pybind_state.set_global_thread_pool_sizes(int(threads), 1)
            except (AttributeError, RuntimeError) as e:
                raise ModelError(f"cannot install onnxruntime's global thread pool ({e}); use "
                                 "thread_pool='per_session'") from e
            _global_pool_threads = int(threads)
        elif _global_pool_threads != threads:
            log.warning("onnxruntime global pool already has %d threads; %d requested", _global_pool_threads, threads)


def global_pool_threads() -> int | None:
    """The global pool's size once installed, else ``None``."""
    return _global_pool_threads


# "Load model from <path> failed:" and the C++ source line and signature onnxruntime puts before its reason
# (a template's "const [with T = float]" too)
_ORT_LOAD_PREFIX = re.compile(r"Load model from .*? failed:\s*")
_ORT_SOURCE = re.compile(r"\S+\.(?:cc|cpp|h|hpp):\d+ [^()]*\([^()]*\)\s*(?:const\s*)?(?:\[with [^\]]*\]\s*)?")
_REASON_CHARS = 500
# what onnxruntime says when the operating system refuses the file (13: permission denied, 5: an I/O error)
_ORT_ERRNO = re.compile(r"system error number (\d+)")
#: onnxruntime's own log, to stderr: only what is fatal. Its errors come back as exceptions, which the runtime
#: raises as its own naming the graph and file; logged as well, each put a second, raw line in the journal
#: (ANSI-coloured, with the C++ source location) before the daemon's own.
ORT_LOG_SEVERITY = 4
#: Where no recorded link (the fp32 file's sha256, a weights id, the painter's training record) says whether an int8
#: file was quantized from the fp32 file beside it, it was not when it is older than that file by more than this. A
#: margin, not "older": a copy or a git checkout resets the times in the order it writes the files (encoder.int8.onnx
#: 0.09 s before encoder.onnx in a checkout of models/), while an export made after training comes minutes after the
#: one before.
STALE_INT8_AGE_S = 600.0


def non_finite_output(outputs: Iterable[tuple[str, np.ndarray]]) -> tuple[str, int, int] | None:
    """The first of a warm-up run's ``(name, value)`` outputs holding NaN or infinite values, as ``(name, how many,
    of how many)``; None where all are finite. Weights that hold them answer them to every input: the model's
    graphs and the skeleton prior refuse them at warm-up by this one check."""
    for name, value in outputs:
        finite = np.isfinite(value)
        if not finite.all():
            return name, int(finite.size - np.count_nonzero(finite)), int(finite.size)
    return None


def ort_reason(error: Exception, limit: int = _REASON_CHARS) -> str:
    """onnxruntime's words for ``error``, on one line: without the C++ source location and function signature
    that would take up the message, with the operating system's words for an error number it gives ("system
    error number 13": a file the service's user may not read), and at most ``limit`` characters of its end
    (where onnxruntime says why)."""
    text = _ORT_SOURCE.sub("", _ORT_LOAD_PREFIX.sub("", " ".join(str(error).split())))
    text = _ORT_ERRNO.sub(lambda m: f"{os.strerror(int(m.group(1)))} ({m.group(0)})", text)
    return "..." + text[-limit:] if len(text) > limit else text


def load_failure(error: Exception, path: Path, what: str) -> ModelLoadError:
    """The error for an onnxruntime that cannot load ``path``: its reason (:func:`ort_reason`: an IR version or
    opset too new, an unknown operator, a file it may not read), and "truncated or corrupt?" only where the file
    did not parse."""
    text = ort_reason(error)
    damaged = "; truncated or corrupt?" if "protobuf" in text.lower() else ""  # else: it parsed, and said why
    size = path.stat().st_size if path.is_file() else 0
    return ModelLoadError(f"onnxruntime cannot load the {what} ({size} bytes{damaged}): {type(error).__name__}: "
                          f"{text}", path=str(path))


def open_onnx_file(path: str | Path, threads: int, what: str):
    """``(onnxruntime.InferenceSession, custom metadata dict)`` of ``path``; ``what`` names the file in the
    error when it is missing (``ModelLoadError``, also when onnxruntime cannot load it)."""
    sess = _session(Path(path), threads, what)
    return sess, dict(sess.get_modelmeta().custom_metadata_map)


def onnx_metadata(path: str | Path, what: str) -> dict[str, str]:
    """The custom metadata (``metadata_props``) of the ONNX file ``path``, parsed by the protobuf library with
    only that field declared, its graph skipped unparsed: milliseconds, where an onnxruntime session of the 11 MB
    encoder takes 165 ms even unoptimised, for a file only read to compare it with another. ``what`` names it in
    the error.

    Raises:
        ModelLoadError: naming the file, where it cannot be read or is no protobuf message (truncated, not ONNX).
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ModelLoadError(f"cannot read the {what} file: {e.strerror or e}", path=str(path)) from None
    from google.protobuf.message import DecodeError

    try:
        model = _model_metadata_class().FromString(data)
    except DecodeError as e:  # cut short, or not a protobuf message
        raise ModelLoadError(f"the {what} file is no ONNX model (truncated or corrupt?): {e}",
                             path=str(path)) from None
    return {entry.key: entry.value for entry in model.metadata_props}


@functools.cache
def _model_metadata_class():
    """A message class of ``onnx.proto``'s ``ModelProto`` with only ``metadata_props`` (field 14, each a
    ``StringStringEntryProto`` of ``key`` 1 and ``value`` 2): the graph and the other fields parse as unknown
    fields, unread. Declared here, as the ``onnx`` package (its generated classes) is training-only; built once,
    in a pool of its own (not the default pool, where an imported ``onnx`` declares the real ``onnx.ModelProto``).
    proto3, where onnx.proto is proto2: the same wire format, and a key or value that is not UTF-8 is a DecodeError
    (proto2 strings parse as bytes)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    desc = descriptor_pb2.FieldDescriptorProto
    entry = descriptor_pb2.DescriptorProto(name="StringStringEntryProto", field=[
        desc(name=name, number=number, type=desc.TYPE_STRING, label=desc.LABEL_OPTIONAL)
        for number, name in ((1, "key"), (2, "value"))])
    model = descriptor_pb2.DescriptorProto(name="ModelProto", field=[
        desc(name="metadata_props", number=_METADATA_FIELD, type=desc.TYPE_MESSAGE, label=desc.LABEL_REPEATED,
             type_name=".ghnerf_onnx_lite.StringStringEntryProto")])
    pool = descriptor_pool.DescriptorPool()
    pool.Add(descriptor_pb2.FileDescriptorProto(name="ghnerf_onnx_lite.proto", package="ghnerf_onnx_lite",
                                                syntax="proto3", message_type=[entry, model]))
    return message_factory.GetMessageClass(pool.FindMessageTypeByName("ghnerf_onnx_lite.ModelProto"))


#: ``ModelProto.metadata_props`` (onnx.proto).
_METADATA_FIELD = 14


def _session(path: Path, threads: int, what: str):
    import onnxruntime as ort

    if not path.is_file():
        raise ModelLoadError(f"no such {what} file", path=str(path))
    opts = ort.SessionOptions()
    opts.log_severity_level = ORT_LOG_SEVERITY
    if global_pool_threads() is not None:  # every session of the process must then run on it
        opts.use_per_session_threads = False
    else:
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    try:
        return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    except Exception as e:  # onnxruntime's own exception types
        raise load_failure(e, path, what) from e


def stale_int8_reason(int8: Path, fp32: Path, differs: list[str] | None,
                      fp32_sha256: str | None = None) -> str | None:
    """Why the int8 file ``int8`` was not quantized from its fp32 twin ``fp32`` (for a warning), None where it may
    have been. ``fp32_sha256``: the sha256 of the fp32 file the quantizer recorded in the int8 one; where given it
    decides alone (the same bytes: quantized from this file, whatever the times; other bytes: not). Else
    ``differs``: the recorded links (metadata of the fp32 file an int8 file carries over) that differ between the
    two, ``[]`` where they agree; None where the files record none, and their times decide
    (:data:`STALE_INT8_AGE_S`)."""
    if fp32_sha256 is not None:
        try:
            with open(fp32, "rb") as fh:
                actual = hashlib.file_digest(fh, "sha256").hexdigest()
        except OSError:  # the load that follows names the file it cannot read
            return None
        return None if actual == fp32_sha256 else (f"it was quantized from a file of sha256 {fp32_sha256[:12]}..., "
                                                   f"and {fp32.name} has sha256 {actual[:12]}...")
    if differs is not None:
        return f"its {', '.join(differs)} differ{'s' if len(differs) == 1 else ''} from {fp32.name}'s" if differs \
            else None
    try:
        age = fp32.stat().st_mtime - int8.stat().st_mtime
    except OSError:  # the load that follows names the file it cannot read
        return None
    if age <= STALE_INT8_AGE_S:
        return None
    return f"it records no link to {fp32.name} and is {age / 3600:.1f} h older"


def warn_stale_int8(folder: Path, stale: list[tuple[Path, Path, str]], fix: str) -> None:
    """One WARNING for the ``(int8, fp32, reason)`` files of ``folder`` whose fp32 twin runs instead, with ``fix``
    (the command that quantizes them again): a folder exported before stale int8 files were removed (session 73)
    keeps them, and the int8 file was taken."""
    if not stale:
        return
    said = "; ".join(f"{i.name} is not quantized from {f.name} ({why})" for i, f, why in stale)
    log.warning("%s: %s: running %s instead; quantize again (%s) or remove %s", folder, said,
                ", ".join(f.name for _, f, _ in stale), fix, ", ".join(i.name for i, _, _ in stale))
