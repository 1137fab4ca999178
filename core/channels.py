"""The channel table: every channel quadfdi knows, with its unit and a stable id, written once; and
the channel profiles as named lists over it. Each table is the one place of its contract (the C++ gets
them from ``firmware_ref/include/fwref/channels_gen.hpp``: ``python -m quadfdi.core.channels --header``;
a test checks that the committed header is what this module generates):

- ``CHANNELS``: the raw channels, each with an id never renumbered nor reused (a profile, an availability
  mask and the C++ name a channel by it). The simulator's 23 telemetry channels first, in the paper
  dataset's order (a model trained on the simulator reads the same columns as one reading an ingested
  flight), then those only richer logs (and the realistic suite) carry: together flight.npz's columns.
  Each autopilot's vibration metric is its own channel: ``vib_px4`` PX4's ``accel_vibration_metric``
  (m/s^2), ``vib_ap`` ArduPilot's VIBE in-plane mean (VibeX + VibeY) / 2 (the simulator has no vertical
  vibration model). Last ``airborne`` (0/1), which only a stream carries.
- ``MODEL_CHANNELS``: what a profile gives a model, each from named raw channels by the formula
  docs/profiles.md shows (core/profiles.py computes them; fwref/profile.hpp in float32).
- ``PROFILE_TABLE``: each profile as the raw channels a vehicle must log for it (in stream order), with
  the id weights.bin's on-board record stores. Its model channels are derived: every model channel whose
  raw channels it has, in ``MODEL_CHANNELS`` order. ``paper`` (id 0) is the identity.
- ``AVAILABILITY_GROUPS``, ``MINIMUM_RAW`` and ``MASK_PATTERNS``: a masked profile takes whatever channels
  a log has. A group is a set of raw channels a log has or lacks together; the minimum is never masked
  (the hover estimate and the airborne rule need it); after the model channels come one availability
  channel per group (``avail_<group>``: 1 when the flight has the group, constant over a flight). A model
  channel needing a group the flight lacks takes its ``fill`` (what a level, healthy hover gives), inside
  the range the int8 calibration saw. Fills, like formulas, belong to the profile: changing one is a new
  profile id. ``MASK_PATTERNS`` names the patterns real logs show (docs/profiles.md "The masked profile").

Everything that names a channel (the simulator's sensors, ``flight.npz``, profiles, the on-board
record, stream files and the C++) takes names, units and ids from here.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

from quadfdi.core.resources import firmware_sources


@dataclass(frozen=True)
class Channel:
    id: int  # stable: never renumbered, never reused
    name: str
    unit: str
    kind: str  # "sim": the simulator's telemetry; "log": richer logs; "stream": only a stream carries it


CHANNELS: tuple[Channel, ...] = (
    Channel(0, "x", "m", "sim"), Channel(1, "y", "m", "sim"), Channel(2, "z", "m", "sim"),
    Channel(3, "vx", "m/s", "sim"), Channel(4, "vy", "m/s", "sim"), Channel(5, "vz", "m/s", "sim"),
    Channel(6, "roll", "rad", "sim"), Channel(7, "pitch", "rad", "sim"), Channel(8, "yaw", "rad", "sim"),
    Channel(9, "p", "rad/s", "sim"), Channel(10, "q", "rad/s", "sim"), Channel(11, "r", "rad/s", "sim"),
    Channel(12, "V_b", "V", "sim"), Channel(13, "I_b", "A", "sim"), Channel(14, "SoC", "-", "sim"),
    Channel(15, "T1", "degC", "sim"), Channel(16, "T2", "degC", "sim"), Channel(17, "T3", "degC", "sim"),
    Channel(18, "T4", "degC", "sim"),
    Channel(19, "thr1", "-", "sim"), Channel(20, "thr2", "-", "sim"), Channel(21, "thr3", "-", "sim"),
    Channel(22, "thr4", "-", "sim"),
    Channel(23, "vib_px4", "m/s^2", "log"),
    Channel(24, "rpm1", "rpm", "log"), Channel(25, "rpm2", "rpm", "log"), Channel(26, "rpm3", "rpm", "log"),
    Channel(27, "rpm4", "rpm", "log"),
    Channel(28, "esc_temp1", "degC", "log"), Channel(29, "esc_temp2", "degC", "log"),
    Channel(30, "esc_temp3", "degC", "log"), Channel(31, "esc_temp4", "degC", "log"),
    Channel(32, "esc_cur1", "A", "log"), Channel(33, "esc_cur2", "A", "log"), Channel(34, "esc_cur3", "A", "log"),
    Channel(35, "esc_cur4", "A", "log"),
    Channel(36, "vib_ap", "m/s^2", "log"),
    Channel(37, "airborne", "-", "stream"),  # 0/1, the last channel of a stream with a hover estimate
)
CHANNEL_IDS = {c.name: c.id for c in CHANNELS}
SIM_CHANNELS = tuple((c.name, c.unit) for c in CHANNELS if c.kind == "sim")
EXTRA_CHANNELS = tuple((c.name, c.unit) for c in CHANNELS if c.kind == "log")
ALL_CHANNELS = SIM_CHANNELS + EXTRA_CHANNELS
CHANNEL_NAMES = tuple(n for n, _ in ALL_CHANNELS)  # flight.npz's columns, in order
CHANNEL_UNITS = dict(ALL_CHANNELS)
SIM_CHANNEL_NAMES = tuple(n for n, _ in SIM_CHANNELS)
SIM_CHANNEL_UNITS = tuple(u for _, u in SIM_CHANNELS)
ANGLE_CHANNELS = frozenset({"roll", "pitch", "yaw"})  # unwrapped before resampling, wrapped after
# The logging group of each channel: channels an autopilot logs from one message, at one rate
# (the simulator draws one rate per group and flight; `quadfdi ingest rates` measures them on logs).
RATE_GROUP: dict[str, str] = {
    **{c: "pos" for c in ("x", "y", "z", "vx", "vy", "vz")}, **{c: "att" for c in ("roll", "pitch", "yaw")},
    **{c: "rate" for c in ("p", "q", "r")}, **{c: "batt" for c in ("V_b", "I_b", "SoC")},
    **{f"T{k}": "esc" for k in range(1, 5)}, **{f"thr{k}": "act" for k in range(1, 5)},
    "vib_px4": "vib_px4", "vib_ap": "vib_ap",
    **{f"{g}{k}": "esc" for g in ("rpm", "esc_temp", "esc_cur") for k in range(1, 5)},
}
AIRBORNE = "airborne"  # the raw channel (0/1) that profiles with a hover estimate add last to a stream


@dataclass(frozen=True)
class ModelChannel:
    name: str
    unit: str
    raw: tuple[str, ...]  # raw channels it is computed from
    formula: str  # what docs/profiles.md shows
    fill: float  # the masked profile's value when the flight lacks the channel's group (float32-exact)
    reference: bool = False  # relative to the vehicle record (core/vehicle_record.py): a reference profile's only
    physics: bool = False  # a recursion over the flight so far (core/causal.py): a physics profile's only


# The fills: what a level, healthy hover gives. Attitude, rates, velocities 0; every share and ratio 1 (by
# definition at hover: a motor at the collective, the current at the hover current, each ESC at the four's
# mean); temperature differences 0; ``v_cell`` 3.7 V, a LiPo's nominal cell voltage and the healthy realistic
# suite's median under load (3.72 V; 5-95 % 3.52-3.98 V: percentiles of V_b / pack_cells over its healthy
# flights); vibration 5.5 m/s^2, the geometric middle of the simulator's healthy floor (2-15 m/s^2,
# log-uniform: sim.realistic_params VIB_FLOOR; the healthy suite's median 6.1 (vib_px4), 5.5 (vib_ap)).
V_CELL_FILL = 3.7  # V
VIB_FILL = 5.5  # m/s^2
_ROTORS = range(1, 5)
MODEL_CHANNELS: tuple[ModelChannel, ...] = (
    ModelChannel("roll", "rad", ("roll",), "roll", 0.0),
    ModelChannel("pitch", "rad", ("pitch",), "pitch", 0.0),
    ModelChannel("p", "rad/s", ("p",), "p", 0.0),
    ModelChannel("q", "rad/s", ("q",), "q", 0.0),
    ModelChannel("r", "rad/s", ("r",), "r", 0.0),
    ModelChannel("vx_h", "m/s", ("vx", "vy", "yaw"), "cos(yaw) vx + sin(yaw) vy", 0.0),
    ModelChannel("vy_h", "m/s", ("vx", "vy", "yaw"), "-sin(yaw) vx + cos(yaw) vy", 0.0),
    ModelChannel("vz", "m/s", ("vz",), "vz", 0.0),
    ModelChannel("v_cell", "V", ("V_b",), "V_b / cells", V_CELL_FILL),
    ModelChannel("i_rel", "-", ("I_b",), "I_b / hover current", 1.0),
    *(ModelChannel(f"m{k}_rel", "-", (f"thr{k}",), f"thr{k} / hover collective command", 1.0) for k in _ROTORS),
    ModelChannel("vib", "m/s^2", ("vib_px4",), "PX4 accel_vibration_metric", VIB_FILL),
    ModelChannel("vib_ap", "m/s^2", ("vib_ap",), "ArduPilot VIBE in-plane mean", VIB_FILL),
    *(ModelChannel(f"rpm{k}_rel", "-", ("rpm1", "rpm2", "rpm3", "rpm4"),
                   f"rpm{k} / ((((rpm1 + rpm2) + rpm3) + rpm4) * 0.25)", 1.0) for k in _ROTORS),
    *(ModelChannel(f"esc{k}_i_rel", "-", ("esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4"),
                   f"esc_cur{k} / ((((esc_cur1 + esc_cur2) + esc_cur3) + esc_cur4) * 0.25)", 1.0) for k in _ROTORS),
    *(ModelChannel(f"esc{k}_t_rel", "K", ("esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4"),
                   f"esc_temp{k} - ((((esc_temp1 + esc_temp2) + esc_temp3) + esc_temp4) * 0.25)", 0.0)
      for k in _ROTORS),
    # the reference channels (core/vehicle_record.py): each a deviation from the vehicle's own healthy flights
    *(ModelChannel(f"m{k}_ref", "-", (f"thr{k}",), f"m{k}_rel / the reference's share of motor {k} at the sample's "
                   "forward speed and yaw rate", 1.0, True) for k in _ROTORS),
    ModelChannel("vib_ref", "m/s^2", ("vib_px4",), "vib - the reference's floor at the sample's collective", 0.0, True),
    ModelChannel("vib_ap_ref", "m/s^2", ("vib_ap",), "vib_ap - the reference's floor at the sample's collective",
                 0.0, True),
    *(ModelChannel(f"rpm{k}_ref", "-", ("rpm1", "rpm2", "rpm3", "rpm4"), f"rpm{k}_rel / the reference's rpm{k} share",
                   1.0, True) for k in _ROTORS),
    # the physics channels (core/causal.py), recursions from the flight's first sample; r_cell's fill 0 is what a
    # steady current gives (no evidence of sag); the smoothed deviations keep their deviations' fills
    ModelChannel("r_cell", "ohm", ("V_b", "I_b"), "-cov(v_cell, I_b) / (var(I_b) + 0.0625), tau 4 s", 0.0, False, True),
    ModelChannel("r_cell_ref", "ohm", ("V_b", "I_b"), "r_cell - the reference's sag per A per cell", 0.0, True, True),
    *(ModelChannel(f"m{k}_ref_lp", "-", (f"thr{k}",), f"ewma(thr{k} / reference share, tau 4 s) / hover command",
                   1.0, True, True) for k in _ROTORS),
    ModelChannel("vib_ref_lp", "m/s^2", ("vib_px4",), "ewma(vib_ref, tau 4 s)", 0.0, True, True),
    ModelChannel("vib_ap_ref_lp", "m/s^2", ("vib_ap",), "ewma(vib_ap_ref, tau 4 s)", 0.0, True, True),
)


@dataclass(frozen=True)
class AvailabilityGroup:
    name: str
    raw: tuple[str, ...]  # raw channels a log has or lacks together


AVAILABILITY_GROUPS: tuple[AvailabilityGroup, ...] = (
    AvailabilityGroup("pitch", ("pitch",)),  # the Crazyflie logs no pitch
    AvailabilityGroup("rates", ("p", "q", "r")),
    AvailabilityGroup("vel_h", ("vx", "vy", "yaw")),  # no position fix, or no yaw: no heading-frame velocity
    AvailabilityGroup("battery", ("V_b",)),  # a disconnected battery monitor (or no cell count)
    AvailabilityGroup("current", ("I_b",)),  # absent or uncalibrated
    AvailabilityGroup("vib_px4", ("vib_px4",)),
    AvailabilityGroup("vib_ap", ("vib_ap",)),
    AvailabilityGroup("esc_rpm", ("rpm1", "rpm2", "rpm3", "rpm4")),
    AvailabilityGroup("esc_cur", ("esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4")),
    AvailabilityGroup("esc_temp", ("esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4")),
)
GROUP_NAMES = tuple(g.name for g in AVAILABILITY_GROUPS)
GROUP_OF_RAW = {r: g.name for g in AVAILABILITY_GROUPS for r in g.raw}
# Never masked: what the model needs (attitude, climb rate, the four commands) and what the hover
# estimate (core.hover: vz, roll, thr1..4) and the airborne rule need; a flight without one is refused.
MINIMUM_RAW = ("roll", "vz", "thr1", "thr2", "thr3", "thr4")
AVAIL_PREFIX = "avail_"
# A reference profile's pseudo-group: the vehicle record (core/vehicle_record.py) is there or not, per flight;
# it has no raw channel (the record is loaded beside the stream, not logged in it).
REFERENCE_GROUP = "reference"
# Training drops the record from this share of the windows (train/masks.py), on top of the drawn mask
# pattern, so that one model decides with and without a reference.
NO_REFERENCE_PROBABILITY = 0.3


@dataclass(frozen=True)
class MaskPattern:
    name: str
    groups: tuple[str, ...]  # the groups a log of this kind lacks
    seen: str  # which logs show it


_ESC = ("esc_rpm", "esc_cur", "esc_temp")
MASK_PATTERNS: tuple[MaskPattern, ...] = (
    MaskPattern("all", (), "the realistic suite as simulated (every channel)"),
    MaskPattern("no_current", ("current",), "an absent or uncalibrated current sensor (the GPS-interference flight)"),
    MaskPattern("no_esc", _ESC, "no ESC telemetry (most PX4 and ArduPilot logs)"),
    MaskPattern("no_position_fix", ("vel_h",), "no GPS or external position: no horizontal velocity"),
    MaskPattern("no_rates", ("rates",), "no body rates logged"),
    MaskPattern("no_pitch", ("pitch",), "no pitch logged"),
    MaskPattern("no_yaw", ("vel_h",), "no yaw logged (six CrazyPAD E8 logs): no heading-frame velocity"),
    MaskPattern("px4_vibration_only", ("vib_ap",), "every PX4 log"),
    MaskPattern("ardupilot_vibration_only", ("vib_px4",), "every ArduPilot log"),
    MaskPattern("no_vibration", ("vib_px4", "vib_ap"), "an autopilot logging neither metric"),
    MaskPattern("crazyflie", ("pitch", "rates", "current", "vib_px4", "vib_ap") + _ESC,
                "the CrazyPAD Crazyflie logs"),
    MaskPattern("no_battery_monitor", ("battery", "current"),
                "a disconnected battery monitor (the battery-monitor-disconnected flight)"),
)
PATTERN_BY_NAME = {p.name: p for p in MASK_PATTERNS}
# Training draws "all" with this probability and another pattern uniformly otherwise (train/masks.py):
# a quarter of the windows keep every channel, so the full-channel decision stays as good as possible.
ALL_CHANNELS_PROBABILITY = 0.25


@dataclass(frozen=True)
class Profile:
    id: int  # weights.bin's on-board record dims[0]; fwref::Profile
    name: str
    raw: tuple[str, ...] | None  # the channels a vehicle must log, in stream order (None: the dataset's own)
    vibration: str | None  # which vibration quantity its ``vib`` is ("any": both, each its own channel)
    masked: bool = False  # takes whatever channels a log has: groups may be absent (AVAILABILITY_GROUPS)
    reference: bool = False  # also reads the vehicle record (core/vehicle_record.py); masked profiles only
    physics: bool = False  # also the causal physics channels (core/causal.py); reference profiles only

    @property
    def model(self) -> tuple[ModelChannel, ...] | None:
        """Every model channel whose raw channels the profile has (None: ``paper``, the identity; the
        reference channels only for a reference profile); a masked profile then one availability channel
        per group, and a reference profile ``avail_reference`` last."""
        if self.raw is None:
            return None
        derived = tuple(c for c in MODEL_CHANNELS if set(c.raw) <= set(self.raw)
                        and (self.reference or not c.reference) and (self.physics or not c.physics))
        tail = (REFERENCE_AVAILABILITY,) if self.reference else ()
        return derived + (AVAILABILITY_CHANNELS if self.masked else ()) + tail


AVAILABILITY_CHANNELS = tuple(ModelChannel(AVAIL_PREFIX + g, "-", (), f"1 if the flight has {', '.join(r)}, else 0",
                                           1.0) for g, r in ((g.name, g.raw) for g in AVAILABILITY_GROUPS))
REFERENCE_AVAILABILITY = ModelChannel(AVAIL_PREFIX + REFERENCE_GROUP, "-", (),
                                      "1 if the vehicle record is loaded, else 0", 1.0)


def groups_of_model(c: ModelChannel) -> tuple[str, ...]:
    """The availability groups a model channel needs, in group order (``r_cell``: battery and current)."""
    return tuple(g for g in GROUP_NAMES if g in {GROUP_OF_RAW.get(r) for r in c.raw})


def group_of_model(c: ModelChannel) -> str | None:
    """A model channel's first availability group (None: the minimum, or an availability channel)."""
    return next(iter(groups_of_model(c)), None)


