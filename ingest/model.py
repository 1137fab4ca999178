"""The channel table of an ingested flight and the result of reading one log.

Channel order: the simulator's 23 telemetry channels first, in ``sim.sensors.CHANNEL_NAMES`` order
and units (so a model trained on the simulator reads the same columns), then the extras only real
logs have. A channel the log lacks is kept, fully masked, with the reason in its status.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SIM_CHANNELS: tuple[tuple[str, str], ...] = (
    ("x", "m"), ("y", "m"), ("z", "m"), ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"),
    ("roll", "rad"), ("pitch", "rad"), ("yaw", "rad"), ("p", "rad/s"), ("q", "rad/s"), ("r", "rad/s"),
    ("V_b", "V"), ("I_b", "A"), ("SoC", "-"), ("T1", "degC"), ("T2", "degC"), ("T3", "degC"), ("T4", "degC"),
    ("thr1", "-"), ("thr2", "-"), ("thr3", "-"), ("thr4", "-"),
)
EXTRA_CHANNELS: tuple[tuple[str, str], ...] = (
    ("vib_acc", "m/s^2"), ("rpm1", "rpm"), ("rpm2", "rpm"), ("rpm3", "rpm"), ("rpm4", "rpm"),
    ("esc_temp1", "degC"), ("esc_temp2", "degC"), ("esc_temp3", "degC"), ("esc_temp4", "degC"),
    ("esc_cur1", "A"), ("esc_cur2", "A"), ("esc_cur3", "A"), ("esc_cur4", "A"),
)
ALL_CHANNELS = SIM_CHANNELS + EXTRA_CHANNELS
CHANNEL_NAMES = tuple(n for n, _ in ALL_CHANNELS)
CHANNEL_UNITS = dict(ALL_CHANNELS)
ANGLE_CHANNELS = frozenset({"roll", "pitch", "yaw"})  # unwrapped before resampling, wrapped after


@dataclass
class Channel:
    """One channel at its logged times: ``t`` in s from the log start, ``v`` in project units
    (NaN where the log marks the sample invalid)."""

    name: str
    t: np.ndarray
    v: np.ndarray
    source: str  # "topic[instance].field" or "MSG.Field", with the conversion applied

    @property
    def unit(self) -> str:
        return CHANNEL_UNITS[self.name]

    @property
    def rate_hz(self) -> float:
        """Mean logged rate: samples per second over the channel's own span (what a reader of
        the log would count; gaps lower it, see ``resample`` for how gaps are masked)."""
        if len(self.t) < 2 or self.t[-1] <= self.t[0]:
            return 0.0
        return float((len(self.t) - 1) / (self.t[-1] - self.t[0]))


@dataclass
class LogRead:
    """Everything a reader extracts from one log, before resampling."""

    autopilot: str  # "px4" or "ardupilot"
    channels: dict[str, Channel]
    status: dict[str, str]  # channel -> why it is absent or unusable (channels not listed are "ok")
    vehicle: dict  # frame, motor map, cell count, PWM range, where each came from
    armed: list[tuple[float, float]]
    airborne: list[tuple[float, float]]
    airborne_source: str
    data_span: tuple[float, float]  # first and last sample time of the data topics (not the header)
    notes: list[str] = field(default_factory=list)  # traps met: dropped samples, ignored publishers

    def note(self, text: str) -> None:
        self.notes.append(text)
