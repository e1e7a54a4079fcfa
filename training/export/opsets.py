"""The ONNX opsets the export can write (torch-free: the command line checks ``--opset`` before torch loads).

* below :data:`MIN_OPSET` torch's exporter refuses ``aten::grid_sampler`` (the feature and volume sampling):
  ONNX has ``GridSample`` only since opset 16;
* above :data:`MAX_OPSET` the TorchScript exporter (``dynamo=False``, ``training.export.export``) is
  unsupported: torch 2.x only warns and writes a graph nobody tested (torch's own
  ``ONNX_TORCHSCRIPT_EXPORTER_MAX_OPSET``; ``tests/training/test_training_cli_args.py`` keeps the two in step).

Checked with torch 2.15 and onnxruntime 1.31 (session 51): ``tiny`` exported and quantized to int8 at 16 and 20,
``edge128`` at 16, and every test exports at 17; ``tests/training/test_onnx_export.py`` exports at 16 and not at 15.
"""
from __future__ import annotations

DEFAULT_OPSET = 17
MIN_OPSET = 16
MAX_OPSET = 20


def opset_problem(opset: int) -> str | None:
    """Why ``opset`` cannot be exported (a phrase), or None when it can."""
    if MIN_OPSET <= opset <= MAX_OPSET:
        return None
    return f"must be {MIN_OPSET} to {MAX_OPSET} (GridSample needs {MIN_OPSET}; torch's exporter stops at {MAX_OPSET})"


__all__ = ["DEFAULT_OPSET", "MIN_OPSET", "MAX_OPSET", "opset_problem"]
