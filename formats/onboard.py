"""weights.bin's on-board record: the section a streaming runtime reads besides the weights: the
channel profile (its id, the raw channels the stream delivers in their order, the model's
channels), the window, stride and sample period, the hover filter's constants, where the
cell count comes from, and the alarm policy (core.alarm). Layout: ``ONBOARD_*`` below (the model
sections' is formats/weights_layout.py); the C++ reader: firmware_ref/include/fwref/onboard.hpp;
docs/formats.md.

Written by ``quadfdi export`` from the manifest's ``profile`` and ``alarm``; weights.bin files written
before it lack it (``read_onboard`` then returns None). The last tensor, ``alarm.rotor_side`` (core.alarm
rule 5: which alarm classes report a motor), is optional: a record written before it is read as every
class rotor-side (``onboard_dict``'s ``rotor_side`` None; the C++ the same), i.e. core.alarm's rule 4 alone.
After it, ``alarm.models`` (optional too): one policy per network (export/alarm_policies.py), rows
(model code, k, n, clear_m, latch, the threshold's two words); a record without it (written before
it) runs ``alarm.policy`` for every model, as does a model it does not list (``policy_of``, which is
core.alarm.resolve_policy; the C++: fwref::policy_for).

The masked profile (``flightlog-mask``, id 4) needs nothing more here: its availability groups and fills
belong to the profile id (core/channels.py, compiled into the C++ from fwref/channels_gen.hpp), and which
channels a flight lacks is the flight's, so the stream file says it (formats/stream.py carried flags),
not the record; its raw channels stay every channel the profile can read, in one fixed order.

The tables behind the record are written once elsewhere: profile ids and channel names in
core/channels.py, model codes and the policy columns (``ALARM_POLICY_COLUMNS``,
``ALARM_MODELS_COLUMNS``) in core/contracts.py; the C++ reads the same tables from the generated
headers fwref/channels_gen.hpp and fwref/contracts_gen.hpp.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from quadfdi.core import hover
from quadfdi.core.alarm import check_policy, resolve_policy, rotor_columns
from quadfdi.core.channels import AIRBORNE, PROFILE_BY_NAME, PROFILE_TABLE
from quadfdi.core.contracts import ALARM_MODELS_COLUMNS, ALARM_POLICY_COLUMNS, MODEL_CODES, POLICY_KEYS, POLICY_NETWORKS
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import required_raw, uses_hover
from quadfdi.formats.binfmt import Section

KIND = ("none", "none")  # (model, precision) of the section

# The layout: weights.bin's last section, model 0 and precision 0 ("none none"): what a streaming runtime needs
# besides the weights (docs/formats.md "on-board record"). Files written before it lack it (readers
# of the model sections do not need it; firmware_ref's Stream refuses a file without it). The C++
# reader is fwref/onboard.hpp (tests/test_stream.py checks it prints back these values).
PROFILE_OF_ID = {p.id: p.name for p in PROFILE_TABLE}  # dims[0]: the profile's id (core/channels.py)
ONBOARD_DIMS = ("profile", "window", "stride", "raw_channels", "channels", "cells_from_stream",
                "hover_steady_samples", "hover_settle_samples")  # dims[i], u32
# name, dtype, shape ("text": int32 (n,) ASCII codes, every name NUL-terminated)
ONBOARD_TENSORS = (("raw.names", np.int32, "text"),  # the stream's channels, in sample order
                   ("model.names", np.int32, "text"),  # the model's input channels (the profile's)
                   ("sample_dt_s", np.float32, (1,)),
                   ("hover.limits", np.float32, (3,)),  # vz_max m/s, tilt_max rad, cmd_min
                   ("alarm.threshold", np.int32, (2,)),  # the float64 threshold's bits, low word first
                   ("alarm.policy", np.int32, (len(ALARM_POLICY_COLUMNS),)),  # ALARM_POLICY_COLUMNS
                   ("alarm.rotor_side", np.int32, "classes"),  # (K,) 0/1: the class reports a motor (rule 5)
                   ("alarm.models", np.int32, "models"))  # (M, len(ALARM_MODELS_COLUMNS)): one row per network
ONBOARD_OPTIONAL = ("alarm.rotor_side", "alarm.models")  # trailing, may be absent (records written before them)
POLICY_MODELS = {n: MODEL_CODES[n] for n in POLICY_NETWORKS}  # alarm.models' model codes (1, 2, 18)
_MODELS_WIDTH = len(ALARM_MODELS_COLUMNS)


def stream_channels(profile: str, model_channels: list[str]) -> list[str]:
    """The raw channels a stream delivers, in sample order: ``paper`` the model's own channels; a
    profile with a hover estimate the raw channels it reads (core.profiles.required_raw, first-use
    order) and ``airborne`` (0/1) last."""
    if not uses_hover(profile):
        return list(model_channels)
    return required_raw(profile) + [AIRBORNE]


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


def _policy_columns(p: dict, columns: tuple[str, ...], **more: int) -> list[int]:
    """One policy as the int32 columns ``columns`` name (ALARM_POLICY_COLUMNS, ALARM_MODELS_COLUMNS)."""
    lo, hi = _words(p["threshold"])
    values = {**{k: int(bool(p[k])) if k == "latch" else int(p[k]) for k in POLICY_KEYS if k != "threshold"},
              "threshold_lo": lo, "threshold_hi": hi, **more}
    return [values[c] for c in columns]


def _policy_of_columns(row, columns: tuple[str, ...], threshold: float) -> dict:
    """The policy (POLICY_KEYS order) of int32 columns ``row`` named ``columns``."""
    v = dict(zip(columns, (int(x) for x in row)))
    return {k: threshold if k == "threshold" else bool(v[k]) if k == "latch" else v[k] for k in POLICY_KEYS}


def policy_rows(per_model: dict[str, dict]) -> np.ndarray:
    """alarm.models (M, 7) int32 of network -> policy (threshold, k, n, clear_m, latch), in POLICY_MODELS order."""
    unknown = sorted(set(per_model) - set(POLICY_MODELS))
    if unknown:
        raise QuadfdiError(f"the on-board record's alarm.models knows networks {tuple(POLICY_MODELS)}, not {unknown[0]!r}")
    rows = [_policy_columns(p, ALARM_MODELS_COLUMNS, model=code)
            for net, code in POLICY_MODELS.items() if (p := per_model.get(net)) is not None]
    return np.array(rows, np.int32).reshape(-1, _MODELS_WIDTH)


def onboard_section(profile: str, model_channels: list[str], window: int, stride: int, sample_dt_s: float,
                    policy: dict, class_names: list[str], per_model: dict[str, dict] | None = None) -> Section:
    """The record of one export; ``policy`` the manifest's ``alarm`` (threshold, k, n, clear_m, latch),
    ``per_model`` network -> policy (alarm.models; None: a record without the table)."""
    if profile not in PROFILE_BY_NAME:
        raise QuadfdiError(f"the on-board record knows profiles {tuple(PROFILE_BY_NAME)}, not {profile!r}")
    raw = stream_channels(profile, model_channels)
    has_hover = uses_hover(profile)
    dims = {"profile": PROFILE_BY_NAME[profile].id, "window": window, "stride": stride, "raw_channels": len(raw),
            "channels": len(model_channels), "cells_from_stream": int(has_hover),
            "hover_steady_samples": hover.STEADY_SAMPLES if has_hover else 0,
            "hover_settle_samples": hover.SETTLE_SAMPLES if has_hover else 0}
    healthy = class_names.index("Healthy") if "Healthy" in class_names else -1
    values = {"raw.names": _text(raw), "model.names": _text(list(model_channels)), "sample_dt_s": [sample_dt_s],
              "hover.limits": [hover.VZ_MAX, hover.TILT_MAX, hover.CMD_MIN], "alarm.threshold": _words(policy["threshold"]),
              "alarm.policy": _policy_columns(policy, ALARM_POLICY_COLUMNS, healthy=healthy),
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
        table = shape == "models" and a.ndim == 2 and a.shape[1] == _MODELS_WIDTH
        if a.dtype != dtype or (vector and a.ndim != 1) or (shape == "models" and not table) or \
                (shape not in ("text", "classes", "models") and a.shape != shape):
            raise QuadfdiError(f"{where}: on-board tensor '{name}' is {a.dtype} {a.shape}, expected {np.dtype(dtype)} "
                               f"{shape}")
    d = dict(zip(ONBOARD_DIMS, s.dims))
    if d["profile"] not in PROFILE_OF_ID or len(_names(s["raw.names"])) != d["raw_channels"] or \
            len(_names(s["model.names"])) != d["channels"]:
        raise QuadfdiError(f"{where}: the on-board record's dims {s.dims} disagree with its tensors")
    rotor = s.tensors.get("alarm.rotor_side")
    if rotor is not None and (not np.isin(rotor.array, (0, 1)).all() or len(rotor.array) < 2 or
                              not -1 <= _healthy(s) < len(rotor.array) or len(rotor.array) > 32):
        raise QuadfdiError(f"{where}: the on-board record's alarm.rotor_side {rotor.array.tolist()} is not 2..32 "
                           f"0/1 flags covering the Healthy class")
    single = _policy_of_columns(s["alarm.policy"], ALARM_POLICY_COLUMNS, _threshold(s["alarm.threshold"]))
    if int(s["alarm.policy"][ALARM_POLICY_COLUMNS.index("latch")]) not in (0, 1) or not _valid(single):
        raise QuadfdiError(f"{where}: the on-board record's alarm.policy {s['alarm.policy'].tolist()} (threshold "
                           f"{single['threshold']}) is not a valid policy")
    if "alarm.models" in s.tensors:
        _check_models(s["alarm.models"], where)


def _healthy(s: Section) -> int:
    return int(s["alarm.policy"][ALARM_POLICY_COLUMNS.index("healthy")])


def _models_table(rows: np.ndarray) -> dict[str, dict]:
    """alarm.models' rows as network -> policy."""
    col = ALARM_MODELS_COLUMNS.index
    nets = {code: net for net, code in POLICY_MODELS.items()}
    return {nets[int(r[col("model")])]: _policy_of_columns(r, ALARM_MODELS_COLUMNS, _threshold(
        r[[col("threshold_lo"), col("threshold_hi")]])) for r in rows}


