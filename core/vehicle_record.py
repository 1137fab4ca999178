"""The vehicle record: what a reference profile (``flightlog-ref``, core/channels.py) reads of the vehicle's
own healthy flights, as 25 float32 numbers. Written once here; the C++ reads the same layout
(fwref/vehicle_record.hpp, loaded at reset) and computes the same deviations.

The record comes from a vehicle reference (``quadfdi vehicle learn``'s vehicle.json, docs/formats.md);
``from_reference`` copies, per the layout below, the numbers the reference channels use:

====================  =====  ==============================================================================
field                 index  meaning
====================  =====  ==============================================================================
``share_a``           0-3    each motor's healthy command share at zero forward speed and yaw rate
``share_v``           4-7    its change per m/s of forward speed (0: the reference fitted none)
``share_r``           8-11   its change per rad/s of yaw rate (0: none)
``v_lo``, ``v_hi``    12-13  forward speed range the reference flew (5-95 %), m/s (0, 0: none)
``r_lo``, ``r_hi``    14-15  yaw-rate range, rad/s (0, 0: none)
``vib_floor``         16-17  PX4 vibration metric = floor + slope x collective (NaN: the reference has none)
``vib_ap_floor``      18-19  the same for ArduPilot's VIBE in-plane mean (NaN: none)
``rpm_share``         20-23  each ESC's rpm over the four's mean (NaN: the reference logs no ESC rpm)
``sag``               24     the healthy sag per ampere per cell, ohm (-battery.sag_v_per_a; NaN: no current
                             that moves in its flights, or a version 1 record)
====================  =====  ==============================================================================

A share is the motor's command over the four's mean (vehicle/quantities.py). Where the reference holds no
share model (too few steady samples) its airborne mean share stands in with no slopes. What the record
gives per sample (``reference_values``, float32, this order of operations, no fused multiply-add):

- expected share ``s_k = (share_a[k] + share_v[k] * vf) + share_r[k] * yr`` with ``vf = clip(vx_h, v_lo,
  v_hi)`` (0 before clipping when the flight has no heading-frame velocity) and ``yr = clip(r, r_lo, r_hi)``
  (0 before clipping without body rates): the reference's line is not extrapolated beyond what it flew;
- ``m{k}_ref = m{k}_rel / s_k``: the motor's command over the hover collective, over its healthy share
  (1 for the vehicle as its reference flew, whatever its own asymmetry);
- ``vib_ref = vib - (vib_floor[0] + vib_floor[1] * c)`` with ``c`` the sample's collective command
  (core.hover.collective): the vibration above the vehicle's own floor at that thrust; ``vib_ap_ref`` alike;
- ``rpm{k}_ref = rpm{k}_rel / rpm_share[k]``;
- ``r_cell_ref = r_cell - sag`` (``flightlog-phys``, core/causal.py): the sag beyond the vehicle's own.

A channel whose record field is NaN takes its fill (the reference holds nothing for it), as one whose raw
channels the flight lacks; a flight without a record (all NaN) has every reference channel at its fill and
``avail_reference`` 0.

The record file (formats/vehicle_record_bin.py, what ``fwref_stream --vehicle`` loads) is a 16-byte header,
then the 25 float32 little-endian: ``char[8]`` magic ``FILE_MAGIC``, ``u32`` ``FILE_VERSION``, ``u32`` the id
of the profile it is for (core/channels.py), then the record. Version 1 (112 bytes, the first ``SIZE_V1``
fields, before ``sag``) is still read: its ``sag`` NaN. The C++ takes these constants and the field
offsets from ``firmware_ref/include/fwref/vehicle_record_gen.hpp`` (``python -m quadfdi.core.vehicle_record
--header``; a test checks the committed header is what this module generates).
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.core.resources import firmware_sources

SIZE = 25
SIZE_V1 = 24  # a version 1 record: every field before ``sag``
FIELDS = {"share_a": (0, 4), "share_v": (4, 8), "share_r": (8, 12), "v_range": (12, 14), "r_range": (14, 16),
          "vib_floor": (16, 18), "vib_ap_floor": (18, 20), "rpm_share": (20, 24), "sag": (24, 25)}
VIBRATION_FIELDS = {"vib_px4": "vib_floor", "vib_ap": "vib_ap_floor"}  # raw metric -> its record field
FILE_MAGIC = b"QFDIVEH\0"
FILE_VERSION = 2
FILE_HEADER_BYTES = 16  # magic, version, profile id
FILE_BYTES = FILE_HEADER_BYTES + 4 * SIZE
FILE_BYTES_V1 = FILE_HEADER_BYTES + 4 * SIZE_V1
HEADER_PATH = firmware_sources() / "include" / "fwref" / "vehicle_record_gen.hpp"


def empty() -> np.ndarray:
    """No reference: every field NaN."""
    return np.full(SIZE, np.nan, np.float32)


def has_record(record: np.ndarray) -> np.ndarray:
    """(...,) bool: the record holds a reference (its first share is finite)."""
    return np.isfinite(np.asarray(record, np.float32)[..., 0])


def _field(rec: np.ndarray, name: str) -> np.ndarray:
    lo, hi = FIELDS[name]
    return rec[lo:hi]


def from_reference(ref: dict) -> np.ndarray:
    """The record of a vehicle reference (vehicle.json's dict); a one-line ValueError when it holds no
    motor shares (not a vehicle reference)."""
    shares = ref.get("motor_share")
    if not isinstance(shares, list) or len(shares) != 4 or any(s.get("mean") is None for s in shares):
        raise ValueError("the vehicle reference holds no four motor shares")
    rec = empty()
    model = ref.get("share_model") or {}
    motors = model.get("motors")
    regs = (model.get("regressors") or []) if motors else []
    for k in range(4):
        m = motors[k] if motors else {}
        rec[k] = m.get("intercept", shares[k]["mean"]) if motors else shares[k]["mean"]
        rec[4 + k] = m.get("per_v_forward", 0.0) if "v_forward" in regs else 0.0
        rec[8 + k] = m.get("per_yaw_rate", 0.0) if "yaw_rate" in regs else 0.0
    ranges = model.get("range_5_95") or {}
    for name, at in (("v_forward", 12), ("yaw_rate", 14)):
        rec[at:at + 2] = ranges[name] if name in regs and ranges.get(name) else (0.0, 0.0)
    for raw, field in VIBRATION_FIELDS.items():
        vib = (ref.get("vibration") or {}).get(raw)
        if vib and vib["floor"]["mean"] is not None:
            lo = FIELDS[field][0]
            rec[lo:lo + 2] = (vib["floor"]["mean"], vib["per_collective"]["mean"])
    rpm = (ref.get("esc") or {}).get("rpm_share")
    if rpm:
        rec[20:24] = [m["mean"] if m.get("mean") is not None else np.nan for m in rpm["motors"]]
    bat = ref.get("battery") or {}
    if bat.get("mode") == "sag" and (bat.get("sag_v_per_a") or {}).get("mean") is not None:
        rec[24] = -bat["sag_v_per_a"]["mean"]  # vehicle/fits.py's slope dV/dI is negative: the sag is its opposite
    return rec


def from_v1(fields: np.ndarray) -> np.ndarray:
    """A version 1 record's 24 fields as a record: ``sag`` NaN (it holds none)."""
    return np.concatenate([np.asarray(fields, np.float32), np.full(SIZE - SIZE_V1, np.nan, np.float32)])


def _per(x: np.ndarray) -> np.ndarray:
    """A per-flight (..., ) field -> (..., 1): broadcast over samples."""
    return x[..., None]


def expected_shares(values: dict[str, np.ndarray], record: np.ndarray, rates: np.ndarray,
                    vel_h: np.ndarray) -> list[np.ndarray]:
    """Each motor's expected share ``s_k`` (module docstring), (..., T) float32, from the profile's ``vx_h`` and
    ``r`` and ``record`` (..., 24); ``rates``, ``vel_h`` (...,) bool: the flight has body rates, heading-frame
    velocity (0 before clipping without)."""
    rec = np.asarray(record, np.float32)
    f = lambda i: _per(rec[..., i])  # noqa: E731
    zero = np.float32(0.0)
    vx = np.where(_per(np.asarray(vel_h, bool)), values["vx_h"], zero)
    r = np.where(_per(np.asarray(rates, bool)), values["r"], zero)
    vf = np.minimum(np.maximum(vx, f(12)), f(13)).astype(np.float32)
    yr = np.minimum(np.maximum(r, f(14)), f(15)).astype(np.float32)
    with np.errstate(invalid="ignore"):
        return [((f(k) + f(4 + k) * vf) + f(8 + k) * yr).astype(np.float32) for k in range(4)]


def reference_values(values: dict[str, np.ndarray], record: np.ndarray, rates: np.ndarray,
                     vel_h: np.ndarray) -> dict[str, np.ndarray]:
    """The reference channels (module docstring) from the profile's ``values`` (core.profiles: ``m{k}_rel``,
    ``vx_h``, ``r``, ``vib``, ``vib_ap``, ``rpm{k}_rel``, ``collective``; (..., T) float32) and ``record``
    (..., 24) per flight; ``rates``, ``vel_h`` (...,) bool: the flight has body rates, heading-frame velocity.
    NaN where the record holds nothing for a channel (the caller puts its fill there)."""
    rec = np.asarray(record, np.float32)
    f = lambda i: _per(rec[..., i])  # noqa: E731
    out = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, s in enumerate(expected_shares(values, record, rates, vel_h)):
            out[f"m{k + 1}_ref"] = (values[f"m{k + 1}_rel"] / s).astype(np.float32)
        c = values["collective"]
        for name, (raw, lo) in (("vib_ref", ("vib", 16)), ("vib_ap_ref", ("vib_ap", 18))):
            if raw in values:
                out[name] = (values[raw] - (f(lo) + f(lo + 1) * c)).astype(np.float32)
        if "rpm1_rel" in values:
            for k in range(4):
                out[f"rpm{k + 1}_ref"] = (values[f"rpm{k + 1}_rel"] / f(20 + k)).astype(np.float32)
    return out


def held(record: np.ndarray) -> dict[str, np.ndarray]:
    """Reference channel -> (...,) bool per flight: the record holds what the channel reads (else it takes its
    fill)."""
    rec = np.asarray(record, np.float32)
    ok = lambda i: np.isfinite(rec[..., i])  # noqa: E731
    out = {f"m{k + 1}_ref": ok(k) for k in range(4)}
    out.update(vib_ref=ok(16) & ok(17), vib_ap_ref=ok(18) & ok(19))
    out.update({f"rpm{k + 1}_ref": ok(20 + k) for k in range(4)})
    out["r_cell_ref"] = ok(24)
    return out


def cpp_header() -> str:
    """The text of fwref/vehicle_record_gen.hpp: the record's size, its field offsets and the file's layout."""
    fields = "\n".join(f"constexpr int k{''.join(w.title() for w in name.split('_'))} = {lo};  // {hi - lo} floats"
                       for name, (lo, hi) in FIELDS.items())
    magic = FILE_MAGIC.rstrip(b"\0").decode("ascii")
    return f"""// GENERATED by `python -m quadfdi.core.vehicle_record --header` from core/vehicle_record.py; do not edit.
// The vehicle record's layout ({SIZE} float32) and its file's (formats/vehicle_record_bin.py), as
// fwref/vehicle_record.hpp reads them.
#pragma once

#include <cstdint>

namespace fwref {{
namespace vehicle {{

constexpr int kSize = {SIZE};  // floats in a record
constexpr int kSizeV1 = {SIZE_V1};  // floats in a version 1 record (every field before kSag)
// Each field's first index in the record (core/vehicle_record.py FIELDS).
{fields}

// The record file: char[8] magic, u32 version, u32 profile id, then kSize float32 little-endian.
constexpr char kFileMagic[9] = "{magic}";  // + NUL: 8 bytes
constexpr std::uint32_t kFileVersion = {FILE_VERSION};
constexpr int kFileHeaderBytes = {FILE_HEADER_BYTES};
constexpr int kFileBytes = {FILE_BYTES};
constexpr std::uint32_t kFileVersionV1 = 1;  // still read: kSizeV1 floats, kSag NaN
constexpr int kFileBytesV1 = {FILE_BYTES_V1};

}}  // namespace vehicle
}}  // namespace fwref
"""


if __name__ == "__main__":
    from quadfdi.core.contracts import header_cli

    sys.exit(header_cli(sys.argv[1:], HEADER_PATH, cpp_header, "quadfdi.core.vehicle_record"))
