"""torchdiffeq's `jump_t` losing the knots (docs/solvers.md, "torchdiffeq's jump_t loses the knots"): dopri5
on a scalar ODE dz/dt = -z + u(t), u the linear interpolation of 80 random samples, with the 78 interior knots
as `jump_t`, at rtol 1e-6 ... 1e-10 (atol = rtol / 10); prints the vector-field evaluations of each solve.
A solve that keeps the knots grows slowly with the tolerance; one that lost them explodes.

    python lab/torchdiffeq_jump_t.py
"""

from __future__ import annotations

import numpy as np
import torch
from torchdiffeq import odeint

W = 80  # samples of the window: 78 interior knots


def main() -> None:
    tk = torch.arange(W, dtype=torch.float64) / (W - 1)
    x = torch.from_numpy(np.random.default_rng(0).normal(size=W))

    def u(t: torch.Tensor) -> torch.Tensor:
        i = min(max(int(float(t) * (W - 1)), 0), W - 2)
        return x[i] + (float(t) - float(tk[i])) * (x[i + 1] - x[i]) * (W - 1)

    for rtol in (1e-6, 1e-8, 1e-9, 1e-10):
        n = [0]

        def f(t: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
            n[0] += 1
            return -z + u(t)

        odeint(f, torch.zeros(1, dtype=torch.float64), torch.tensor([0.0, 1.0], dtype=torch.float64),
               rtol=rtol, atol=rtol / 10, method="dopri5", options={"jump_t": tk[1:-1]})
        print(f"rtol {rtol:g}: {n[0]} evaluations")


if __name__ == "__main__":
    main()