_MIN_RAW = ("roll", "pitch", "p", "q", "r", "vx", "vy", "yaw", "vz", "V_b", "I_b", "thr1", "thr2", "thr3", "thr4",
            "vib_px4")
ESC_RAW = ("rpm1", "rpm2", "rpm3", "rpm4", "esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4",
           "esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4")  # sim.esc_telemetry's
PROFILE_TABLE: tuple[Profile, ...] = (
    Profile(0, "paper", None, None),
    Profile(1, "flightlog-min", _MIN_RAW, "px4"),
    Profile(2, "flightlog-nocur", tuple(c for c in _MIN_RAW if c != "I_b"), "px4"),  # no (usable) current sensor
    Profile(3, "flightlog-esc", _MIN_RAW + ESC_RAW, "px4"),
    # every raw channel a group or the minimum names, in the order fwref/profile.hpp reads
    Profile(4, "flightlog-mask", _MIN_RAW + ESC_RAW + ("vib_ap",), "any", masked=True),
    # flightlog-mask's channels, the reference ones (deviations from the vehicle record), the physics ones (causal.py)
    Profile(5, "flightlog-ref", _MIN_RAW + ESC_RAW + ("vib_ap",), "any", masked=True, reference=True),
    Profile(6, "flightlog-phys", _MIN_RAW + ESC_RAW + ("vib_ap",), "any", masked=True, reference=True, physics=True),
)
PROFILE_BY_NAME = {p.name: p for p in PROFILE_TABLE}
PROFILE_NAMES = tuple(p.name for p in PROFILE_TABLE)  # in id order


