#!/usr/bin/env python3
"""Generate the microcontroller build's constant arrays from weights.bin (and reference.bin).

    gen_weights.py --weights <weights.bin> [--reference <reference.bin>] --out <folder>

Writes into <folder>:
  fwref_limits.h              FWREF_MAX_* = the model's own dimensions (fwref/config.hpp reads it
                              through -DFWREF_LIMITS_HEADER), so no buffer is larger than needed;
  fwref_weights.hpp           extern const fwref::CnodeF32 kCnodeF32, kCnodeI8, kGruF32, kGruI8;
  fwref_weights_<model>_<precision>.cpp   each section's tensors as const arrays (flash) and the
                              model struct pointing at them (constant-initialised: flash, not RAM);
  fwref_reference.hpp/.cpp    (with --reference) the reference windows and every expected tensor,
                              for the QEMU parity harness (mcu/parity_main.cpp).

Standard library only (struct, zlib), so any python3 can run it at build time. It checks the
container like export/binfmt.py (magic, version, size, CRCs, every size field) and exits 2 with one
line on stderr if the file is unusable. Floats are written as C++17 hexadecimal literals: exact.
A file is rewritten only when its text changes, so an unchanged weights.bin rebuilds nothing.
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
import tempfile
import zlib
from pathlib import Path

FILE_HEADER = struct.Struct("<8sIIQ")
SECTION_HEADER = struct.Struct("<4sIII8II")
TENSOR_HEADER = struct.Struct("<48sII4IiII")
DTYPES = {1: ("f", 4, "float"), 2: ("b", 1, "std::int8_t"), 3: ("i", 4, "std::int32_t")}
MODELS = {0: "none", 1: "cnode", 2: "gru"}
PRECISIONS = {0: "none", 1: "fp32", 2: "int8"}
WEIGHTS_MAGIC, REFERENCE_MAGIC = b"QFDIWTS\0", b"QFDIREF\0"


class FileError(Exception):
    """An unusable input file; printed as one line."""


class Tensor:
    def __init__(self, name, dtype, shape, values, scales):
        self.name, self.dtype, self.shape, self.values, self.scales = name, dtype, shape, values, scales


def parse(path: Path, magic: bytes, what: str) -> list[tuple[str, str, tuple[int, ...], dict[str, Tensor]]]:
    """Sections of a weights.bin / reference.bin as (model, precision, dims, {name: Tensor})."""
    where = f"{what} {path}"
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FileError(f"cannot read {where}: {exc.strerror}") from None
    if len(data) < FILE_HEADER.size or data[:8] != magic:
        raise FileError(f"{where} is not a quadfdi {what} or is truncated (magic {data[:8]!r}, expected {magic!r})")
    _, version, n_sections, size = FILE_HEADER.unpack_from(data)
    if version != 1:
        raise FileError(f"{where} has format version {version}, this generator reads version 1")
    if size != len(data) or size < FILE_HEADER.size + 4:
        raise FileError(f"{where} is truncated (or has trailing bytes): its header says {size} bytes, the file has {len(data)}")
    if zlib.crc32(data[:-4]) != struct.unpack_from("<I", data, size - 4)[0]:
        raise FileError(f"{where} fails its file CRC-32 check")
    end, pos, sections = size - 4, FILE_HEADER.size, []
    for index in range(n_sections):
        if end - pos < SECTION_HEADER.size:
            raise FileError(f"{where}: section {index} is truncated")
        tag, ssize, model, prec, *rest = SECTION_HEADER.unpack_from(data, pos)
        dims, n_tensors = tuple(rest[:8]), rest[8]
        if tag != b"SECT" or model not in MODELS or prec not in PRECISIONS or ssize < SECTION_HEADER.size + 4 \
                or pos + ssize > end:
            raise FileError(f"{where}: section {index} has a bad header")
        if zlib.crc32(data[pos:pos + ssize - 4]) != struct.unpack_from("<I", data, pos + ssize - 4)[0]:
            raise FileError(f"{where}: section {index} fails its CRC-32 check")
        tensors, p, send = {}, pos + SECTION_HEADER.size, pos + ssize - 4
        for k in range(n_tensors):
            if send - p < TENSOR_HEADER.size:
                raise FileError(f"{where}: section {index} tensor {k} is truncated")
            name_b, code, ndim, *r = TENSOR_HEADER.unpack_from(data, p)
            shape4, axis, n_scales, nbytes = r[:4], r[4], r[5], r[6]
            name = name_b.split(b"\0", 1)[0].decode("ascii", "replace")
            if code not in DTYPES or ndim > 4 or axis not in (-1, 0):
                raise FileError(f"{where}: tensor {name!r} has a bad header")
            shape = tuple(shape4[:ndim])
            count = 1
            for d in shape:
                count *= d
            fmt_char, itemsize, _ = DTYPES[code]
            want_scales = 0 if code != 2 else (1 if axis == -1 else (shape[0] if ndim else -1))
            pad = (-nbytes) % 4
            if nbytes != count * itemsize or n_scales != want_scales or p + TENSOR_HEADER.size + nbytes + pad \
                    + 8 * n_scales > send:
                raise FileError(f"{where}: tensor {name!r} has inconsistent sizes")
            p += TENSOR_HEADER.size
            values = struct.unpack_from(f"<{count}{fmt_char}", data, p)
            p += nbytes + pad
            scales = struct.unpack_from(f"<{n_scales}f", data, p) if n_scales else ()
            zps = struct.unpack_from(f"<{n_scales}i", data, p + 4 * n_scales) if n_scales else ()
            if any(zps):
                raise FileError(f"{where}: tensor {name!r} has a non-zero zero point")
            p += 8 * n_scales
            tensors[name] = Tensor(name, code, shape, values, scales)
        if p != send:
            raise FileError(f"{where}: section {index} has bytes beyond its tensors")
        sections.append((MODELS[model], PRECISIONS[prec], dims, tensors))
        pos += ssize
    if pos != end:
        raise FileError(f"{where} has unexpected bytes after its sections")
    return sections


def c_float(v: float) -> str:
    """Exact C++17 literal of a float32 value (hexadecimal)."""
    if v != v or v in (float("inf"), float("-inf")):
        raise FileError(f"non-finite value {v!r} cannot be compiled in")
    h = float(v).hex()  # '0x1.99999a0000000p-4' (exact: a float32 is a double)
    mant, exp = h.split("p")
    if "." in mant:
        mant = mant.rstrip("0").rstrip(".")
    return f"{mant}p{exp}f"


def c_array(ctype: str, name: str, values, per_line: int = 8) -> str:
    fmt = c_float if ctype == "float" else str
    items = [fmt(v) for v in values]
    lines = [", ".join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    body = ",\n    ".join(lines)
    return f"alignas(4) const {ctype} {name}[{max(len(items), 1)}] = {{\n    {body}\n}};\n"


def ident(*parts: str) -> str:
    return "_".join(p.replace(".", "_") for p in parts)


class Unit:
    """One generated .cpp: the arrays of one section and the model struct that points at them."""

    def __init__(self, model: str, precision: str, tensors: dict[str, Tensor]):
        self.prefix = f"{model}_{'f32' if precision == 'fp32' else 'i8'}"
        self.tensors, self.parts = tensors, []

    def need(self, name: str) -> Tensor:
        t = self.tensors.get(name)
        if t is None:
            raise FileError(f"section {self.prefix} lacks tensor {name!r}")
        return t

    def arr(self, name: str) -> str:
        t = self.need(name)
        cname = ident(self.prefix, name)
        self.parts.append(c_array(DTYPES[t.dtype][2], cname, t.values))
        return cname

    def matf(self, name: str) -> str:
        t = self.need(name)
        return f"{{{self.arr(name)}, {t.shape[0]}, {t.shape[1]}}}"

    def matq(self, name: str) -> str:
        t = self.need(name)
        q = self.arr(name)
        s = ident(self.prefix, name, "scale")
        self.parts.append(c_array("float", s, t.scales))
        return f"{{{q}, {s}, {t.shape[0]}, {t.shape[1]}}}"

    def scalar(self, name: str) -> str:
        return c_float(self.need(name).values[0])


def cnode_unit(precision: str, dims, tensors) -> tuple[str, str]:
    u = Unit("cnode", precision, tensors)
    q = precision == "int8"
    mat = u.matq if q else u.matf
    d = f"{{{dims[0]}, {dims[1]}, {dims[2]}, {dims[3]}, {dims[4]}, {dims[5]}, {dims[6]}}}"
    fields = [d, u.arr("norm.mean"), u.arr("norm.std"), mat("interp"), u.arr("stage_index"), u.arr("rk4.consts"),
              mat("encoder.weight"), u.arr("encoder.bias"), mat("lin1_z.weight"), mat("lin1_u.weight"),
              u.arr("lin1.bias"), mat("lin2.weight"), u.arr("lin2.bias"), mat("head.weight"), u.arr("head.bias")]
    if q:
        fields += [u.arr("act.x_norm.scale"), u.arr("act.u.scale"), u.arr("act.stage.scale"),
                   u.scalar("act.hidden.scale"), u.scalar("act.z1.scale")]
    typ, var = ("CnodeI8", "kCnodeI8") if q else ("CnodeF32", "kCnodeF32")
    return var, struct_unit(u, typ, var, fields)


def gru_unit(precision: str, dims, tensors) -> tuple[str, str]:
    u = Unit("gru", precision, tensors)
    q = precision == "int8"
    mat = u.matq if q else u.matf
    d = f"{{{dims[0]}, {dims[1]}, {dims[2]}, {dims[3]}}}"
    fields = [d, u.arr("norm.mean"), u.arr("norm.std"), mat("gru.weight_ih"), mat("gru.weight_hh"),
              u.arr("gru.bias_ih"), u.arr("gru.bias_hh"), mat("head.weight"), u.arr("head.bias")]
    if q:
        fields += [u.arr("act.x_norm.scale"), u.scalar("act.h.scale")]
    typ, var = ("GruI8", "kGruI8") if q else ("GruF32", "kGruF32")
    return var, struct_unit(u, typ, var, fields)


HEADER = "// GENERATED by firmware_ref/tools/gen_weights.py from {src}; do not edit.\n"


def struct_unit(u: Unit, typ: str, var: str, fields: list[str]) -> str:
    body = "".join(u.parts)
    init = ",\n    ".join(fields)
    return (f'#include "fwref_weights.hpp"\n\nnamespace fwref_data {{\nnamespace {{\n{body}}}  // namespace\n\n'
            f"const fwref::{typ} {var} = {{\n    {init}\n}};\n\n"
            f"}}  // namespace fwref_data\n")


def limits_header(sections) -> str:
    by = {(m, p): dims for m, p, dims, _ in sections}
    c, w, k, h, lat, n, s = by[("cnode", "fp32")][:7]
    gc, gw, gk, gh = by[("gru", "fp32")][:4]
    for key, dims in by.items():
        ref = by[(key[0], "fp32")]
        if dims != ref:
            raise FileError(f"{key[0]} fp32 and int8 sections have different dimensions")
    return (f"// The model's own dimensions as the build's maxima: no buffer holds more than this model needs.\n"
            f"#pragma once\n#define FWREF_MAX_CHANNELS {max(c, gc)}\n#define FWREF_MAX_WINDOW {max(w, gw)}\n"
            f"#define FWREF_MAX_CLASSES {max(k, gk)}\n#define FWREF_MAX_LATENT {lat}\n"
            f"#define FWREF_MAX_CNODE_HIDDEN {h}\n#define FWREF_MAX_STEPS {n}\n#define FWREF_MAX_GRU_HIDDEN {gh}\n")


WEIGHTS_HPP = """#pragma once
// The four models of weights.bin as constant structs in flash (one .cpp per section).
#include "fwref/cnode.hpp"
#include "fwref/gru.hpp"

