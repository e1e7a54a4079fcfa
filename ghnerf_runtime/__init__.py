"""On-device runtime: rig geometry, model contract, onnxruntime sessions, heatmap decoding.

Imports nothing of ours; numpy, onnxruntime and OpenCV only (never torch).
"""
from ghnerf_runtime.vendor_telemetry import default_onnxruntime_telemetry_off

# Before any of this package's modules imports onnxruntime, which reads its switch on import.
default_onnxruntime_telemetry_off()
