"""``vehicle.json``: a reference of one airframe, learned from its own healthy flights (docs/formats.md,
"Vehicle reference"; written by ``quadfdi vehicle learn``, read by ``quadfdi vehicle rules`` and
``quadfdi detect --vehicle``), and the vehicles map of ``quadfdi detect --vehicles`` (``read_vehicle_map``).

Strict JSON (no NaN: a quantity that cannot be estimated is ``null``), top-level keys:

- ``format_version`` (1; ``load_vehicle`` refuses any other), ``kind`` (``"quadfdi vehicle reference"``).
- ``vehicle``: ``autopilot``, ``frame``, ``cells``, ``motor_map`` (log motor index, 0-based, of project
  rotors 1..4), ``log_motor_names`` (the log's names of its motors, in the log's order).
- ``flights``: one entry per flight it was learned from: ``file``, ``sha256`` (of the file given),
  ``log_file``, ``log_sha256`` (the source log), ``airborne_s``.
- ``settings``: the constants of the estimate (minimum airborne seconds, window, disagreement k, ...).
- ``motor_share``: four entries in project rotor order, each a *statistic* (below) plus ``rotor``
  (1..4) and ``log_motor`` (the log's name).
- ``share_model``, ``hover``, ``battery``, ``vibration``, ``esc``, ``motor_temp`` (per motor, T_k minus
  the four's mean: simulated flights only): the other quantities (null or empty when not logged);
  ``warnings``: the disagreements found (kept, not refused).

A *statistic* is ``mean`` (over the flights' means), ``between_std`` (std of the flights' means, ddof 1;
null with one flight), ``within_std`` (RMS over flights of the std over a flight's samples),
``window_std`` (the same for 2 s window means), ``se`` (RMS over flights of a flight mean's standard
error, window_std / sqrt(windows)), ``seconds`` (samples it rests on, all flights) and ``flights``:
per flight ``mean``, ``within_std``, ``window_std``, ``windows``, ``seconds``, in ``flights`` order.
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json, write_json

FORMAT_VERSION = 1
KIND = "quadfdi vehicle reference"
VEHICLE_KEYS = ("autopilot", "frame", "cells", "motor_map", "log_motor_names")
STAT_KEYS = ("mean", "between_std", "within_std", "window_std", "se", "seconds", "flights")
REGRESSORS = ("v_forward", "yaw_rate")  # the share model's (vehicle/fits.share_model)


def write_vehicle(path: str | Path, reference: dict) -> None:
    """Write a reference (checked first, so that nothing this reader would refuse reaches the disk)."""
    check_vehicle(reference, str(path))
    write_json(path, reference)


def load_vehicle(path: str | Path) -> dict:
    """A vehicle.json's content, checked; one-line QuadfdiError naming the file and the field."""
    data = read_json(path, "vehicle reference")
    check_vehicle(data, str(path))
    return data


def _number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def check_stat(stat, n_flights: int, where: str, nullable: bool = False) -> None:
    """A statistic's keys, its numbers and one per-flight entry (with its mean) per flight; the means must
    be numbers, or, ``nullable``, may be null (a quantity a flight could not estimate)."""
    ok = _optional_number if nullable else _number
    if not isinstance(stat, dict) or any(k not in stat for k in STAT_KEYS):
        raise QuadfdiError(f"{where}: expected the keys {', '.join(STAT_KEYS)}")
    if not ok(stat["mean"]):
        raise QuadfdiError(f"{where}.mean is {stat['mean']!r}, expected a number{' or null' if nullable else ''}")
    per = stat["flights"]
    if not isinstance(per, list) or len(per) != n_flights:
        raise QuadfdiError(f"{where}.flights holds {len(per) if isinstance(per, list) else per!r} entries, "
                           f"expected one per flight ({n_flights})")
    if not all(isinstance(f, dict) and ok(f.get("mean")) for f in per):
        raise QuadfdiError(f"{where}.flights: each flight's entry needs its mean (a number"
                           f"{' or null' if nullable else ''})")
    if not all(_optional_number(stat[k]) for k in ("between_std", "within_std", "window_std", "se", "seconds")):
        raise QuadfdiError(f"{where}: between_std, within_std, window_std, se and seconds must be numbers or null")


