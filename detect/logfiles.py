"""Which files of a folder are flight logs, the stable name of each flight's output folder, and the
date a log was flown.

A log is known by its first bytes, never by its name (Crazyflie uSD logs have no extension): the
magic numbers that ``ingest.flight.read_log`` dispatches on (``ULog``, DataFlash's ``A3 95``, the
Crazyflie event log's ``BC``), or an ingested ``flight.npz`` (a zip holding ``log_sha256.npy``).
Anything else in a folder (README, LICENSE, figures) is skipped without a word; a file named on the
command line is always tried, so that a foreign file gets its one-line refusal.

The date is the UTC time of the log's first sample where the log can say it: a PX4 ULog through
its GPS topic (``time_utc_usec`` at a known log timestamp, moved back to the log's start), a
DataFlash log through its first GPS message with a week number (``GWk``, ``GMS``: GPS time, minus
the 18 leap seconds since 1980); a Crazyflie log and a log without a GPS fix have none (None).
"""

from __future__ import annotations

import hashlib
import re
from collections import Counter
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from quadfdi.ingest.logkind import log_kind, walk_logs

GPS_EPOCH = datetime(1980, 1, 6, tzinfo=timezone.utc)
GPS_LEAP_S = 18  # GPS - UTC since 2017-01-01
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _safe(text: str) -> str:
    return _UNSAFE.sub("_", text).strip("._") or "log"


def find_logs(paths: list[str | Path]) -> list[tuple[Path, str]]:
    """(log path, output folder name) of every log given or found (recursively, by content) in a
    folder given, in a stable order. A file given by name is kept whatever it holds (its refusal
    is then reported); a folder's files are kept only when :func:`log_kind` knows them.

    The name is the path relative to the folder given, prefixed with that folder's name (a file
    given alone: its own name), with separators as ``__``: ``normal_flight__E8_log00``. Two paths
    that would share a name (the same file name in two folders given) both get a suffix of their
    absolute path's sha1, so a flight's folder depends only on its own path."""
    unique = [(f, "__".join(_safe(part) for part in parts) if parts else _safe(f.name))
              for f, parts in walk_logs(paths)]
    counts = Counter(name for _, name in unique)
    return [(f, name + "-" + hashlib.sha1(str(f.resolve()).encode()).hexdigest()[:8] if counts[name] > 1 else name)
            for f, name in unique]


def _ulog_date(path: Path) -> datetime | None:
    from pyulog import ULog

    try:
        u = ULog(str(path), ["vehicle_gps_position", "sensor_gps"], parse_header_only=False)
    except Exception:  # noqa: BLE001 (pyulog's own errors: the date is optional, ingest reports the log)
        return None
    for d in u.data_list:
        utc, ts = d.data.get("time_utc_usec"), d.data.get("timestamp")
        if utc is None or ts is None:
            continue
        ok = np.flatnonzero(utc > 0)
        if len(ok):
            start_us = int(utc[ok[0]]) - (int(ts[ok[0]]) - int(u.start_timestamp))
            return datetime.fromtimestamp(start_us * 1e-6, tz=timezone.utc)
    return None


def _dataflash_date(path: Path, max_messages: int = 200_000) -> datetime | None:
    """GPS time of the first 3D fix, moved back to the log's first ``TimeUS`` (ingest's time 0)."""
    from pymavlink import DFReader

    try:
        log = DFReader.DFReader_binary(str(path), zero_time_base=True)
        first_us = None
        for _ in range(max_messages):
            m = log.recv_msg()
            if m is None:
                return None
            t_us = getattr(m, "TimeUS", None)
            if t_us is None:
                continue
            first_us = int(t_us) if first_us is None else first_us
            if m.get_type() == "GPS" and getattr(m, "GWk", 0) and int(getattr(m, "Status", 0)) >= 3:
                gps = GPS_EPOCH + timedelta(weeks=int(m.GWk), milliseconds=int(m.GMS) - GPS_LEAP_S * 1000)
                return gps - timedelta(microseconds=int(t_us) - first_us)
    except Exception:  # noqa: BLE001 (pymavlink raises anything on a damaged log; the date is optional)
        return None
    return None


def log_date(path: Path) -> str | None:
    """The log's start as ``YYYY-MM-DD HH:MM UTC``, or None where the log cannot say."""
    kind = log_kind(path)
    when = _ulog_date(path) if kind == "ulog" else _dataflash_date(path) if kind == "dataflash" else None
    return None if when is None else when.strftime("%Y-%m-%d %H:%M UTC")
