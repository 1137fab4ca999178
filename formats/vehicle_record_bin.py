"""The vehicle record file: a reference profile's vehicle record (core/vehicle_record.py, 25 float32) as
the C++ loads it at reset (``fwref_stream --vehicle RECORD.bin``, fwref/vehicle_record.hpp).

Little-endian, 116 bytes (the constants are core/vehicle_record.py's, generated into
fwref/vehicle_record_gen.hpp):

    0   char[8]   magic       b"QFDIVEH\\0"
    8   u32       version     2 (1, still read: 112 bytes, f32[24], every field before ``sag``, which is NaN)
    12  u32       profile     the id of the reference profile it is for (core/channels.py: 5 flightlog-ref, 6 flightlog-phys)
    16  f32[25]   record      core/vehicle_record.py's layout; NaN: the reference holds nothing there

A record with NaN in its first share is "no reference"; an infinite field is refused (by both readers).
"""

from __future__ import annotations

import os
import stat
import struct
from pathlib import Path

import numpy as np

from quadfdi.core import vehicle_record as vr
from quadfdi.core.channels import PROFILE_BY_NAME, PROFILE_TABLE
from quadfdi.core.errors import QuadfdiError

HEADER = struct.Struct("<8sII")
assert HEADER.size == vr.FILE_HEADER_BYTES


def check_profile(profile: str) -> int:
    """The id of reference profile ``profile``; a one-line QuadfdiError for a profile that reads no record."""
    p = PROFILE_BY_NAME.get(profile)
    if p is None or not p.reference:
        refs = [q.name for q in PROFILE_TABLE if q.reference]
        raise QuadfdiError(f"profile {profile!r} reads no vehicle record (the reference profiles: {', '.join(refs)})")
    return p.id


def check_record(record, where: str) -> np.ndarray:
    """``record`` as (25,) float32; a one-line QuadfdiError when it has another size or an infinite field."""
    rec = np.asarray(record, np.float32)
    if rec.shape != (vr.SIZE,):
        raise QuadfdiError(f"{where}: a vehicle record is {vr.SIZE} numbers, not shape {rec.shape}")
    if np.isinf(rec).any():
        raise QuadfdiError(f"{where}: vehicle record field {int(np.flatnonzero(np.isinf(rec))[0])} is infinite")
    return rec


def record_bytes(record, profile: str) -> bytes:
    """The 116 bytes of ``record`` for reference profile ``profile``."""
    rec = check_record(record, "vehicle record")
    return HEADER.pack(vr.FILE_MAGIC, vr.FILE_VERSION, check_profile(profile)) + rec.astype("<f4").tobytes()


def write_record(path: str | Path, record, profile: str) -> None:
    from quadfdi.core.atomic import write_bytes

    write_bytes(path, record_bytes(record, profile))


def parse_record(data: bytes, profile: str, where: str) -> np.ndarray:
    """The (25,) float32 record of a record file's bytes (version 1: ``sag`` NaN), for reference profile
    ``profile``; one-line QuadfdiError on a foreign, truncated or longer file, another version or profile."""
    want = check_profile(profile)
    if len(data) < 8 or data[:8] != vr.FILE_MAGIC:
        raise QuadfdiError(f"{where} is not a quadfdi vehicle record")
    version = HEADER.unpack_from(data)[1] if len(data) >= HEADER.size else None
    size = {1: vr.FILE_BYTES_V1, vr.FILE_VERSION: vr.FILE_BYTES}.get(version, vr.FILE_BYTES)
    if len(data) != size:
        raise QuadfdiError(f"{where} holds {len(data)} bytes, a vehicle record {size} (truncated or not a "
                           "vehicle record)")
    _, version, pid = HEADER.unpack_from(data)
    if version not in (1, vr.FILE_VERSION):
        raise QuadfdiError(f"{where} has vehicle record version {version}, this reader reads 1 and {vr.FILE_VERSION}")
    if pid != want:
        name = PROFILE_TABLE[pid].name if pid < len(PROFILE_TABLE) else f"id {pid}"
        raise QuadfdiError(f"{where} is for profile {name!r}, the model's is {profile!r}")
    fields = np.frombuffer(data, "<f4", (len(data) - HEADER.size) // 4, HEADER.size)
    return check_record(vr.from_v1(fields) if version == 1 else fields, where)


def read_record(path: str | Path, profile: str) -> np.ndarray:
    """Read a record file, bounded: a regular file of at most 1 MiB (as fwref/read_limits.hpp), then parsed."""
    where = f"vehicle record {path}"
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise QuadfdiError(f"cannot read {where}: {exc.strerror}") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise QuadfdiError(f"{where} is not a regular file")
    with os.fdopen(fd, "rb") as fh:
        data = fh.read(1 << 20)
    return parse_record(data, profile, where)


def record_from_vehicle_json(path: str | Path) -> np.ndarray:
    """The vehicle record (25,) float32 of a vehicle reference (``quadfdi vehicle learn``'s vehicle.json,
    checked by formats.vehicle.load_vehicle); one-line QuadfdiError when it holds no motor shares."""
    from quadfdi.formats.vehicle import load_vehicle

    try:
        return vr.from_reference(load_vehicle(path))
    except ValueError as exc:
        raise QuadfdiError(f"vehicle reference {path}: {exc}") from None
