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
  the four's mean: simulated flights only): the other quantities (null or empty when not logged); ``warnings``: the disagreements found (kept, not refused).

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


def check_stat(stat, n_flights: int, where: str) -> None:
    """A statistic's keys, a finite mean and one per-flight entry per flight."""
    if not isinstance(stat, dict) or any(k not in stat for k in STAT_KEYS):
        raise QuadfdiError(f"{where}: expected the keys {', '.join(STAT_KEYS)}")
    if not _number(stat["mean"]):
        raise QuadfdiError(f"{where}.mean is {stat['mean']!r}, expected a number")
    per = stat["flights"]
    if not isinstance(per, list) or len(per) != n_flights:
        raise QuadfdiError(f"{where}.flights holds {len(per) if isinstance(per, list) else per!r} entries, "
                           f"expected one per flight ({n_flights})")


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
    if not isinstance(flights, list) or not flights or not all(isinstance(f, dict) and "sha256" in f for f in flights):
        raise QuadfdiError(f"{where}: flights must list the flights it was learned from, each with its sha256")
    shares = data.get("motor_share")
    if not isinstance(shares, list) or len(shares) != 4:
        raise QuadfdiError(f"{where}: motor_share must hold four entries (project rotors 1..4)")
    for k, entry in enumerate(shares):
        check_stat(entry, len(flights), f"{where}: motor_share[{k}]")


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
