"""Logits of the decided windows from ONNX Runtime (the exported graph) or the C++ reference
(``fwref_infer`` on weights.bin through parity.fwref_cli, as parity.runners uses it). Neither path
imports torch (4 s of the 10 s that ingest + detect took on a 79 s flight)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


CHUNK = 512


def ort_logits(graph: Path, x: np.ndarray) -> np.ndarray:
    return ort_outputs(graph, x, ["logits"])[0]


def ort_outputs(graph: Path, x: np.ndarray, names: list[str]) -> list[np.ndarray]:
    """The graph's outputs ``names`` (e.g. logits, motor_logits) of windows ``x``, float32."""
    from quadfdi.export.ort_session import session

    sess = session(Path(graph).read_bytes())
    parts = [sess.run(names, {"telemetry": x[i:i + CHUNK]}) for i in range(0, len(x), CHUNK)]
    return [np.concatenate([p[j] for p in parts]).astype(np.float32) for j in range(len(names))]


def cpp_logits(weights: Path, net: str, int8: bool, x: np.ndarray) -> np.ndarray:
    return cpp_outputs(weights, net, int8, x, motor=False)[0]


def cpp_outputs(weights: Path, net: str, int8: bool, x: np.ndarray, motor: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """(logits, motor_logits or None): ``fwref_infer`` with ``--motor-out`` when ``motor``."""
    from quadfdi.parity.build import HOST_BUILD, build_host
    from quadfdi.parity.fwref_cli import fwref_infer

    return fwref_infer(build_host(HOST_BUILD, log=lambda _: None) / "fwref_infer", weights, net, int8, x, motor)
