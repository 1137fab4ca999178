"""Logits of a set of windows from each runtime, one window at a time where it matters.

- C++: ``fwref_infer`` (the program's contract: raw float32 windows in, float32 logits out; it runs
  the windows one by one, batch 1, as firmware does).
- ONNX Runtime: one ``session.run`` per window (batch 1), one thread, the export's session options.
- PyTorch: the trained checkpoints, the CNODE with classic RK4 and the export's N (batched: it is
  the float reference, not a deployment runtime).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from quadfdi.export.ort_session import session
from quadfdi.export.verify import torch_logits
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import RunDir
from quadfdi.parity.fwref_cli import fwref_infer
from quadfdi.train.checkpoint import load_checkpoint
from quadfdi.train.models import SolverSpec



def cpp_logits(build_dir: Path, weights: Path, model: str, int8: bool, x: np.ndarray) -> np.ndarray:
    """fwref_infer on windows ``x`` (n, W, C) float32 -> logits (n, K) float32."""
    return cpp_outputs(build_dir, weights, model, int8, x, motor=False)[0]


def cpp_outputs(build_dir: Path, weights: Path, model: str, int8: bool, x: np.ndarray,
                motor: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """fwref_infer of ``build_dir`` on windows ``x`` -> (logits (n, K), motor logits (n, 4) or None)."""
    return fwref_infer(Path(build_dir) / "fwref_infer", weights, model, int8, x, motor)


def ort_logits(onnx_path: Path, x: np.ndarray) -> np.ndarray:
    """ONNX Runtime logits of ``x`` (n, W, C), one window per run (batch 1)."""
    return ort_outputs(onnx_path, x, ["logits"])[0]


def ort_outputs(onnx_path: Path, x: np.ndarray, names: list[str]) -> list[np.ndarray]:
    """ONNX Runtime outputs ``names`` (e.g. logits, motor_logits) of ``x``, one window per run (batch 1)."""
    try:
        sess = session(Path(onnx_path).read_bytes())
    except OSError as exc:
        raise QuadfdiError(f"cannot read {onnx_path}: {exc.strerror}") from None
    except Exception as exc:  # onnxruntime's own exception types: a truncated or foreign graph
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise QuadfdiError(f"{onnx_path} is not a loadable ONNX graph (truncated or foreign file?): {first}") from None
    out = [sess.run(names, {"telemetry": x[i:i + 1]}) for i in range(len(x))]
    return [np.stack([o[j][0] for o in out]).astype(np.float32) if out else np.zeros((0, 0), np.float32)
            for j in range(len(names))]


def torch_motor(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    from quadfdi.export.verify import torch_motor_logits

    return torch_motor_logits(model, x).astype(np.float32)


def torch_models(run: RunDir, steps: int) -> dict[str, torch.nn.Module]:
    """The run's trained models; the CNODE with classic RK4 over ``steps`` steps (the export's N)."""
    models = {}
    for kind in ("cnode", "gru"):
        model, _ = load_checkpoint(run.checkpoint(kind), kind)
        model.eval()
        if kind == "cnode":
            model.solver = SolverSpec(method="rk4", steps=int(steps))
        models[kind] = model
    return models


def pytorch_logits(model: torch.nn.Module, x: np.ndarray) -> np.ndarray:
    return torch_logits(model, x).astype(np.float32)
