"""The channel table: every channel quadfdi knows, with its unit and a stable id, written once; and
the channel profiles as named lists over it.

Three tables, each the one place of its contract (the C++ gets them from the generated header
``firmware_ref/include/fwref/channels_gen.hpp``: ``python -m quadfdi.core.channels --header``; a test
checks that the committed header is what this module generates):

- ``CHANNELS``: the raw channels, each with an id that never changes and is never reused (a channel
  added later takes the next free id; a profile, an availability mask and the C++ name a channel by
  it). The simulator's 23 telemetry channels come first, in the order of the paper's dataset (so a
  model trained on the simulator reads the same columns as one reading an ingested flight), then the
  channels only richer logs (and the realistic suite) carry: together flight.npz's columns, in id
  order. Each autopilot's vibration metric is its own channel, as the simulator computes it from its
  accelerometer: ``vib_px4`` is PX4's ``accel_vibration_metric`` (m/s^2), ``vib_ap`` ArduPilot's
  VIBE as the in-plane mean (VibeX + VibeY) / 2 (the simulator has no vertical vibration model, so
  VibeZ is not used). Last ``airborne`` (0/1), which only a stream carries.
- ``MODEL_CHANNELS``: what a profile gives a model, each computed from named raw channels with the
  formula docs/profiles.md shows (core/profiles.py computes them; fwref/profile.hpp in float32).
- ``PROFILE_TABLE``: each profile as the raw channels a vehicle must log for it (in the order a
  stream delivers them), with the id weights.bin's on-board record stores. Its model channels are
  derived: every model channel whose raw channels the profile has, in ``MODEL_CHANNELS`` order. So a
  profile is a set of available channels, and an availability mask over ``CHANNELS`` would be one
  too. ``paper`` (id 0) is the identity over the dataset's own channels.

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


_ROTORS = range(1, 5)
MODEL_CHANNELS: tuple[ModelChannel, ...] = (
    ModelChannel("roll", "rad", ("roll",), "roll"),
    ModelChannel("pitch", "rad", ("pitch",), "pitch"),
    ModelChannel("p", "rad/s", ("p",), "p"),
    ModelChannel("q", "rad/s", ("q",), "q"),
    ModelChannel("r", "rad/s", ("r",), "r"),
    ModelChannel("vx_h", "m/s", ("vx", "vy", "yaw"), "cos(yaw) vx + sin(yaw) vy"),
    ModelChannel("vy_h", "m/s", ("vx", "vy", "yaw"), "-sin(yaw) vx + cos(yaw) vy"),
    ModelChannel("vz", "m/s", ("vz",), "vz"),
    ModelChannel("v_cell", "V", ("V_b",), "V_b / cells"),
    ModelChannel("i_rel", "-", ("I_b",), "I_b / hover current"),
    *(ModelChannel(f"m{k}_rel", "-", (f"thr{k}",), f"thr{k} / hover collective command") for k in _ROTORS),
    ModelChannel("vib", "m/s^2", ("vib_px4",), "PX4 accel_vibration_metric"),
    *(ModelChannel(f"rpm{k}_rel", "-", ("rpm1", "rpm2", "rpm3", "rpm4"),
                   f"rpm{k} / ((((rpm1 + rpm2) + rpm3) + rpm4) * 0.25)") for k in _ROTORS),
    *(ModelChannel(f"esc{k}_i_rel", "-", ("esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4"),
                   f"esc_cur{k} / ((((esc_cur1 + esc_cur2) + esc_cur3) + esc_cur4) * 0.25)") for k in _ROTORS),
    *(ModelChannel(f"esc{k}_t_rel", "K", ("esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4"),
                   f"esc_temp{k} - ((((esc_temp1 + esc_temp2) + esc_temp3) + esc_temp4) * 0.25)") for k in _ROTORS),
)


@dataclass(frozen=True)
class Profile:
    id: int  # weights.bin's on-board record dims[0]; fwref::Profile
    name: str
    raw: tuple[str, ...] | None  # the channels a vehicle must log, in stream order (None: the dataset's own)
    vibration: str | None  # which vibration quantity its ``vib`` is

    @property
    def model(self) -> tuple[ModelChannel, ...] | None:
        """Every model channel whose raw channels the profile has (None: ``paper``, the identity)."""
        if self.raw is None:
            return None
        return tuple(c for c in MODEL_CHANNELS if set(c.raw) <= set(self.raw))


_MIN_RAW = ("roll", "pitch", "p", "q", "r", "vx", "vy", "yaw", "vz", "V_b", "I_b", "thr1", "thr2", "thr3", "thr4",
            "vib_px4")
ESC_RAW = ("rpm1", "rpm2", "rpm3", "rpm4", "esc_cur1", "esc_cur2", "esc_cur3", "esc_cur4",
           "esc_temp1", "esc_temp2", "esc_temp3", "esc_temp4")  # sim.esc_telemetry's
PROFILE_TABLE: tuple[Profile, ...] = (
    Profile(0, "paper", None, None),
    Profile(1, "flightlog-min", _MIN_RAW, "px4"),
    Profile(2, "flightlog-nocur", tuple(c for c in _MIN_RAW if c != "I_b"), "px4"),  # no (usable) current sensor
    Profile(3, "flightlog-esc", _MIN_RAW + ESC_RAW, "px4"),
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
        return f'    {{"{p.name}", 0, 0, nullptr, nullptr, -1, -1, -1}},'
    raw = stream_raw(p)
    if raw[:len(CPP_FIXED_PREFIX)] != CPP_FIXED_PREFIX or raw[raw.index("thr1"):raw.index("thr1") + 5] != \
            ("thr1", "thr2", "thr3", "thr4", "vib_px4") or ("rpm1" in raw and raw[raw.index("rpm1"):][:12] != ESC_RAW):
        raise ValueError(f"profile {p.name}: fwref/profile.hpp reads {CPP_FIXED_PREFIX}, thr1..4 vib_px4 and the "
                         f"ESC block by position; its raw channels {raw} are not in that order")
    tag = _camel(p.name)
    col = {n: raw.index(n) if n in raw else -1 for n in ("I_b", "thr1", "rpm1")}
    return (f'    {{"{p.name}", {len(raw)}, {len(p.model)}, k{tag}Raw, k{tag}Model, {col["I_b"]}, {col["thr1"]}, '
            f'{col["rpm1"]}}},')


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
}};

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
