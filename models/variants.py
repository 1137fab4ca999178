"""CNODE variants used by the solver study: other control representations and solve strategies.

- ``AverageControlCNODE`` (control ``"average"``): a fixed-step solver drives step k with the
  mean of the control over the step (``average_matrix``), so a coarse grid still sees every
  sample. Another model: it is trained that way (``solverstudy.matrix``).
- ``KnotRestartCNODE`` (control ``"point"``): the CNODE itself, its adaptive solve restarted at
  every knot of the path instead of told the knots through torchdiffeq's ``jump_t``.

Every variant has the CNODE's parameters and state dict, so weights move freely between them;
``model_signature`` records the control representation and ``CNODE_CLASSES`` maps it back to a
class, so ``models.checkpoint.load_checkpoint`` rebuilds either control without a special case.
``rebuild`` gives a copy of a model's weights in another variant, solver and dtype.
"""

from __future__ import annotations

import copy

import numpy as np
import torch
from torch import nn

from quadfdi.models.control import interp_matrix
from quadfdi.models.networks import CNODE, model_signature
from quadfdi.models.solvers import SolverSpec, integrate_fixed


def average_matrix(n_steps: int, window: int = 80) -> np.ndarray:
    """Per-step mean of the linearly interpolated path, as a constant (n_steps, W) matrix A.

    Row k of A @ X is (1/h) * integral of u(t) over step k = [k h, (k+1) h], h = 1 / n_steps,
    computed exactly for the piecewise-linear path: the trapezoid rule on the sub-intervals cut
    at every sample time inside the step is exact on each linear piece. Rows sum to 1 (a mean)
    and every sample with a knot inside or next to the step gets weight, so a coarse grid still
    sees every sample. Like ``interp_matrix`` it is a constant linear map of the window, so a
    model using it stays exportable (one matrix product, no data-dependent indexing).
    """
    if isinstance(n_steps, bool) or int(n_steps) != n_steps or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, found {n_steps!r}")
    n, w = int(n_steps), int(window)
    sample_t = np.arange(w, dtype=np.float64) / (w - 1)
    rows = np.zeros((n, w), dtype=np.float64)
    for k in range(n):
        a, b = k / n, (k + 1) / n
        inside = sample_t[(sample_t > a) & (sample_t < b)]
        cuts = np.concatenate([[a], inside, [b]])  # (m+1,) breakpoints; u is linear between them
        m = interp_matrix(cuts, w)  # (m+1, W)
        widths = np.diff(cuts)  # (m,)
        rows[k] = (widths[:, None] * 0.5 * (m[:-1] + m[1:])).sum(axis=0) / (b - a)
    return rows


class AverageControlCNODE(CNODE):
    """A CNODE whose fixed-step solver drives step k with the step's mean control.

    Same parameters and state dict as ``CNODE`` (weights move freely between the two), but a
    different model: with N fixed steps, every stage of step k evaluates f(z, ubar_k) with
    ubar = A @ x_norm, A = ``average_matrix(N, W)`` (a constant (N, W) matrix, exportable like
    ``interp_matrix``). So the vector field of step k is autonomous and sees the mean of every
    sample in the step, where the point-sampled CNODE sees u only at the stage times (rk4 at N=2
    sees 5 points of an 80-sample window). As N grows ubar -> u(t) and both models tend to the
    same ODE; with an adaptive solver this class integrates that limit (the point path).

    It must be trained this way to be compared fairly (``solverstudy.matrix``).
    """

    control = "average"

    def _control_table(self, x_norm: torch.Tensor) -> tuple[np.ndarray, torch.Tensor]:
        """Step start times (N,) and the per-step mean control ubar = A @ x_norm, (batch, N, C)."""
        key = ("average", self.solver.steps, x_norm.dtype, x_norm.device)
        if key not in self._interp_cache:
            a = torch.as_tensor(average_matrix(self.solver.steps, self.window), dtype=x_norm.dtype, device=x_norm.device)
            times = np.arange(self.solver.steps, dtype=np.float64) / self.solver.steps
            self._interp_cache[key] = (times, a)  # (N,), (N, W)
        times, a = self._interp_cache[key]
        return times, torch.matmul(a, x_norm)  # (N, W) @ (B, W, C) -> (B, N, C)

    def _integrate_fixed(self, z0: torch.Tensor, x_norm: torch.Tensor, trace: list | None = None) -> torch.Tensor:
        # Stage times alone cannot say which step an evaluation belongs to (rk4's last stage of
        # step k and the first of step k+1 share a time but not a control), so step one by one.
        _, ubar = self._control_table(x_norm)
        n = self.solver.steps
        inner = [] if isinstance(trace, list) else None
        z = z0
        for k in range(n):
            uk = ubar[:, k]  # (B, C)
            z = integrate_fixed(lambda t, zz, uk=uk: self._f(zz, uk), z, self.solver.method, 1,
                                t0=k / n, t1=(k + 1) / n, trace=inner)
            if inner is not None:
                trace.extend(inner[:1] if k == 0 else [])
                trace.extend(inner[1:-1])
                inner.clear()
        if isinstance(trace, list):
            trace.append(z)
        return z

    def macs_breakdown(self, evals: int | None = None) -> dict[str, int]:
        parts = super().macs_breakdown(evals)
        if self.solver.is_fixed:
            parts["control_matmul"] = self.solver.steps * self.window * self.n_channels
        return parts