def _check_models(rows: np.ndarray, where: str) -> None:
    """Each alarm.models row a valid policy (core.alarm.check_policy) of a distinct known network."""
    codes = [int(r[ALARM_MODELS_COLUMNS.index("model")]) for r in rows]
    if len(set(codes)) != len(codes) or not set(codes) <= set(POLICY_MODELS.values()):
        raise QuadfdiError(f"{where}: the on-board record's alarm.models names models {codes}: each at most once, "
                           f"of {sorted(POLICY_MODELS.values())}")
    latch = ALARM_MODELS_COLUMNS.index("latch")
    for r, p in zip(rows, _models_table(rows).values()):
        if int(r[latch]) not in (0, 1) or not _valid(p):
            raise QuadfdiError(f"{where}: the on-board record's alarm.models row {r.tolist()} is not a valid policy")


def _valid(p: dict) -> bool:
    try:
        check_policy(p["threshold"], p["k"], p["n"], p["clear_m"])
    except QuadfdiError:
        return False
    return True


def onboard_dict(s: Section) -> dict:
    """The record as plain values (what tests compare with the C++ reader's print-out); ``rotor_side``
    (K,) bool per class, or None for a record written before it (every class rotor-side);
    ``alarm_models`` network -> policy, or None for a record without the table (``policy_of``)."""
    d = dict(zip(ONBOARD_DIMS, (int(v) for v in s.dims)))
    return {"profile": PROFILE_OF_ID[d["profile"]], "window": d["window"], "stride": d["stride"],
            "raw_channels": _names(s["raw.names"]), "channels": _names(s["model.names"]),
            "cells_from_stream": bool(d["cells_from_stream"]), "sample_dt_s": float(s["sample_dt_s"][0]),
            "hover": {"steady_samples": d["hover_steady_samples"], "settle_samples": d["hover_settle_samples"],
                      "limits": [float(v) for v in s["hover.limits"]]},
            "alarm": _policy_of_columns(s["alarm.policy"], ALARM_POLICY_COLUMNS, _threshold(s["alarm.threshold"])),
            "healthy": _healthy(s),
            "rotor_side": [bool(v) for v in s["alarm.rotor_side"]] if "alarm.rotor_side" in s.tensors else None,
            "alarm_models": _models_table(s["alarm.models"]) if "alarm.models" in s.tensors else None}


def record_dict(s: Section | None, where: str | Path) -> dict:
    """``onboard_dict`` of weights.bin's record ``s`` (formats.weights_bin.WeightsFile.onboard; ``where``
    names the file), or a one-line refusal of a file written before the record (``s`` None)."""
    if s is None:
        raise QuadfdiError(f"{where} has no on-board record (exported before it: re-run `quadfdi export`)")
    return onboard_dict(s)


def max_alarm_n(record: dict) -> int:
    """The largest n of ``onboard_dict``'s policies (the single one and every alarm.models row): the
    alarm ring a stream that runs any of the record's models needs (FWREF_MAX_ALARM_N)."""
    return max([record["alarm"]["n"]] + [p["n"] for p in (record.get("alarm_models") or {}).values()])


def policy_of(record: dict, net: str) -> tuple[dict, str]:
    """(policy, where from) of ``net`` in ``onboard_dict``'s record: its alarm.models row ("alarm.models"),
    else the record's single policy ("alarm.policy": a record without the table or a network it omits).
    The rule is core.alarm.resolve_policy, as for a manifest (formats.export_folder.Export.policy)."""
    pol, own = resolve_policy(net, record.get("alarm_models"), record["alarm"])
    return pol, "alarm.models" if own else "alarm.policy"
