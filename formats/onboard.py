"""weights.bin's on-board record (issue 16): the section a streaming runtime reads besides the
weights: the channel profile (its id, the raw channels the stream delivers in their order, the
model's channels), the window, stride and sample period, the hover filter's constants, where the
cell count comes from, and the alarm policy (core.alarm). Layout: ``ONBOARD_*`` below (the model
sections' is formats/weights_layout.py); the C++ reader: firmware_ref/include/fwref/onboard.hpp;
docs/formats.md.

Written by ``quadfdi export`` from the manifest's ``profile`` and ``alarm``; weights.bin files written
before it lack it (``read_onboard`` then returns None). The last tensor, ``alarm.rotor_side`` (core.alarm
rule 5: which alarm classes report a motor), is optional: a record written before it is read as every
class rotor-side (``onboard_dict``'s ``rotor_side`` None; the C++ the same), i.e. core.alarm's rule 4 alone.
After it, ``alarm.models`` (optional too): one policy per network (export/alarm_policies.py), rows
(model code of export/binfmt.MODELS, k, n, clear_m, latch, the threshold's two words); a record
without it (written before it) runs ``alarm.policy`` for every model, as does a model it does not list
(``policy_of``; the C++: fwref::policy_for).
"""

from __future__ import annotations

import struct

import numpy as np

from quadfdi.core import hover
from quadfdi.core.alarm import rotor_columns
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import required_raw, uses_hover
from quadfdi.formats.binfmt import MODELS, Section

KIND = ("none", "none")  # (model, precision) of the section

# The layout: weights.bin's last section, model 0 and precision 0 ("none none"): what a streaming runtime needs
# besides the weights (docs/formats.md "on-board record"). Files written before it lack it (readers
# of the model sections do not need it; firmware_ref's Stream refuses a file without it). The C++
# reader is fwref/onboard.hpp (hand-written: tests/test_stream.py checks it prints back these values).
ONBOARD_PROFILES = ("paper", "flightlog-min", "flightlog-nocur", "flightlog-esc")  # dims[0]: the index here
ONBOARD_DIMS = ("profile", "window", "stride", "raw_channels", "channels", "cells_from_stream",
                "hover_steady_samples", "hover_settle_samples")  # dims[i], u32
# name, dtype, shape ("text": int32 (n,) ASCII codes, every name NUL-terminated)
ONBOARD_TENSORS = (("raw.names", np.int32, "text"),  # the stream's channels, in sample order
                   ("model.names", np.int32, "text"),  # the model's input channels (the profile's)
                   ("sample_dt_s", np.float32, (1,)),
                   ("hover.limits", np.float32, (3,)),  # vz_max m/s, tilt_max rad, cmd_min
                   ("alarm.threshold", np.int32, (2,)),  # the float64 threshold's bits, low word first
                   ("alarm.policy", np.int32, (5,)),  # k, n, clear_m, latch (0/1), Healthy's class index
                   ("alarm.rotor_side", np.int32, "classes"),  # (K,) 0/1: the class reports a motor (rule 5)
                   ("alarm.models", np.int32, "models"))  # (M, 7): model, k, n, clear_m, latch, threshold lo, hi
ONBOARD_OPTIONAL = ("alarm.rotor_side", "alarm.models")  # trailing, may be absent (records written before them)
POLICY_MODELS = {n: MODELS[n] for n in ("cnode", "gru", "sgru")}  # alarm.models' model codes (1, 2, 18)
STREAM_AIRBORNE = "airborne"  # the raw channel (0/1) that profiles with a hover estimate add last


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


def _words(threshold: float) -> list[int]:
    """The float64 threshold's bits as two int32, low word first."""
    return list(struct.unpack("<ii", struct.pack("<d", float(threshold))))


def _threshold(words) -> float:
    return struct.unpack("<d", struct.pack("<ii", *(int(v) for v in words)))[0]


