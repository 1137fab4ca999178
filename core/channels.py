"""The channel table: every telemetry channel quadfdi knows, with its unit, written once.

The simulator's 23 telemetry channels come first, in the order of the paper's dataset (so a model
trained on the simulator reads the same columns as one reading an ingested flight), then the
channels only richer logs (and the realistic suite) carry. Each autopilot's vibration metric is its
own channel, as the simulator computes it from its accelerometer: ``vib_px4`` is PX4's
``accel_vibration_metric`` (m/s^2), ``vib_ap`` ArduPilot's VIBE as the in-plane mean
(VibeX + VibeY) / 2 (the simulator has no vertical vibration model, so VibeZ is not used). Everything that names a channel — the
simulator's sensors, ``flight.npz``, channel profiles, the stream files and the generated C++
header — takes names and units from here.
"""

from __future__ import annotations

SIM_CHANNELS: tuple[tuple[str, str], ...] = (
    ("x", "m"), ("y", "m"), ("z", "m"), ("vx", "m/s"), ("vy", "m/s"), ("vz", "m/s"),
    ("roll", "rad"), ("pitch", "rad"), ("yaw", "rad"), ("p", "rad/s"), ("q", "rad/s"), ("r", "rad/s"),
    ("V_b", "V"), ("I_b", "A"), ("SoC", "-"), ("T1", "degC"), ("T2", "degC"), ("T3", "degC"), ("T4", "degC"),
    ("thr1", "-"), ("thr2", "-"), ("thr3", "-"), ("thr4", "-"),
)
EXTRA_CHANNELS: tuple[tuple[str, str], ...] = (
    ("vib_px4", "m/s^2"), ("vib_ap", "m/s^2"), ("rpm1", "rpm"), ("rpm2", "rpm"), ("rpm3", "rpm"), ("rpm4", "rpm"),
    ("esc_temp1", "degC"), ("esc_temp2", "degC"), ("esc_temp3", "degC"), ("esc_temp4", "degC"),
    ("esc_cur1", "A"), ("esc_cur2", "A"), ("esc_cur3", "A"), ("esc_cur4", "A"),
)
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
