"""Number formats and runtime names shared by bench's report section and figures."""

from __future__ import annotations

RUNTIME_ORDER = {"cpp": 0, "ort": 1, "torch": 2}
RUNTIME_NAME = {"cpp": "C++", "ort": "ONNX Runtime", "torch": "PyTorch"}


def us(x: float | None) -> str:
    if x is None:
        return "—"
    return f"{x:.2f}" if x < 10 else f"{x:.1f}" if x < 1000 else f"{x:,.0f}"


def nbytes(n: float | None) -> str:
    if n is None:
        return "—"
    n = float(n)
    if abs(n) < 1024:
        return f"{n:.0f} B"
    if abs(n) < 1024 ** 2:
        return f"{n / 1024:.1f} KiB"
    return f"{n / 1024 ** 2:.1f} MiB"


def setting(r: dict) -> str:
    spin = "" if r.get("spinning") is None else (", spin" if r["spinning"] else ", no spin")
    return f"{r['threads']} thr{spin}"
