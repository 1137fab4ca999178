"""The tensor-record container that weights.bin and reference.bin share (docs/formats.md).

Little-endian, every field 4-byte aligned, every count before its array, so that a C++ reader
can check each size before it reads (llm.c style: magic, version and dimensions up front):

    FILE HEADER (24 bytes)
      0  char[8]  magic         b"QFDIWTS\\0" (weights.bin) or b"QFDIREF\\0" (reference.bin)
      8  u32      version       1
     12  u32      n_sections
     16  u64      file_size     bytes of the whole file, trailer included
    SECTIONS, back to back
      0  char[4]  b"SECT"
      4  u32      section_size  bytes from the section's first byte to the end of its CRC
      8  u32      model         core.contracts.MODEL_CODES: 0 = none (inputs), 1 = cnode, 2 = gru, ...
     12  u32      precision     core.contracts.PRECISION_CODES: 0 = none, 1 = fp32, 2 = int8
     16  u32[8]   dims          meaning per file (weights_bin.py, reference_bin.py)
     48  u32      n_tensors
     52  TENSOR RECORDS
      .  u32      crc32         zlib CRC-32 of the section's bytes [0, section_size - 4)
    TRAILER
         u32      crc32         CRC-32 of the file's bytes [0, file_size - 4)

    TENSOR RECORD
      0  char[48] name          ASCII, NUL-padded (at most 47 characters)
     48  u32      dtype         1 = float32, 2 = int8, 3 = int32
     52  u32      ndim          0..4
     56  u32[4]   shape         row-major (C order); unused entries 0
     72  i32      quant_axis    -1: per tensor or not quantized; 0: one scale per index of axis 0
     76  u32      n_scales      0 (float32, int32), 1 (int8 per tensor) or shape[0] (int8 per row)
     80  u32      data_bytes    prod(shape) * itemsize
     84  data, zero-padded to a multiple of 4
      .  f32[n_scales] scales, then i32[n_scales] zero_points   (value = scale * (q - zero_point))

Every malformed file (foreign, truncated, corrupted, wrong version) raises a one-line
QuadfdiError that names the file and the problem.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfdi.core.contracts import MODEL_CODES as MODELS, PRECISION_CODES as PRECISIONS
from quadfdi.core.errors import QuadfdiError

DTYPES = {1: np.dtype("<f4"), 2: np.dtype("i1"), 3: np.dtype("<i4")}
NATIVE = {1: np.float32, 2: np.int8, 3: np.int32}
_DTYPE_CODE = {np.dtype(np.float32): 1, np.dtype(np.int8): 2, np.dtype(np.int32): 3}
NAME_BYTES = 48
N_DIMS = 8
MAX_NDIM = 4
FILE_HEADER = struct.Struct("<8sIIQ")  # 24 bytes
SECTION_HEADER = struct.Struct("<4sIII8II")  # 52 bytes
TENSOR_HEADER = struct.Struct(f"<{NAME_BYTES}sII4IiII")  # 84 bytes
SECTION_MAGIC = b"SECT"


@dataclass(frozen=True)
class Tensor:
    """A named array; an int8 tensor carries its scales and zero points (``axis`` -1 or 0)."""

    name: str
    array: np.ndarray
    scales: np.ndarray | None = None
    zero_points: np.ndarray | None = None
    axis: int = -1

    def dequant(self) -> np.ndarray:
        """float32 value of an int8 tensor: scale * (q - zero_point)."""
        if self.scales is None:
            return self.array.astype(np.float32)
        shape = (-1,) + (1,) * (self.array.ndim - 1) if self.axis == 0 else ()
        s = self.scales.reshape(shape) if self.axis == 0 else self.scales[0]
        z = self.zero_points.reshape(shape) if self.axis == 0 else self.zero_points[0]
        return (s * (self.array.astype(np.float32) - z)).astype(np.float32)


@dataclass
class Section:
    model: str
    precision: str
    dims: tuple[int, ...]
    tensors: dict[str, Tensor] = field(default_factory=dict)

    def add(self, name: str, array, dtype=None, scales=None, axis: int = -1) -> None:
        arr = np.ascontiguousarray(np.asarray(array, dtype=dtype))
        if scales is not None:
            scales = np.atleast_1d(np.asarray(scales, np.float32)).reshape(-1)
            self.tensors[name] = Tensor(name, arr, scales, np.zeros(scales.shape, np.int32), axis)
        else:
            self.tensors[name] = Tensor(name, arr)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.tensors[name].array


def _pad4(n: int) -> int:
    return (-n) % 4


def _pack_tensor(t: Tensor) -> bytes:
    arr = t.array
    code = _DTYPE_CODE.get(arr.dtype)
    if code is None:
        raise TypeError(f"tensor {t.name}: dtype {arr.dtype} is not float32, int8 or int32")
    if arr.ndim > MAX_NDIM:
        raise ValueError(f"tensor {t.name}: {arr.ndim} dimensions, at most {MAX_NDIM}")
    name = t.name.encode("ascii")
    if len(name) >= NAME_BYTES:
        raise ValueError(f"tensor name {t.name!r} is longer than {NAME_BYTES - 1} characters")
    n_scales = 0 if t.scales is None else len(t.scales)
    want = 0 if code != 2 else (1 if t.axis == -1 else arr.shape[0])
    if n_scales != want:
        raise ValueError(f"tensor {t.name}: {n_scales} scales do not fit dtype {arr.dtype}, axis {t.axis}, "
                         f"shape {arr.shape}")
    shape = list(arr.shape) + [0] * (MAX_NDIM - arr.ndim)
    data = arr.astype(DTYPES[code], copy=False).tobytes()
    out = [TENSOR_HEADER.pack(name, code, arr.ndim, *shape, t.axis if n_scales else -1, n_scales, len(data)),
           data, b"\0" * _pad4(len(data))]
    if n_scales:
        out += [t.scales.astype("<f4").tobytes(), t.zero_points.astype("<i4").tobytes()]
    return b"".join(out)


def _pack_section(s: Section) -> bytes:
    dims = list(s.dims) + [0] * (N_DIMS - len(s.dims))
    body = b"".join(_pack_tensor(t) for t in s.tensors.values())
    size = SECTION_HEADER.size + len(body) + 4
    head = SECTION_HEADER.pack(SECTION_MAGIC, size, MODELS[s.model], PRECISIONS[s.precision], *dims, len(s.tensors))
    blob = head + body
    return blob + struct.pack("<I", zlib.crc32(blob))


def pack(magic: bytes, version: int, sections: list[Section]) -> bytes:
    """The file's bytes: header, sections, trailer CRC."""
    body = b"".join(_pack_section(s) for s in sections)
    size = FILE_HEADER.size + len(body) + 4
    blob = FILE_HEADER.pack(magic, version, len(sections), size) + body
    return blob + struct.pack("<I", zlib.crc32(blob))


