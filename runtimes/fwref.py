"""The C++ reference's command-line tools as functions: ``fwref_infer`` (raw float32 windows in, the
class logits and with ``motor`` the motor head's logits out, through temporary files). Imports no
torch: detect, parity and bench share it."""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError

CPP_TIMEOUT_S = 1800
# Windows per fwref_infer call are cut so that its input file stays at most this size: the C++ reader
# refuses a file above 1024 MiB (fwref/read_limits.hpp), a fleet test split at 120 samples x 57 channels
# is 1.2 GB, and windows are independent, so chunks give the same logits as one call.
MAX_INPUT_BYTES = 512 * 2**20


def fwref_infer(exe: Path, weights: Path, model: str, int8: bool, x: np.ndarray,
                motor: bool = False, max_bytes: int = MAX_INPUT_BYTES) -> tuple[np.ndarray, np.ndarray | None]:
    """``exe`` (fwref_infer) on windows ``x`` (n, W, C) -> (logits (n, K), motor logits (n, 4) with
    ``motor``, else None): the class and motor heads of one inference, in calls of at most ``max_bytes``
    of input each. The C++ side checks weights.bin against the manifest's sha256 when the export folder
    has one."""
    per = max(1, int(max_bytes) // max(1, int(np.prod(x.shape[1:], dtype=np.int64)) * 4))
    if len(x) > per:
        parts = [_infer_once(exe, weights, model, int8, x[i:i + per], motor) for i in range(0, len(x), per)]
        return (np.concatenate([p[0] for p in parts]),
                np.concatenate([p[1] for p in parts]) if motor else None)
    return _infer_once(exe, weights, model, int8, x, motor)


def _infer_once(exe: Path, weights: Path, model: str, int8: bool, x: np.ndarray,
                motor: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """One ``fwref_infer`` call on all of ``x``."""
    with tempfile.TemporaryDirectory(prefix="quadfdi-fwref-") as tmp:
        src, dst, mdst = Path(tmp) / "windows.f32", Path(tmp) / "logits.f32", Path(tmp) / "motor.f32"
        np.ascontiguousarray(x, dtype="<f4").tofile(src)
        cmd = [str(exe), "--weights", str(weights), "--model", model, "--in", str(src), "--out", str(dst)]
        cmd += ["--motor-out", str(mdst)] if motor else []
        manifest = Path(weights).parent / "manifest.json"
        if manifest.is_file():
            cmd += ["--manifest", str(manifest)]
        if int8:
            cmd.append("--int8")
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=CPP_TIMEOUT_S)
        if res.returncode != 0:
            msg = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
            raise QuadfdiError(f"fwref_infer ({model} {'int8' if int8 else 'fp32'}) failed: {msg}")
        out = np.fromfile(dst, dtype="<f4")
        mout = np.fromfile(mdst, dtype="<f4") if motor else None
    if out.size % max(len(x), 1) or (mout is not None and mout.size != 4 * len(x)):
        raise QuadfdiError(f"fwref_infer wrote {out.size} values for {len(x)} windows")
    return out.reshape(len(x), -1).astype(np.float32), None if mout is None else mout.reshape(len(x), 4)


def cpp_outputs(weights: Path, net: str, int8: bool, x: np.ndarray, motor: bool = False,
                build_dir: Path | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(logits, motor logits or None) of windows ``x`` from the host build's ``fwref_infer`` (built
    on first use; ``build_dir`` an existing build instead)."""
    if build_dir is None:
        build_dir = _host_build()
    return fwref_infer(Path(build_dir) / "fwref_infer", weights, net, int8, x, motor)


_HOST_BUILDS: dict[Path, Path] = {}  # sources' cache folder -> its host build, built by this process


def _host_build() -> Path:
    """The host build of the installed sources, built once per process: CMake's up-to-date check
    costs 0.6 s, more than ``fwref_infer`` on a flight, and a folder of logs calls this once a flight.
    A change to the sources is a new cache folder (runtimes.build), hence a new build."""
    from quadfdi.runtimes.build import build_host, fwref_home

    home = fwref_home()
    if home not in _HOST_BUILDS or not (_HOST_BUILDS[home] / "fwref_infer").is_file():
        _HOST_BUILDS[home] = build_host(log=lambda _: None)
    return _HOST_BUILDS[home]


def fwref_stream(exe: Path, weights: Path, model: str, int8: bool, stream: Path, step_weights: Path | None = None) -> str:
    """``exe`` (fwref_stream) replaying the stream file ``stream`` through ``model`` (cnode, gru, sgru with an
    sgru_weights.bin, or scnode with its ``step_weights``): its output, one line per stride (``stream_lines``)."""
    cmd = [str(exe), "--weights", str(weights), "--model", model, "--in", str(stream)] + (["--int8"] if int8 else [])
    cmd += ["--step-weights", str(step_weights)] if step_weights is not None else []
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=CPP_TIMEOUT_S)
    if res.returncode != 0:
        msg = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
        raise QuadfdiError(f"fwref_stream ({model} {'int8' if int8 else 'fp32'}) on {stream} failed: {msg}")
    return res.stdout


def stream_lines(text: str, classes: int) -> dict[str, np.ndarray]:
    """fwref_stream's output -> arrays per stride: index, t, status (str), logits (n, K) float32,
    proba (n, K), vote, active, raised, cleared (bool), cls, motor (the alarm's), wmotor (the stride's
    motor-head argmax; -1 from a reader without the column) (int)."""
    rows = [ln.split() for ln in text.splitlines() if ln and not ln.startswith("#")]
    k = classes
    col = lambda j, dt: np.array([r[j] for r in rows], dtype=dt)  # noqa: E731
    out = {"index": col(0, np.int64), "t": col(1, np.float64), "status": np.array([r[2] for r in rows]),
           "logits": np.array([[float(v) for v in r[3:3 + k]] for r in rows], np.float32).reshape(-1, k),
           "proba": np.array([[float(v) for v in r[3 + k:3 + 2 * k]] for r in rows], np.float64).reshape(-1, k)}
    for j, name in enumerate(("vote", "active", "raised", "cleared")):
        out[name] = col(3 + 2 * k + j, np.int64).astype(bool)
    out["cls"], out["motor"] = col(7 + 2 * k, np.int64), col(8 + 2 * k, np.int64)
    out["wmotor"] = np.array([int(r[9 + 2 * k]) if len(r) > 9 + 2 * k else -1 for r in rows], np.int64)
    return out
