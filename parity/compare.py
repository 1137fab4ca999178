"""Pair metrics of two logit arrays, int8 quantisation steps, and the parity targets.

Tolerances are core/contracts.py's (the C++ side has them from the generated
fwref/contracts_gen.hpp; docs/firmware.md explains them):
- fp32: C++ against ONNX Runtime, max |diff| <= FP32_REL_TOL * max(1, max |logit|), argmax 100 %
  (FP32_REL_TOL is contracts.FP32_CPP_REL_TOL).
- int8: C++ against ONNX Runtime, argmax agreement >= INT8_ARGMAX_MIN and max |diff| <=
  INT8_TOL_STEPS logit steps, where class o's step is 127 * s_in * s_w[o] = s_in * max_i |W_head[o, i]|,
  the largest change one quantisation step of one head input can make.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.contracts import FP32_CPP_REL_TOL as FP32_REL_TOL
from quadfdi.core.contracts import INT8_ARGMAX_MIN, INT8_TOL_STEPS
from quadfdi.formats.weights_bin import WeightsFile
HEAD_INPUT_SCALE = {"cnode": "act.z1.scale", "gru": "act.h.scale"}


def pair_metrics(a: np.ndarray, b: np.ndarray) -> dict:
    """``a`` against reference ``b`` (n, K): max abs diff, RMSE, relative L2 ||a-b||/||b||, cosine
    similarity of the flattened logits, argmax agreement (all in float64)."""
    a64, b64 = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a64.shape != b64.shape:
        raise ValueError(f"logit arrays differ in shape: {a64.shape} and {b64.shape}")
    d = a64 - b64
    nb, na = float(np.linalg.norm(b64)), float(np.linalg.norm(a64))
    agree = a64.argmax(axis=1) == b64.argmax(axis=1)
    return {
        "windows": int(len(a64)),
        "max_abs_diff": float(np.abs(d).max()) if d.size else 0.0,
        "rmse": float(np.sqrt(np.mean(d * d))) if d.size else 0.0,
        "rel_l2": float(np.linalg.norm(d) / nb) if nb > 0 else float(np.linalg.norm(d)),
        "cosine": float(np.dot(a64.ravel(), b64.ravel()) / (na * nb)) if na > 0 and nb > 0 else 1.0,
        "argmax_agreement": float(np.mean(agree)) if agree.size else 1.0,
        "argmax_disagreements": int(np.sum(~agree)),
        "max_abs_logit_ref": float(np.abs(b64).max()) if b64.size else 0.0,
        "bitwise_identical_windows": int(np.sum(np.all(a64 == b64, axis=1))),
    }


def logit_steps(weights: WeightsFile, model: str) -> np.ndarray:
    """(K,) logit quantisation step of each class of ``model``'s int8 head."""
    sec = weights.section(model, "int8")
    s_in = float(sec[HEAD_INPUT_SCALE[model]][0])
    return 127.0 * s_in * sec.tensors["head.weight"].scales.astype(np.float64)


def fp32_target(m: dict) -> dict:
    bound = FP32_REL_TOL * max(1.0, m["max_abs_logit_ref"])
    passed = m["max_abs_diff"] <= bound and m["argmax_agreement"] == 1.0
    return {"bound": bound, "rule": f"max|diff| <= {FP32_REL_TOL:g} * max(1, max|logit|) and argmax 100 %",
            "passed": bool(passed)}


def int8_target(a: np.ndarray, b: np.ndarray, steps: np.ndarray, m: dict) -> dict:
    diff_steps = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64)) / steps[None, :]
    max_steps = float(diff_steps.max()) if diff_steps.size else 0.0
    passed = m["argmax_agreement"] >= INT8_ARGMAX_MIN and max_steps <= INT8_TOL_STEPS
    return {"max_diff_steps": max_steps, "logit_step": steps.tolist(), "tol_steps": INT8_TOL_STEPS,
            "argmax_min": INT8_ARGMAX_MIN,
            "rule": f"argmax >= {100 * INT8_ARGMAX_MIN:.1f} % and max|diff| <= {INT8_TOL_STEPS:g} logit steps",
            "passed": bool(passed)}
