"""On-device runtime: rig geometry, model contract, onnxruntime sessions, heatmap decoding.

Imports nothing of ours; numpy, onnxruntime and OpenCV only (never torch).
"""