namespace fwref_data {
extern const fwref::CnodeF32 kCnodeF32;
extern const fwref::CnodeI8 kCnodeI8;
extern const fwref::GruF32 kGruF32;
extern const fwref::GruI8 kGruI8;
}  // namespace fwref_data
"""

REFERENCE_HPP = """#pragma once
// reference.bin compiled in: the windows and every expected tensor (fp32 from PyTorch, int8 from
// ONNX Runtime), for the QEMU parity harness.
namespace fwref_ref {
struct Tensor {
  const char* model;      // "cnode" / "gru"
  const char* precision;  // "fp32" / "int8"
  const char* name;       // "z0", "stages", "h", "logits", ...
  const float* data;
  int count;
};
extern const int kWindows;  // n
extern const float kTelemetry[];  // (n, W, C) raw
extern const int kLabels[];       // (n,)
extern const Tensor kTensors[];
extern const int kTensorCount;
}  // namespace fwref_ref
"""


def reference_unit(sections) -> str:
    """The windows and labels (external linkage: the header declares them) and each expected tensor
    (internal, reached through the kTensors table)."""
    inputs = next((t for m, _, _, t in sections if m == "none"), None)
    if inputs is None or "telemetry" not in inputs or "label" not in inputs:
        raise FileError("reference file has no inputs section with 'telemetry' and 'label'")
    tel = inputs["telemetry"]
    private, rows = [], []
    for model, prec, _, tensors in sections:
        if model == "none":
            continue
        for name in ("x_norm", "u", "z0", "stages", "z1", "h", "logits"):
            if name in tensors:
                cname = ident("ref", model, prec, name)
                private.append(c_array("float", cname, tensors[name].values))
                rows.append(f'{{"{model}", "{prec}", "{name}", {cname}, {len(tensors[name].values)}}}')
    labels = ", ".join(map(str, inputs["label"].values))
    table = ",\n    ".join(rows)
    return ('#include "fwref_reference.hpp"\n\nnamespace fwref_ref {\nnamespace {\n' + "".join(private) +
            "}  // namespace\n\n" + c_array("float", "kTelemetry", tel.values) +
            f"alignas(4) const int kLabels[{tel.shape[0]}] = {{{labels}}};\n"
            f"const int kWindows = {tel.shape[0]};\nconst int kTensorCount = {len(rows)};\n"
            f"const Tensor kTensors[] = {{\n    {table}\n}};\n}}  // namespace fwref_ref\n")


def write_if_changed(path: Path, text: str) -> None:
    if path.is_file() and path.read_text() == text:
        return
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def generate(weights: Path, reference: Path | None, out: Path) -> list[Path]:
    sections = parse(weights, WEIGHTS_MAGIC, "weights file")
    have = {(m, p): (dims, t) for m, p, dims, t in sections}
    for key in (("cnode", "fp32"), ("cnode", "int8"), ("gru", "fp32"), ("gru", "int8")):
        if key not in have:
            raise FileError(f"weights file {weights} holds no {key[0]} {key[1]} section")
    out.mkdir(parents=True, exist_ok=True)
    files = {"fwref_limits.h": HEADER.format(src=weights.name) + limits_header(sections),
             "fwref_weights.hpp": HEADER.format(src=weights.name) + WEIGHTS_HPP}
    for model, prec in have:
        dims, tensors = have[(model, prec)]
        _, text = (cnode_unit if model == "cnode" else gru_unit)(prec, dims, tensors)
        files[f"fwref_weights_{model}_{'f32' if prec == 'fp32' else 'i8'}.cpp"] = HEADER.format(src=weights.name) + text
    if reference is not None:
        ref = parse(reference, REFERENCE_MAGIC, "reference file")
        files["fwref_reference.hpp"] = HEADER.format(src=reference.name) + REFERENCE_HPP
        files["fwref_reference.cpp"] = HEADER.format(src=reference.name) + reference_unit(ref)
    for name, text in files.items():
        write_if_changed(out / name, text)
    return [out / n for n in files]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", required=True, type=Path)
    ap.add_argument("--reference", type=Path, default=None)
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)
    try:
        generate(args.weights, args.reference, args.out)
    except FileError as exc:
        print(f"gen_weights.py: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
