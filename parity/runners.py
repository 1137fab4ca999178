"""Logits of a set of windows from each runtime, one window at a time where it matters.

- C++: ``fwref_infer`` (the program's contract: raw float32 windows in, float32 logits out; it runs
  the windows one by one, batch 1, as firmware does).
- ONNX Runtime: one ``session.run`` per window (batch 1), one thread, the export's session options.
- PyTorch: the trained checkpoints, the CNODE with classic RK4 and the export's N (batched: it is
  the float reference, not a deployment runtime).
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import numpy as np
import torch

from export.ort_session import session
from export.verify import torch_logits
from core.errors import QuadfdiError
from core.rundir import RunDir
from train.checkpoint import load_checkpoint
from train.models import SolverSpec

CPP_TIMEOUT_S = 1800


def cpp_logits(build_dir: Path, weights: Path, model: str, int8: bool, x: np.ndarray) -> np.ndarray:
    """fwref_infer on windows ``x`` (n, W, C) float32 -> logits (n, K) float32."""
    return cpp_outputs(build_dir, weights, model, int8, x, motor=False)[0]


def cpp_outputs(build_dir: Path, weights: Path, model: str, int8: bool, x: np.ndarray,
                motor: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """fwref_infer on windows ``x`` -> (logits (n, K), motor logits (n, 4) with ``motor``, else None):
    the class and motor heads of one inference (``--motor-out``)."""
    exe = Path(build_dir) / "fwref_infer"
    with tempfile.TemporaryDirectory(prefix="quadfdi-parity-") as tmp:
        src, dst, mdst = Path(tmp) / "windows.f32", Path(tmp) / "logits.f32", Path(tmp) / "motor.f32"
        np.ascontiguousarray(x, dtype="<f4").tofile(src)
        cmd = [str(exe), "--weights", str(weights), "--model", model, "--in", str(src), "--out", str(dst)]
        cmd += ["--motor-out", str(mdst)] if motor else []
        manifest = Path(weights).parent / "manifest.json"
        if manifest.is_file():  # the C++ side checks weights.bin against the manifest's sha256 itself
            cmd += ["--manifest", str(manifest)]
        if int8:
            cmd.append("--int8")
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=CPP_TIMEOUT_S)
        if res.returncode != 0:
            msg = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
            raise QuadfdiError(f"fwref_infer ({model} {'int8' if int8 else 'fp32'}) failed: {msg}")
        out = np.fromfile(dst, dtype="<f4")
        mout = np.fromfile(mdst, dtype="<f4") if motor else None
    if out.size % len(x) or (mout is not None and mout.size != 4 * len(x)):
        raise QuadfdiError(f"fwref_infer wrote {out.size} values for {len(x)} windows")
    return out.reshape(len(x), -1).astype(np.float32), None if mout is None else mout.reshape(len(x), 4)


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
    from export.verify import torch_motor_logits

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
