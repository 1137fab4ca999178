"""Dataset flights -> a channel profile's inputs (core.profiles), for train, export and parity.

``profiled_dataset(ds, profile)`` returns the dataset with its ``telemetry`` replaced by the
profile's channels (same flights, samples, labels, splits), so windows, normalisation, calibration
and reference windows are made the same way. ``paper`` returns ``ds`` itself (nothing changes).

For a profile with a hover estimate (core.hover) the per-flight estimate is stored beside it:
``hover_cmd``, ``hover_cur`` (float32) and ``hover_freeze`` (sample index; the estimate is applied to
every sample of the flight once frozen; a flight that never freezes gets ``hover_freeze`` = its
length and the whole-flight means). A window whose last sample is before ``hover_freeze`` has
no decision on a real vehicle (detect gives none): ``decided`` tells them, and training and
validation drop them (train.data). The test metrics and prediction sets keep every window (the
evaluation's window grid); the windows before the freeze there use the estimate from later in the
flight (docs/profiles.md says so).

The masked profile (``flightlog-mask``): every flight gets the channels of one mask pattern
(core.profiles.flight_pattern of its ``traj_index``: the patterns in turn), its lacking groups at
their fills, an absent pitch entering the hover estimate as 0 (core.hover); ``mask_pattern`` (F,)
stores each flight's pattern index (core/channels.py MASK_PATTERNS). That is the dataset export
calibrates and verifies on and parity replays. ``patterns=False`` gives every flight every channel
(``mask_pattern`` 0, "all"): training draws its own pattern per window (train/masks.py).

A reference profile (``flightlog-ref``) also reads each flight's vehicle record (core/vehicle_record.py):
``records`` (F, 24) float32, a NaN row for a flight without one (train/vehicle_ref.py learns them from
each fleet vehicle's own reference flights); stored as ``vehicle_record``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core import causal
from quadfdi.core.channels import MASK_PATTERNS, PROFILE_BY_NAME
from quadfdi.core.hover import INPUTS as HOVER_INPUTS, collective, estimate_many
from quadfdi.core import vehicle_record as vr
from quadfdi.core.profiles import (apply_profile, channel_names, channel_units, flight_pattern, has_reference,
                                   is_masked, pattern_available, required_raw, uses_hover)
from quadfdi.formats.dataset import Dataset

PROFILE_KEY = "profile"  # the checkpoint's key (train.run) and the manifest's (export.manifest)


def profile_of(blob_or_manifest: dict) -> str:
    """The profile of a checkpoint blob (a name) or a manifest (``export.manifest.profile_entry``: a
    dict with ``name``): ``paper`` when it predates profiles."""
    value = blob_or_manifest.get(PROFILE_KEY) or "paper"
    return str(value["name"] if isinstance(value, dict) else value)


def flight_patterns(ds: Dataset, patterns: bool = True) -> np.ndarray:
    """(F,) int: each flight's mask pattern index (0, "all", for every flight when ``patterns`` is False)."""
    index = np.asarray(ds["traj_index"], np.int64)
    if not patterns:
        return np.zeros(len(index), np.int64)
    return np.array([MASK_PATTERNS.index(flight_pattern(i)) for i in index], np.int64)


def _availability(pattern: np.ndarray) -> dict[str, np.ndarray]:
    """group -> (F,) bool of flights with pattern indices ``pattern``."""
    per = [pattern_available(MASK_PATTERNS[i]) for i in pattern]
    return {g: np.array([a[g] for a in per], bool) for g in (per[0] if per else {})}


def profiled_dataset(ds: Dataset, profile: str, patterns: bool = True, records: np.ndarray | None = None) -> Dataset:
    """The dataset with the profile's inputs as ``telemetry`` (module docstring); ``patterns``: a
    masked profile's flights each with their pattern's channels (False: every channel); ``records``:
    a reference profile's vehicle records per flight (None: no flight has one)."""
    if not uses_hover(profile):
        return ds
    names, tel = ds.channel_names, ds["telemetry"]
    if "esc_telemetry" in ds.arrays and not set(required_raw(profile, names)) <= set(names):
        # the realistic suite's ESC channels (sim.esc_telemetry) are a key of their own, so that every
        # earlier array (and a paper-profile model's inputs) stays as it was
        names = names + [str(n) for n in ds["esc_channel_names"]]
        tel = np.concatenate([tel, ds["esc_telemetry"]], axis=2)
    missing = [r for r in required_raw(profile, names) if r not in names]
    if missing:
        raise QuadfdiError(f"profile {profile!r} needs raw channels {', '.join(missing)}, absent from {ds.path}")
    if "pack_cells" not in ds.arrays:
        raise QuadfdiError(f"profile {profile!r} needs each flight's cell count (pack_cells), absent from {ds.path}")
    if PROFILE_BY_NAME[profile].physics and abs(ds.config.sim.sample_dt_s - causal.SAMPLE_DT_S) > 1e-9:
        raise QuadfdiError(f"profile {profile!r}: its recursions step every {causal.SAMPLE_DT_S} s (core/causal.py); "
                           f"{ds.path} is sampled every {ds.config.sim.sample_dt_s} s")
    hover_cols = tel[:, :, [names.index(c) for c in HOVER_INPUTS]]  # the dataset has I_b
    masked = is_masked(profile)
    pattern = flight_patterns(ds, patterns) if masked else None
    available = _availability(pattern) if masked else None
    if masked and not available["pitch"].all():  # a log without pitch: level in the steady test (core.hover)
        hover_cols = hover_cols.copy()
        hover_cols[~available["pitch"], :, HOVER_INPUTS.index("pitch")] = 0.0
    cmd, cur, freeze = estimate_many(hover_cols)
    never = freeze < 0  # no decided window at all; their (evaluation-only) inputs use the whole-flight mean
    if never.any():
        hv = hover_cols[never]
        cmd[never] = collective(hv[:, :, 3:7]).mean(axis=1)
        cur[never] = hv[:, :, 7].mean(axis=1)
        freeze[never] = tel.shape[1]
    raw = {r: tel[:, :, names.index(r)] for r in required_raw(profile, names)}
    if has_reference(profile):
        n = len(tel)
        records = np.full((n, vr.SIZE), np.nan, np.float32) if records is None else np.asarray(records, np.float32)
        if records.shape != (n, vr.SIZE):
            raise ValueError(f"vehicle records must be ({n}, {vr.SIZE}), found {records.shape}")
    x = apply_profile(profile, raw, ds["pack_cells"], cmd, cur, available, records if has_reference(profile) else None)
    arrays = dict(ds.arrays)
    arrays.update(telemetry=x, channel_names=np.array(channel_names(profile, names)),
                  channel_units=np.array(channel_units(profile, [str(u) for u in ds["channel_units"]])),
                  hover_cmd=cmd, hover_cur=cur, hover_freeze=freeze)
    if masked:
        arrays["mask_pattern"] = pattern
    if has_reference(profile):
        arrays["vehicle_record"] = records
    return dataclasses.replace(ds, arrays=arrays)


def decided(ds: Dataset, traj: np.ndarray, start: np.ndarray) -> np.ndarray:
    """(n,) bool: the window (traj, start) ends at or after its flight's hover freeze (always True
    without a hover estimate)."""
    if "hover_freeze" not in ds.arrays:
        return np.ones(len(traj), bool)
    last = np.asarray(start) + ds.config.sim.window - 1
    return last >= ds["hover_freeze"][np.asarray(traj)]
