"""The control path u(t) of the CNODE: a window's normalised samples, linearly interpolated.

Sample k of a window of W samples sits at t_k = k / (W - 1), k = 0..W-1, so the window spans
t in [0, 1] whatever the sampling rate (paper Eq. 10). Between samples u is linear; the knots
t_1..t_{W-2} are where du/dt jumps, which is why an adaptive solver must be told about them.

Two evaluations of the same path, computed once per window and then cheap (torchcde style):
- ``interp_matrix(times)``: a constant (len(times), W) matrix M with U = M @ X, for the fixed-step
  solvers, whose evaluation times are known in advance. The deployed ONNX graph and the C++
  reference use exactly this matrix: no data-dependent indexing.
- ``LinearPath(x_norm)``: u(t) at any t, for adaptive solvers, with precomputed slopes.
"""

from __future__ import annotations

import math

import numpy as np
import torch


def _check_window(window: int) -> int:
    if isinstance(window, bool) or int(window) != window or window < 2:
        raise ValueError(f"window must be an integer of at least 2 samples, found {window!r}")
    return int(window)


def sample_times(window: int = 80) -> np.ndarray:
    """t_k = k / (W - 1), k = 0..W-1 (float64): the times of a window's samples."""
    w = _check_window(window)
    return np.arange(w, dtype=np.float64) / (w - 1)


def knots(window: int = 80) -> np.ndarray:
    """Interior knot times t_1..t_{W-2} (float64, W-2 values), for torchdiffeq's ``jump_t``.

    The ends 0 and 1 are not passed: the solver starts and stops there anyway.
    """
    return sample_times(window)[1:-1]


def interp_matrix(times: np.ndarray, window: int = 80) -> np.ndarray:
    """Linear-interpolation weights: U = M @ X gives the path at ``times``.

    Args:
        times: (T,) times in [0, 1] (a rounding slack of 1e-12 outside is clipped).
        window: W, samples per window.

    Returns:
        M, (T, W) float64. Row j has weight 1 - w on sample i and w on sample i + 1, where
        s = t_j (W - 1), i = min(floor(s), W - 2), w = s - i; so rows sum to 1, have at most two
        non-zeros, and a time on a sample picks that sample alone. With X (W, C) or
        (batch, W, C), M @ X is (T, C) or (batch, T, C), equal to np.interp per channel.

    Raises:
        ValueError: a time outside [0, 1] (the window holds no data there).
    """
    w = _check_window(window)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    if not np.all(np.isfinite(t)) or t.size and (t.min() < -1e-12 or t.max() > 1.0 + 1e-12):
        bad = t[~np.isfinite(t) | (t < -1e-12) | (t > 1.0 + 1e-12)][0]
        raise ValueError(f"control times must lie in [0, 1], found {bad!r}")
    s = np.clip(t, 0.0, 1.0) * (w - 1)
    # k/(W-1) * (W-1) is not always k in floating point: snap near-integers so that a time on a
    # sample gives exactly weights (1, 0), not (1 - 2e-15, 2e-15)
    snapped = np.round(s)
    s = np.where(np.abs(s - snapped) <= 4 * np.spacing(float(w - 1)), snapped, s)
    i = np.minimum(np.floor(s).astype(np.int64), w - 2)
    frac = s - i
    m = np.zeros((t.size, w), dtype=np.float64)
    rows = np.arange(t.size)
    m[rows, i] = 1.0 - frac
    m[rows, i + 1] += frac  # frac == 0 on a sample: the row is that sample alone
    return m


class LinearPath:
    """u(t) for adaptive solvers: the window's samples, linearly interpolated, in torch.

    Args:
        x_norm: (batch, W, C) normalised telemetry; gradients flow through it.

    ``path(t)`` for a scalar t (tensor or float) returns u(t), (batch, C), in O(batch C): the
    segment index is clamped to [0, W-2], so a t slightly outside [0, 1] (an adaptive step that
    overshoots t = 1 and is then interpolated back, or torchdiffeq's one-ulp perturbation at a
    knot) extrapolates the end segment linearly rather than adding a kink at the ends.
    """

    def __init__(self, x_norm: torch.Tensor) -> None:
        if x_norm.ndim != 3 or x_norm.shape[1] < 2:
            raise ValueError(f"LinearPath needs (batch, samples >= 2, channels), found {tuple(x_norm.shape)}")
        self.x = x_norm  # (batch, W, C)
        self.window = x_norm.shape[1]
        self.dt = 1.0 / (self.window - 1)
        self.slopes = (x_norm[:, 1:] - x_norm[:, :-1]) * (self.window - 1)  # (batch, W-1, C), du/dt

    def _segment(self, t: torch.Tensor | float) -> tuple[int, float]:
        # t as a Python float: no gradient flows into the time. Backpropagating through
        # torchdiffeq's adaptive steps gives t a graph (the step size depends on the state through
        # the error estimate); differentiating the step-size choice is not wanted.
        tf = float(t.detach()) if isinstance(t, torch.Tensor) else float(t)
        i = min(max(int(math.floor(tf * (self.window - 1))), 0), self.window - 2)
        return i, tf - i * self.dt

    def __call__(self, t: torch.Tensor | float) -> torch.Tensor:
        i, tau = self._segment(t)
        return self.x[:, i] + tau * self.slopes[:, i]  # (batch, C)

    def derivative(self, t: torch.Tensor | float) -> torch.Tensor:
        """du/dt on the segment holding t, (batch, C) (right derivative at a knot)."""
        return self.slopes[:, self._segment(t)[0]]
