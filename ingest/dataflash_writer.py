"""A simulated flight as an ArduCopter DataFlash log (.BIN), at ArduCopter's logging rates: the inverse of
``ingest.ardupilot``, so that a simulated fault can be replayed through any tool that reads such logs.

    python -m quadfdi.ingest.dataflash_writer DATASET.npz INDEX TEMPLATE.BIN OUT.BIN

The message formats are not written here: they are copied, byte for byte, from the FMT records of
``TEMPLATE.BIN``, a log of the ArduCopter firmware whose logs you want to imitate (any ArduCopter log
holds the FMT records of the messages it can write). So the file is what that firmware writes, and
pymavlink's own reader parses it without knowing this module.

Messages (ArduCopter's defaults on boards that log at 10 Hz): PARM (frame quad-X, motor PWM range and
thrust expo, SERVO1..4_FUNCTION 33..36, BATT_CELLS), MSG (the firmware line), ARM, then at
``RATE_HZ``: XKF1 (core 0: NED position and velocity), ATT (roll, pitch, yaw, deg), RATE (deg/s),
BAT (volt, current, remaining %), RCOU (C1..C4 PWM), VIBE (IMU 0), CTUN (throttle out, altitude).
A simulated flight has no take-off: the log holds one second armed on the ground at home
(CTUN only) before it, and CTUN's altitude is above a home ``HOME_BELOW_M`` under the flight's lowest
point. Frames and units are the inverse of ``ingest.ardupilot``'s (sim z-up/FLU -> NED/FRD, rad -> deg),
motors are renumbered from the project's order to ArduCopter's quad-X, and each motor's thrust
command becomes PWM through the inverse of the thrust curve ``thr = (1 - k) a + k a^2``. VIBE's X and
Y are the flight's ``vib_ap`` (the in-plane mean ingest reads back), Z the same (the simulator has no
vertical vibration model; ingest does not read VibeZ).
"""

from __future__ import annotations

import argparse
import struct
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.ingest import motors

HEAD = b"\xa3\x95"
FMT_TYPE = 128
RATE_HZ = 10.0
HOME_BELOW_M = 2.0  # m: home (CTUN altitude 0) below the flight's lowest point, clear of ArduCopter's 0.5 m rule
WANTED = ("PARM", "MSG", "ARM", "XKF1", "ATT", "RATE", "BAT", "RCOU", "VIBE", "CTUN")
PWM_MIN, PWM_MAX, EXPO = 1100.0, 1900.0, 0.65  # ArduCopter's defaults (MOT_PWM_MIN/MAX via RC3, MOT_THST_EXPO)
FIRMWARE = "ArduCopter V4.5.7 (quadfdi simulated flight)"
# struct letters of DataFlash format characters (AP_Logger/LogStructure.h)
_LETTER = {"b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "f": "f", "d": "d", "n": "4s", "N": "16s",
           "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i", "M": "B", "q": "q", "Q": "Q", "a": "64s"}
_SCALED = {"c": 100.0, "C": 100.0, "e": 100.0, "E": 100.0, "L": 1e7}  # stored as value x scale


class Format:
    """One message's format (from a FMT record): type id, name, format characters, columns."""

    def __init__(self, type_id: int, length: int, name: str, chars: str, columns: list[str]) -> None:
        self.type_id, self.length, self.name, self.chars, self.columns = type_id, length, name, chars, columns
        self.struct = struct.Struct("<" + "".join(_LETTER[c] for c in chars))
        if self.struct.size + 3 != length:
            raise QuadfdiError(f"FMT {name}: format {chars!r} packs {self.struct.size + 3} bytes, the record says {length}")

    def pack(self, **values: float | str) -> bytes:
        out = []
        for c, col in zip(self.chars, self.columns):
            v = values.get(col, 0)
            if c in "nNZa":
                out.append(str(v).encode("ascii"))
            elif c in "fd":
                out.append(float(v))
            else:
                out.append(int(round(float(v) * _SCALED.get(c, 1.0))))
        return HEAD + bytes([self.type_id]) + self.struct.pack(*out)


def template_formats(path: str | Path) -> tuple[bytes, dict[str, Format]]:
    """(the FMT records of ``WANTED`` and of FMT itself, as found in the template log; {name: Format})."""
    data = Path(path).read_bytes()
    fmt_len = 89  # FMT's own record: head, type, length, name[4], format[16], columns[64]
    records, formats, off = [], {}, 0
    while True:
        off = data.find(HEAD + bytes([FMT_TYPE]), off)
        if off < 0 or off + fmt_len > len(data):
            break
        rec = data[off:off + fmt_len]
        type_id, length = rec[3], rec[4]
        name = rec[5:9].rstrip(b"\0").decode("ascii", "replace")
        chars = rec[9:25].rstrip(b"\0").decode("ascii", "replace")
        cols = rec[25:89].rstrip(b"\0").decode("ascii", "replace").split(",")
        if (name in WANTED or type_id == FMT_TYPE) and name not in formats:
            formats[name] = Format(type_id, length, name, chars, cols)
            records.append(rec)
        off += fmt_len
    missing = [n for n in WANTED if n not in formats]
    if missing:
        raise QuadfdiError(f"{path}: no FMT record for {', '.join(missing)} (not an ArduCopter DataFlash log?)")
    return b"".join(records), formats


def _pwm(thr: np.ndarray) -> np.ndarray:
    """PWM of thrust fractions: the inverse of ingest.motors.pwm_to_thrust's curve."""
    t = np.clip(np.asarray(thr, np.float64), 0.0, 1.0)
    a = (-(1 - EXPO) + np.sqrt((1 - EXPO) ** 2 + 4 * EXPO * t)) / (2 * EXPO)
    return PWM_MIN + a * (PWM_MAX - PWM_MIN)