class KnotRestartCNODE(CNODE):
    """The point-sampled CNODE with its adaptive solve restarted at every knot.

    Between two samples the path is linear, so the ODE is smooth on each segment
    [t_k, t_k+1]; a fresh ``odeint`` per segment never steps over a kink, which is what
    ``jump_t`` is meant to achieve. Why not ``jump_t``: torchdiffeq 0.2.5 (``rk_common.py``,
    ``_adaptive_step``) clips a step to the next jump only when ``t0 < jump < t0 + dt`` strictly
    and advances ``next_jump_index`` only after such a clipped step. When an accepted step lands
    exactly on a knot by itself -- which happens when the step-size factor is clamped to 1
    (error ratio between about 0.6 and 1) and the previous, clipped step was exactly one knot
    spacing -- the index stays on that knot, ``t0 < jump`` is false from then on, and every
    later knot is ignored: the solver then steps over kinks and, at tight tolerances, burns
    thousands of evaluations on rejected steps (measured: 560 -> 7000 per window at rtol 1e-9).
    Costs one initial-step selection (2 evaluations) per segment more than a working ``jump_t``.
    The segment index is explicit, so no time is ever looked up on the wrong side of a knot.
    Its weights are a point-control CNODE's: a checkpoint of it loads as ``CNODE``.
    """

    def _integrate_adaptive(self, z0: torch.Tensor, x_norm: torch.Tensor) -> torch.Tensor:
        from torchdiffeq import odeint

        tk = np.arange(self.window, dtype=np.float64) / (self.window - 1)  # sample times
        slopes = (x_norm[:, 1:] - x_norm[:, :-1]) * (self.window - 1)  # (B, W-1, C), du/dt per segment
        z = z0
        for k in range(self.window - 1):
            t = torch.tensor([tk[k], tk[k + 1]], dtype=torch.float64, device=z0.device)

            def f(tt: torch.Tensor, zz: torch.Tensor, k: int = k) -> torch.Tensor:
                return self._f(zz, x_norm[:, k] + (float(tt) - tk[k]) * slopes[:, k])

            z = odeint(f, z, t, rtol=self.solver.rtol, atol=self.solver.atol, method=self.solver.method)[-1]
        return z


# The CNODE class of each control representation (``model_signature``'s "control").
CNODE_CLASSES: dict[str, type[CNODE]] = {"point": CNODE, "average": AverageControlCNODE}
CONTROLS = tuple(CNODE_CLASSES)


def rebuild(model: CNODE, solver: SolverSpec, control: str = "point", knot_restart: bool = False,
            dtype: torch.dtype = torch.float32) -> CNODE:
    """A copy of ``model``'s weights in the class of ``control`` (``KnotRestartCNODE`` when
    ``knot_restart``), with ``solver`` and ``dtype``, in eval mode; ``model`` is untouched."""
    if control not in CNODE_CLASSES:
        raise ValueError(f"control must be one of {', '.join(CONTROLS)}, found {control!r}")
    if knot_restart and control != "point":
        raise ValueError("knot restarts are defined for the point control only")
    sig = model_signature(model)
    sig.pop("kind")
    sig.pop("control")
    n_motors = sig.pop("n_motors", None)  # the motor head is a layer added after construction (models.networks)
    cls = KnotRestartCNODE if knot_restart else CNODE_CLASSES[control]
    out = cls(**sig, solver=solver)
    if n_motors is not None:
        out.motor_head = nn.Linear(out.head.in_features, n_motors)
    out.load_state_dict(copy.deepcopy(model.state_dict()))
    out = out.to(dtype)
    out.eval()
    return out
