"""The collective hover estimate: one command and one current for the vehicle,
averaged over its first steady seconds of flight and then frozen (PX4's hover-thrust estimator
settles the same way). The profile ``flightlog-min`` divides the motor commands and the current
by it, so the inputs do not depend on the vehicle (docs/profiles.md).

The filter, sample by sample on the 25 Hz grid (everything in float32):

1. collective ``c_i = (((thr1 + thr2) + thr3) + thr4) * 0.25`` (this order).
2. sample i is **steady** when all of: airborne for more than ``SETTLE_SAMPLES = 50`` samples
   (2 s) since the last take-off (a flight's ``airborne``; a flight that starts airborne, as every
   simulated one does, is settled from its first sample: real logs' spool-up and climb-out
   otherwise pulled the estimate down by 12-30 %), vz, roll, pitch and thr1..4 finite (the
   current is not needed: a vehicle without a current sensor still gets its command estimate),
   ``|vz| <= 0.5 m/s``, ``|roll| <= 0.25 rad`` and ``|pitch| <= 0.25 rad`` (14.3 deg; per axis,
   no product, so C++ and numpy compare the same floats), ``c_i >= 0.05`` (motors spinning).
3. the estimate **freezes** at the first sample i that ends a run of ``N = 50`` consecutive steady
   samples (2.0 s): ``cmd = s_c / 50`` and ``cur = s_I / 50`` with ``s`` the float32 sum over the
   run's samples in time order (``s = 0; s += x`` from the oldest), then never changes (``cur`` is
   NaN when the current is missing in the run: a profile using it then refuses the flight).
4. Before the freeze the estimate does not exist: a window that ends before it gives no decision
   (``freeze`` is the index of that sample; -1 if the flight never has 2 s of steady flight).

A log without pitch (the masked profile, core/channels.py: the Crazyflie logs none) enters the steady
test with pitch 0 (level): the arithmetic is unchanged, the caller passes 0 for the absent column
(detect/inputs.py, fwref/profile.hpp ``hover_inputs``). Measured by dropping the pitch test
(``python lab/hover_without_pitch.py DATASET.npz LOG...`` on the realistic suite's seed-0 dataset and
the four shared PX4 quad logs): the frozen estimate and its freeze sample are identical on all four
real flights and on 7 of the first 8 simulated ones; the eighth freezes earlier, its command within
0.77 %.

``firmware_ref/include/fwref/hover.hpp`` is the same arithmetic in C++ (float32, fixed size, no
heap); tests/test_hover.py checks both give bit-identical estimates on simulated and real flights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STEADY_SAMPLES = 50  # N: 2.0 s at 25 Hz
VZ_MAX = np.float32(0.5)  # m/s
TILT_MAX = np.float32(0.25)  # rad, |roll| and |pitch| each (14.3 deg: hovering in wind tilts)
CMD_MIN = np.float32(0.05)  # collective command (fraction of full thrust)
SETTLE_SAMPLES = 50  # 2.0 s after a take-off before a sample can be steady (motor spool-up, climb-out)
INPUTS = ("vz", "roll", "pitch", "thr1", "thr2", "thr3", "thr4", "I_b")  # the columns hover.hpp reads, in order


@dataclass(frozen=True)
class Hover:
    """A frozen estimate: ``cmd`` (collective command) and ``cur`` (A) as float32, ``freeze`` the
    sample index at which it froze (-1: never; cmd and cur are then NaN)."""

    cmd: np.float32
    cur: np.float32
    freeze: int

    @property
    def ok(self) -> bool:
        return self.freeze >= 0


def collective(thr: np.ndarray) -> np.ndarray:
    """(..., 4) motor commands -> (...) collective command, float32, fixed summation order."""
    t = np.asarray(thr, dtype=np.float32)
    return ((t[..., 0] + t[..., 1]) + t[..., 2] + t[..., 3]) * np.float32(0.25)


def settled(airborne: np.ndarray, n: int = SETTLE_SAMPLES) -> np.ndarray:
    """(T,) bool: airborne for more than ``n`` samples since the last take-off (a flight that starts
    airborne, as every simulated one does, counts as settled from its first sample)."""
    out = np.zeros(len(airborne), bool)
    run = n  # the C++ mirror starts its counter here too
    for i, a in enumerate(np.asarray(airborne, bool)):
        run = run + 1 if a else 0
        out[i] = run > n
    return out


def steady(cols: np.ndarray, airborne: np.ndarray | None = None) -> np.ndarray:
    """(T, 8) columns ``INPUTS`` -> (T,) bool, the steady-sample test of step 2."""
    x = np.asarray(cols, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(x[:, :7]).all(axis=1)
        ok &= (np.abs(x[:, 0]) <= VZ_MAX) & (np.abs(x[:, 1]) <= TILT_MAX) & (np.abs(x[:, 2]) <= TILT_MAX)
        ok &= collective(x[:, 3:7]) >= CMD_MIN
    return ok if airborne is None else ok & settled(airborne)


def first_run_end(ok: np.ndarray, n: int = STEADY_SAMPLES) -> int:
    """Index of the first sample ending a run of ``n`` consecutive True; -1 if none."""
    ok = np.asarray(ok, bool)
    if ok.size < n:
        return -1
    cs = np.concatenate([[0], np.cumsum(ok, dtype=np.int64)])
    full = np.flatnonzero(cs[n:] - cs[:-n] == n)
    return int(full[0]) + n - 1 if full.size else -1


def _mean32(x: np.ndarray) -> np.float32:
    s = np.float32(0.0)
    for v in np.asarray(x, dtype=np.float32):
        s = np.float32(s + v)
    return np.float32(s / np.float32(len(x)))


def estimate(cols: np.ndarray, airborne: np.ndarray | None = None, n: int = STEADY_SAMPLES) -> Hover:
    """The estimate of one flight from its (T, 8) columns ``INPUTS`` (float32, NaN = no sample)."""
    x = np.asarray(cols, dtype=np.float32)
    if x.ndim != 2 or x.shape[1] != len(INPUTS):
        raise ValueError(f"hover inputs must be (samples, {len(INPUTS)}) columns {INPUTS}, found {x.shape}")
    end = first_run_end(steady(x, airborne), n)
    if end < 0:
        return Hover(np.float32(np.nan), np.float32(np.nan), -1)
    run = slice(end - n + 1, end + 1)
    return Hover(_mean32(collective(x[run, 3:7])), _mean32(x[run, 7]), end)


def estimate_many(cols: np.ndarray, n: int = STEADY_SAMPLES) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, T, 8) simulated flights (always airborne) -> cmd (F,), cur (F,) float32 and freeze (F,)."""
    out = [estimate(c, None, n) for c in np.asarray(cols, dtype=np.float32)]
    return (np.array([h.cmd for h in out], np.float32), np.array([h.cur for h in out], np.float32),
            np.array([h.freeze for h in out], np.int64))
