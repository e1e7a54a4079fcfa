"""ONNX export, int8 static quantization and parity checks of the GHNeRF graphs."""
