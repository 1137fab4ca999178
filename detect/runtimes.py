"""Logits of the decided windows from ONNX Runtime (the exported graph) or the C++ reference
(``fwref_infer`` on weights.bin: the program's contract, as parity.runners uses it). Neither path
imports torch (4 s of the 10 s that ingest + detect took on a 79 s flight)."""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import numpy as np

from core.errors import QuadfdiError

CHUNK = 512
CPP_TIMEOUT_S = 600


def ort_logits(graph: Path, x: np.ndarray) -> np.ndarray:
    return ort_outputs(graph, x, ["logits"])[0]


def ort_outputs(graph: Path, x: np.ndarray, names: list[str]) -> list[np.ndarray]:
    """The graph's outputs ``names`` (e.g. logits, motor_logits) of windows ``x``, float32."""
    from export.ort_session import session

    sess = session(Path(graph).read_bytes())
    parts = [sess.run(names, {"telemetry": x[i:i + CHUNK]}) for i in range(0, len(x), CHUNK)]
    return [np.concatenate([p[j] for p in parts]).astype(np.float32) for j in range(len(names))]


def cpp_logits(weights: Path, net: str, int8: bool, x: np.ndarray) -> np.ndarray:
    return cpp_outputs(weights, net, int8, x, motor=False)[0]


def cpp_outputs(weights: Path, net: str, int8: bool, x: np.ndarray, motor: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """(logits, motor_logits or None): ``fwref_infer`` with ``--motor-out`` when ``motor``."""
    from parity.build import HOST_BUILD, build_host

    exe = build_host(HOST_BUILD, log=lambda _: None) / "fwref_infer"
    with tempfile.TemporaryDirectory(prefix="quadfdi-detect-") as tmp:
        src, dst, mdst = Path(tmp) / "windows.f32", Path(tmp) / "logits.f32", Path(tmp) / "motor.f32"
        np.ascontiguousarray(x, dtype="<f4").tofile(src)
        cmd = [str(exe), "--weights", str(weights), "--model", net, "--in", str(src), "--out", str(dst),
               "--manifest", str(Path(weights).parent / "manifest.json")] + (["--int8"] if int8 else [])
        cmd += ["--motor-out", str(mdst)] if motor else []
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=CPP_TIMEOUT_S)
        if res.returncode != 0:
            msg = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
            raise QuadfdiError(f"fwref_infer ({net} {'int8' if int8 else 'fp32'}) failed: {msg}")
        out = np.fromfile(dst, dtype="<f4")
        mout = np.fromfile(mdst, dtype="<f4") if motor else None
    if out.size % max(len(x), 1) or (mout is not None and mout.size != 4 * len(x)):
        raise QuadfdiError(f"fwref_infer wrote {out.size} values for {len(x)} windows")
    return out.reshape(len(x), -1).astype(np.float32), None if mout is None else mout.reshape(len(x), 4)
