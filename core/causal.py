"""Physics channels computed causally: a recursion per sample whose state starts at the flight's first
sample, so a window's values depend on the flight before it, as on board where the stream computes its
channels sample by sample (the ``flightlog-phys`` profile, core/channels.py; docs/profiles.md). The C++
mirror is fwref/causal.hpp (constants from the generated fwref/causal_gen.hpp), float32 in this order of
operations, no fused multiply-add.

One time constant ``TAU_S`` for every recursion, one per-sample coefficient ``ALPHA = 1 - exp(-dt / TAU_S)``
at the grid period dt (core.resample.GRID_DT, 25 Hz). Why 4 s: exponential weights hold about
``2 TAU_S / dt`` = 200 samples (8 s, 2.5 of the baselines' 3.2 s windows), enough throttle changes for the
current to move in a hover; short against the minutes over which the pack's open-circuit voltage falls,
and shorter than the fault ramps the simulator draws (fleet and realistic suites 0.10-0.30 of 75 s, 7.5-22.5 s;
paper 0.30-0.62 of 16 s, 4.8-9.9 s), so the channels follow a fault as it grows.

- ``sag_per_ampere`` (``r_cell``): the pack's voltage sag per ampere per cell, the causal twin of the
  baselines' ``r_int`` (train/features.py ``internal_resistance``): R = -cov(v_cell, I) / (var(I) + I_FLOOR_A^2)
  with exponentially weighted moments. Mathematically the EW means of v_cell, I, v_cell I and I^2 started at
  the first sample's values (cov = E[vI] - E[v] E[I]); computed in the centred form (West's update:
  ``C <- (1 - a) (C + a dv di)`` with dv, di the deviations from the previous means), because float32 raw
  moments of 4 V and 20 A cancel: at a 0.3 A swing around 20 A they are 13 % off the float64 value where the
  centred form is within 0.01 % (tests/test_phys_profile.py ``test_centred_form_is_the_ew_moments``).
  ``r_cell_ref`` is r_cell minus the vehicle record's healthy sag (core/vehicle_record.py ``sag``).
- ``ewma``: an exponentially weighted mean started at the first finite sample (the smoothed deviations).

A sample whose input is not finite (a gap, a NaN in the log, a channel the flight lacks) leaves the state
as it was and gives NaN at that sample (its windows are undecided anyway); the first finite sample starts
the state.
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.core import vehicle_record as vr
from quadfdi.core.resample import GRID_DT
from quadfdi.core.resources import firmware_sources

TAU_S = 4.0  # s, every recursion's time constant (module docstring says why)
SAMPLE_DT_S = GRID_DT  # s, the grid the recursions step on
I_FLOOR_A = 0.25  # A, the baselines' (train/features.py): below this current std the sag is shrunk towards 0
ALPHA = np.float32(-np.expm1(-SAMPLE_DT_S / TAU_S))  # the new sample's weight
BETA = np.float32(np.float32(1.0) - ALPHA)  # the old state's
FLOOR2 = np.float32(I_FLOOR_A * I_FLOOR_A)  # exact: 0.0625
# a smoothed deviation takes its fill where its deviation does (the record holds nothing for it)
LOW_PASSED = {**{f"m{k}_ref_lp": f"m{k}_ref" for k in range(1, 5)}, "vib_ref_lp": "vib_ref",
              "vib_ap_ref_lp": "vib_ap_ref"}
HEADER_PATH = firmware_sources() / "include" / "fwref" / "causal_gen.hpp"


def ewma(x: np.ndarray) -> np.ndarray:
    """(..., T) float32 -> (..., T): m_0 = x at the first finite sample, then m <- m + ALPHA (x - m) on finite
    samples; NaN where x is not finite (the state held across)."""
    x = np.asarray(x, np.float32)
    out = np.full(x.shape, np.nan, np.float32)
    m = np.zeros(x.shape[:-1], np.float32)
    started = np.zeros(x.shape[:-1], bool)
    for t in range(x.shape[-1]):
        xt = x[..., t]
        ok = np.isfinite(xt)
        with np.errstate(invalid="ignore", over="ignore"):
            step = np.where(started, m + ALPHA * (xt - m), xt)
        m = np.where(ok, step, m).astype(np.float32)
        started |= ok
        out[..., t] = np.where(ok, m, np.float32(np.nan))
    return out


def sag_per_ampere(v: np.ndarray, i: np.ndarray) -> np.ndarray:
    """(..., T) per-cell voltage (V) and pack current (A) float32 -> (..., T) the sag per ampere per cell
    (ohm) at every sample (module docstring): -C_vi / (C_ii + I_FLOOR_A^2); NaN where v or i is not finite."""
    v, i = np.asarray(v, np.float32), np.asarray(i, np.float32)
    out = np.full(v.shape, np.nan, np.float32)
    shape = v.shape[:-1]
    mv, mi, cvi, cii = (np.zeros(shape, np.float32) for _ in range(4))
    started = np.zeros(shape, bool)
    for t in range(v.shape[-1]):
        vt, it = v[..., t], i[..., t]
        ok = np.isfinite(vt) & np.isfinite(it)
        with np.errstate(invalid="ignore", over="ignore"):
            dv, di = vt - mv, it - mi
            nmv, nmi = mv + ALPHA * dv, mi + ALPHA * di
            ncvi = BETA * (cvi + (ALPHA * dv) * di)
            ncii = BETA * (cii + (ALPHA * di) * di)
        first = ok & ~started  # the first usable sample starts the state: means at it, no spread
        zero = np.float32(0.0)
        mv = np.where(first, vt, np.where(ok, nmv, mv)).astype(np.float32)
        mi = np.where(first, it, np.where(ok, nmi, mi)).astype(np.float32)
        cvi = np.where(first, zero, np.where(ok, ncvi, cvi)).astype(np.float32)
        cii = np.where(first, zero, np.where(ok, ncii, cii)).astype(np.float32)
        started |= ok
        with np.errstate(invalid="ignore", divide="ignore"):
            out[..., t] = np.where(ok, -cvi / (cii + FLOOR2), np.float32(np.nan))
    return out


def physics_values(f32: dict[str, np.ndarray], values: dict[str, np.ndarray], record: np.ndarray, rates, vel_h,
                   hover_cmd) -> dict[str, np.ndarray]:
    """The physics channels (core/channels.py), (..., T) float32, from the raw channels ``f32``, the profile's
    ``values`` (``v_cell`` and the reference channels, before any fill), the vehicle ``record`` (..., 25),
    ``rates``/``vel_h`` as core.vehicle_record.expected_shares and the hover command (...,):

    - ``r_cell`` = ``sag_per_ampere(v_cell, I_b)``; ``r_cell_ref`` = ``r_cell - sag``, the record's healthy sag
      per ampere per cell (core/vehicle_record.py ``sag``);
    - ``m{k}_ref_lp`` = ``ewma(thr{k} / s_k) / hover_cmd``: the smoothed ``m{k}_ref``, divided by the hover
      estimate last (on board it freezes after the flight's start; the recursion runs before it does);
    - ``vib_ref_lp``, ``vib_ap_ref_lp`` = ``ewma`` of ``vib_ref``, ``vib_ap_ref``.
    NaN where the record holds nothing (the caller puts the fill there)."""
    shares = vr.expected_shares(values, record, rates, vel_h)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = [f32[f"thr{k + 1}"] / s for k, s in enumerate(shares)]
        lp = ewma(np.stack(q + [values["vib_ref"], values["vib_ap_ref"]]))
        cmd = np.asarray(hover_cmd, np.float32)[..., None]
        out = {f"m{k + 1}_ref_lp": (lp[k] / cmd).astype(np.float32) for k in range(4)}
    out.update(vib_ref_lp=lp[4], vib_ap_ref_lp=lp[5], r_cell=sag_per_ampere(values["v_cell"], f32["I_b"]))
    with np.errstate(invalid="ignore"):
        out["r_cell_ref"] = (out["r_cell"] - np.asarray(record, np.float32)[..., 24:25]).astype(np.float32)
    return out


def _hex(x: np.float32) -> str:
    return float(x).hex() + "f"


def cpp_header() -> str:
    """The text of fwref/causal_gen.hpp: the recursions' constants, float32-exact (hex literals)."""
    return f"""// GENERATED by `python -m quadfdi.core.causal --header` from core/causal.py; do not edit.
// The causal physics channels' constants (fwref/causal.hpp's recursions), float32 as Python rounds them.
#pragma once

namespace fwref {{
namespace causal {{

constexpr double kTauS = {TAU_S!r};        // s, every recursion's time constant
constexpr double kSampleDtS = {SAMPLE_DT_S!r};  // s, the grid period they step on
constexpr float kAlpha = {_hex(ALPHA)};  // 1 - exp(-dt / tau): the new sample's weight
constexpr float kBeta = {_hex(BETA)};   // 1 - kAlpha in float32: the old state's
constexpr float kFloor2 = {_hex(FLOOR2)};  // I_FLOOR_A^2, A^2: the sag's shrinkage at a steady current

}}  // namespace causal
}}  // namespace fwref
"""


if __name__ == "__main__":
    from quadfdi.core.contracts import header_cli

    sys.exit(header_cli(sys.argv[1:], HEADER_PATH, cpp_header, "quadfdi.core.causal"))
