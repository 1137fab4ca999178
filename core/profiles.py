"""Channel profiles: a model's inputs as a named, ordered list of channels, each computed from named
raw channels (docs/profiles.md). The profiles themselves, their channels and ids are core/channels.py's
tables (``PROFILE_TABLE``, ``MODEL_CHANNELS``); this module computes them. Used identically by
``train`` (dataset flights) and ``detect`` (ingested real flights); the profile's name is stored in
the checkpoint (``profile``), in the export manifest (``profile``) and, by id, in weights.bin's
on-board record.

- ``paper``: the identity over the dataset's channels (the default; every earlier run is one).
- ``flightlog-min``: what a stock autopilot logs, with no heading-dependent channel and no
  vehicle-dependent scale: roll, pitch; p, q, r; vx, vy rotated by -yaw into the heading frame, vz;
  per-cell voltage; current and the four motor commands over the collective hover estimate
  (core.hover: one scalar per vehicle, so damage present from take-off stays visible); PX4's
  ``accel_vibration_metric`` (ArduPilot's VIBE is another quantity and is refused).
- ``flightlog-nocur``: ``flightlog-min`` without the current, for vehicles whose current sensor is
  absent or uncalibrated (ingest marks it unusable).
- ``flightlog-esc``: ``flightlog-min`` plus ESC telemetry: each ESC's rpm and each ESC's current over
  the four ESCs' collective of the same sample (``(((a1 + a2) + a3) + a4) * 0.25``): a per-motor
  share, no vehicle scale, no state, and no calibration between the ESCs' current sensing and the
  battery monitor (on the UAVCAN mission the ESC currents sum to 0.53 of I_b); and each ESC's
  temperature MINUS the four's collective of the same sample (K): no ambient, no common heating,
  no state (docs/profiles.md says why not "relative to ambient").

Raw names are the channel table's (core/channels.py), the same in a simulated dataset and in an
ingested flight.npz: ``vib_px4`` is PX4's metric only, so a log of another autopilot lacks it.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.channels import PROFILE_BY_NAME, PROFILE_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.hover import INPUTS as HOVER_INPUTS

DEFAULT_PROFILE = "paper"
PROFILES = {p.name: p.model for p in PROFILE_BY_NAME.values()}  # name -> model channels (None: paper)
VIBRATION = {p.name: p.vibration for p in PROFILE_BY_NAME.values() if p.vibration}  # which vibration quantity


def check_profile(name: str) -> None:
    if name not in PROFILE_BY_NAME:
        raise QuadfdiError(f"unknown channel profile {name!r}; valid: {', '.join(PROFILE_NAMES)}")


def uses_hover(name: str) -> bool:
    check_profile(name)
    return PROFILES[name] is not None


def channel_names(name: str, raw_names: list[str] | tuple[str, ...]) -> list[str]:
    """The profile's input channels (``paper``: the raw channels themselves)."""
    check_profile(name)
    spec = PROFILES[name]
    return list(raw_names) if spec is None else [c.name for c in spec]


def channel_units(name: str, raw_units: list[str] | tuple[str, ...]) -> list[str]:
    spec = PROFILES[name]
    return list(raw_units) if spec is None else [c.unit for c in spec]


def required_raw(name: str, raw_names: list[str] | tuple[str, ...] = ()) -> list[str]:
    """Raw channels the profile reads (the hover estimate's included), in stream order (``paper``:
    ``raw_names`` themselves)."""
    check_profile(name)
    raw = PROFILE_BY_NAME[name].raw
    if raw is None:
        return list(raw_names)
    return list(raw) + [r for r in HOVER_INPUTS if r not in raw and r != "I_b"]  # the hover current is optional


def apply_profile(name: str, raw: dict[str, np.ndarray], cells, hover_cmd, hover_cur) -> np.ndarray:
    """Profile inputs (..., T, C') float32 from raw channels ``raw[name]`` (..., T).

    ``cells`` (the pack's cell count), ``hover_cmd`` and ``hover_cur`` (core.hover) are scalars or
    per-flight arrays (...,). ``paper`` is not computed here (it is the raw telemetry as is).
    """
    spec = PROFILES[name]
    if spec is None:
        raise ValueError("the paper profile is the raw telemetry itself")
    f32 = {k: np.asarray(v, dtype=np.float32) for k, v in raw.items()}
    per = lambda v: np.asarray(v, dtype=np.float32)[..., None]  # noqa: E731 (per flight -> broadcast over T)
    # cos and sin in float64, then rounded to float32: libm's correctly rounded values, which the C++
    # mirror (firmware_ref fwref/profile.hpp) reproduces bit for bit; numpy's float32 SIMD cos differs
    # from them in the last bit for ~15 % of angles, which would make int8 stream parity a lottery.
    yaw = f32["yaw"].astype(np.float64)
    c, s = np.cos(yaw).astype(np.float32), np.sin(yaw).astype(np.float32)
    values = {"roll": f32["roll"], "pitch": f32["pitch"], "p": f32["p"], "q": f32["q"], "r": f32["r"],
              "vx_h": c * f32["vx"] + s * f32["vy"], "vy_h": -s * f32["vx"] + c * f32["vy"], "vz": f32["vz"],
              "v_cell": f32["V_b"] / per(cells), "vib": f32["vib_px4"]}
    if "I_b" in f32:
        values["i_rel"] = f32["I_b"] / per(hover_cur)
    for k in range(1, 5):
        values[f"m{k}_rel"] = f32[f"thr{k}"] / per(hover_cmd)
    if "rpm1" in f32:
        for raw_name, out in (("rpm", "rpm{}_rel"), ("esc_cur", "esc{}_i_rel")):
            a = [f32[f"{raw_name}{k}"] for k in range(1, 5)]
            collective = (((a[0] + a[1]) + a[2]) + a[3]) * np.float32(0.25)
            with np.errstate(divide="ignore", invalid="ignore"):  # motors stopped: NaN / inf, an undecided window
                for k in range(1, 5):
                    values[out.format(k)] = a[k - 1] / collective
    if "esc_temp1" in f32:  # each ESC above (or below) the four's common temperature: a difference, never undefined
        a = [f32[f"esc_temp{k}"] for k in range(1, 5)]
        collective = (((a[0] + a[1]) + a[2]) + a[3]) * np.float32(0.25)
        for k in range(1, 5):
            values[f"esc{k}_t_rel"] = a[k - 1] - collective
    return np.stack([values[ch.name] for ch in spec], axis=-1).astype(np.float32)
