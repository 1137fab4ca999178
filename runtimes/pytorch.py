"""PyTorch as a runtime: a trained checkpoint's logits on windows, the float reference that ONNX
Runtime and the C++ are checked against (the CNODE with the export's classic RK4 N)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

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
