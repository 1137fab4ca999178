"""Static activation ranges for the int8 graphs, from training windows.

The ranges are measured the way ONNX Runtime's MinMax calibrator measures them: the fp32 graph
is run with the probed intermediates added as outputs, over batches that a
``CalibrationDataReader`` yields, and each probe keeps its running max |x| (per tensor, or per
channel = last axis). The scales derived from them are constants of the int8 graph, so a
window's int8 result never depends on the other windows of its batch (dynamic quantization's
per-tensor scale spans the batch: one unusual window would change its neighbours' results).

Calibration windows are taken evenly over the training split (every trajectory contributes, no
random draw), never from the test split that the verification reports on.
"""

from __future__ import annotations

import numpy as np
from onnxruntime.quantization import CalibrationDataReader

from quadfdi.export.graph import Built
from quadfdi.runtimes.ort import session


class WindowReader(CalibrationDataReader):
    """Yields ``{"telemetry": (b, W, C) float32}`` batches of calibration windows, then None."""

    def __init__(self, windows: np.ndarray, batch: int = 256) -> None:
        self.windows = np.ascontiguousarray(windows, dtype=np.float32)
        self.batch = int(batch)
        self._next = 0

    def get_next(self) -> dict | None:
        if self._next >= len(self.windows):
            return None
        chunk = self.windows[self._next:self._next + self.batch]
        self._next += self.batch
        return {"telemetry": chunk}

    def rewind(self) -> None:
        self._next = 0

    def __len__(self) -> int:
        return -(-len(self.windows) // self.batch)


def select_windows(n_available: int, n_wanted: int) -> np.ndarray:
    """Indices of ``n_wanted`` windows spread evenly over ``n_available`` (all if fewer)."""
    if n_available <= n_wanted:
        return np.arange(n_available)
    return np.unique(np.round(np.linspace(0, n_available - 1, n_wanted)).astype(np.int64))


def collect_ranges(built: Built, probes: dict[str, str], reader: CalibrationDataReader) -> dict[str, np.ndarray]:
    """max |x| of each probe over every batch of ``reader``.

    ``probes`` maps a probe key of ``built`` to "tensor" (a scalar result) or "channel" (one value
    per index of the last axis).
    """
    keys = list(probes)
    sess = session(built.with_probes(keys).SerializeToString())
    names = [built.probes[k][0] for k in keys]
    amax: dict[str, np.ndarray] = {}
    for feed in reader:
        for key, out in zip(keys, sess.run(names, feed)):
            a = np.abs(out)
            m = a.reshape(-1, a.shape[-1]).max(axis=0) if probes[key] == "channel" else a.max()
            amax[key] = m if key not in amax else np.maximum(amax[key], m)
    if not amax:
        raise ValueError("calibration reader yielded no batch")
    return {k: np.asarray(v, np.float64) for k, v in amax.items()}
