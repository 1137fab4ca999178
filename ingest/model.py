"""What a log reader returns: each channel at its logged times, and the log's facts.

The channels and their units are the table of ``quadfdi.core.channels``. A channel the log lacks is
kept, fully masked, with the reason in its status.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadfdi.core.channels import CHANNEL_UNITS


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
    # The airborne intervals end at a land detector's "landed", which lags touchdown (segments.cut_landings
    # cuts it back); False where they come from a rule that ends at touchdown itself.
    landing_lag: bool = True

    def note(self, text: str) -> None:
        self.notes.append(text)
