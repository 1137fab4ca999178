"""weights.bin's on-board record (issue 16): the section a streaming runtime reads besides the
weights: the channel profile (its id, the raw channels the stream delivers in their order, the
model's channels), the window, stride and sample period, the hover filter's constants, where the
cell count comes from, and the alarm policy (core.alarm). Layout: export/weights_layout.py
(``ONBOARD_*``); the C++ reader: firmware_ref/include/fwref/onboard.hpp; docs/formats.md.

Written by ``quadfdi export`` from the manifest's ``profile`` and ``alarm``; weights.bin files written
before it lack it (``read_onboard`` then returns None).
"""

from __future__ import annotations

import struct

import numpy as np

from core import hover
from core.errors import QuadfdiError
from core.profiles import required_raw, uses_hover
from export.binfmt import Section
from export.weights_layout import (
    ONBOARD_DIMS,
    ONBOARD_PROFILES,
    ONBOARD_TENSORS,
    STREAM_AIRBORNE,
)

KIND = ("none", "none")  # (model, precision) of the section


def stream_channels(profile: str, model_channels: list[str]) -> list[str]:
    """The raw channels a stream delivers, in sample order: ``paper`` the model's own channels; a
    profile with a hover estimate the raw channels it reads (core.profiles.required_raw, first-use
    order) and ``airborne`` (0/1) last."""
    if not uses_hover(profile):
        return list(model_channels)
    return required_raw(profile) + [STREAM_AIRBORNE]


def _text(names: list[str]) -> np.ndarray:
    data = b"".join(n.encode("ascii") + b"\0" for n in names)
    return np.frombuffer(data, np.uint8).astype(np.int32)


def _names(codes: np.ndarray) -> list[str]:
    data = bytes(np.asarray(codes, np.int32).astype(np.uint8).tolist())
    return [n.decode("ascii") for n in data.split(b"\0")[:-1]]


def onboard_section(profile: str, model_channels: list[str], window: int, stride: int, sample_dt_s: float,
                    policy: dict, class_names: list[str]) -> Section:
    """The record of one export; ``policy`` the manifest's ``alarm`` (threshold, k, n, clear_m, latch)."""
    if profile not in ONBOARD_PROFILES:
        raise QuadfdiError(f"the on-board record knows profiles {ONBOARD_PROFILES}, not {profile!r}")
    raw = stream_channels(profile, model_channels)
    has_hover = uses_hover(profile)
    dims = {"profile": ONBOARD_PROFILES.index(profile), "window": window, "stride": stride, "raw_channels": len(raw),
            "channels": len(model_channels), "cells_from_stream": int(has_hover),
            "hover_steady_samples": hover.STEADY_SAMPLES if has_hover else 0,
            "hover_settle_samples": hover.SETTLE_SAMPLES if has_hover else 0}
    lo, hi = struct.unpack("<ii", struct.pack("<d", float(policy["threshold"])))
    healthy = class_names.index("Healthy") if "Healthy" in class_names else -1
    values = {"raw.names": _text(raw), "model.names": _text(list(model_channels)), "sample_dt_s": [sample_dt_s],
              "hover.limits": [hover.VZ_MAX, hover.TILT_MAX, hover.CMD_MIN], "alarm.threshold": [lo, hi],
              "alarm.policy": [int(policy["k"]), int(policy["n"]), int(policy["clear_m"]), int(bool(policy["latch"])),
                               healthy]}
    s = Section(*KIND, tuple(int(dims[d]) for d in ONBOARD_DIMS))
    for name, dtype, _ in ONBOARD_TENSORS:
        s.add(name, values[name], dtype)
    return s


def check_onboard(s: Section, where: str) -> None:
    """One-line QuadfdiError unless ``s`` holds the record's tensors, in order, with their dtypes and shapes."""
    names = [t[0] for t in ONBOARD_TENSORS]
    if list(s.tensors) != names:
        raise QuadfdiError(f"{where}: the on-board record holds tensors {list(s.tensors)}, the layout is {names}")
    for name, dtype, shape in ONBOARD_TENSORS:
        a = s.tensors[name].array
        if a.dtype != dtype or (shape == "text" and a.ndim != 1) or (shape != "text" and a.shape != shape):
            raise QuadfdiError(f"{where}: on-board tensor '{name}' is {a.dtype} {a.shape}, expected {np.dtype(dtype)} "
                               f"{shape}")
    d = dict(zip(ONBOARD_DIMS, s.dims))
    if d["profile"] >= len(ONBOARD_PROFILES) or len(_names(s["raw.names"])) != d["raw_channels"] or \
            len(_names(s["model.names"])) != d["channels"]:
        raise QuadfdiError(f"{where}: the on-board record's dims {s.dims} disagree with its tensors")


def onboard_dict(s: Section) -> dict:
    """The record as plain values (what tests compare with the C++ reader's print-out)."""
    d = dict(zip(ONBOARD_DIMS, (int(v) for v in s.dims)))
    k, n, m, latch, healthy = (int(v) for v in s["alarm.policy"])
    (thr,) = struct.unpack("<d", struct.pack("<ii", *(int(v) for v in s["alarm.threshold"])))
    return {"profile": ONBOARD_PROFILES[d["profile"]], "window": d["window"], "stride": d["stride"],
            "raw_channels": _names(s["raw.names"]), "channels": _names(s["model.names"]),
            "cells_from_stream": bool(d["cells_from_stream"]), "sample_dt_s": float(s["sample_dt_s"][0]),
            "hover": {"steady_samples": d["hover_steady_samples"], "settle_samples": d["hover_settle_samples"],
                      "limits": [float(v) for v in s["hover.limits"]]},
            "alarm": {"threshold": thr, "k": k, "n": n, "clear_m": m, "latch": bool(latch)}, "healthy": healthy}
