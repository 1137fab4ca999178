"""How far float32 rounding moves a GRU's logits at the edge of chaos, against how far a wrong graph lies
(core/contracts.py's ROUNDING_FACTOR): random GRUs (5 channels, 80 steps, the recurrent weights scaled by
7.5 or 8.5 at 6 units, 7.5 or 8 at 16), 256 random-walk windows each, seeds 0-7. For the windows where
ONNX Runtime's fp32 graph and PyTorch part by more than the fp32 bound: ONNX Runtime's distance from the
float64 result over ``rounding_spread`` (the spread drawn with four seeds), for the correct graph and,
on the first 64 windows of seeds 0-1, for a graph with linear_before_reset=0.

    PYTHONPATH=. python lab/export_rounding.py   # from the repository root (the GRUs are the test's)
"""

from __future__ import annotations

import numpy as np

from quadfdi.export.onnx_gru import build_gru_fp32, gru_params
from quadfdi.core.contracts import ROUNDING_FACTOR
from quadfdi.export.verify import parity
from quadfdi.models.networks import GRUClassifier
from quadfdi.runtimes.ort import outputs, session
from quadfdi.runtimes.pytorch import rounding_spread, torch_logits
from tests.test_fp32_rounding import OPSET, edge_gru

SHAPES = ((6, 7.5), (6, 8.5), (16, 7.5), (16, 8.0))  # (units, recurrent scale): tests/test_fp32_rounding.py's EDGE


def ratios(gru: GRUClassifier, x: np.ndarray, lbr: int, limit: int | None, seeds: range) -> list[float]:
    ref = torch_logits(gru, x)
    graph = build_gru_fp32(gru_params(gru), OPSET, linear_before_reset=lbr).model.SerializeToString()
    ort = outputs(session(graph), x, ["logits"])[0]
    over = np.flatnonzero(np.abs(ort - ref).max(1) > parity(ort, ref)["bound"])[:limit]
    out: list[float] = []
    for s in seeds if len(over) else ():
        exact, spread = rounding_spread(gru, x[over], seed=s)
        out += list(np.abs(ort[over].astype(np.float64) - exact).max(1) / spread)
    return out


def main() -> None:
    good, wrong = [], []
    for seed in range(8):
        for hidden, scale in SHAPES:
            gru, x = edge_gru(seed, hidden, scale)
            good += ratios(gru, x, 1, None, range(4))
            if seed < 2:
                wrong += ratios(gru, x, 0, 64, range(1))
    g, b = np.array(good), np.array(wrong)
    print(f"correct graph: {len(g) // 4} windows over the bound x 4 spreads; ratio median {np.median(g):.2f}, "
          f"99.9 % {np.quantile(g, 0.999):.2f}, max {g.max():.2f}")
    print(f"linear_before_reset=0: {len(b)} windows; ratio min {b.min():.1f}, median {np.median(b):.3g}")
    print(f"ROUNDING_FACTOR {ROUNDING_FACTOR:g}")


if __name__ == "__main__":
    main()