class _Cursor:
    def __init__(self, data: bytes, where: str, end: int) -> None:
        self.data, self.where, self.pos, self.end = data, where, 0, end

    def take(self, n: int, what: str) -> bytes:
        if n < 0 or self.pos + n > self.end:
            raise QuadfdiError(f"{self.where} is truncated or corrupted: {what} needs {n} bytes at offset "
                               f"{self.pos}, only {self.end - self.pos} left (re-run `quadfdi export`)")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out


def unpack(data: bytes, magic: bytes, version: int, where: str, what: str = "file") -> tuple[int, list[Section]]:
    """Parse and check a container; ``where`` names the file in error messages, ``what`` its kind."""
    if len(data) < FILE_HEADER.size and magic.startswith(data[:8]):
        raise QuadfdiError(f"{where} is truncated: {len(data)} bytes, shorter than its {FILE_HEADER.size}-byte "
                           f"header (re-run `quadfdi export`)")
    if data[:8] != magic:
        raise QuadfdiError(f"{where} is not a quadfdi {what} (magic {data[:8]!r}, expected {magic!r})")
    _, ver, n_sections, size = FILE_HEADER.unpack_from(data)
    if ver != version:
        raise QuadfdiError(f"{where} has format version {ver}, this reader reads version {version} "
                           f"(re-run `quadfdi export`)")
    if size != len(data):
        raise QuadfdiError(f"{where} is truncated (or has trailing bytes): its header says {size} bytes, "
                           f"the file has {len(data)} (re-run `quadfdi export`)")
    (crc,) = struct.unpack_from("<I", data, size - 4)
    if zlib.crc32(data[:size - 4]) != crc:
        raise QuadfdiError(f"{where} fails its file CRC-32 check: the file is corrupted (re-run `quadfdi export`)")
    cur = _Cursor(data, where, size - 4)
    cur.take(FILE_HEADER.size, "file header")
    sections = [_unpack_section(cur, i) for i in range(n_sections)]
    if cur.pos != cur.end:
        raise QuadfdiError(f"{where} has {cur.end - cur.pos} unexpected bytes after its {n_sections} sections")
    return ver, sections