def stream_raw(profile: Profile) -> tuple[str, ...]:
    """A hover profile's stream channels: its raw channels, then ``airborne``."""
    return tuple(profile.raw or ()) + (AIRBORNE,)


# In firmware_ref's sources, found as package data (a checkout: the tracked firmware_ref/include/fwref/).
HEADER_PATH = firmware_sources() / "include" / "fwref" / "channels_gen.hpp"
# The raw columns fwref/profile.hpp reads by position in every hover profile's stream (profile_prep).
CPP_FIXED_PREFIX = ("roll", "pitch", "p", "q", "r", "vx", "vy", "yaw", "vz", "V_b")


def _cpp_names(names) -> str:
    return "{" + ", ".join(f'"{n}"' for n in names) + "}"


def _cpp_spec(p: Profile) -> str:
    """One fwref::ProfileSpec initializer; the columns fwref/profile.hpp reads by name (-1: absent)."""
    if p.raw is None:
        return f'    {{"{p.name}", 0, 0, nullptr, nullptr, -1, -1, -1, -1, 0, nullptr, nullptr, nullptr, ' + \
            "-1, -1, -1, -1},"
    raw = stream_raw(p)
    if raw[:len(CPP_FIXED_PREFIX)] != CPP_FIXED_PREFIX or raw[raw.index("thr1"):raw.index("thr1") + 5] != \
            ("thr1", "thr2", "thr3", "thr4", "vib_px4") or ("rpm1" in raw and raw[raw.index("rpm1"):][:12] != ESC_RAW):
        raise ValueError(f"profile {p.name}: fwref/profile.hpp reads {CPP_FIXED_PREFIX}, thr1..4 vib_px4 and the "
                         f"ESC block by position; its raw channels {raw} are not in that order")
    tag = _camel(p.name)
    col = {n: raw.index(n) if n in raw else -1 for n in ("I_b", "thr1", "rpm1", "vib_ap")}
    head = (f'    {{"{p.name}", {len(raw)}, {len(p.model)}, k{tag}Raw, k{tag}Model, {col["I_b"]}, {col["thr1"]}, '
            f'{col["rpm1"]}, {col["vib_ap"]}, ')
    if not p.masked:
        return head + "0, nullptr, nullptr, nullptr, -1, -1, -1, -1},"
    names = [c.name for c in p.model]
    ref = (names.index("m1_ref"), names.index(REFERENCE_AVAILABILITY.name)) if p.reference else (-1, -1)
    phys = names.index("r_cell") if p.physics else -1
    for at, kind, block in ((ref[0], "reference", [c.name for c in MODEL_CHANNELS if c.reference and not c.physics]),
                            (phys, "physics", [c.name for c in MODEL_CHANNELS if c.physics])):
        if at >= 0 and names[at:at + len(block)] != block:
            raise ValueError(f"profile {p.name}: fwref/profile.hpp reads the {kind} channels in table order")
    return head + (f"{len(AVAILABILITY_GROUPS)}, k{tag}RawGroup, k{tag}ModelGroups, k{tag}Fill, "
                   f"{p.model.index(AVAILABILITY_CHANNELS[0])}, {ref[0]}, {ref[1]}, {phys}}},")


