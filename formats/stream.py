"""Stream files (docs/formats.md "Stream file"): a flight as the raw telemetry stream a flight
controller would deliver, for ``fwref_stream`` (firmware_ref's streaming runtime).

Little-endian; a 128-byte fixed header, the channel names, then the samples:

    0   char[8]   magic          b"QFDISTR\\0"
    8   u32       version        4 with a vehicle record, else 2 (1: no carried flags, every channel carried; 3:
                                 a version 1 vehicle record, f32[24], still read)
    12  u32       header_bytes   where the samples begin (128 + names + flags, padded to a multiple of 8)
    16  u32       n_channels     R
    20  u32       cells          the pack's cell count (0: unknown / not needed)
    24  f64       sample_dt_s    the grid period (0.04)
    32  char[32]  profile        the channel profile the stream is for (core.profiles), NUL-padded
    64  char[64]  source         the flight it came from, NUL-padded (truncated)
    128 names     R channel names, each NUL-terminated ASCII
        carried   u8[R] (version 2): 1 the stream carries the channel, 0 the flight lacks it (its column
                  is NaN throughout)
        vehicle   f32[25] (version 4; f32[24] version 3, its ``sag`` NaN): the vehicle record the stream
                  replays with (core/vehicle_record.py, a reference profile only; unaligned, read by copying);
                  then zero padding
    SAMPLES       f64 t (s), f32 values[R]   (8 + 4R bytes each; NaN = no data for that channel)

The columns are always the on-board record's, so the C++ reads every profile by position; a flight
lacking channels says which with the carried flags. Only the masked profile (core/channels.py
``flightlog-mask``) accepts a stream that does not carry every channel (its minimum always), and
takes each availability group as present when every channel of it is carried (fwref/stream.hpp
``Stream::set_carried``); a NaN sample in a carried channel is a gap, as in version 1. A reference
profile's stream (``flightlog-ref``) may carry the vehicle record (version 4): ``fwref_stream`` then loads
it at reset, as ``streamref.windows_of`` applies it; a version 2 stream of it replays without a reference
(or with ``fwref_stream --vehicle RECORD.bin``).

The channels are the raw ones the export's on-board record names, in its order
(formats/onboard.py stream_channels; the record of an export: formats.export_folder.Export.onboard):
for a profile with a hover estimate the raw channels it reads and ``airborne`` (0/1) last; for
``paper`` the model's own channels.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core import vehicle_record as vr
from quadfdi.core.channels import AIRBORNE, PROFILE_BY_NAME
from quadfdi.core.errors import QuadfdiError

MAGIC = b"QFDISTR\0"
VERSION = 2  # without a vehicle record (VEHICLE_VERSION with one)
VEHICLE_VERSION = 4
READS = (1, 2, 3, 4)  # version 1: every channel carried; 3: a version 1 vehicle record (24 floats)
FIXED = struct.Struct("<8sIIIId32s64s")  # 128 bytes


@dataclass
class RawStream:
    source: str
    profile: str
    names: list[str]
    sample_dt_s: float
    cells: int
    time: np.ndarray  # (T,) float64, s
    values: np.ndarray  # (T, R) float32
    carried: np.ndarray | None = None  # (R,) bool: the flight has the channel (None: every channel)
    vehicle: np.ndarray | None = None  # (24,) float32 vehicle record (a reference profile; None: no reference)

    def column(self, name: str) -> np.ndarray:
        return self.values[:, self.names.index(name)]

    @property
    def carried_flags(self) -> np.ndarray:
        """(R,) bool, every channel carried when ``carried`` is None."""
        return np.ones(len(self.names), bool) if self.carried is None else np.asarray(self.carried, bool)

    def carries(self, name: str) -> bool:
        return bool(self.carried_flags[self.names.index(name)])


def stream_bytes(rs: RawStream) -> bytes:
    flags = rs.carried_flags
    if len(flags) != len(rs.names) or np.isfinite(rs.values[:, ~flags]).any():
        raise QuadfdiError(f"stream {rs.source}: a channel it does not carry must be NaN throughout, one flag per channel")
    names = b"".join(n.encode("ascii") + b"\0" for n in rs.names) + flags.astype(np.uint8).tobytes()
    if rs.vehicle is not None:
        from quadfdi.formats.vehicle_record_bin import record_bytes

        names += record_bytes(rs.vehicle, rs.profile)[vr.FILE_HEADER_BYTES:]  # checks the profile reads one
    header_bytes = FIXED.size + len(names) + (-(FIXED.size + len(names))) % 8
    head = FIXED.pack(MAGIC, VERSION if rs.vehicle is None else VEHICLE_VERSION, header_bytes, len(rs.names), int(rs.cells), float(rs.sample_dt_s),
                      rs.profile.encode("ascii"), rs.source.encode("utf-8")[:63])
    rec = np.zeros(len(rs.time), dtype=[("t", "<f8"), ("v", "<f4", (len(rs.names),))])
    rec["t"], rec["v"] = rs.time, rs.values
    return head + names.ljust(header_bytes - FIXED.size, b"\0") + rec.tobytes()


def write_stream(path: str | Path, rs: RawStream) -> None:
    from quadfdi.core.atomic import write_bytes

    write_bytes(path, stream_bytes(rs))


# The reader's bounds, as fwref_stream's (firmware_ref/include/fwref/read_limits.hpp): the header and the
# channel count; the whole file is read into memory here, so it is bounded too.
MAX_HEADER_BYTES = 64 * 1024
MAX_CHANNELS = 1024
MAX_FILE_BYTES = 1 << 30


def _read_bounded(path: str | Path) -> bytes:
    """The bytes of the regular file ``path`` (a FIFO or a device is refused: they block or never end)."""
    import os
    import stat

    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as exc:
        raise QuadfdiError(f"cannot read stream file {path}: {exc.strerror}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode) or st.st_size > MAX_FILE_BYTES:
        os.close(fd)
        why = "is not a regular file" if not stat.S_ISREG(st.st_mode) else f"holds {st.st_size} bytes, more than {MAX_FILE_BYTES}"
        raise QuadfdiError(f"stream file {path} {why}")
    with os.fdopen(fd, "rb") as fh:
        return fh.read(MAX_FILE_BYTES + 1)


def read_stream(path: str | Path) -> RawStream:
    """Parse a stream file; a foreign, truncated or inconsistent file (header_bytes, n_channels or the sample
    period out of range, a partial sample) is a one-line QuadfdiError."""
    data = _read_bounded(path)
    if len(data) < FIXED.size or data[:8] != MAGIC:
        raise QuadfdiError(f"{path} is not a quadfdi stream file")
    _, version, header_bytes, r, cells, dt, profile, source = FIXED.unpack_from(data)
    if version not in READS:
        raise QuadfdiError(f"{path} has stream version {version}, this reader reads {' and '.join(map(str, READS))}")
    if not (FIXED.size + r <= header_bytes <= min(MAX_HEADER_BYTES, len(data)) and 1 <= r <= MAX_CHANNELS):
        raise QuadfdiError(f"{path} has a bad header: header_bytes {header_bytes}, {r} channels")
    if not (np.isfinite(dt) and dt > 0):
        raise QuadfdiError(f"{path} has sample period {dt} s: not a positive finite number")
    head = data[FIXED.size:header_bytes]
    names = [n.decode("ascii", "replace") for n in head.split(b"\0")[:r]]
    end = sum(len(n.encode("ascii", "replace")) + 1 for n in names)
    carried = np.frombuffer(head[end:end + r], np.uint8) if version >= 2 else np.ones(r, np.uint8)
    size = vr.SIZE if version >= 4 else vr.SIZE_V1
    vehicle = head[end + r:end + r + 4 * size] if version >= 3 else None
    body = data[header_bytes:]
    rec = np.dtype([("t", "<f8"), ("v", "<f4", (r,))])
    if len(names) != r or len(carried) != r or not np.isin(carried, (0, 1)).all() or len(body) % rec.itemsize or \
            (vehicle is not None and len(vehicle) != 4 * size):
        raise QuadfdiError(f"{path} is truncated or has a bad header")
    profile = profile.rstrip(b"\0").decode("ascii", "replace")
    if vehicle is not None:
        from quadfdi.formats.vehicle_record_bin import check_record

        fields = np.frombuffer(vehicle, "<f4")
        vehicle = check_record(fields if version >= 4 else vr.from_v1(fields), f"{path}'s vehicle record")
        if not getattr(PROFILE_BY_NAME.get(profile), "reference", False):
            raise QuadfdiError(f"{path} carries a vehicle record, but its profile {profile!r} reads none")
    arr = np.frombuffer(body, rec)
    return RawStream(source.rstrip(b"\0").decode("utf-8", "replace"), profile, names, float(dt), int(cells),
                     arr["t"].astype(np.float64), arr["v"].astype(np.float32).reshape(-1, r), carried.astype(bool),
                     vehicle)


def from_dataset(dataset: str | Path, flight: int, record: dict, ds=None, vehicle=None) -> RawStream:
    """Flight ``flight`` of a simulated dataset.npz (every simulated flight is airborne throughout);
    ``ds`` the file already loaded (formats.dataset.load_dataset), for a caller taking several flights.
    The masked profile: the flight carries the channels of its mask pattern (core.profiles.flight_pattern,
    as models.inputs.profiled_dataset gives the window path), the others NaN and not carried. ``vehicle``:
    the vehicle record the stream carries (a reference profile; None: none)."""
    from quadfdi.core.profiles import flight_pattern, is_masked
    from quadfdi.core.channels import GROUP_OF_RAW
    from quadfdi.formats.dataset import load_dataset

    ds = load_dataset(dataset) if ds is None else ds
    tel = ds["telemetry"]
    if not 0 <= flight < tel.shape[0]:
        raise QuadfdiError(f"{dataset} has flights 0..{tel.shape[0] - 1}, not {flight}")
    names, cols = ds.channel_names, []
    esc = [str(n) for n in ds["esc_channel_names"]] if "esc_telemetry" in ds.arrays else []  # realistic suite
    for r in record["raw_channels"]:
        if r == AIRBORNE and record["cells_from_stream"]:
            cols.append(np.ones(tel.shape[1], np.float32))
        elif r in names:
            cols.append(tel[flight, :, names.index(r)])
        elif r in esc:
            cols.append(np.asarray(ds["esc_telemetry"][flight, :, esc.index(r)], np.float32))
        else:
            raise QuadfdiError(f"{dataset} has no channel {r!r}, which the model's stream needs")
    cells = 0
    if record["cells_from_stream"]:
        if "pack_cells" not in ds.arrays:
            raise QuadfdiError(f"{dataset} has no pack_cells: profile {record['profile']!r} needs the cell count")
        cells = int(ds["pack_cells"][flight])
    dt = float(ds.config.sim.sample_dt_s)
    values = np.stack(cols, axis=1).astype(np.float32)
    carried = None
    if is_masked(record["profile"]):
        lacks = set(flight_pattern(int(ds["traj_index"][flight])).groups)
        carried = np.array([GROUP_OF_RAW.get(r) not in lacks for r in record["raw_channels"]])
        values[:, ~carried] = np.nan
    return RawStream(f"{Path(dataset).name}#{flight}", record["profile"], list(record["raw_channels"]), dt, cells,
                     np.arange(tel.shape[1]) * dt, values, carried, None if vehicle is None else np.asarray(vehicle, np.float32))
