"""parity: the C++ firmware reference against ONNX Runtime and PyTorch, on the host and on Cortex-M.

One job per module: ``compare`` (pair metrics, quantisation steps, the targets), ``mcu`` (cross-build,
QEMU runs, flash/RAM/instructions), ``stream`` (the on-board streaming cost of every model on the
Cortex-M, held against the host's fwref_stream), ``report`` (parity.md), ``run`` (the stage:
``parity_run``), ``cli``. Builds and runtimes are quadfdi.runtimes' (build, fwref, ort, pytorch, mcu).
"""
