"""The Python window path on a stream's samples: what ``fwref_stream`` must reproduce at every stride
(docs/firmware.md "Streaming"), and the reader of its output lines.

``windows_of(rs, record)`` applies the same rules as detect/inputs.py to a RawStream
(detect/streamfile.py): the hover estimate over the whole stream (core.hover), the profile
(core.profiles.apply_profile), windows on the grid starts 0, stride, ... and a window decided when
it ends at or after the freeze and every one of its samples is usable (every raw channel finite,
airborne, every model value finite). ``paper``: the identity, no hover estimate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core import hover
from core.profiles import apply_profile, uses_hover
from detect.streamfile import RawStream


@dataclass
class StreamWindows:
    x: np.ndarray  # (T, C) float32 model values
    starts: np.ndarray  # (n,) window first samples
    ends: np.ndarray  # (n,) window last samples
    decided: np.ndarray  # (n,) bool
    nohover: np.ndarray  # (n,) bool: no decision because the hover estimate had not frozen
    hover: hover.Hover | None

    def windows(self, window: int) -> np.ndarray:
        """(n_decided, W, C) float32."""
        s = self.starts[self.decided]
        return np.ascontiguousarray(self.x[s[:, None] + np.arange(window)[None, :]], np.float32)


def windows_of(rs: RawStream, record: dict) -> StreamWindows:
    window, stride, profile = int(record["window"]), int(record["stride"]), record["profile"]
    t = len(rs.time)
    starts = np.arange(0, t - window + 1, stride, dtype=np.int64) if t >= window else np.zeros(0, np.int64)
    ends = starts + window - 1
    if not uses_hover(profile):
        x = rs.values.astype(np.float32)
        ok = np.isfinite(x).all(axis=1)
        est, nohover = None, np.zeros(len(starts), bool)
    else:
        airborne = rs.column("airborne") >= 0.5
        cols = np.stack([rs.column(c) if c in rs.names else np.full(t, np.nan, np.float32) for c in hover.INPUTS], 1)
        est = hover.estimate(cols, airborne)
        raw = {n: rs.column(n) for n in rs.names if n != "airborne"}
        with np.errstate(invalid="ignore", divide="ignore"):
            x = apply_profile(profile, raw, rs.cells, est.cmd, est.cur)
        ok = np.isfinite(rs.values[:, :-1]).all(axis=1) & airborne & np.isfinite(x).all(axis=1)
        nohover = ~((est.freeze >= 0) & (ends >= est.freeze))
    cs = np.concatenate([[0], np.cumsum(ok)])
    decided = ~nohover & (cs[starts + window] - cs[starts] == window)
    return StreamWindows(x=x, starts=starts, ends=ends, decided=decided, nohover=nohover, hover=est)


def read_lines(text: str, classes: int) -> dict[str, np.ndarray]:
    """fwref_stream's output -> arrays per stride: index, t, status (str), logits (n, K) float32,
    proba (n, K), vote, active, raised, cleared (bool), cls, motor (int)."""
    rows = [ln.split() for ln in text.splitlines() if ln and not ln.startswith("#")]
    k = classes
    col = lambda j, dt: np.array([r[j] for r in rows], dtype=dt)
    out = {"index": col(0, np.int64), "t": col(1, np.float64), "status": np.array([r[2] for r in rows]),
           "logits": np.array([[float(v) for v in r[3:3 + k]] for r in rows], np.float32).reshape(-1, k),
           "proba": np.array([[float(v) for v in r[3 + k:3 + 2 * k]] for r in rows], np.float64).reshape(-1, k)}
    for j, name in enumerate(("vote", "active", "raised", "cleared")):
        out[name] = col(3 + 2 * k + j, np.int64).astype(bool)
    out["cls"], out["motor"] = col(7 + 2 * k, np.int64), col(8 + 2 * k, np.int64)
    return out
