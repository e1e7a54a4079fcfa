"""Training side (PyTorch, never on the device): the GHNeRF model, losses, presets, ONNX export and int8
quantization.

``import training`` does not import torch; the submodules that need it do.
"""
