"""PX4 motor commands and ESC telemetry -> thr1..4, rpm1..4, esc_temp1..4, esc_cur1..4 in the project's motor order.

actuator_motors (PX4 >= 1.13) is the thrust command in [0, 1]: used as is. Otherwise
actuator_outputs, which real logs make treacherous: several instances (an unused one always 0
beside UAVCAN ESCs, an AUX bank of constant servo values), and a second publisher interleaved in
one instance (told apart by its ``noutputs``). Every (instance, noutputs) stream is a candidate;
streams always 0 or constant are dropped (and said so), the one that varies most is the motors.
"""

from __future__ import annotations

import numpy as np

from quadfdi.ingest import motors
from quadfdi.ingest.model import Channel, LogRead

UAVCAN_FULL_SCALE = 8191.0  # PX4 UAVCAN ESC raw command range 0..8191 (uavcan.equipment.esc.RawCommand)


def _streams(tp, lr: LogRead) -> list[tuple[str, dict]]:
    out = []
    for inst, d in sorted(tp.instances("actuator_outputs").items()):
        keys = np.unique(d["noutputs"]) if "noutputs" in d else np.array([0])
        for k in keys:
            sel = d["noutputs"] == k if "noutputs" in d else np.ones(len(d["t"]), bool)
            s = {f: v[sel] for f, v in d.items()}
            name = f"actuator_outputs[{inst}]" + (f" (noutputs={int(k)})" if len(keys) > 1 else "")
            block = np.stack([s[f"output[{i}]"].astype(float) for i in range(4)])
            if np.all(block == 0):
                lr.note(f"{name}: unused (always 0), ignored")
            elif np.all(block == block[:, :1]):
                lr.note(f"{name}: {int(sel.sum())} samples of constant outputs {block[:, 0].tolist()} "
                        "(a second publisher, not the motors), ignored")
            else:
                out.append((name, s))
    return out


def _pwm_range(params: dict, motor: int) -> tuple[float, float, str]:
    lo, hi = params.get(f"PWM_MAIN_MIN{motor + 1}", -1), params.get(f"PWM_MAIN_MAX{motor + 1}", -1)
    if lo is not None and hi is not None and lo > 0 and hi > 0:
        return float(lo), float(hi), f"PWM_MAIN_MIN{motor + 1}/MAX{motor + 1}"
    return float(params.get("PWM_MAIN_MIN", 1000)), float(params.get("PWM_MAIN_MAX", 2000)), "PWM_MAIN_MIN/MAX"


def motor_channels(tp, params: dict, mmap: list[int], lr: LogRead) -> None:
    am = tp.get("actuator_motors")
    if am is not None:
        for k, m in enumerate(mmap):
            lr.channels[f"thr{k + 1}"] = Channel(f"thr{k + 1}", am["t"], am[f"control[{m}]"].astype(float),
                                                 f"actuator_motors.control[{m}]")
        lr.vehicle["motor_command"] = "actuator_motors (thrust fraction, as logged)"
        # recorded for the vehicle facts only: actuator_motors is already normalised
        lr.vehicle["pwm_range"] = {f"motor{m + 1}": [*_pwm_range(params, m)[:2], _pwm_range(params, m)[2] + " (not used)"]
                                   for m in range(4)}
        return
    streams = _streams(tp, lr)
    if not streams:
        for k in range(4):
            lr.status[f"thr{k + 1}"] = "absent: no actuator_motors and no varying actuator_outputs"
        return
    name, s = max(streams, key=lambda ns: float(np.std([ns[1][f"output[{i}]"] for i in range(4)])))
    expo = float(params.get("THR_MDL_FAC", 0.0) or 0.0)
    peak = max(float(np.max(s[f"output[{i}]"])) for i in range(4))
    uavcan = int(params.get("UAVCAN_ENABLE", 0) or 0) >= 2 and peak > 2200
    below_total = 0
    for k, m in enumerate(mmap):
        raw = s[f"output[{m}]"].astype(float)
        if uavcan:
            lo, hi, rng = 0.0, UAVCAN_FULL_SCALE, "UAVCAN raw 0..8191"
        else:
            lo, hi, rng = _pwm_range(params, m)
        thr, below = motors.pwm_to_thrust(raw, lo, hi, expo)
        below_total += below if not uavcan else 0
        lr.channels[f"thr{k + 1}"] = Channel(f"thr{k + 1}", s["t"], thr,
                                             f"{name}.output[{m}] -> ({rng}), THR_MDL_FAC={expo:g}")
        lr.vehicle.setdefault("pwm_range", {})[f"motor{m + 1}"] = [lo, hi, rng]
    lr.vehicle["motor_command"] = f"{name}, normalised"
    lr.vehicle["pwm_samples_below_min"] = below_total
    if below_total:
        lr.note(f"{name}: {below_total} motor samples below the PWM minimum (armed idle under PWM_MAIN_MIN?), clipped to 0")


def esc_channels(tp, mmap: list[int], lr: LogRead) -> None:
    esc = tp.get("esc_status")
    if esc is None or int(np.max(esc["esc_count"])) == 0:
        why = "absent: esc_status " + ("not logged" if esc is None else "logged but empty (esc_count = 0)")
        for k in range(4):
            for name in ("rpm", "esc_temp", "esc_cur"):
                lr.status[f"{name}{k + 1}"] = why
        return
    n = int(np.max(esc["esc_count"]))
    if n > 4:
        lr.note(f"esc_status reports {n} ESCs on a quad: ESCs 5..{n} ignored")
    for k, m in enumerate(mmap):
        if m >= n:
            continue
        rpm = esc[f"esc[{m}].esc_rpm"].astype(float)
        lr.channels[f"rpm{k + 1}"] = Channel(f"rpm{k + 1}", esc["t"], rpm, f"esc_status.esc[{m}].esc_rpm")
        cur = esc[f"esc[{m}].esc_current"].astype(float)
        if np.all(cur == 0):
            lr.status[f"esc_cur{k + 1}"] = "absent: ESC reports no current (always 0)"
        else:
            lr.channels[f"esc_cur{k + 1}"] = Channel(f"esc_cur{k + 1}", esc["t"], cur, f"esc_status.esc[{m}].esc_current")
        temp = esc[f"esc[{m}].esc_temperature"].astype(float)
        if np.all(temp == 0):
            lr.status[f"esc_temp{k + 1}"] = "absent: ESC reports no temperature (always 0)"
            continue
        kelvin = np.nanmedian(temp) > 200.0  # UAVCAN ESCs of PX4 < 1.10 report kelvin
        lr.channels[f"esc_temp{k + 1}"] = Channel(
            f"esc_temp{k + 1}", esc["t"], temp - 273.15 if kelvin else temp,
            f"esc_status.esc[{m}].esc_temperature" + (" (K -> degC)" if kelvin else ""))