def _params(cells: int) -> dict[str, float]:
    out = {"FRAME_CLASS": 1, "FRAME_TYPE": 1, "MOT_PWM_MIN": PWM_MIN, "MOT_PWM_MAX": PWM_MAX, "MOT_THST_EXPO": EXPO,
           "BATT_CELLS": cells, "LOG_BITMASK": 176126}
    out.update({f"SERVO{k}_FUNCTION": 32 + k for k in range(1, 5)})
    return out


def flight_records(f: dict[str, Format], cols: dict[str, np.ndarray], t: np.ndarray, cells: int) -> list[bytes]:
    """The records of one flight: ``cols`` name -> (T,) in the simulator's frames, ``t`` (T,) seconds.
    A simulated flight starts and ends in the air: home is put ``HOME_BELOW_M`` below its lowest point."""
    ground = float(np.min(cols["z"])) - HOME_BELOW_M
    us = lambda s: int(round((s + 1.0) * 1e6))  # noqa: E731 - the log starts a second before the flight
    out = [f["PARM"].pack(TimeUS=us(-1.0), Name=k, Value=v, Default=v) for k, v in _params(cells).items()]
    out += [f["MSG"].pack(TimeUS=us(-1.0), Message=FIRMWARE), f["ARM"].pack(TimeUS=us(-1.0), ArmState=1, Method=0)]
    # armed on the ground at home for the second before the flight: ArduCopter's airborne rule reads the
    # altitude above its minimum, so the log must show the ground
    out += [f["CTUN"].pack(TimeUS=us(k / RATE_HZ - 1.0), ThO=0.0, Alt=0.0, BAlt=0.0) for k in range(int(RATE_HZ))]
    log_of = motors.motor_map(motors.QUAD_X)  # project rotor k -> ArduCopter motor index
    for i in np.flatnonzero(np.diff(np.floor(t * RATE_HZ), prepend=-1) > 0):
        c = {k: float(v[i]) for k, v in cols.items()}
        ts = us(float(t[i]))
        out.append(f["XKF1"].pack(TimeUS=ts, C=0, Roll=np.degrees(c["roll"]), Pitch=-np.degrees(c["pitch"]),
                                  Yaw=np.degrees(-c["yaw"]) % 360.0, VN=c["vx"], VE=-c["vy"], VD=-c["vz"],
                                  PN=c["x"], PE=-c["y"], PD=-c["z"]))
        out.append(f["ATT"].pack(TimeUS=ts, Roll=np.degrees(c["roll"]), Pitch=-np.degrees(c["pitch"]),
                                 Yaw=np.degrees(-c["yaw"]) % 360.0))
        out.append(f["RATE"].pack(TimeUS=ts, R=np.degrees(c["p"]), P=-np.degrees(c["q"]), Y=-np.degrees(c["r"])))
        out.append(f["BAT"].pack(TimeUS=ts, Inst=0, Volt=c["V_b"], Curr=c["I_b"], RemPct=int(round(100 * c["SoC"]))))
        pwm = _pwm(np.array([c[f"thr{k + 1}"] for k in range(4)]))
        out.append(f["RCOU"].pack(TimeUS=ts, **{f"C{log_of[k] + 1}": pwm[k] for k in range(4)}))
        out.append(f["VIBE"].pack(TimeUS=ts, IMU=0, VibeX=c["vib_ap"], VibeY=c["vib_ap"], VibeZ=c["vib_ap"]))
        thr_out = float(np.mean([c[f"thr{k + 1}"] for k in range(4)]))
        alt = c["z"] - ground  # above home
        out.append(f["CTUN"].pack(TimeUS=ts, ThO=thr_out, Alt=alt, BAlt=alt))
    return out


def dataflash_bytes(arrays: dict, index: int, template: str | Path) -> bytes:
    """A realistic-suite dataset's flight ``index`` (``arrays``: dataset.npz's arrays) as a .BIN file's bytes."""
    names = [str(n) for n in arrays["channel_names"]]
    need = ("x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "V_b", "I_b", "SoC",
            "thr1", "thr2", "thr3", "thr4", "vib_ap")
    missing = [n for n in need if n not in names]
    if missing:
        raise QuadfdiError(f"the dataset lacks {', '.join(missing)} (a realistic-suite dataset has them)")
    if not 0 <= index < arrays["telemetry"].shape[0]:
        raise QuadfdiError(f"the dataset has flights 0..{arrays['telemetry'].shape[0] - 1}, not {index}")
    fmt_records, formats = template_formats(template)
    cols = {n: np.asarray(arrays["telemetry"][index, :, names.index(n)], np.float64) for n in need}
    cells = int(arrays["pack_cells"][index]) if "pack_cells" in arrays else 0
    return fmt_records + b"".join(flight_records(formats, cols, np.asarray(arrays["time"], np.float64), cells))


def main(argv: list[str] | None = None) -> int:
    from quadfdi.core.atomic import write_bytes
    from quadfdi.formats.dataset import load_dataset

    p = argparse.ArgumentParser(prog="python -m quadfdi.ingest.dataflash_writer", description=__doc__.split("\n\n")[0])
    p.add_argument("dataset")
    p.add_argument("index", type=int)
    p.add_argument("template", help="an ArduCopter .BIN log whose FMT records are copied")
    p.add_argument("out")
    a = p.parse_args(argv)
    try:
        data = dataflash_bytes(load_dataset(a.dataset).arrays, a.index, a.template)
        write_bytes(Path(a.out), data)
    except (QuadfdiError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