def policy_rows(per_model: dict[str, dict]) -> np.ndarray:
    """alarm.models (M, 7) int32 of network -> policy (threshold, k, n, clear_m, latch), in POLICY_MODELS order."""
    unknown = sorted(set(per_model) - set(POLICY_MODELS))
    if unknown:
        raise QuadfdiError(f"the on-board record's alarm.models knows networks {tuple(POLICY_MODELS)}, not {unknown[0]!r}")
    rows = [[code, int(p["k"]), int(p["n"]), int(p["clear_m"]), int(bool(p["latch"]))] + _words(p["threshold"])
            for net, code in POLICY_MODELS.items() if (p := per_model.get(net)) is not None]
    return np.array(rows, np.int32).reshape(-1, 7)


def onboard_section(profile: str, model_channels: list[str], window: int, stride: int, sample_dt_s: float,
                    policy: dict, class_names: list[str], per_model: dict[str, dict] | None = None) -> Section:
    """The record of one export; ``policy`` the manifest's ``alarm`` (threshold, k, n, clear_m, latch),
    ``per_model`` network -> policy (alarm.models; None: a record without the table)."""
    if profile not in ONBOARD_PROFILES:
        raise QuadfdiError(f"the on-board record knows profiles {ONBOARD_PROFILES}, not {profile!r}")
    raw = stream_channels(profile, model_channels)
    has_hover = uses_hover(profile)
    dims = {"profile": ONBOARD_PROFILES.index(profile), "window": window, "stride": stride, "raw_channels": len(raw),
            "channels": len(model_channels), "cells_from_stream": int(has_hover),
            "hover_steady_samples": hover.STEADY_SAMPLES if has_hover else 0,
            "hover_settle_samples": hover.SETTLE_SAMPLES if has_hover else 0}
    healthy = class_names.index("Healthy") if "Healthy" in class_names else -1
    values = {"raw.names": _text(raw), "model.names": _text(list(model_channels)), "sample_dt_s": [sample_dt_s],
              "hover.limits": [hover.VZ_MAX, hover.TILT_MAX, hover.CMD_MIN], "alarm.threshold": _words(policy["threshold"]),
              "alarm.policy": [int(policy["k"]), int(policy["n"]), int(policy["clear_m"]), int(bool(policy["latch"])),
                               healthy],
              "alarm.rotor_side": rotor_columns(class_names).astype(np.int32),
              "alarm.models": None if per_model is None else policy_rows(per_model)}
    s = Section(*KIND, tuple(int(dims[d]) for d in ONBOARD_DIMS))
    for name, dtype, _ in ONBOARD_TENSORS:
        if values[name] is not None:
            s.add(name, values[name], dtype)
    return s


def check_onboard(s: Section, where: str) -> None:
    """One-line QuadfdiError unless ``s`` holds the record's tensors, in order, with their dtypes and shapes."""
    names = [t[0] for t in ONBOARD_TENSORS]
    required = len(names) - len(ONBOARD_OPTIONAL)
    if list(s.tensors) not in [names[:i] for i in range(required, len(names) + 1)]:
        raise QuadfdiError(f"{where}: the on-board record holds tensors {list(s.tensors)}, the layout is {names} "
                           f"(the last {len(ONBOARD_OPTIONAL)} optional)")
    for name, dtype, shape in ONBOARD_TENSORS:
        if name not in s.tensors:
            continue
        a = s.tensors[name].array
        vector = shape in ("text", "classes")
        table = shape == "models" and a.ndim == 2 and a.shape[1] == 7
        if a.dtype != dtype or (vector and a.ndim != 1) or (shape == "models" and not table) or \
                (shape not in ("text", "classes", "models") and a.shape != shape):
            raise QuadfdiError(f"{where}: on-board tensor '{name}' is {a.dtype} {a.shape}, expected {np.dtype(dtype)} "
                               f"{shape}")
    d = dict(zip(ONBOARD_DIMS, s.dims))
    if d["profile"] >= len(ONBOARD_PROFILES) or len(_names(s["raw.names"])) != d["raw_channels"] or \
            len(_names(s["model.names"])) != d["channels"]:
        raise QuadfdiError(f"{where}: the on-board record's dims {s.dims} disagree with its tensors")
    rotor = s.tensors.get("alarm.rotor_side")
    if rotor is not None and (not np.isin(rotor.array, (0, 1)).all() or len(rotor.array) < 2 or
                              not -1 <= int(s["alarm.policy"][4]) < len(rotor.array) or len(rotor.array) > 32):
        raise QuadfdiError(f"{where}: the on-board record's alarm.rotor_side {rotor.array.tolist()} is not 2..32 "
                           f"0/1 flags covering the Healthy class")
    if "alarm.models" in s.tensors:
        _check_models(s["alarm.models"], where)