def check_vehicle(data, where: str) -> None:
    """The fields a reader relies on (version first: a file of another version is refused as a whole)."""
    if not isinstance(data, dict) or data.get("kind") != KIND:
        raise QuadfdiError(f"{where} is not a quadfdi vehicle reference (no kind {KIND!r}; make one with "
                           "`quadfdi vehicle learn`)")
    if data.get("format_version") != FORMAT_VERSION:
        raise QuadfdiError(f"{where} has format_version {data.get('format_version')!r}, this quadfdi reads "
                           f"{FORMAT_VERSION} (re-run `quadfdi vehicle learn` on its flights)")
    veh = data.get("vehicle")
    if not isinstance(veh, dict) or any(k not in veh for k in VEHICLE_KEYS):
        raise QuadfdiError(f"{where}: vehicle must hold {', '.join(VEHICLE_KEYS)}")
    if sorted(veh["motor_map"]) != [0, 1, 2, 3] or len(veh["log_motor_names"]) != 4:
        raise QuadfdiError(f"{where}: vehicle.motor_map {veh['motor_map']!r} is not a permutation of the four "
                           f"motors, or log_motor_names {veh['log_motor_names']!r} does not name four")
    flights = data.get("flights")
    if not isinstance(flights, list) or not flights or not all(
            isinstance(f, dict) and all(isinstance(f.get(k), str) for k in ("file", "sha256", "log_sha256"))
            and _number(f.get("airborne_s")) for f in flights):
        raise QuadfdiError(f"{where}: flights must list the flights it was learned from, each with its file, sha256, "
                           "log_sha256 and airborne_s")
    shares = data.get("motor_share")
    if not isinstance(shares, list) or len(shares) != 4:
        raise QuadfdiError(f"{where}: motor_share must hold four entries (project rotors 1..4)")
    for k, entry in enumerate(shares):
        check_stat(entry, len(flights), f"{where}: motor_share[{k}]")
        _motor_entry(entry, k, f"{where}: motor_share[{k}]")
    n = len(flights)
    _check_share_model(data.get("share_model"), f"{where}: share_model")
    _check_hover(data.get("hover"), n, f"{where}: hover")
    _check_battery(data.get("battery"), n, f"{where}: battery")
    _check_sections(data, n, where)


def _fail(where: str, what: str) -> None:
    raise QuadfdiError(f"{where}: {what} (the file is not as `quadfdi vehicle learn` writes it; learn it again)")


def _optional_number(x) -> bool:
    return x is None or _number(x)


def _motor_entry(entry: dict, k: int, where: str) -> None:
    if entry.get("rotor") != k + 1 or not isinstance(entry.get("log_motor"), str):
        _fail(where, f"expected rotor {k + 1} and the log's motor name, found rotor {entry.get('rotor')!r}, "
                     f"log_motor {entry.get('log_motor')!r}")


def _check_summary(x, n: int, where: str, mean_required: bool = False) -> None:
    """A per-flight coefficient (vehicle/fits.summary): mean, between_std (numbers or null), one value per flight."""
    if not isinstance(x, dict) or any(k not in x for k in ("mean", "between_std", "flights")):
        _fail(where, "expected mean, between_std and flights")
    if not (_number(x["mean"]) if mean_required else _optional_number(x["mean"])) or \
            not _optional_number(x["between_std"]):
        _fail(where, f"mean {x['mean']!r} and between_std {x['between_std']!r} must be numbers"
                     + ("" if mean_required else " or null"))
    if not isinstance(x["flights"], list) or len(x["flights"]) != n or not all(map(_optional_number, x["flights"])):
        _fail(where, f"flights must hold one number (or null) per flight ({n})")


def _check_share_model(m, where: str) -> None:
    if not isinstance(m, dict) or not isinstance(m.get("regressors"), list) or \
            not set(m["regressors"]) <= set(REGRESSORS) or not isinstance(m.get("range_5_95"), dict):
        _fail(where, f"expected regressors (some of {', '.join(REGRESSORS)}) and range_5_95")
    for name in m["regressors"]:
        r = m["range_5_95"].get(name)
        if not isinstance(r, list) or len(r) != 2 or not all(map(_number, r)) or r[0] > r[1]:
            _fail(f"{where}.range_5_95", f"{name} must be [low, high], found {r!r}")
    if "yaw_rate" in m["regressors"] and not isinstance(m.get("yaw_rate_source"), list):
        _fail(where, "yaw_rate_source must list where the yaw rate came from")
    motors = m.get("motors")
    if motors is None:
        return
    keys = ("intercept", "residual_std", "seconds", *(f"per_{r}" for r in m["regressors"]))
    if not isinstance(motors, list) or len(motors) != 4 or \
            not all(isinstance(x, dict) and all(_number(x.get(k)) for k in keys) for x in motors):
        _fail(f"{where}.motors", f"expected null or four lines, each with the numbers {', '.join(keys)}")
    for k, x in enumerate(motors):
        _motor_entry(x, k, f"{where}.motors[{k}]")


