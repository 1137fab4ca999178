"""Crazyflie uSD-card event log (version 2) reader: records -> project channels.

The format (Bitcraze's uSD-card deck event logging, as the CrazyPAD README documents it; all
integers little-endian): byte 0 ``0xBC``; uint16 version; uint16 number of event types; per event
type a uint16 id, its NUL-terminated name, a uint16 variable count and one NUL-terminated
``group.name(T)`` per variable (``T`` a Python ``struct`` letter); then records until the last
4 bytes: uint16 event id, uint64 timestamp (us), the type's variables packed in order; last, the
CRC-32 (zlib's) of every byte before it. The files carry no extension: ``read_log`` knows them by
their first byte and a readable header.

Frames: the Crazyflie's world frame is z up (x, y the positioning system's axes) and its body frame
x forward, y left, z up, the simulator's frames, so positions, velocities, roll and yaw enter as
logged (degrees to radians; a positive roll accelerates the vehicle towards -y, as the logs show:
the correlation of ``stateEstimate.ay`` with ``roll`` is -0.5 on healthy flights). Pitch, body
rates, current, temperatures and vibration are not logged.

Motor commands: ``motor.m1..m4`` (0-65535), the power the controller asks of each motor, become
``thr`` = m / 65535. ``pwm.m*`` is the same command after the firmware's battery compensation
(scaled up as the cell sags, to hold thrust); the simulator's ``thr`` is the commanded thrust
before the battery's effect (its Eq. 8 applies the voltage), so ``motor.m*`` is the matching
quantity, and a sagging pack does not move the four shares.

Motor numbering (Bitcraze, Crazyflie 2.x "system overview" and the firmware's quad-X mixer
``power_distribution_quadrotor.c``): M1 front-right, M2 rear-right, M3 rear-left, M4 front-left
seen from above; M1 and M3 turn counter-clockwise, M2 and M4 clockwise. ``ingest.motors.motor_map``
turns that into the project's order; ``vehicle.motor_map`` records it, so a motor named by detect
traces back to the log's M1-M4.

Airborne: these logs have no arming or land-detector flag. Armed = any motor command above zero;
airborne = armed, the mean command above ``THR_AIRBORNE`` and the height more than ``H_AIRBORNE``
above the ground level (the median height while the motors are off, else 0). The height rule
already ends a flight at touchdown, so no land-detector lag is cut back.
"""

from __future__ import annotations

import os
import stat
import struct
import zlib
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.ingest import battery, motors, segments
from quadfdi.ingest.model import Channel, LogRead

MAGIC = 0xBC
VERSION = 2
MAX_BYTES = 256 << 20  # a 100 Hz log of 20 variables grows ~25 MB per hour: far above any flight
COMMAND_FULL = 65535.0  # motor.m*: uint16 range of the controller's power command
THR_AIRBORNE = 0.2  # -: the CrazyPAD Crazyflie hovers at 0.55-0.7 of full command; off is 0
H_AIRBORNE = 0.15  # m: above the ground level; the logs hover at about 0.5 m
# (x forward, y right) in FRD and spin seen from above (+1 CCW), motors M1..M4 (module docstring)
CRAZYFLIE_X = ((1.0, 1.0, +1), (-1.0, 1.0, -1), (-1.0, -1.0, +1), (1.0, -1.0, -1))
_TYPES = {"B": "u1", "b": "i1", "H": "<u2", "h": "<i2", "I": "<u4", "i": "<i4", "Q": "<u8", "q": "<i8",
          "f": "<f4", "d": "<f8"}
_RECORD_HEAD = struct.Struct("<HQ")
ABSENT = "absent: not in this Crazyflie log configuration"


def _cstring(data: bytes, off: int, where: str) -> tuple[str, int]:
    end = data.find(b"\0", off)
    if end < 0:
        raise QuadfdiError(f"{where}: Crazyflie log header truncated (a name has no terminating NUL)")
    try:
        return data[off:end].decode("ascii"), end + 1
    except UnicodeDecodeError:
        raise QuadfdiError(f"{where}: Crazyflie log header holds a non-ASCII name (a foreign file?)") from None


def _u16(data: bytes, off: int, where: str) -> tuple[int, int]:
    if off + 2 > len(data):
        raise QuadfdiError(f"{where}: Crazyflie log header truncated at byte {off}")
    return struct.unpack_from("<H", data, off)[0], off + 2


