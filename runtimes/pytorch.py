"""PyTorch as a runtime: a trained checkpoint's logits on windows, the float reference that ONNX
Runtime and the C++ are checked against (the CNODE with the export's classic RK4 N)."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from quadfdi.core.contracts import FP32_OVER_BOUND_SHARE, ROUNDING_FACTOR, ROUNDING_SAMPLES, STREAM_OVER_BOUND_SHARE
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

Forward = Callable[[torch.nn.Module, torch.Tensor], torch.Tensor]
HEADS: dict[str, Forward] = {
    "logits": lambda m, x: m(x),  # a windowed network's class logits (n, K)
    "motor": lambda m, x: m.motor_head(m.features(x)),  # its motor head's logits (n, 4)
    "stream": lambda m, x: m(x)[0][0],  # a streaming network over one flight (1, T, C): logits at every step (T, K)
}


@torch.no_grad()
def rounding_spread(model: torch.nn.Module, x: np.ndarray, head: str = "logits",
                    seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(exact, spread): ``model``'s outputs on ``x`` in float64 and, per output row (a window; a step of a
    stream), the largest distance from them over ROUNDING_SAMPLES float64 evaluations with every weight
    and input scaled by 1 + u * FLOAT32_ULP, u uniform in [-1, 1]: how far float32 rounding can move
    that row's result (a float32 program computes the exact result of slightly perturbed data).
    ``head``: a key of HEADS (what ``x`` is and which outputs are compared)."""
    gen = torch.Generator().manual_seed(seed)
    out_of = HEADS[head]

    def jitter(t: torch.Tensor) -> torch.Tensor:
        return t * (1 + FLOAT32_ULP * (2 * torch.rand(t.shape, generator=gen, dtype=torch.float64) - 1))

    exact_model, xt = copy.deepcopy(model).double(), torch.from_numpy(x).double()
    with torch_threads(THREADS):
        exact = out_of(exact_model, xt).numpy()
        spread = np.zeros(len(exact))
        for _ in range(ROUNDING_SAMPLES):
            moved = copy.deepcopy(exact_model)
            for p in moved.parameters():
                p.copy_(jitter(p))
            spread = np.maximum(spread, np.abs(out_of(moved, jitter(xt)).numpy() - exact).max(1))
    return exact, spread


def rounding_judgement(out: np.ndarray, outside: np.ndarray, model: torch.nn.Module, x: np.ndarray,
                       head: str = "logits") -> dict:
    """A float32 runtime's outputs ``out`` of ``model`` on ``x`` where ``outside`` (per output row) marks
    those past a parity bound: each within ROUNDING_FACTOR x its ``rounding_spread`` of the float64
    result, and at most FP32_OVER_BOUND_SHARE of the rows (at least one) past the bound: windows
    (core/contracts.py), or steps of one replayed flight with ``head`` "stream" (STREAM_OVER_BOUND_SHARE:
    a carried state takes the steps after an ill-conditioned one with it)."""
    over = np.flatnonzero(outside)
    share = STREAM_OVER_BOUND_SHARE if head == "stream" else FP32_OVER_BOUND_SHARE
    allowed = max(1, int(share * len(out)))
    res = {"windows_over_bound": int(len(over)), "over_bound_allowed": allowed, "passed": len(over) == 0}
    if 0 < len(over) <= allowed:
        if head == "stream":  # the whole flight replayed, its steps over the bound read
            exact, spread = (a[over] for a in rounding_spread(model, x, head))
        else:
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
