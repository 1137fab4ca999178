"""export: trained checkpoints -> deployable ONNX graphs (fp32 and int8) and files for the C++ reference.

One job per module: ``graph`` (node-by-node builder), ``onnx_cnode`` / ``onnx_gru`` (the two
models' graphs; ``onnx_gru_unrolled`` the int8 GRU as exported before its Scan, a reference),
``quantize`` (the int8 scheme), ``calibrate`` (static activation ranges), ``binfmt`` (the binary
container), ``weights_bin`` / ``reference_bin`` (the two files), ``coverage``, ``verify``,
``manifest``, ``run`` (the stage), ``cli``.
"""