def parse_header(data: bytes, where: str) -> tuple[dict[int, tuple[str, np.dtype]], int]:
    """({event id: (name, record dtype)}, offset of the first record); one-line error on a foreign file."""
    if len(data) < 9 or data[0] != MAGIC:
        raise QuadfdiError(f"{where}: not a Crazyflie uSD event log (first byte {data[:1].hex() or 'none'}, "
                           f"expected {MAGIC:#x})")
    version, off = _u16(data, 1, where)
    if version != VERSION:
        raise QuadfdiError(f"{where}: Crazyflie event log version {version}, this reader knows version {VERSION}")
    n_types, off = _u16(data, off, where)
    types: dict[int, tuple[str, np.dtype]] = {}
    for _ in range(n_types):
        eid, off = _u16(data, off, where)
        name, off = _cstring(data, off, where)
        n_vars, off = _u16(data, off, where)
        fields = []
        for _ in range(n_vars):
            var, off = _cstring(data, off, where)
            if not (var.endswith(")") and "(" in var and var[-2] in _TYPES):
                raise QuadfdiError(f"{where}: event {name!r} declares variable {var!r}; expected group.name(T) with "
                                   f"T one of {''.join(_TYPES)}")
            fields.append((var[:var.index("(")], _TYPES[var[-2]]))
        types[eid] = (name, np.dtype(fields))
    return types, off


def parse(data: bytes, where: str) -> tuple[dict[str, dict[str, np.ndarray]], list[str]]:
    """({event name: {"t": seconds since the first record, variable: values}} of the types that have
    records, [names of declared types without records])."""
    if len(data) < 4 or zlib.crc32(data[:-4]) != struct.unpack_from("<I", data, len(data) - 4)[0]:
        raise QuadfdiError(f"{where}: CRC-32 mismatch (truncated or corrupted Crazyflie log)")
    types, off = parse_header(data, where)
    end = len(data) - 4
    rows: dict[int, list[int]] = {}  # event id -> record offsets (after the record head)
    stamps: dict[int, list[int]] = {}
    while off < end:
        if off + _RECORD_HEAD.size > end:
            raise QuadfdiError(f"{where}: a record head is cut off at byte {off}")
        eid, t_us = _RECORD_HEAD.unpack_from(data, off)
        if eid not in types:
            raise QuadfdiError(f"{where}: record at byte {off} has event id {eid}, which the header does not declare")
        off += _RECORD_HEAD.size
        size = types[eid][1].itemsize
        if off + size > end:
            raise QuadfdiError(f"{where}: the record at byte {off - _RECORD_HEAD.size} is cut off")
        rows.setdefault(eid, []).append(off)
        stamps.setdefault(eid, []).append(t_us)
        off += size
    if not rows:
        raise QuadfdiError(f"{where}: the log holds no records")
    t0 = min(s[0] for s in stamps.values())
    out: dict[str, dict[str, np.ndarray]] = {}
    buf = np.frombuffer(data, np.uint8)
    for eid, offsets in rows.items():
        name, dt = types[eid]
        idx = np.asarray(offsets)[:, None] + np.arange(dt.itemsize)
        rec = buf[idx].copy().view(dt).reshape(-1)  # (n,) structured: one row per record
        cols = {f: rec[f].astype(np.float64) for f in dt.names}
        cols["t"] = (np.asarray(stamps[eid], np.float64) - t0) / 1e6
        out[name] = cols
    return out, [name for eid, (name, _) in types.items() if eid not in rows]