def _mask_tables(p: Profile) -> str:
    """A masked profile's per-column group indices and fills (fwref::ProfileSpec raw_group, model_groups, fill)."""
    raw = stream_raw(p)
    outside = [r for r in raw if r not in GROUP_OF_RAW and r not in MINIMUM_RAW + (AIRBORNE,)]
    if outside:
        raise ValueError(f"profile {p.name}: raw channels {outside} are in no availability group nor the minimum")
    index = {g: i for i, g in enumerate(GROUP_NAMES)}
    raw_group = [index.get(GROUP_OF_RAW.get(r), -1) for r in raw]
    model_groups = [sum(1 << index[g] for g in groups_of_model(c)) for c in p.model]
    tag = _camel(p.name)
    return (f"constexpr signed char k{tag}RawGroup[] = {{{', '.join(map(str, raw_group))}}};\n"
            f"constexpr unsigned short k{tag}ModelGroups[] = {{{', '.join(map(str, model_groups))}}};\n"
            f"constexpr float k{tag}Fill[] = {{{', '.join(f'{c.fill!r}f' for c in p.model)}}};")


def _camel(name: str) -> str:
    return "".join(part[:1].upper() + part[1:] for part in name.replace("-", "_").split("_"))


def profile_enum(name: str) -> str:
    """The fwref::Profile enumerator of profile ``name`` (``flightlog-min`` -> ``kFlightlogMin``)."""
    return "k" + _camel(PROFILE_BY_NAME[name].name)


