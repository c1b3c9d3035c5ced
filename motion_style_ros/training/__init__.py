"""Training loops, ONNX export and model cards (torch)."""
