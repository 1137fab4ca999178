"""Classic RK4, written once: the tableau, the evaluation program and the step function.

Everything that integrates with classic RK4 takes it from here: the simulator's physics step
(numpy float64), training (torch float32), the unrolled ONNX graph (``export.onnx_cnode`` evaluates
``rk4_step`` on symbolic graph values, so the graph *is* this program), and the C++ reference,
whose ``rk4_integrate`` (firmware_ref/src/model_common.hpp) follows ``RK4_PROGRAM`` line by line.

Classic RK4 (stages at 0, h/2, h/2, h; weights 1/6, 2/6, 2/6, 1/6), not torchdiffeq's ``'rk4'``,
which is the 3/8 rule (stages at 0, h/3, 2h/3, h; weights 1/8, 3/8, 3/8, 1/8).

Why the *order* of operations is part of the contract: float addition is not associative, and the
int8 graphs requantise every stage state, so ``z + k*(h/2)`` and ``z + (k*h)/2`` can land on
different int8 codes. ONNX Runtime, PyTorch and C++ agree bit for bit only because all three
evaluate exactly ``RK4_PROGRAM`` with the float32 constants of ``rk4_constants``.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

# Butcher tableau of classic RK4.
RK4_C = (0.0, 0.5, 0.5, 1.0)  # stage offsets, fraction of h, in evaluation order
RK4_A = ((), (0.5,), (0.0, 0.5), (0.0, 0.0, 1.0))
RK4_B = (1.0 / 6.0, 2.0 / 6.0, 2.0 / 6.0, 1.0 / 6.0)
RK4_ORDER = 4

# The constants the graphs and weights.bin hold, in this order (float32 of the float64 value).
RK4_CONSTANT_NAMES = ("half_h", "h", "two", "h_over_6")

# The evaluation program, one line per statement, in order. C++ and the ONNX graph follow it.
RK4_PROGRAM = (
    "k1 = f(t, z)",
    "k2 = f(t + h/2, z + half_h * k1)",
    "k3 = f(t + h/2, z + half_h * k2)",
    "k4 = f(t + h, z + h * k3)",
    "z = z + h_over_6 * (((k1 + two * k2) + two * k3) + k4)",
)


def rk4_constants(h: float) -> np.ndarray:
    """(4,) float32 [h/2, h, 2, h/6]: ``RK4_CONSTANT_NAMES`` for a step of ``h``."""
    return np.array([0.5 * h, h, 2.0, h / 6.0], dtype=np.float32)


def rk4_step(f: Callable[[float, Any], Any], t: float, z: Any, h: float, k1: Any = None) -> Any:
    """One classic RK4 step of dz/dt = f(t, z): ``RK4_PROGRAM`` expression by expression.

    ``z`` is anything with ``+`` and ``*`` by a Python float: a numpy array (batch, ...), a torch
    tensor, or a symbolic graph value; the result keeps its type and dtype. ``k1`` = f(t, z) when
    the caller has it already (the simulator evaluates it for its diagnostics).
    """
    half = 0.5 * h
    if k1 is None:
        k1 = f(t, z)
    k2 = f(t + half, z + k1 * half)
    k3 = f(t + half, z + k2 * half)
    k4 = f(t + h, z + k3 * h)
    return z + (((k1 + k2 * 2.0) + k3 * 2.0) + k4) * (h / 6.0)
