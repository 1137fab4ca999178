"""parity: the C++ firmware reference against ONNX Runtime and PyTorch, on the host and on Cortex-M.

One job per module: ``build`` (cmake builds of firmware_ref/: host, sanitizer, Cortex-M, with a
lock), ``runners`` (logits of the whole test split from C++ via fwref_infer, ONNX Runtime at batch 1,
PyTorch), ``compare`` (pair metrics, quantisation steps, the targets), ``mcu`` (cross-build, QEMU
runs, flash/RAM/instructions), ``report`` (parity.md), ``run`` (the stage: ``parity_run``), ``cli``.
"""
