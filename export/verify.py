"""Export checks itself: ONNX Runtime against PyTorch (fp32) and int8 against fp32.

- fp32 parity: max |logit_ORT - logit_PyTorch| over the windows must be at most
  ``FP32_REL_TOL * max(1, max |logit_PyTorch|)`` (the CNODE with the same classic RK4 N), except on
  windows where the float32 program itself is ill-conditioned (``judged_parity``). A failure stops the
  export: nothing is written. The streaming exports check the steps of one replayed flight the same way
  (``stream_check``).
- int8 against fp32: argmax agreement, max |logit| difference, and the change of macro F1 in
  points (100 x); target: a drop of at most ``F1_DROP_TARGET_POINTS``. Reported, not enforced
  (a target, and meaningless for an untrained model).
- batch independence: each of a few windows run alone gives the same logits as inside the full
  batch (static scales; integer products are exact).
"""

from __future__ import annotations

import numpy as np
import onnxruntime as ort
import torch
from sklearn.metrics import f1_score

from quadfdi.core.contracts import FP32_ORT_VS_TORCH_REL_TOL
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.reportmd import over_bound_clause
from quadfdi.runtimes.ort import outputs
from quadfdi.runtimes.pytorch import rounding_judgement, torch_motor_logits

FP32_REL_TOL = FP32_ORT_VS_TORCH_REL_TOL  # ONNX Runtime against PyTorch (core/contracts.py)
F1_DROP_TARGET_POINTS = 0.5


def parity(logits: np.ndarray, reference: np.ndarray, rel: float = FP32_REL_TOL) -> dict:
    """max abs logit difference against ``reference`` and whether it is within rel * max(1, max|ref|)."""
    diff = float(np.abs(logits.astype(np.float64) - reference).max())
    scale = max(1.0, float(np.abs(reference).max()))
    return {"max_abs_logit_diff": diff, "max_abs_logit": float(np.abs(reference).max()),
            "bound": rel * scale, "argmax_agreement": float(np.mean(logits.argmax(1) == reference.argmax(1))),
            "windows": int(len(logits)), "passed": bool(diff <= rel * scale)}


def judged_parity(logits: np.ndarray, reference: np.ndarray, model: torch.nn.Module, x: np.ndarray,
                  head: str = "logits") -> dict:
    """``parity`` of ONNX Runtime's fp32 ``logits`` against PyTorch's ``reference`` of ``model`` on
    windows ``x``, the windows over its bound judged against float32 rounding instead
    (runtimes/pytorch.py ``rounding_judgement``): a recurrence or ODE that amplifies rounding (a window
    near a switch of the hidden state) lets two correct float32 programs with other summation orders
    part by more than the bound; a wrong graph misses on (nearly) every window. ``head``: "logits" or
    "motor"; "stream": ``logits`` are a streaming network's at every step of the one flight ``x`` (1, T, C)
    replayed step by step, ``reference`` PyTorch's over the whole flight."""
    res = parity(logits, reference)
    outside = np.abs(logits.astype(np.float64) - reference).max(1) > res["bound"]
    return {**res, **rounding_judgement(logits, outside, model, x, head)}


def stream_check(graph: str, logits: np.ndarray, reference: np.ndarray, model: torch.nn.Module, tel: np.ndarray,
                 row: int, state_diff: float) -> dict:
    """A streaming export's self-check: ``judged_parity`` (head "stream") of ONNX Runtime's step-by-step
    replay ``logits`` of flight ``tel`` (dataset row ``row``) against PyTorch's ``reference``, with the
    state's max abs difference; a failure raises, naming ``graph``, before the export writes anything."""
    check = {**judged_parity(logits, reference.astype(np.float64), model, tel[None], head="stream"),
             "max_abs_state_diff": float(state_diff), "flight_row": int(row), "steps": len(tel)}
    if not check["passed"]:
        raise QuadfdiError(f"{graph} differs from PyTorch on flight {row}: max |logit diff| "
                           f"{check['max_abs_logit_diff']:.3g} > {check['bound']:.3g}"
                           + over_bound_clause(check, "step"))
    return check


def int8_vs_fp32(int8_logits: np.ndarray, fp32_logits: np.ndarray, y: np.ndarray) -> dict:
    """Argmax agreement, logit difference and macro-F1 change (points) of int8 against fp32."""
    labels = list(range(fp32_logits.shape[1]))  # the model's K classes
    f1_fp32 = 100 * f1_score(y, fp32_logits.argmax(1), labels=labels, average="macro", zero_division=0)
    f1_int8 = 100 * f1_score(y, int8_logits.argmax(1), labels=labels, average="macro", zero_division=0)
    drop = f1_fp32 - f1_int8
    return {"argmax_agreement": float(np.mean(int8_logits.argmax(1) == fp32_logits.argmax(1))),
            "max_abs_logit_diff": float(np.abs(int8_logits - fp32_logits).max()),
            "macro_f1_fp32_points": float(f1_fp32), "macro_f1_int8_points": float(f1_int8),
            "macro_f1_drop_points": float(drop), "macro_f1_drop_target_points": F1_DROP_TARGET_POINTS,
            "meets_target": bool(drop <= F1_DROP_TARGET_POINTS), "windows": int(len(y))}


def batch_independence(sess: ort.InferenceSession, x: np.ndarray, batch_logits: np.ndarray, n: int = 4) -> dict:
    """max |logits of window i alone - its logits in the batch| over the first ``n`` windows."""
    diffs = [float(np.abs(sess.run(["logits"], {"telemetry": x[i:i + 1]})[0][0] - batch_logits[i]).max())
             for i in range(min(n, len(x)))]
    return {"windows_checked": len(diffs), "max_abs_logit_diff": max(diffs) if diffs else 0.0}


def motor_verification(sessions: dict, models: dict[str, torch.nn.Module], x: np.ndarray) -> dict:
    """Per model with a motor head: fp32 ORT against PyTorch (``judged_parity``, the class logits' bound)
    and int8 against fp32 (argmax agreement, max logit difference; reported)."""
    out = {}
    for kind, model in models.items():
        if getattr(model, "motor_head", None) is None:
            continue
        ref = torch_motor_logits(model, x)
        fp32, int8 = (outputs(sessions[f"{kind}_{p}"], x, ["motor_logits"])[0] for p in ("fp32", "int8"))
        out[f"{kind}_motor_fp32_vs_pytorch"] = judged_parity(fp32, ref, model, x, head="motor")
        out[f"{kind}_motor_int8_vs_fp32"] = {"argmax_agreement": float(np.mean(int8.argmax(1) == fp32.argmax(1))),
                                             "max_abs_logit_diff": float(np.abs(int8 - fp32).max()),
                                             "windows": int(len(x))}
    return out