def cpp_header() -> str:
    """The text of fwref/channels_gen.hpp."""
    ids = "\n".join(f"constexpr int kChannel{_camel(c.name)} = {c.id};  // {c.unit}, {c.kind}" for c in CHANNELS)
    enum = ", ".join(f"{profile_enum(p.name)} = {p.id}" for p in PROFILE_TABLE)
    lists = "\n".join(f"constexpr const char* k{_camel(p.name)}Raw[] = {_cpp_names(stream_raw(p))};\n"
                      f"constexpr const char* k{_camel(p.name)}Model[] = {_cpp_names(c.name for c in p.model)};"
                      for p in PROFILE_TABLE if p.raw is not None)
    lists += "".join("\n" + _mask_tables(p) for p in PROFILE_TABLE if p.masked)
    group_ids = "\n".join(f"constexpr int kGroup{_camel(g)} = {i};" for i, g in enumerate(GROUP_NAMES))
    specs = "\n".join(_cpp_spec(p) for p in PROFILE_TABLE)
    return f"""// GENERATED by `python -m quadfdi.core.channels --header` from core/channels.py; do not edit.
// The channel table (stable ids) and the channel profiles over it, as fwref/profile.hpp computes them.
#pragma once

namespace fwref {{

// Raw channel ids (core/channels.py CHANNELS): never renumbered, never reused.
constexpr int kChannelCount = {len(CHANNELS)};
constexpr const char* kChannelNames[kChannelCount] = {_cpp_names(c.name for c in CHANNELS)};
{ids}

// The profiles, by the id weights.bin's on-board record stores (dims[0]).
enum class Profile : int {{ {enum} }};
constexpr int kProfileCount = {len(PROFILE_TABLE)};

struct ProfileSpec {{
  const char* name;
  int raw;          // stream channels (0: paper, the model's own)
  int channels;     // model channels (0: paper)
  const char* const* raw_names;
  const char* const* model_names;
  int i_b;          // raw column of the current (-1: none)
  int thr;          // raw column of thr1 (thr1..thr4, then vib_px4 follow)
  int rpm;          // raw column of rpm1 (rpm1..4, then esc_cur1..4, then esc_temp1..4 follow; -1: none)
  int vib_ap;       // raw column of vib_ap (-1: none)
  int groups;       // availability groups a flight may lack (0: a profile without a mask)
  const signed char* raw_group;    // (raw) each stream column's group; -1: never absent (the minimum, airborne)
  const unsigned short* model_groups;  // (channels) bit g: needs group g (0: the minimum, an availability channel)
  const float* fill;               // (channels) a model channel's value when the flight lacks its group
  int avail;        // model column of the first availability channel (one per group, in group order; -1: none)
  int ref;          // model column of m1_ref (m1..4_ref vib_ref vib_ap_ref rpm1..4_ref follow; -1: no vehicle record)
  int avail_ref;    // model column of avail_reference (-1: none)
  int phys;         // model column of r_cell (r_cell_ref m1..4_ref_lp vib_ref_lp vib_ap_ref_lp follow; -1: none)
}};

// The availability groups (core/channels.py AVAILABILITY_GROUPS): bit g of an availability mask.
constexpr int kGroupCount = {len(AVAILABILITY_GROUPS)};
constexpr const char* kGroupNames[kGroupCount] = {_cpp_names(GROUP_NAMES)};
{group_ids}

namespace profile_tables {{
// Stream channels (the profile's raw channels, then airborne) and model channels of each hover profile.
{lists}
constexpr ProfileSpec kSpecs[kProfileCount] = {{
{specs}
}};
}}  // namespace profile_tables

}}  // namespace fwref
"""


if __name__ == "__main__":
    from quadfdi.core.contracts import header_cli

    sys.exit(header_cli(sys.argv[1:], HEADER_PATH, cpp_header, "quadfdi.core.channels"))
