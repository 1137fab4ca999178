"""PX4 ULog reader (pyulog): topics -> project channels in project units and frames.

Topics: vehicle_local_position (x, y, z, vx, vy, vz; NED), vehicle_attitude (q; NED/FRD; PX4 < 1.10
also rollspeed...), vehicle_angular_velocity (xyz; FRD), battery_status, actuator_motors or
actuator_outputs (px4_motors.py), esc_status, vehicle_imu_status / vehicle_imu / estimator_status
(the vibration metric in m/s^2: px4_vibration.py), vehicle_land_detected, vehicle_status. Docs: docs/ingest.md.
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.ingest import battery, checks, motors, px4_motors, px4_vibration, segments
from quadfdi.core import frames
from quadfdi.ingest.model import Channel, LogRead

TOPICS = ["vehicle_local_position", "vehicle_attitude", "vehicle_angular_velocity", "battery_status",
          "actuator_motors", "actuator_outputs", "esc_status", "vehicle_imu_status", "vehicle_imu", "estimator_status",
          "vehicle_land_detected", "vehicle_status"]
STATE_TOPICS = {"vehicle_status", "vehicle_land_detected"}  # published on change: a sample holds until the next
MULTIROTOR_MAV_TYPES = {2: "quadrotor", 3: "coaxial", 13: "hexarotor", 14: "octorotor", 15: "tricopter"}


class Topics:
    """The log's topic instances with times in s from the log start; samples stamped before the
    log start or after its last sample are dropped and counted (they come from a publisher that
    ran before logging, e.g. a stale actuator_outputs instance)."""

    def __init__(self, ulog, lr_notes: list[str]):
        self.t0 = ulog.start_timestamp
        self.by_name: dict[str, dict[int, dict]] = {}
        for d in ulog.data_list:
            ts = d.data["timestamp"].astype(np.int64)
            if d.name in STATE_TOPICS:  # the state at logging start was published before it: keep it
                ts = np.maximum(ts, self.t0)
            keep = (ts >= self.t0) & (ts <= ulog.last_timestamp)
            if not keep.all():
                lr_notes.append(f"{d.name}[{d.multi_id}]: dropped {int((~keep).sum())} of {len(ts)} samples "
                                f"stamped outside the log ({'before its start' if (ts < self.t0).any() else 'after its end'})")
            if not keep.any():
                continue
            data = {k: v[keep] for k, v in d.data.items()}
            data["t"] = (ts[keep] - self.t0) / 1e6
            self.by_name.setdefault(d.name, {})[d.multi_id] = data

    def get(self, name: str, instance: int = 0) -> dict | None:
        return self.by_name.get(name, {}).get(instance)

    def instances(self, name: str) -> dict[int, dict]:
        return self.by_name.get(name, {})

    def span(self) -> tuple[float, float]:
        ts = [d["t"] for inst in self.by_name.values() for d in inst.values() if len(d["t"])]
        return float(min(t[0] for t in ts)), float(max(t[-1] for t in ts))


def open_ulog(path: str):
    return open_ulog_topics(path, TOPICS)


def open_ulog_topics(path: str, topics: list[str]):
    from pyulog import ULog

    try:
        return ULog(str(path), message_name_filter_list=topics)
    except Exception as exc:  # pyulog raises bare Exceptions for foreign or truncated files
        raise QuadfdiError(f"{path} is not a readable ULog: {str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None


def check_multirotor(params: dict, tp: Topics) -> str:
    """MAV_TYPE of a quadrotor, else a one-line refusal (a VTOL reports rotary wing in hover: ask MAV_TYPE)."""
    mt = params.get("MAV_TYPE")
    vs = tp.get("vehicle_status")
    if vs is not None and "is_vtol" in vs and np.any(vs["is_vtol"]):
        raise QuadfdiError(f"not a multirotor: a VTOL (vehicle_status.is_vtol, MAV_TYPE {mt})")
    if mt is None:
        raise QuadfdiError("not a multirotor: the log has no MAV_TYPE parameter")
    if int(mt) not in MULTIROTOR_MAV_TYPES:
        raise QuadfdiError(f"not a multirotor: MAV_TYPE {int(mt)} (2 = quadrotor)")
    if int(mt) != 2:
        raise QuadfdiError(f"not a quadrotor: MAV_TYPE {int(mt)} ({MULTIROTOR_MAV_TYPES[int(mt)]})")
    return "quadrotor"


def position_channels(tp: Topics, out: dict, status: dict) -> None:
    lp = tp.get("vehicle_local_position")
    if lp is None:
        return
    src = "vehicle_local_position"
    ok_xy = lp["xy_valid"].astype(bool) if "xy_valid" in lp else np.ones(len(lp["t"]), bool)
    ok_z = lp["z_valid"].astype(bool) if "z_valid" in lp else np.ones(len(lp["t"]), bool)
    ok_vxy = lp["v_xy_valid"].astype(bool) if "v_xy_valid" in lp else ok_xy
    ok_vz = lp["v_z_valid"].astype(bool) if "v_z_valid" in lp else ok_z
    x, y, z = frames.ned_to_sim(lp["x"].astype(float), lp["y"].astype(float), lp["z"].astype(float))
    vx, vy, vz = frames.ned_to_sim(lp["vx"].astype(float), lp["vy"].astype(float), lp["vz"].astype(float))
    for name, v, ok, desc in (("x", x, ok_xy, ".x (N)"), ("y", y, ok_xy, ".y (E), negated"),
                              ("z", z, ok_z, ".z (D), negated"), ("vx", vx, ok_vxy, ".vx"),
                              ("vy", vy, ok_vxy, ".vy, negated"), ("vz", vz, ok_vz, ".vz, negated")):
        if ok.any():
            out[name] = Channel(name, lp["t"], np.where(ok, v, np.nan), src + desc)
        else:
            status[name] = f"unusable: {src} marks it invalid throughout (*_valid = 0: no fix)"


def attitude_channels(tp: Topics, out: dict) -> None:
    att = tp.get("vehicle_attitude")
    if att is not None:
        r, p, y = frames.quat_to_euler(*(att[f"q[{i}]"].astype(float) for i in range(4)))
        r, p, y = frames.euler_ned_to_sim(r, p, y)
        for name, v, desc in (("roll", r, "roll"), ("pitch", p, "-pitch"), ("yaw", y, "-yaw")):
            out[name] = Channel(name, att["t"], v, f"vehicle_attitude.q -> ZYX {desc}")
    av = tp.get("vehicle_angular_velocity")
    if av is not None:
        p, q, r = frames.frd_to_sim(*(av[f"xyz[{i}]"].astype(float) for i in range(3)))
        src = "vehicle_angular_velocity.xyz"
    elif att is not None and "rollspeed" in att:  # PX4 < 1.10 logged the rates with the attitude
        p, q, r = frames.frd_to_sim(att["rollspeed"].astype(float), att["pitchspeed"].astype(float),
                                    att["yawspeed"].astype(float))
        src, av = "vehicle_attitude.rollspeed/pitchspeed/yawspeed", att
    else:
        return
    for name, v, k in (("p", p, "[0]"), ("q", q, "[1], negated"), ("r", r, "[2], negated")):
        out[name] = Channel(name, av["t"], v, f"{src}{k}")


def battery_channels(tp: Topics, out: dict, status: dict) -> float:
    """V_b, I_b, SoC of battery_status instance 0; returns the highest usable voltage (NaN if none)."""
    b = tp.get("battery_status")
    if b is None:
        return float("nan")
    v = b["voltage_v"].astype(float)
    connected = b["connected"].astype(bool) if "connected" in b else np.ones(len(v), bool)
    if not connected.any():
        why = f"unusable: battery monitor disconnected (connected = 0, {np.nanmedian(v):.2f} V)"
        for name in ("V_b", "I_b", "SoC"):
            status[name] = why
        return float("nan")
    cur = b["current_a"].astype(float)
    rem = b["remaining"].astype(float)
    out["V_b"] = Channel("V_b", b["t"], np.where(connected, v, np.nan), "battery_status[0].voltage_v")
    if np.all(cur < 0):
        status["I_b"] = "unusable: current logged as -1 (no current sensor)"
    else:
        out["I_b"] = Channel("I_b", b["t"], np.where(connected & (cur >= 0), cur, np.nan), "battery_status[0].current_a")
    out["SoC"] = Channel("SoC", b["t"], np.where(connected & (rem >= 0), rem, np.nan),
                         "battery_status[0].remaining (the autopilot's estimate)")
    return float(np.nanmax(np.where(connected, v, np.nan)))


def read_topic(path: str, name: str) -> dict | None:
    """Instance 0 of one topic, read from the log on demand (times as in Topics)."""
    ulog = open_ulog_topics(path, [name])
    return Topics(ulog, []).get(name)


def flight_state(tp: Topics, lr: LogRead) -> None:
    """Armed (vehicle_status.arming_state == 2) and airborne (armed and not landed) intervals."""
    t_end = lr.data_span[1]
    vs, ld = tp.get("vehicle_status"), tp.get("vehicle_land_detected")
    if vs is not None:
        lr.armed = segments.step_intervals(vs["t"], vs["arming_state"] == 2, t_end)
    if ld is not None:
        flying = segments.step_intervals(ld["t"], ld["landed"] == 0, t_end)
        lr.airborne = segments.intersect(flying, lr.armed) if vs is not None else flying
        lr.airborne_source = "vehicle_land_detected.landed == 0" + (" and armed" if vs is not None else "")
        return
    thr = [lr.channels[f"thr{i}"] for i in range(1, 5) if f"thr{i}" in lr.channels]
    if thr and "z" in lr.channels:
        t = thr[0].t
        thr_mean = np.mean([c.v for c in thr], axis=0)
        z = np.interp(t, lr.channels["z"].t, lr.channels["z"].v)
        lr.airborne = segments.fallback_airborne(t, thr_mean, z - np.nanmin(z), t_end)
        lr.airborne_source = "fallback: mean motor command > 0.15 and height > 0.5 m"


def read_px4(path: str) -> LogRead:
    ulog = open_ulog(path)
    params = ulog.initial_parameters
    notes: list[str] = []
    tp = Topics(ulog, notes)
    if not tp.by_name:
        raise QuadfdiError(f"{path}: no flight topics in the log")
    check_multirotor(params, tp)
    rotors, geo_src = motors.px4_geometry(params)
    mmap = motors.motor_map(rotors)
    lr = LogRead("px4", {}, {}, {"frame": "quadrotor", "geometry_source": geo_src, "motor_map": mmap,
                                 "mav_type": int(params["MAV_TYPE"]), "airframe": int(params.get("SYS_AUTOSTART", 0))},
                 [], [], "none", tp.span(), notes)
    position_channels(tp, lr.channels, lr.status)
    attitude_channels(tp, lr.channels)
    v_max = battery_channels(tp, lr.channels, lr.status)
    px4_vibration.vibration_channel(tp, ulog.msg_info_dict, lambda name: read_topic(path, name), lr)
    lr.status["vib_ap"] = "absent: ArduPilot's VIBE metric (a PX4 log carries vib_px4)"
    px4_motors.motor_channels(tp, params, mmap, lr)
    px4_motors.esc_channels(tp, mmap, lr)
    b = tp.get("battery_status")
    cc = int(np.max(b["cell_count"])) if b is not None and "cell_count" in b else None
    lr.vehicle["battery"] = battery.cell_count(
        [("battery_status.cell_count", cc), ("BAT1_N_CELLS", params.get("BAT1_N_CELLS")),
         ("BAT_N_CELLS", params.get("BAT_N_CELLS"))], v_max)
    flight_state(tp, lr)
    checks.plausibility(lr)
    return lr
