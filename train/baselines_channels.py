"""The channels the baselines read: the simulator's telemetry, or what a real log carries.

A run whose networks read a flight-log profile (``core.profiles.uses_hover``: the ``flightlog-*``
profiles) is meant for real vehicles, and its networks never see the motor windings' temperatures
``T1..T4``: no autopilot logs them, only the simulator models them. Its baselines then read the ESC
board temperatures ``esc_temp1..4`` in their place (the dataset's ``esc_telemetry``, sim/esc_thermal.py:
what a log with ESC telemetry carries, and what those profiles' ``esc{k}_t_rel`` read), so that no
baseline wins on a quantity the networks cannot have. The two differ where it matters: over
its last 2 s an overheating motor's winding is 25.25 K above the four's mean on the fleet suite's seed-0
overheat flights, its ESC -0.08 K (sim/esc_thermal.py: an ESC heats with the current it carries, not with
its motor; docs/training.md, "Baselines with the networks' tuning budget").

A dataset without ESC telemetry (the paper suite) keeps its channels: there is nothing to read in
their place, and its runs' networks read ``T1..T4`` too.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from quadfdi.formats.dataset import Dataset

WINDINGS = tuple(f"T{k}" for k in range(1, 5))
ESCS = tuple(f"esc_temp{k}" for k in range(1, 5))


def logged_view(ds: Dataset) -> tuple[Dataset, str]:
    """(the dataset with ``T1..T4`` replaced column for column by ``esc_temp1..4``, "esc_temp"), or (``ds``
    unchanged, "T") when it has no ESC temperatures or no winding temperatures to replace."""
    names = ds.channel_names
    esc = [str(n) for n in ds.arrays.get("esc_channel_names", [])]
    if not all(t in names for t in WINDINGS) or not all(e in esc for e in ESCS):
        return ds, "T"
    tel = np.array(ds.arrays["telemetry"], copy=True)
    for t, e in zip(WINDINGS, ESCS):
        tel[:, :, names.index(t)] = ds.arrays["esc_telemetry"][:, :, esc.index(e)]
    arrays = dict(ds.arrays, telemetry=tel,
                  channel_names=np.array([ESCS[WINDINGS.index(n)] if n in WINDINGS else n for n in names]))
    return dataclasses.replace(ds, arrays=arrays), "esc_temp"
