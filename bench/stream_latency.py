"""The streaming runtime's host latency per sample (bench.json ``stream.latency``).

``replay_timings(exe, weights, net, precision, path, tmp, prefix)`` runs ``fwref_stream --timings``
on one stream file (lines to ``--out``, so a decided push pays for formatting its line into memory,
not for a pipe) and splits its per-push steady-clock seconds by what the push did: ``push`` (the
sample ended no stride), ``decision`` (its stride was decided: window, model, alarm policy) and
``other`` (a stride skipped or waiting for the hover estimate). ``latency_records`` pools them over
the flights per model and precision: p50 / p99 / max in microseconds and the counts.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np


def replay_timings(exe: Path, weights: Path, net: str, precision: str, path: Path, tmp: Path,
                   prefix: list[str]) -> dict[str, np.ndarray]:
    lines, secs = tmp / "lines.txt", tmp / "t.f64"
    cmd = [*prefix, str(exe), "--weights", str(weights), "--model", net, "--in", str(path), "--out", str(lines),
           "--timings", str(secs)] + (["--int8"] if precision == "int8" else [])
    subprocess.run(cmd, capture_output=True, text=True, check=True)
    rows = [ln.split() for ln in lines.read_text().splitlines() if ln and not ln.startswith("#")]
    return split_timings(np.fromfile(secs, dtype="<f8"), np.array([int(r[0]) for r in rows], np.int64),
                         np.array([r[2] == "decided" for r in rows], bool))


def split_timings(t: np.ndarray, index: np.ndarray, decided: np.ndarray) -> dict[str, np.ndarray]:
    """``fwref_stream --timings``' seconds per push ``t`` split by what the push did, from its stride
    lines (sample ``index`` of each stride, ``decided`` or not)."""
    kind = np.zeros(len(t), np.int8)  # 0 push, 1 decision, 2 other stride
    kind[index[~decided]] = 2
    kind[index[decided]] = 1
    return {"push": t[kind == 0], "decision": t[kind == 1], "other": t[kind == 2]}


def _stats(us: np.ndarray, name: str) -> dict:
    if us.size == 0:
        return {f"{name}_n": 0, f"{name}_p50_us": None, f"{name}_p99_us": None, f"{name}_max_us": None}
    return {f"{name}_n": int(us.size), f"{name}_p50_us": float(np.percentile(us, 50)),
            f"{name}_p99_us": float(np.percentile(us, 99)), f"{name}_max_us": float(us.max())}


def latency_records(exe: Path, weights: Path, paths: list[Path], tmp: Path, prefix: list[str],
                    nets=("cnode", "gru"), precisions=("fp32", "int8")) -> list[dict]:
    out = []
    for net in nets:
        for prec in precisions:
            parts = [replay_timings(exe, weights, net, prec, p, tmp, prefix) for p in paths]
            rec = {"model": net, "precision": prec, "runtime": "fwref_stream", "flights": len(paths),
                   "other_strides": int(sum(len(p["other"]) for p in parts))}
            for name in ("push", "decision"):
                rec.update(_stats(np.concatenate([p[name] for p in parts]) * 1e6, name))
            out.append(rec)
    return out