def _check_models(rows: np.ndarray, where: str) -> None:
    """Each alarm.models row a valid policy (core.alarm.check_policy) of a distinct known network."""
    codes = [int(r[0]) for r in rows]
    if len(set(codes)) != len(codes) or not set(codes) <= set(POLICY_MODELS.values()):
        raise QuadfdiError(f"{where}: the on-board record's alarm.models names models {codes}: each at most once, "
                           f"of {sorted(POLICY_MODELS.values())}")
    for r in rows:
        if not (1 <= int(r[1]) <= int(r[2]) and int(r[3]) >= 1 and int(r[4]) in (0, 1) and 0.0 < _threshold(r[5:7]) <= 1.0):
            raise QuadfdiError(f"{where}: the on-board record's alarm.models row {r.tolist()} is not a valid policy")


def onboard_dict(s: Section) -> dict:
    """The record as plain values (what tests compare with the C++ reader's print-out); ``rotor_side``
    (K,) bool per class, or None for a record written before it (every class rotor-side);
    ``alarm_models`` network -> policy, or None for a record without the table (``policy_of``)."""
    d = dict(zip(ONBOARD_DIMS, (int(v) for v in s.dims)))
    k, n, m, latch, healthy = (int(v) for v in s["alarm.policy"])
    thr = _threshold(s["alarm.threshold"])
    return {"profile": ONBOARD_PROFILES[d["profile"]], "window": d["window"], "stride": d["stride"],
            "raw_channels": _names(s["raw.names"]), "channels": _names(s["model.names"]),
            "cells_from_stream": bool(d["cells_from_stream"]), "sample_dt_s": float(s["sample_dt_s"][0]),
            "hover": {"steady_samples": d["hover_steady_samples"], "settle_samples": d["hover_settle_samples"],
                      "limits": [float(v) for v in s["hover.limits"]]},
            "alarm": {"threshold": thr, "k": k, "n": n, "clear_m": m, "latch": bool(latch)}, "healthy": healthy,
            "rotor_side": [bool(v) for v in s["alarm.rotor_side"]] if "alarm.rotor_side" in s.tensors else None,
            "alarm_models": None if "alarm.models" not in s.tensors else {
                net: {"threshold": _threshold(r[5:7]), "k": int(r[1]), "n": int(r[2]), "clear_m": int(r[3]),
                      "latch": bool(r[4])} for r in s["alarm.models"] for net, code in POLICY_MODELS.items()
                if int(r[0]) == code}}


def max_alarm_n(record: dict) -> int:
    """The largest n of ``onboard_dict``'s policies (the single one and every alarm.models row): the
    alarm ring a stream that runs any of the record's models needs (FWREF_MAX_ALARM_N)."""
    return max([record["alarm"]["n"]] + [p["n"] for p in (record.get("alarm_models") or {}).values()])


def policy_of(record: dict, net: str) -> tuple[dict, str]:
    """(policy, where from) of ``net`` in ``onboard_dict``'s record: its alarm.models row ("alarm.models"),
    else the record's single policy ("alarm.policy": a record without the table or a network it omits)."""
    table = record.get("alarm_models") or {}
    return (dict(table[net]), "alarm.models") if net in table else (dict(record["alarm"]), "alarm.policy")
