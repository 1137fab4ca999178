"""PyTorch as a runtime: a trained checkpoint's logits on windows, the float reference that ONNX
Runtime and the C++ are checked against (the CNODE with the export's classic RK4 N)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import torch

from quadfdi.core.contracts import FP32_OVER_BOUND_SHARE, ROUNDING_FACTOR, ROUNDING_SAMPLES
from quadfdi.models.checkpoint import load_checkpoint
from quadfdi.models.networks import SolverSpec
from quadfdi.models.threads import torch_threads
from quadfdi.runtimes.ort import CHUNK, THREADS


@torch.no_grad()
def torch_logits(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    """(n, K) float32 logits of windows ``x`` (n, W, C), in chunks, at the export's thread count."""
    with torch_threads(THREADS):
        return np.concatenate([model(torch.from_numpy(x[i:i + CHUNK])).numpy()
                               for i in range(0, len(x), CHUNK)]).astype(np.float32)


@torch.no_grad()
def torch_motor_logits(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    """(n, 4) float32 motor logits of a model with a motor head (models.motor)."""
    with torch_threads(THREADS):
        return np.concatenate([model.motor_head(model.features(torch.from_numpy(x[i:i + CHUNK]))).numpy()
                               for i in range(0, len(x), CHUNK)]).astype(np.float32)


FLOAT32_ULP = 2.0 ** -23  # relative spacing of float32 numbers in [1, 2)


@torch.no_grad()
def rounding_spread(model: torch.nn.Module, x: np.ndarray, head: str = "logits",
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(exact, spread): ``model``'s outputs on windows ``x`` in float64 and, per window, the largest
    distance from them over ROUNDING_SAMPLES float64 evaluations with every weight and input scaled by
    1 + u * FLOAT32_ULP, u uniform in [-1, 1]: how far float32 rounding can move this window's result
    (a float32 program computes the exact result of slightly perturbed data). ``head``: "logits" or
    "motor" (the motor head's logits)."""
    gen = torch.Generator().manual_seed(seed)

    def jitter(t: torch.Tensor) -> torch.Tensor:
        return t * (1 + FLOAT32_ULP * (2 * torch.rand(t.shape, generator=gen, dtype=torch.float64) - 1))

    def out(m: torch.nn.Module, xt: torch.Tensor) -> np.ndarray:
        return (m(xt) if head == "logits" else m.motor_head(m.features(xt))).numpy()

    exact_model, xt = copy.deepcopy(model).double(), torch.from_numpy(x).double()
    with torch_threads(THREADS):
        exact, spread = out(exact_model, xt), np.zeros(len(x))
        for _ in range(ROUNDING_SAMPLES):
            moved = copy.deepcopy(exact_model)
            for p in moved.parameters():
                p.copy_(jitter(p))
            spread = np.maximum(spread, np.abs(out(moved, jitter(xt)) - exact).max(1))
    return exact, spread


def rounding_judgement(out: np.ndarray, outside: np.ndarray, model: torch.nn.Module, x: np.ndarray,
                       head: str = "logits") -> dict:
    """A float32 runtime's outputs ``out`` of ``model`` on windows ``x`` where ``outside`` (per window)
    marks those past a parity bound: at most FP32_OVER_BOUND_SHARE of them (at least one) may be, each
    within ROUNDING_FACTOR x its ``rounding_spread`` of the float64 result (core/contracts.py)."""
    over = np.flatnonzero(outside)
    allowed = max(1, int(FP32_OVER_BOUND_SHARE * len(out)))
    res = {"windows_over_bound": int(len(over)), "over_bound_allowed": allowed, "passed": len(over) == 0}
    if 0 < len(over) <= allowed:
        exact, spread = rounding_spread(model, x[over], head)
        ratio = np.abs(out[over].astype(np.float64) - exact).max(1) / np.maximum(spread, np.finfo(np.float64).tiny)
        res.update(over_bound_rounding_ratio=float(ratio.max()), rounding_factor=ROUNDING_FACTOR,
                   passed=bool(np.all(ratio <= ROUNDING_FACTOR)))
    return res


def load_models(checkpoints: dict[str, Path], steps: int) -> dict[str, torch.nn.Module]:
    """The trained models of ``checkpoints`` ({kind: path}), in eval mode; the CNODE with classic RK4
    over ``steps`` steps (the export's N)."""
    models = {}
    for kind, path in checkpoints.items():
        model, _ = load_checkpoint(path, kind)
        model.eval()
        if kind == "cnode":
            model.solver = SolverSpec(method="rk4", steps=int(steps))
        models[kind] = model
    return models
