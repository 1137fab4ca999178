"""Fixed-step solvers and the control path, against independent references.

- A zoo of ODEs with exact solutions (closed forms, scipy's expm) over method x array type x
  dtype: each method's global error shrinks at its declared order.
- torchdiffeq: our euler and midpoint equal its 'euler' and 'midpoint'; its 'rk4' is the 3/8 rule
  (reimplemented here) and differs from our classic RK4, each matching its own error theory.
- Evaluation counts and traces; stage times.
- interp_matrix against np.interp; LinearPath against interp_matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pytest
import scipy.linalg
import torch
from torchdiffeq import odeint

from quadfdi.models.control import LinearPath, interp_matrix, knots, sample_times
from quadfdi.models.solvers import (
    FIXED_METHODS,
    SolverSpec,
    euler_step,
    integrate_fixed,
    midpoint_step,
    nearest_index,
    rk4_step,
    stage_times,
)

# ---------------------------------------------------------------------------------------------
# The problem zoo. Each problem builds (f, z0, exact z(t1)) for an array library and dtype;
# f(t, z) uses only arithmetic on z and a float of t, so numpy, torch and torchdiffeq all run it.
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Problem:
    name: str
    t0: float
    t1: float
    build: Callable[[Callable[[np.ndarray], object]], tuple[Callable, object, np.ndarray]]


def _exp_problem(arr):
    a = np.array([-0.7, 0.4, 1.3])
    z0 = np.array([1.0, -0.5, 2.0])
    a_ = arr(a)
    return (lambda t, z: a_ * z), arr(z0), z0 * np.exp(a * 1.0)


_A = np.random.default_rng(7).normal(size=(3, 3)) * 0.8


def _linear_problem(arr):
    z0 = np.array([[1.0, 0.0, -1.0], [0.5, 2.0, 0.3]])  # (batch 2, dim 3), dz/dt = A z per row
    at = arr(_A.T.copy())
    return (lambda t, z: z @ at), arr(z0), z0 @ scipy.linalg.expm(_A * 1.0).T


def _cos_problem(arr):
    z0 = np.array([0.3, -1.0])
    return (lambda t, z: 0.0 * z + math.cos(float(t))), arr(z0), z0 + math.sin(2.0) - math.sin(0.5)


def _logistic_problem(arr):
    # dz/dt = (1 + t) z (1 - z): time-dependent and nonlinear; z = 1 / (1 + (1/z0 - 1) e^{-(t + t^2/2)})
    z0 = np.array([0.2, 0.7])
    exact = 1.0 / (1.0 + (1.0 / z0 - 1.0) * np.exp(-(1.0 + 0.5)))
    return (lambda t, z: (1.0 + float(t)) * z * (1.0 - z)), arr(z0), exact


ZOO = [
    Problem("exp", 0.0, 1.0, _exp_problem),
    Problem("linear_expm", 0.0, 1.0, _linear_problem),
    Problem("cos", 0.5, 2.0, _cos_problem),
    Problem("logistic", 0.0, 1.0, _logistic_problem),
]

ARRAYS = {
    "numpy64": lambda a: np.asarray(a, dtype=np.float64),
    "torch64": lambda a: torch.as_tensor(a, dtype=torch.float64),
    "numpy32": lambda a: np.asarray(a, dtype=np.float32),
    "torch32": lambda a: torch.as_tensor(a, dtype=torch.float32),
}


def _to_np(z) -> np.ndarray:
    return z.detach().numpy() if isinstance(z, torch.Tensor) else np.asarray(z)


def _error(problem: Problem, array: str, method: str, n: int) -> float:
    f, z0, exact = problem.build(ARRAYS[array])
    z1 = integrate_fixed(f, z0, method, n, problem.t0, problem.t1)
    return float(np.max(np.abs(_to_np(z1).astype(np.float64) - exact)))


# Steps where the error is asymptotic yet far above float64 rounding.
ORDER_STEPS = {"euler": (16, 32, 64), "midpoint": (8, 16, 32), "rk4": (4, 8, 16)}


@pytest.mark.parametrize("problem", ZOO, ids=lambda p: p.name)
@pytest.mark.parametrize("method", list(FIXED_METHODS))
@pytest.mark.parametrize("array", ["numpy64", "torch64"])
def test_global_error_shrinks_at_declared_order(problem, method, array):
    errors = [_error(problem, array, method, n) for n in ORDER_STEPS[method]]
    observed = [math.log2(a / b) for a, b in zip(errors, errors[1:])]
    order = FIXED_METHODS[method].order
    assert all(abs(p - order) < 0.3 for p in observed), (errors, observed)


@pytest.mark.parametrize("problem", ZOO, ids=lambda p: p.name)
@pytest.mark.parametrize("method", list(FIXED_METHODS))
@pytest.mark.parametrize("lib", ["numpy", "torch"])
def test_float32_keeps_dtype_and_matches_float64(problem, method, lib):
    f32, z32, _ = problem.build(ARRAYS[f"{lib}32"])
    f64, z64, _ = problem.build(ARRAYS[f"{lib}64"])
    y32 = integrate_fixed(f32, z32, method, 16, problem.t0, problem.t1)
    y64 = integrate_fixed(f64, z64, method, 16, problem.t0, problem.t1)
    assert y32.dtype == z32.dtype and type(y32) is type(z32) and y32.shape == z32.shape
    np.testing.assert_allclose(_to_np(y32), _to_np(y64), rtol=2e-6, atol=2e-6)


# ---------------------------------------------------------------------------------------------
# torchdiffeq as the independent reference
# ---------------------------------------------------------------------------------------------


def _torchdiffeq_fixed(problem: Problem, method: str, n: int) -> torch.Tensor:
    f, z0, _ = problem.build(ARRAYS["torch64"])
    grid = torch.linspace(problem.t0, problem.t1, n + 1, dtype=torch.float64)  # grid = output times
    return odeint(f, z0, grid, method=method)[-1]


@pytest.mark.parametrize("problem", ZOO, ids=lambda p: p.name)
@pytest.mark.parametrize("method", ["euler", "midpoint"])
def test_euler_and_midpoint_equal_torchdiffeq(problem, method):
    f, z0, _ = problem.build(ARRAYS["torch64"])
    ours = integrate_fixed(f, z0, method, 13, problem.t0, problem.t1)
    theirs = _torchdiffeq_fixed(problem, method, 13)
    # Same arithmetic; only the grid's last bits differ (k*h versus linspace).
    torch.testing.assert_close(ours, theirs, rtol=1e-13, atol=1e-13)


def _rk4_three_eighths_step(f, t, z, h):
    """The 3/8 rule, written from its Butcher tableau (c = 0, 1/3, 2/3, 1; b = 1/8, 3/8, 3/8, 1/8)."""
    k1 = f(t, z)
    k2 = f(t + h / 3, z + h * k1 / 3)
    k3 = f(t + 2 * h / 3, z + h * (k2 - k1 / 3))
    k4 = f(t + h, z + h * (k1 - k2 + k3))
    return z + h * (k1 + 3 * k2 + 3 * k3 + k4) / 8


@pytest.mark.parametrize("n", [1, 2, 4, 7])
def test_classic_rk4_and_torchdiffeq_rk4_are_different_schemes(n):
    # dz/dt = t^4 on [0, 1], z(1) = 1/5. Classic RK4 is Simpson's rule here, whose error on a step
    # is h^5 f''''/2880 = h^5/120; the 3/8 rule's is h^5 f''''/6480 = h^5/270. f'''' is constant,
    # so the global errors are exactly N h^5/120 = 1/(120 N^4) and 1/(270 N^4).
    def f(t, z):
        return torch.ones_like(z) * float(t) ** 4

    z0 = torch.zeros(1, dtype=torch.float64)
    ours = integrate_fixed(f, z0, "rk4", n).item()
    theirs = odeint(f, z0, torch.linspace(0, 1, n + 1, dtype=torch.float64), method="rk4")[-1].item()
    assert ours - 0.2 == pytest.approx(1.0 / (120 * n**4), rel=1e-9)
    assert theirs - 0.2 == pytest.approx(1.0 / (270 * n**4), rel=1e-9)


@pytest.mark.parametrize("problem", ZOO, ids=lambda p: p.name)
def test_torchdiffeq_rk4_is_the_three_eighths_rule(problem):
    f, z0, exact = problem.build(ARRAYS["torch64"])
    n = 8
    h = (problem.t1 - problem.t0) / n
    z = z0
    for k in range(n):
        z = _rk4_three_eighths_step(f, problem.t0 + k * h, z, h)
    torch.testing.assert_close(_torchdiffeq_fixed(problem, "rk4", n), z, rtol=1e-13, atol=1e-14)
    if problem.name in ("exp", "linear_expm"):
        ours = integrate_fixed(f, z0, "rk4", n, problem.t0, problem.t1)
        torch.testing.assert_close(ours, z, rtol=1e-13, atol=1e-14)
    if problem.name == "logistic":
        # Both 4th order, but not the same numbers on a nonlinear problem. (On a linear autonomous
        # one, such as exp or linear_expm, every 4-stage 4th-order RK method gives the same
        # degree-4 Taylor polynomial of e^{hA}, hence the same numbers.)
        ours = integrate_fixed(f, z0, "rk4", n, problem.t0, problem.t1)
        assert (ours - z).abs().max().item() > 1e-9
        errs = []
        for m in (4, 8, 16):
            zz, hh = z0, (problem.t1 - problem.t0) / m
            for k in range(m):
                zz = _rk4_three_eighths_step(f, problem.t0 + k * hh, zz, hh)
            errs.append(np.abs(zz.numpy() - exact).max())
        assert all(abs(math.log2(a / b) - 4) < 0.3 for a, b in zip(errs, errs[1:])), errs


# ---------------------------------------------------------------------------------------------
# Evaluation counts, traces, stage times
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", list(FIXED_METHODS))
@pytest.mark.parametrize("n", [1, 5])
def test_evaluation_counts_trace_and_stage_times(method, n):
    problem = ZOO[3]  # logistic: time-dependent, so stage times matter
    f, z0, _ = problem.build(ARRAYS["numpy64"])
    calls: list[float] = []

    def counted(t, z):
        calls.append(t)
        return f(t, z)

    trace: list = []
    z1 = integrate_fixed(counted, z0, method, n, trace=trace)
    spec = FIXED_METHODS[method]
    s = spec.evals_per_step
    assert len(calls) == n * s == {"euler": n, "midpoint": 2 * n, "rk4": 4 * n}[method]
    assert len(trace) == 2 + n * s
    assert trace[0] is z0 and trace[-1] is z1
    for k in range(n + 1):  # trace[1 + k*S] is the state after k steps
        state = trace[1 + k * s] if k < n else trace[-1]
        np.testing.assert_allclose(state, integrate_fixed(f, z0, method, k, 0.0, k / n) if k else z0, rtol=1e-14)
    # the times match the declared offsets, and stage_times lists exactly the times used
    expected = [(k + c) / n for k in range(n) for c in spec.stage_offsets]
    np.testing.assert_allclose(calls, expected, rtol=0, atol=1e-15)
    times = stage_times(method, n)
    np.testing.assert_allclose(times, np.unique(np.round(expected, 12)), rtol=0, atol=1e-15)
    assert {nearest_index(times, t) for t in calls} == set(range(len(times)))


def test_stage_times_counts():
    np.testing.assert_allclose(stage_times("rk4", 8), np.linspace(0, 1, 17), atol=1e-15)
    assert len(stage_times("rk4", 13)) == 27  # 2N + 1
    assert len(stage_times("midpoint", 13)) == 26  # t1 is never evaluated
    assert len(stage_times("euler", 13)) == 13
    np.testing.assert_allclose(stage_times("rk4", 2, 1.0, 3.0), [1.0, 1.5, 2.0, 2.5, 3.0])


def test_registry_declarations():
    assert {m: (s.order, s.stage_offsets) for m, s in FIXED_METHODS.items()} == {
        "euler": (1, (0.0,)),
        "midpoint": (2, (0.0, 0.5)),
        "rk4": (4, (0.0, 0.5, 0.5, 1.0)),
    }
    assert FIXED_METHODS["rk4"].step is rk4_step
    assert FIXED_METHODS["midpoint"].step is midpoint_step
    assert FIXED_METHODS["euler"].step is euler_step


def test_bad_arguments():
    f = lambda t, z: z  # noqa: E731
    with pytest.raises(ValueError, match="unknown fixed-step method 'dopri5'"):
        integrate_fixed(f, np.ones(2), "dopri5", 4)
    with pytest.raises(ValueError, match="positive integer"):
        integrate_fixed(f, np.ones(2), "rk4", 0)
    with pytest.raises(ValueError, match="not one of the stage times"):
        nearest_index(stage_times("rk4", 2), 0.3)
    with pytest.raises(ValueError, match="unknown solver method"):
        SolverSpec("rk45")
    with pytest.raises(ValueError, match="rtol"):
        SolverSpec("dopri5", rtol=0.0)
    with pytest.raises(ValueError, match="positive integer"):
        SolverSpec("rk4", steps=0)


# ---------------------------------------------------------------------------------------------
# The control path
# ---------------------------------------------------------------------------------------------


def _random_times(rng, n=200):
    # random times plus the ends, every sample time and a few rounding-level neighbours
    w = 80
    special = np.concatenate([[0.0, 1.0, 1.0 - 1e-16], sample_times(w), sample_times(w)[1:-1] + 1e-15])
    return np.concatenate([rng.uniform(0, 1, n), special])


def test_interp_matrix_reproduces_np_interp():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(80, 6))  # (W, C)
    times = _random_times(rng)
    m = interp_matrix(times, 80)
    assert m.shape == (len(times), 80) and m.dtype == np.float64
    expected = np.stack([np.interp(times, sample_times(80), x[:, c]) for c in range(6)], axis=1)
    np.testing.assert_allclose(m @ x, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.sum(axis=1), 1.0, atol=1e-15)
    assert (m >= 0).all() and ((m != 0).sum(axis=1) <= 2).all()
    # a time on a sample picks that sample alone
    np.testing.assert_array_equal(interp_matrix(sample_times(80), 80), np.eye(80))
    # batched windows: (T, W) @ (B, W, C) -> (B, T, C)
    xb = rng.normal(size=(3, 80, 6))
    np.testing.assert_allclose((m @ xb)[1], m @ xb[1])


def test_interp_matrix_refuses_times_outside_the_window():
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        interp_matrix(np.array([0.5, 1.01]))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        interp_matrix(np.array([np.nan]))


def test_linear_path_matches_interp_matrix():
    rng = np.random.default_rng(1)
    x = torch.as_tensor(rng.normal(size=(4, 80, 5)))  # (B, W, C) float64
    path = LinearPath(x)
    times = _random_times(rng, 100)
    m = torch.as_tensor(interp_matrix(times, 80))
    expected = m @ x  # (B, T, C)
    for j, t in enumerate(times):
        torch.testing.assert_close(path(t), expected[:, j], rtol=0, atol=1e-12)
        torch.testing.assert_close(path(torch.tensor(t, dtype=torch.float64)), expected[:, j], rtol=0, atol=1e-12)
    # slopes: du/dt on the segment; linear extrapolation of the end segment just beyond t = 1
    t = 0.3
    i = int(t * 79)
    torch.testing.assert_close(path.derivative(t), (x[:, i + 1] - x[:, i]) * 79)
    torch.testing.assert_close(path(1.0 + 1e-3), x[:, -1] + 1e-3 * (x[:, -1] - x[:, -2]) * 79)
    # gradients flow to the window
    xg = x.clone().requires_grad_(True)
    LinearPath(xg)(torch.tensor(0.37)).sum().backward()
    assert xg.grad is not None and xg.grad.abs().sum() > 0


def test_knots_are_the_interior_samples():
    k = knots(80)
    assert k.shape == (78,) and k.dtype == np.float64
    assert (k > 0).all() and (k < 1).all() and (np.diff(k) > 0).all()
    np.testing.assert_allclose(k, np.arange(1, 79) / 79)