def read_bytes(path: str) -> bytes:
    """The file's bytes, refusing a non-regular file or one over MAX_BYTES before reading it."""
    try:
        st = os.stat(path)
    except OSError as exc:
        raise QuadfdiError(f"cannot read {path}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise QuadfdiError(f"{path} is not a regular file")
    if st.st_size > MAX_BYTES:
        raise QuadfdiError(f"{path} holds {st.st_size} bytes, more than a Crazyflie log can ({MAX_BYTES})")
    return Path(path).read_bytes()


def _channels(c: dict[str, np.ndarray], mmap: list[int], lr: LogRead) -> None:
    t = c["t"]
    for name in ("x", "y", "z", "vx", "vy", "vz"):
        lr.channels[name] = Channel(name, t, c[f"stateEstimate.{name}"], f"stateEstimate.{name}")
    lr.channels["roll"] = Channel("roll", t, np.radians(c["stateEstimate.roll"]), "stateEstimate.roll (deg -> rad)")
    if "stateEstimate.yaw" in c:
        yaw = (np.radians(c["stateEstimate.yaw"]) + np.pi) % (2 * np.pi) - np.pi
        lr.channels["yaw"] = Channel("yaw", t, yaw, "stateEstimate.yaw (deg -> rad)")
    else:
        lr.status["yaw"] = "absent: stateEstimate.yaw not logged"
    lr.channels["V_b"] = Channel("V_b", t, c["pm.vbatMV"] / 1000.0, "pm.vbatMV (mV -> V)")
    for k, m in enumerate(mmap):
        lr.channels[f"thr{k + 1}"] = Channel(f"thr{k + 1}", t, c[f"motor.m{m + 1}"] / COMMAND_FULL,
                                             f"motor.m{m + 1} / {COMMAND_FULL:g} (power command, before battery "
                                             "compensation)")
    for name in ("pitch", "p", "q", "r", "I_b", "SoC", "T1", "T2", "T3", "T4", "vib_px4", "vib_ap",
                 *(f"{g}{k}" for g in ("rpm", "esc_temp", "esc_cur") for k in range(1, 5))):
        lr.status.setdefault(name, ABSENT)


def _flight_state(c: dict[str, np.ndarray], lr: LogRead) -> None:
    t, t_end = c["t"], lr.data_span[1]
    cmd = np.mean([c[f"motor.m{k}"] for k in range(1, 5)], axis=0) / COMMAND_FULL
    z = c["stateEstimate.z"]
    off = cmd <= 0.0
    ground = float(np.median(z[off])) if off.any() else 0.0
    lr.armed = segments.step_intervals(t, cmd > 0.0, t_end)
    lr.airborne = segments.step_intervals(t, (cmd > THR_AIRBORNE) & (z - ground > H_AIRBORNE), t_end)
    lr.airborne_source = (f"inferred (no land detector in the log): mean motor.m* > {THR_AIRBORNE:g} of full "
                          f"command and stateEstimate.z > {H_AIRBORNE:g} m above the ground level "
                          f"({ground:+.3f} m, the median height with the motors off)")
    lr.landing_lag = False


def read_crazyflie(path: str) -> LogRead:
    """LogRead of a Crazyflie uSD event log: its ``fixedFrequency`` (or only) event type with motor and
    state variables."""
    where = Path(path).name
    events, silent = parse(read_bytes(path), where)
    need = ("motor.m1", "motor.m2", "motor.m3", "motor.m4", "pm.vbatMV", "stateEstimate.z")
    found = [n for n, cols in events.items() if all(k in cols for k in need)]
    if not found:
        raise QuadfdiError(f"{where}: no event type logs {', '.join(need)} (found {', '.join(events)})")
    c = events[found[0]]
    missing = [k for k in ("x", "y", "vx", "vy", "vz", "roll") if f"stateEstimate.{k}" not in c]
    if missing:
        raise QuadfdiError(f"{where}: the log lacks stateEstimate.{', stateEstimate.'.join(missing)}")
    mmap = motors.motor_map(CRAZYFLIE_X)
    span = (0.0, float(c["t"][-1]))
    lr = LogRead("crazyflie", {}, {}, {"frame": "quadrotor", "motor_map": mmap, "log_motor_names": ["M1", "M2", "M3", "M4"],
                                       "geometry_source": "Crazyflie 2.x quad-X: M1 front-right (CCW), M2 rear-right "
                                                          "(CW), M3 rear-left (CCW), M4 front-left (CW)",
                                       "motor_command": "motor.m* (before battery compensation; pwm.m* not used)",
                                       "event_type": found[0]},
                 [], [], "none", span, [])
    _channels(c, mmap, lr)
    lr.vehicle["battery"] = battery.cell_count([("Crazyflie 2.x (one 1S LiPo)", 1)], float(np.max(c["pm.vbatMV"]) / 1000.0))
    _flight_state(c, lr)
    if silent:
        lr.note(f"declared event types without records (ignored): {', '.join(silent)}")
    return lr
