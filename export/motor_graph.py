"""The motor head in the exported graphs (models.motor): a second output ``motor_logits`` (B, 4).

The head reads the same final hidden representation as the class head (the CNODE's z1, the GRU's
last hidden state) and is built the same way: fp32 one Gemm (CNODE) or MatMul + Add (GRU); int8
one MatMulIntegerToFloat on the activation the class head quantized (same static scale), with
int8 weights per output row. A model without the head gives a graph with the outputs it always
had (``logits``, ``proba``), byte for byte.
"""

from __future__ import annotations

import numpy as np
from onnx import TensorProto, helper

from quadfdi.export.graph import BATCH, Graph, class_outputs
from quadfdi.export.quantize import QWeight, int8_matmul, int8_weight

MOTOR_OUTPUT = "motor_logits"
N_MOTORS = 4


def graph_outputs(n_classes: int, motor: bool) -> list:
    """``logits``, ``proba`` (B, K) and, with a motor head, ``motor_logits`` (B, 4), all float32."""
    extra = [helper.make_tensor_value_info(MOTOR_OUTPUT, TensorProto.FLOAT, [BATCH, N_MOTORS])] if motor else []
    return class_outputs(n_classes) + extra


def output_names(motor: bool) -> list[str]:
    """The graph's output names in order (the manifest lists them)."""
    return ["logits", "proba"] + ([MOTOR_OUTPUT] if motor else [])


def motor_fp32_gemm(g: Graph, z: str, w: np.ndarray, b: np.ndarray) -> str:
    """CNODE fp32: motor_logits = Gemm(z1, W^T) + b."""
    return g.op("Gemm", z, g.const("motor_head.weight", w), g.const("motor_head.bias", b), transB=1, name=MOTOR_OUTPUT)


def motor_fp32_matmul(g: Graph, h: str, w: np.ndarray, b: np.ndarray) -> str:
    """GRU fp32: motor_logits = h_W @ W^T + b (the class head's form)."""
    return g.op("Add", g.op("MatMul", h, g.const("motor_head.weight_t", np.ascontiguousarray(w.T))),
                g.const("motor_head.bias", b), name=MOTOR_OUTPUT)


def motor_int8(g: Graph, xq: str, a_scale: str, w: QWeight, b: np.ndarray, act: str, name: str | None = MOTOR_OUTPUT) -> str:
    """int8: one MatMulIntegerToFloat of the already quantized activation ``xq`` (scale ``a_scale``)."""
    wq, s_w = int8_weight(g, "motor_head", w)
    return int8_matmul(g, xq, a_scale, wq, s_w, g.const("motor_head.bias", b), act, name=name)
