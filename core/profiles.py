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
- ``flightlog-mask``: whatever channels a log has. Its raw channels are every channel an
  availability group or the minimum names (core/channels.py), its inputs every model channel over
  them (both vibration metrics, ``vib`` PX4's and ``vib_ap`` ArduPilot's, each its own channel) and
  one availability channel per group; a group the flight lacks gives its model channels their fill
  (``apply_profile``'s ``available``). Only the minimum (roll, vz, thr1..4) is required.
- ``flightlog-ref``: the masked profile and deviations from the vehicle record (core/vehicle_record.py).
- ``flightlog-phys``: ``flightlog-ref`` and the physics channels computed by recursions over the flight so far
  (core/causal.py): the pack's sag per ampere per cell and the smoothed reference deviations. ``apply_profile``
  takes whole flights from their first sample (``raw`` (..., T)), as the stream computes them sample by sample.

Raw names are the channel table's (core/channels.py), the same in a simulated dataset and in an
ingested flight.npz: ``vib_px4`` is PX4's metric only, so a log of another autopilot lacks it.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core import causal, vehicle_record as vr
from quadfdi.core.channels import (AVAIL_PREFIX, AVAILABILITY_GROUPS, GROUP_NAMES, MASK_PATTERNS, PROFILE_BY_NAME,
                                   PROFILE_NAMES, REFERENCE_GROUP, MaskPattern, groups_of_model)
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


def has_reference(name: str) -> bool:
    """The profile reads the vehicle record (core/vehicle_record.py) beside the flight."""
    check_profile(name)
    return PROFILE_BY_NAME[name].reference


def is_masked(name: str) -> bool:
    """The profile takes whatever channels a log has (availability groups may be absent)."""
    check_profile(name)
    return PROFILE_BY_NAME[name].masked


def group_raw(group: str) -> tuple[str, ...]:
    return next(g.raw for g in AVAILABILITY_GROUPS if g.name == group)


def pattern_available(pattern: MaskPattern) -> dict[str, bool]:
    """group -> available under a mask pattern (core/channels.py MASK_PATTERNS)."""
    return {g: g not in pattern.groups for g in GROUP_NAMES}


def groups_carried(carried: set[str] | frozenset[str]) -> dict[str, bool]:
    """group -> available: every raw channel of the group is among ``carried`` (a stream's carried
    channels; fwref/stream.hpp Stream::set_carried makes the same rule)."""
    return {g.name: set(g.raw) <= set(carried) for g in AVAILABILITY_GROUPS}


def flight_pattern(index: int) -> MaskPattern:
    """The pattern a masked profile gives flight ``index`` of a simulated dataset (its ``traj_index``)
    outside training, where windows draw their own (train/masks.py): the patterns in turn, so that
    every pattern has flights in every split; the window path (models.inputs) and the stream files
    (formats.stream.from_dataset) of the same flight agree on it."""
    return MASK_PATTERNS[int(index) % len(MASK_PATTERNS)]


def mask_layout(name: str) -> tuple[dict[str, list[int]], np.ndarray, dict[str, int]]:
    """A masked profile's model columns per group, the (C,) float32 fills and each group's
    availability column; a reference profile's reference channels are also the ``reference`` group's
    (a reference channel of a lacking raw group is in both)."""
    spec = PROFILES[name]
    cols: dict[str, list[int]] = {g: [] for g in GROUP_NAMES}
    if PROFILE_BY_NAME[name].reference:
        cols[REFERENCE_GROUP] = [j for j, c in enumerate(spec) if c.reference]
    avail = {}
    for j, c in enumerate(spec):
        if c.name.startswith(AVAIL_PREFIX) and not c.raw:
            avail[c.name[len(AVAIL_PREFIX):]] = j
        for g in groups_of_model(c):
            cols[g].append(j)
    return cols, np.array([c.fill for c in spec], np.float32), avail


def apply_profile(name: str, raw: dict[str, np.ndarray], cells, hover_cmd, hover_cur,
                  available: dict | None = None, record: np.ndarray | None = None) -> np.ndarray:
    """Profile inputs (..., T, C') float32 from raw channels ``raw[name]`` (..., T).

    ``cells`` (the pack's cell count), ``hover_cmd`` and ``hover_cur`` (core.hover) are scalars or
    per-flight arrays (...,). ``paper`` is not computed here (it is the raw telemetry as is).
    A masked profile: ``available`` maps each group to a bool or a per-flight (...,) bool array
    (None: every group); a lacking group's raw channels may be left out of ``raw`` and its model
    channels take their fills, its availability channel 0. A reference profile: ``record`` the vehicle
    record (core/vehicle_record.py), (24,) or per flight (..., 24); None or NaN: no reference.
    """
    spec = PROFILES[name]
    if spec is None:
        raise ValueError("the paper profile is the raw telemetry itself")
    masked = PROFILE_BY_NAME[name].masked
    f32 = {k: np.asarray(v, dtype=np.float32) for k, v in raw.items()}
    if masked:
        shape = f32["roll"].shape
        f32 = {r: f32.get(r, np.full(shape, np.nan, np.float32)) for r in required_raw(name)} | f32
        with np.errstate(invalid="ignore", divide="ignore"):
            values = _values(f32, cells, hover_cmd, hover_cur)
        rec = None
        if PROFILE_BY_NAME[name].reference:
            rec = np.broadcast_to(np.asarray(vr.empty() if record is None else record, np.float32),
                                  shape[:-1] + (vr.SIZE,))
            have = available or {}
            values |= vr.reference_values(values, rec, have.get("rates", True), have.get("vel_h", True))
            if PROFILE_BY_NAME[name].physics:
                values |= causal.physics_values(f32, values, rec, have.get("rates", True), have.get("vel_h", True),
                                                hover_cmd)
        return _masked(spec, values, available or {}, shape, rec)
    values = _values(f32, cells, hover_cmd, hover_cur)
    return np.stack([values[ch.name] for ch in spec], axis=-1).astype(np.float32)


def _masked(spec, values: dict[str, np.ndarray], available: dict, shape: tuple[int, ...],
            record: np.ndarray | None = None) -> np.ndarray:
    """The masked profile's (..., T, C) inputs: a lacking group's channels at their fill, then the
    availability channels; a reference profile's reference channels at their fill where the flight has no
    record or the record holds nothing for them, ``avail_reference`` 0 without a record."""
    unknown = sorted(set(available) - set(GROUP_NAMES))
    if unknown:
        raise ValueError(f"unknown availability groups {unknown}; the groups are {GROUP_NAMES}")
    per_sample = lambda a: np.broadcast_to(np.asarray(a, bool)[..., None], shape)  # noqa: E731
    have = {g: per_sample(available.get(g, True)) for g in GROUP_NAMES}
    held = {}
    if record is not None:
        have[REFERENCE_GROUP] = per_sample(vr.has_record(record))
        held = {k: per_sample(v) for k, v in vr.held(record).items()}
        held |= {lp: held[of] for lp, of in causal.LOW_PASSED.items()}  # a smoothed deviation: as its deviation
    cols = []
    for c in spec:
        if c.name.startswith(AVAIL_PREFIX) and not c.raw:
            cols.append(have[c.name[len(AVAIL_PREFIX):]].astype(np.float32))
            continue
        v = values[c.name]
        keep = None
        for g in groups_of_model(c):  # every group the channel needs (r_cell: battery and current)
            keep = have[g] if keep is None else keep & have[g]
        if c.reference:
            keep = held[c.name] if keep is None else keep & held[c.name]
        cols.append(v if keep is None else np.where(keep, v, np.float32(c.fill)).astype(np.float32))
    return np.stack(cols, axis=-1).astype(np.float32)


def _values(f32: dict[str, np.ndarray], cells, hover_cmd, hover_cur) -> dict[str, np.ndarray]:
    """Every model channel the raw channels ``f32`` give, by name (float32, the C++ mirror's order)."""
    per = lambda v: np.asarray(v, dtype=np.float32)[..., None]  # noqa: E731 (per flight -> broadcast over T)
    # cos and sin in float64, then rounded to float32: libm's correctly rounded values, which the C++
    # mirror (firmware_ref fwref/profile.hpp) reproduces bit for bit; numpy's float32 SIMD cos differs
    # from them in the last bit for ~15 % of angles, which would make int8 stream parity a lottery.
    yaw = f32["yaw"].astype(np.float64)
    c, s = np.cos(yaw).astype(np.float32), np.sin(yaw).astype(np.float32)
    values = {"roll": f32["roll"], "pitch": f32["pitch"], "p": f32["p"], "q": f32["q"], "r": f32["r"],
              "vx_h": c * f32["vx"] + s * f32["vy"], "vy_h": -s * f32["vx"] + c * f32["vy"], "vz": f32["vz"],
              "v_cell": f32["V_b"] / per(cells), "vib": f32["vib_px4"],
              "collective": ((f32["thr1"] + f32["thr2"]) + f32["thr3"] + f32["thr4"]) * np.float32(0.25)}
    if "vib_ap" in f32:
        values["vib_ap"] = f32["vib_ap"]
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
    return values
