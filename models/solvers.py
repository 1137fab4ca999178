"""Fixed-step Runge-Kutta solvers, each a small declared thing (torchdiffeq style).

One step function per scheme, reused by training (``models.networks``) and the tests; classic
RK4's lives in ``core.rk4`` (the program the simulator, the ONNX unrolling and the C++ reference
share). Each is ``step(f, t, z, h) -> z_next`` with ``f(t, z)`` the vector field, ``t`` and ``h``
Python floats and ``z`` a torch tensor or a numpy array (the steps are pure arithmetic, so they
work on both and keep the dtype of ``z``). ``integrate_fixed`` owns the grid loop.

``"rk4"`` here is *classic* RK4 (stages at 0, h/2, h/2, h; weights 1/6, 2/6, 2/6, 1/6), chosen on
purpose: its stage times are a subset of the half-step grid, so the control path needs only
2N+1 samples for N steps, and it is what the ONNX graph and the C++ reference unroll.
torchdiffeq's method ``'rk4'`` is a *different* scheme, the 3/8 rule (stages at 0, h/3, 2h/3, h;
weights 1/8, 3/8, 3/8, 1/8, ``rk4_alt_step_func``); both are 4th order but give different numbers
(tests/test_solvers.py shows it on dz/dt = t^4, where the errors are h^4/120 and h^4/270).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Callable

import numpy as np

from quadfdi.core.rk4 import RK4_C, RK4_ORDER, rk4_step

State = Any  # torch.Tensor or np.ndarray, any shape, e.g. (batch, latent)
VectorField = Callable[[float, State], State]  # f(t, z) -> dz/dt, same shape and dtype as z
StepFunction = Callable[[VectorField, float, State, float], State]

ADAPTIVE_METHODS = ("dopri5", "bosh3")  # torchdiffeq's embedded pairs, used through odeint


def euler_step(f: VectorField, t: float, z: State, h: float) -> State:
    """Forward Euler: z + h f(t, z). Order 1, one evaluation."""
    return z + h * f(t, z)


def midpoint_step(f: VectorField, t: float, z: State, h: float) -> State:
    """Explicit midpoint: z + h f(t + h/2, z + h/2 f(t, z)). Order 2, two evaluations.

    Same arithmetic as torchdiffeq's 'midpoint', so the two agree to rounding.
    """
    half = 0.5 * h
    k1 = f(t, z)
    return z + h * f(t + half, z + half * k1)


@dataclass(frozen=True)
class FixedMethod:
    """A fixed-step scheme: its step function, its order and where it evaluates f.

    ``stage_offsets[i]`` is the time of evaluation i within a step, as a fraction of h, in the
    order the step function calls f (rk4: (0, 0.5, 0.5, 1); so it makes len(stage_offsets)
    evaluations per step).
    """

    name: str
    order: int
    stage_offsets: tuple[float, ...]
    step: StepFunction

    @property
    def evals_per_step(self) -> int:
        return len(self.stage_offsets)


FIXED_METHODS: dict[str, FixedMethod] = {
    "euler": FixedMethod("euler", 1, (0.0,), euler_step),
    "midpoint": FixedMethod("midpoint", 2, (0.0, 0.5), midpoint_step),
    "rk4": FixedMethod("rk4", RK4_ORDER, RK4_C, rk4_step),  # core.rk4: the one RK4 program
}


def fixed_method(method: str) -> FixedMethod:
    """The registry entry of ``method``; ValueError naming the valid ones otherwise."""
    try:
        return FIXED_METHODS[method]
    except KeyError:
        raise ValueError(
            f"unknown fixed-step method {method!r}; valid: {', '.join(FIXED_METHODS)}"
        ) from None


def _check_steps(n_steps: int) -> int:
    if isinstance(n_steps, bool) or int(n_steps) != n_steps or n_steps < 1:
        raise ValueError(f"n_steps must be a positive integer, found {n_steps!r}")
    return int(n_steps)


def integrate_fixed(
    f: VectorField,
    z0: State,
    method: str,
    n_steps: int,
    t0: float = 0.0,
    t1: float = 1.0,
    trace: list | None = None,
) -> State:
    """Integrate dz/dt = f(t, z) from t0 to t1 with ``n_steps`` equal steps of ``method``.

    Args:
        f: vector field ``f(t, z)``; ``t`` is a Python float.
        z0: initial state, torch tensor or numpy array of any shape, e.g. (batch, latent).
        method: a key of FIXED_METHODS ("euler", "midpoint", "rk4").
        n_steps: number of steps N; h = (t1 - t0) / N, step k starts at t0 + k h.
        trace: if a list, the states are appended to it in this order:
            ``trace[0]`` = z0;
            ``trace[1 + k*S + i]`` = the state at which stage i of step k evaluates f
            (S = evals per step; stage 0 is the step's start state, so for k = 0 it is z0 again,
            and for k > 0 it is the result of step k - 1), at time t0 + (k + stage_offsets[i]) h;
            ``trace[-1]`` = z1.
            Length 2 + N*S (rk4: 2 + 4N). Entries are the solver's own objects, not copies.

    Returns:
        z1, the state at t1, same type, shape and dtype as z0.
    """
    spec = fixed_method(method)
    n = _check_steps(n_steps)
    t0, t1 = float(t0), float(t1)
    h = (t1 - t0) / n
    g = f
    if isinstance(trace, list):
        trace.append(z0)

        def g(t: float, z: State) -> State:
            trace.append(z)
            return f(t, z)

    z = z0
    for k in range(n):
        z = spec.step(g, t0 + k * h, z, h)
    if isinstance(trace, list):
        trace.append(z)
    return z


def stage_times(method: str, n_steps: int, t0: float = 0.0, t1: float = 1.0) -> np.ndarray:
    """Sorted distinct times (float64) at which ``integrate_fixed`` evaluates the vector field.

    These are the times where the control path is needed: rk4 with N steps gives the 2N+1 points
    t0 + j h/2, j = 0..2N; midpoint 2N points (t1 itself is never evaluated); euler N points.
    Computed from exact fractions, so a stage time reached as t + h/2 + h/2 and the next step's
    start t0 + (k+1) h map to one entry (look times up with a tolerance, not by equality).
    """
    spec = fixed_method(method)
    n = _check_steps(n_steps)
    fractions = sorted({k + Fraction(c).limit_denominator(1000) for k in range(n) for c in spec.stage_offsets})
    t0, t1 = float(t0), float(t1)
    return np.array([t0 + (t1 - t0) * (float(q) / n) for q in fractions], dtype=np.float64)


def nearest_index(times: np.ndarray, t: float, tol: float = 1e-9) -> int:
    """Index of ``t`` in ``times`` (sorted) up to ``tol``; ValueError if ``t`` is not there.

    Used to map the time a step function passes to f back to a row of a precomputed control
    table; plain Python on floats, so an unrolled (traced) graph sees constant indices.
    """
    t = float(t)
    j = int(np.searchsorted(times, t))
    best = min((i for i in (j - 1, j) if 0 <= i < len(times)), key=lambda i: abs(times[i] - t))
    if not math.isclose(times[best], t, rel_tol=0.0, abs_tol=tol):
        raise ValueError(f"time {t!r} is not one of the stage times (nearest {times[best]!r})")
    return best


@dataclass(frozen=True)
class SolverSpec:
    """How a CNODE integrates its latent ODE over [0, 1].

    ``method``: a fixed-step method of FIXED_METHODS (our arithmetic, ``steps`` equal steps) or an
    adaptive one of ADAPTIVE_METHODS (torchdiffeq.odeint with ``rtol``/``atol``; with
    ``jump_t`` the solver is told the control path's knots, see ``models.control.knots``).
    Fields that do not apply to the method are ignored.
    """

    method: str = "rk4"
    steps: int = 8
    rtol: float = 1e-3
    atol: float = 1e-4
    jump_t: bool = True

    def __post_init__(self) -> None:
        if self.method not in FIXED_METHODS and self.method not in ADAPTIVE_METHODS:
            valid = ", ".join((*FIXED_METHODS, *ADAPTIVE_METHODS))
            raise ValueError(f"unknown solver method {self.method!r}; valid: {valid}")
        _check_steps(self.steps)
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"solver {name} must be a positive number, found {value!r}")

    @property
    def is_fixed(self) -> bool:
        return self.method in FIXED_METHODS
