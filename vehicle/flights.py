"""The flights a reference is learned from or scored on: a log (PX4 ULog, ArduPilot DataFlash or
Crazyflie uSD log, ingested on the fly by ``ingest.flight.ingest``) or an ingested ``flight.npz``,
each with the sha256 of the file given; and which files of a folder are flights.

A file is known by its first bytes, never by its name (Crazyflie logs have no extension): the magic
numbers ``ingest.flight.read_log`` dispatches on, or a zip holding ``log_sha256.npy`` (flight.npz).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import file_sha256
from quadfdi.formats.flight import load_flight
from quadfdi.ingest.logkind import LOG_KINDS, log_kind, walk_logs


@dataclass
class Flight:
    """One flight on the 25 Hz grid: ``arrays`` as flight.npz holds them (docs/flight_format.md)."""

    name: str  # how reports name it: the path below the folder given (or the file's own name)
    path: Path
    sha256: str
    arrays: dict[str, np.ndarray] = field(repr=False)

    def __post_init__(self):
        self.names = [str(n) for n in self.arrays["channel_names"]]
        self.vehicle = json.loads(str(self.arrays["vehicle"]))

    @property
    def autopilot(self) -> str:
        return str(self.arrays["autopilot"])

    @property
    def airborne(self) -> np.ndarray:
        return np.asarray(self.arrays["airborne"], bool)

    @property
    def cells(self) -> int | None:
        return (self.vehicle.get("battery") or {}).get("cells")

    @property
    def log_motor_names(self) -> list[str]:
        """The log's own names of its motors, in the log's order (``M1``..``M4`` unless the log says)."""
        return list(self.vehicle.get("log_motor_names") or [f"M{i + 1}" for i in range(4)])

    def status(self, name: str) -> str:
        return str(self.arrays["channel_status"][self.names.index(name)]) if name in self.names else "absent"

    def usable(self, name: str) -> bool:
        return self.status(name) == "ok"

    def col(self, name: str) -> np.ndarray:
        """(T,) float64, NaN where the mask is False or the channel is not usable."""
        if not self.usable(name):
            return np.full(len(self.arrays["time"]), np.nan)
        j = self.names.index(name)
        x = self.arrays["telemetry"][:, j].astype(np.float64)
        return np.where(self.arrays["mask"][:, j], x, np.nan)


def file_kind(path: Path) -> str | None:
    """"log" (a file ``ingest`` reads), "flight.npz" or None, from the file's first bytes."""
    kind = log_kind(path)
    return "log" if kind in LOG_KINDS else kind


def find_flights(paths: list[str | Path]) -> list[tuple[Path, str]]:
    """(path, name) of every file given and every flight found (recursively, by content) in a folder given,
    in a stable order; a file given by name is kept whatever it holds (reading it then says why not).
    The name is the path below the folder given, prefixed with that folder's name; a file given alone is
    named with its own folder's name (``normal_flight/E8_log00``: CrazyPAD's file names repeat)."""
    for given in paths:
        if not Path(given).exists():
            raise QuadfdiError(f"{given} does not exist")
    # a file given alone is named with its own folder's name: the folder says the condition
    return [(f, "/".join(parts) if parts else f"{f.resolve().parent.name}/{f.name}") for f, parts in walk_logs(paths)]


def read_flight(path: str | Path, name: str | None = None, gap_factor: float | None = None) -> Flight:
    """One flight from a log (ingested with ingest's defaults, or bridging gaps up to ``gap_factor`` x a
    channel's median interval) or a flight.npz; a refused log raises the one-line QuadfdiError ingest gives."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"{p} does not exist or is not a regular file")
    if file_kind(p) == "flight.npz":
        arrays = load_flight(p)
    else:
        from quadfdi.ingest.flight import ingest

        arrays = ingest(p)[1] if gap_factor is None else ingest(p, gap_factor=gap_factor)[1]
    return Flight(name or p.name, p, file_sha256(p), arrays)