def _check_hover(h, n: int, where: str) -> None:
    if not isinstance(h, dict) or any(k not in h for k in ("cmd", "cur_a", "freeze_s", "collective")):
        _fail(where, "expected cmd, cur_a, freeze_s and collective")
    _check_summary(h["cmd"], n, f"{where}.cmd", mean_required=True)
    _check_summary(h["cur_a"], n, f"{where}.cur_a")
    if not isinstance(h["freeze_s"], list) or len(h["freeze_s"]) != n:
        _fail(f"{where}.freeze_s", f"expected one value per flight ({n})")
    check_stat(h["collective"], n, f"{where}.collective", nullable=True)


def _check_battery(b, n: int, where: str) -> None:
    if b is None:
        return
    if not isinstance(b, dict) or b.get("mode") not in ("sag", "level") or not isinstance(b.get("cells"), int) \
            or b["cells"] < 1:
        _fail(where, "expected null or a pack model with mode 'sag' or 'level' and a cell count")
    for key in ("v0", "drift_v_per_min", "level", "residual_std") + (("sag_v_per_a",) if b["mode"] == "sag" else ()):
        _check_summary(b.get(key), n, f"{where}.{key}")


def _check_sections(data: dict, n: int, where: str) -> None:
    """vibration, esc, motor_temp and warnings."""
    vib = data.get("vibration")
    if not isinstance(vib, dict):
        _fail(where, "vibration must be an object (empty when no flight logs it)")
    for name, v in vib.items():
        if not isinstance(v, dict) or not isinstance(v.get("unit"), str):
            _fail(f"{where}: vibration.{name}", "expected unit, level, floor, per_collective, residual_std")
        check_stat(v.get("level"), n, f"{where}: vibration.{name}.level", nullable=True)
        for key in ("floor", "per_collective", "residual_std"):
            _check_summary(v.get(key), n, f"{where}: vibration.{name}.{key}")
    esc = data.get("esc")
    if not isinstance(esc, dict):
        _fail(where, "esc must be an object (empty when no flight logs ESC telemetry)")
    for key, v in esc.items():
        motors = v.get("motors") if isinstance(v, dict) else None
        if not isinstance(motors, list) or len(motors) != 4 or not isinstance(v.get("unit"), str):
            _fail(f"{where}: esc.{key}", "expected unit and four motors")
        for k, m in enumerate(motors):
            check_stat(m, n, f"{where}: esc.{key}.motors[{k}]", nullable=True)
            _motor_entry(m, k, f"{where}: esc.{key}.motors[{k}]")
    temp = data.get("motor_temp")
    if temp is not None:
        if not isinstance(temp, list) or len(temp) != 4:
            _fail(where, "motor_temp must be null or four entries")
        for k, m in enumerate(temp):
            check_stat(m, n, f"{where}: motor_temp[{k}]", nullable=True)
    warnings = data.get("warnings")
    if not isinstance(warnings, list) or not all(isinstance(w, str) for w in warnings):
        _fail(where, "warnings must be a list of lines")


def read_vehicle_map(path: str | Path) -> list[tuple[str, Path]]:
    """A vehicles map: ``(log path glob, vehicle.json path)`` in the file's order, both relative to the map
    file's folder (an absolute one as it is). TOML (``"glob" = "vehicle.json"`` lines) or JSON (one object
    of the same), known by the suffix; one-line QuadfdiError for anything else."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"vehicles map {p} does not exist or is not a regular file")
    if p.suffix.lower() not in (".toml", ".json"):
        raise QuadfdiError(f"vehicles map {p}: expected a .toml or .json file (log path glob = vehicle.json)")
    if p.suffix.lower() == ".json":
        data = read_json(p, "vehicles map")
    else:
        import tomllib

        try:
            data = tomllib.loads(p.read_text())
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise QuadfdiError(f"vehicles map {p} cannot be read as TOML: {' '.join(str(exc).split())}") from None
    if not isinstance(data, dict) or not data:
        raise QuadfdiError(f"vehicles map {p}: expected at least one line `\"log path glob\" = \"vehicle.json\"`")
    bad = [k for k, v in data.items() if not k.strip() or not isinstance(v, str) or not v.strip()]
    if bad:
        raise QuadfdiError(f"vehicles map {p}: {bad[0]!r} must map a log path glob to a vehicle.json path (a string), "
                           f"not {data[bad[0]]!r}")
    return [(str(p.parent / k), p.parent / v) for k, v in data.items()]
