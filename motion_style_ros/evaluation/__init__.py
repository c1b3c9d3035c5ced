"""Metrics, the shipped judges and the evaluation harness (numpy + ONNX Runtime, no torch)."""
