"""A trained network as a deployable graph: ONNX export (pose network and detector) and latency benches."""