def _unpack_section(cur: _Cursor, index: int) -> Section:
    start = cur.pos
    head = cur.take(SECTION_HEADER.size, f"section {index} header")
    tag, size, model, prec, *rest = SECTION_HEADER.unpack(head)
    dims, n_tensors = tuple(rest[:N_DIMS]), rest[N_DIMS]
    models = {v: k for k, v in MODELS.items()}
    precs = {v: k for k, v in PRECISIONS.items()}
    if tag != SECTION_MAGIC or model not in models or prec not in precs:
        raise QuadfdiError(f"{cur.where}: section {index} has a bad header (tag {tag!r}, model {model}, "
                           f"precision {prec})")
    if size < SECTION_HEADER.size + 4 or start + size > cur.end:
        raise QuadfdiError(f"{cur.where}: section {index} claims {size} bytes, {cur.end - start} are left")
    (crc,) = struct.unpack_from("<I", cur.data, start + size - 4)
    if zlib.crc32(cur.data[start:start + size - 4]) != crc:
        raise QuadfdiError(f"{cur.where}: section {index} ({models[model]} {precs[prec]}) fails its CRC-32 check")
    sec = Section(models[model], precs[prec], dims)
    inner = _Cursor(cur.data, cur.where, start + size - 4)
    inner.pos = cur.pos
    for k in range(n_tensors):
        t = _unpack_tensor(inner, f"section {index} tensor {k}")
        sec.tensors[t.name] = t
    if inner.pos != inner.end:
        raise QuadfdiError(f"{cur.where}: section {index} has {inner.end - inner.pos} bytes beyond its "
                           f"{n_tensors} tensors")
    cur.pos = start + size
    return sec


def _unpack_tensor(cur: _Cursor, what: str) -> Tensor:
    raw = cur.take(TENSOR_HEADER.size, f"{what} header")
    name_b, code, ndim, *rest = TENSOR_HEADER.unpack(raw)
    shape4, axis, n_scales, nbytes = rest[:4], rest[4], rest[5], rest[6]
    name = name_b.split(b"\0", 1)[0].decode("ascii", "replace")
    # A writer sets unused shape entries to 0 and the axis of an unquantized tensor to -1.
    unused_zero = ndim <= MAX_NDIM and not any(shape4[ndim:])
    if code not in DTYPES or ndim > MAX_NDIM or axis not in (-1, 0) or (code != 2 and axis != -1) or not unused_zero:
        raise QuadfdiError(f"{cur.where}: {what} ({name!r}) has a bad header (dtype {code}, ndim {ndim}, axis {axis}"
                           f"{'' if unused_zero else ', unused shape entries not 0'})")
    shape = tuple(shape4[:ndim])
    dt = DTYPES[code]
    if nbytes != int(np.prod(shape, dtype=np.int64)) * dt.itemsize:
        raise QuadfdiError(f"{cur.where}: {what} ({name!r}) says {nbytes} data bytes, shape {shape} of {dt} needs "
                           f"{int(np.prod(shape, dtype=np.int64)) * dt.itemsize}")
    want = 0 if code != 2 else (1 if axis == -1 else (shape[0] if ndim else -1))
    if n_scales != want:
        raise QuadfdiError(f"{cur.where}: {what} ({name!r}) has {n_scales} scales, expected {want}")
    arr = np.frombuffer(cur.take(nbytes, f"{what} ({name!r}) data"), dtype=dt).reshape(shape).astype(NATIVE[code])
    cur.take(_pad4(nbytes), f"{what} padding")
    if not n_scales:
        return Tensor(name, arr)
    scales = np.frombuffer(cur.take(4 * n_scales, f"{what} scales"), "<f4").astype(np.float32)
    zps = np.frombuffer(cur.take(4 * n_scales, f"{what} zero points"), "<i4").astype(np.int32)
    return Tensor(name, arr, scales, zps, axis)


def read_file(path: str | Path, magic: bytes, version: int, what: str) -> tuple[int, list[Section]]:
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise QuadfdiError(f"{what} {p} does not exist (run `quadfdi export` first)") from None
    except OSError as exc:
        raise QuadfdiError(f"cannot read {what} {p}: {exc.strerror}") from None
    return unpack(data, magic, version, f"{what} {p}", what)
