"""How far float32 rounding moves a streaming GRU's logits over a whole replayed flight at the edge of chaos, against
a wrong graph: random streaming GRUs (5 channels, 6 or 16 units, recurrent weights scaled as in SHAPES), one
random-walk flight of 1,500 samples each (tests/test_fp32_rounding.py's ``edge_stream``), seeds 0-7, replayed step
by step through ONNX Runtime's one-step graph (export/onnx_sgru.py) and through PyTorch over the whole flight. Per
GRU: the share of steps whose logits part from PyTorch's by more than the fp32 bound, and over those steps ONNX
Runtime's distance from the float64 replay in units of ``rounding_spread`` (head "stream"); the same for the graph
with linear_before_reset=0.

    PYTHONPATH=. python lab/stream_rounding.py   # from the repository root (the GRUs are the test's)
"""

from __future__ import annotations

import numpy as np

from quadfdi.export.sgru_run import ort_replay, torch_replay
from quadfdi.export.verify import parity
from quadfdi.models.stream_gru import StreamGRU
from quadfdi.runtimes.pytorch import rounding_spread
from tests.test_fp32_rounding import edge_stream, stream_graph

SHAPES = ((6, 6.0), (6, 7.5), (6, 8.5), (16, 6.0), (16, 7.5), (16, 8.0))  # (units, recurrent scale)


def measure(model: StreamGRU, tel: np.ndarray, lbr: int) -> tuple[float, np.ndarray]:
    ort, _ = ort_replay(stream_graph(model, lbr), tel, model.hidden)
    ref, _ = torch_replay(model, tel)
    over = np.flatnonzero(np.abs(ort - ref).max(1) > parity(ort, ref)["bound"])
    if not len(over):
        return 0.0, np.zeros(0)
    exact, spread = rounding_spread(model, tel[None], "stream")
    ratio = np.abs(ort[over].astype(np.float64) - exact[over]).max(1) / np.maximum(spread[over], 1e-300)
    return len(over) / len(tel), ratio


def main() -> None:
    correct, wrong_flight_max, shares = [], [], {1: [], 0: []}
    for hidden, scale in SHAPES:
        for lbr in (1, 0):
            row_shares, ratios = [], []
            for seed in range(8):
                share, ratio = measure(*edge_stream(seed, hidden, scale), lbr)
                row_shares.append(share)
                ratios += list(ratio)
                if lbr == 0 and len(ratio):
                    wrong_flight_max.append(ratio.max())
            r = np.array(ratios)
            correct += ratios if lbr == 1 else []
            shares[lbr] += row_shares
            text = (f"ratio median {np.median(r):.3g}, max {r.max():.3g}, min {r.min():.3g}" if len(r)
                    else "no step over the bound")
            print(f"hidden {hidden:2d}, scale {scale}, linear_before_reset={lbr}: steps over the bound per flight "
                  f"{', '.join(f'{s:.3f}' for s in row_shares)}; {text}")
    g = np.array(correct)
    print(f"correct graph: {len(g)} steps over the bound in {len(shares[1])} flights (at most {max(shares[1]):.3f} "
          f"of a flight's); ratio 99.9 % {np.quantile(g, 0.999):.2f}, max {g.max():.2f}")
    print(f"linear_before_reset=0: at least {min(shares[0]):.3f} of a flight's steps over the bound; a flight's "
          f"largest ratio at least {min(wrong_flight_max):.3g}")


if __name__ == "__main__":
    main()
