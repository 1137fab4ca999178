"""ArduPilot DataFlash (.BIN) reader (pymavlink DFReader): messages -> project channels.

Messages: XKF1 (core 0; NKF1 on EKF2-era logs) PN/PE/PD, VN/VE/VD (NED); ATT Roll/Pitch/Yaw (deg);
RATE R/P/Y (deg/s; else IMU GyrX/Y/Z, rad/s, FRD); BAT Volt/Curr/RemPct; RCOU C1..C14 (PWM);
ESC RPM/Temp; VIBE VibeX/Y/Z; CTUN ThO/Alt; ARM/EV (arming); PARM. Docs: docs/ingest.md.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.ingest import battery, checks, motors, segments
from quadfdi.core import frames
from quadfdi.ingest.model import Channel, LogRead

WANTED = ["PARM", "MSG", "XKF1", "NKF1", "POS", "ATT", "RATE", "IMU", "BAT", "RCOU", "ESC", "VIBE", "CTUN", "ARM", "EV"]
ARMED_EV, DISARMED_EV = 10, 11  # ArduPilot LogEvent ids


def load(path: str) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, float], list[str]]:
    """Columns per message type (first instance only where an instance field exists), params, MSG texts."""
    from pymavlink import DFReader

    try:
        r = DFReader.DFReader_binary(str(path), zero_time_base=False)
    except Exception as exc:  # pymavlink raises bare Exceptions for foreign files
        raise QuadfdiError(f"{path} is not a readable DataFlash log: {exc}") from None
    rows: dict[str, list[dict]] = {}
    params: dict[str, float] = {}
    texts: list[str] = []
    while True:
        m = r.recv_match(type=WANTED)
        if m is None:
            break
        typ = m.get_type()
        d = m.to_dict()
        if typ == "PARM":
            params.setdefault(d["Name"], float(d["Value"]))
        elif typ == "MSG":
            texts.append(str(d["Message"]))
        elif all(d.get(k, 0) == 0 for k in ("C", "I", "IMU", "Inst")) or typ == "ESC":
            rows.setdefault(typ, []).append(d)
    cols = {typ: {k: np.array([row[k] for row in rs]) for k in rs[0] if k != "mavpackettype"} for typ, rs in rows.items()}
    return cols, params, texts


def check_multirotor(params: dict, texts: list[str]) -> None:
    fw = next((t.split()[0] for t in texts if t.startswith(("ArduCopter", "ArduPlane", "ArduRover", "ArduSub", "Ardu"))), "")
    if fw == "ArduPlane" or "Q_ENABLE" in params:
        q = " (QuadPlane VTOL)" if params.get("Q_ENABLE", 0) else ""
        raise QuadfdiError(f"not a multirotor: ArduPlane log{q}")
    if fw and fw != "ArduCopter" or "FRAME_CLASS" not in params:
        raise QuadfdiError(f"not a multirotor: {fw or 'unknown firmware'} (no FRAME_CLASS parameter)")


def state_channels(c: dict, lr: LogRead) -> None:
    ekf = "XKF1" if "XKF1" in c else "NKF1" if "NKF1" in c else None
    if ekf:
        e = c[ekf]
        x, y, z = frames.ned_to_sim(e["PN"], e["PE"], e["PD"])
        vx, vy, vz = frames.ned_to_sim(e["VN"], e["VE"], e["VD"])
        for name, v, f in (("x", x, "PN"), ("y", y, "PE, negated"), ("z", z, "PD, negated"),
                           ("vx", vx, "VN"), ("vy", vy, "VE, negated"), ("vz", vz, "VD, negated")):
            lr.channels[name] = Channel(name, e["t"], v.astype(float), f"{ekf}.{f}")
    elif "POS" in c:  # no EKF message: the global position, made local at the first fix (no velocity)
        pos_channels(c["POS"], lr)
    if "ATT" in c:
        a = c["ATT"]
        r, p, y = frames.euler_ned_to_sim(*(np.radians(a[k].astype(float)) for k in ("Roll", "Pitch", "Yaw")))
        for name, v, f in (("roll", r, "Roll"), ("pitch", p, "Pitch, negated"), ("yaw", y, "Yaw, negated")):
            lr.channels[name] = Channel(name, a["t"], v, f"ATT.{f} (deg -> rad)")
    if "RATE" in c:
        g = c["RATE"]
        rates = frames.frd_to_sim(*(np.radians(g[k].astype(float)) for k in ("R", "P", "Y")))
        src = ("RATE.R (deg/s -> rad/s)", "RATE.P, negated", "RATE.Y, negated")
    elif "IMU" in c:
        g = c["IMU"]
        rates = frames.frd_to_sim(*(g[k].astype(float) for k in ("GyrX", "GyrY", "GyrZ")))
        src = ("IMU.GyrX", "IMU.GyrY, negated", "IMU.GyrZ, negated")
    else:
        return
    for name, v, s in zip(("p", "q", "r"), rates, src):
        lr.channels[name] = Channel(name, g["t"], v, s)


def pos_channels(p: dict, lr: LogRead) -> None:
    """x, y, z from POS Lat/Lng (deg, equirectangular about the first fix) and RelHomeAlt (m, up)."""
    m_per_deg = 111319.49  # WGS-84 equatorial metres per degree; the error over a flight's extent is < 0.5 %
    lat0, lng0 = float(p["Lat"][0]), float(p["Lng"][0])
    north = (p["Lat"].astype(float) - lat0) * m_per_deg
    east = (p["Lng"].astype(float) - lng0) * m_per_deg * np.cos(np.radians(lat0))
    x, y, z = frames.ned_to_sim(north, east, -p["RelHomeAlt"].astype(float))
    for name, v, f in (("x", x, "Lat -> m north of the first fix"), ("y", y, "Lng -> m west of the first fix"),
                       ("z", z, "RelHomeAlt")):
        lr.channels[name] = Channel(name, p["t"], v, f"POS.{f}")
    for name in ("vx", "vy", "vz"):
        lr.status[name] = "absent: no XKF1/NKF1 (POS has no velocity)"


def power_channels(c: dict, params: dict, lr: LogRead) -> float:
    if "BAT" not in c:
        return float("nan")
    b = c["BAT"]
    lr.channels["V_b"] = Channel("V_b", b["t"], b["Volt"].astype(float), "BAT.Volt")
    lr.channels["I_b"] = Channel("I_b", b["t"], b["Curr"].astype(float), "BAT.Curr")
    if "RemPct" in b:
        lr.channels["SoC"] = Channel("SoC", b["t"], b["RemPct"].astype(float) / 100.0, "BAT.RemPct / 100")
    return float(np.nanmax(b["Volt"]))


def motor_channels(c: dict, params: dict, mmap: list[int], lr: LogRead) -> None:
    lo, hi = params.get("MOT_PWM_MIN", 0.0), params.get("MOT_PWM_MAX", 0.0)
    src = "MOT_PWM_MIN/MAX"
    if not (lo > 0 and hi > lo):  # ArduCopter's own fallback: the throttle channel's range
        lo, hi, src = params.get("RC3_MIN", 1100.0), params.get("RC3_MAX", 1900.0), "RC3_MIN/MAX (MOT_PWM_* unset)"
    expo = float(params.get("MOT_THST_EXPO", 0.65))
    lr.vehicle["pwm_range"] = [lo, hi, src]
    lr.vehicle["thrust_expo"] = expo
    if "RCOU" not in c:
        return
    out = c["RCOU"]
    servo_of = {int(params.get(f"SERVO{n}_FUNCTION", -1)) - 33: n for n in range(1, 17)}  # 33..36 = motor 1..4
    below = 0
    for k, m in enumerate(mmap):
        n = servo_of.get(m, m + 1)
        thr, b = motors.pwm_to_thrust(out[f"C{n}"], lo, hi, expo)
        below += b
        lr.channels[f"thr{k + 1}"] = Channel(f"thr{k + 1}", out["t"], thr, f"RCOU.C{n} -> ({src}), MOT_THST_EXPO={expo:g}")
    lr.vehicle["pwm_samples_below_min"] = below


def extra_channels(c: dict, mmap: list[int], lr: LogRead) -> None:
    if "VIBE" in c:
        v = c["VIBE"]
        # The in-plane mean: what the simulator computes (sim.propeller; no vertical vibration model).
        lr.channels["vib_ap"] = Channel("vib_ap", v["t"], (v["VibeX"].astype(float) + v["VibeY"].astype(float)) / 2.0,
                                        "VIBE: (VibeX + VibeY) / 2")
    if "ESC" not in c:
        for k in range(4):
            for name in ("rpm", "esc_temp", "esc_cur"):
                lr.status[f"{name}{k + 1}"] = "absent: no ESC messages"
        return
    e = c["ESC"]
    for k, m in enumerate(mmap):
        sel = e["Instance"] == m
        lr.channels[f"rpm{k + 1}"] = Channel(f"rpm{k + 1}", e["t"][sel], e["RPM"][sel].astype(float), f"ESC[{m}].RPM")
        lr.channels[f"esc_temp{k + 1}"] = Channel(f"esc_temp{k + 1}", e["t"][sel], e["Temp"][sel].astype(float), f"ESC[{m}].Temp")
        if "Curr" in e:  # ESC.Curr (A) since ArduPilot 3.5
            lr.channels[f"esc_cur{k + 1}"] = Channel(f"esc_cur{k + 1}", e["t"][sel], e["Curr"][sel].astype(float),
                                                     f"ESC[{m}].Curr")
        else:
            lr.status[f"esc_cur{k + 1}"] = "absent: ESC messages without Curr"


def flight_state(c: dict, lr: LogRead) -> None:
    t_end = lr.data_span[1]
    if "ARM" in c:
        lr.armed = segments.step_intervals(c["ARM"]["t"], c["ARM"]["ArmState"] > 0, t_end)
    elif "EV" in c and np.isin(c["EV"]["Id"], [ARMED_EV, DISARMED_EV]).any():
        ev = c["EV"]
        sel = np.isin(ev["Id"], [ARMED_EV, DISARMED_EV])
        lr.armed = segments.step_intervals(ev["t"][sel], ev["Id"][sel] == ARMED_EV, t_end)
    if "CTUN" in c:  # ArduCopter logs no land detector: throttle-and-altitude rule
        ct = c["CTUN"]
        alt = ct["Alt"].astype(float)
        fly = segments.fallback_airborne(ct["t"], ct["ThO"].astype(float), alt - np.nanmin(alt), t_end)
        lr.airborne = segments.intersect(fly, lr.armed) if lr.armed else fly
        lr.airborne_source = "fallback: CTUN.ThO > 0.15 and CTUN.Alt > 0.5 m above its minimum"


def read_ardupilot(path: str) -> LogRead:
    c, params, texts = load(path)
    check_multirotor(params, texts)
    rotors, geo_src = motors.ardupilot_geometry(params)
    mmap = motors.motor_map(rotors)
    t0 = min(float(d["TimeUS"][0]) for d in c.values())
    for d in c.values():
        d["t"] = (d["TimeUS"].astype(float) - t0) / 1e6
    span = (0.0, max(float(d["t"][-1]) for d in c.values()))
    lr = LogRead("ardupilot", {}, {}, {"frame": "quadrotor", "geometry_source": geo_src, "motor_map": mmap,
                                       "firmware": next((t for t in texts if t.startswith("Ardu")), None)},
                 [], [], "none", span, [])
    state_channels(c, lr)
    v_max = power_channels(c, params, lr)
    motor_channels(c, params, mmap, lr)
    extra_channels(c, mmap, lr)
    lr.status["vib_px4"] = "absent: PX4's accel_vibration_metric (an ArduPilot log carries VIBE as vib_ap)"
    lr.vehicle["battery"] = battery.cell_count([("BATT_CELLS", params.get("BATT_CELLS"))], v_max)
    flight_state(c, lr)
    checks.plausibility(lr)
    return lr
