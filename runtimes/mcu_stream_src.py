"""The Cortex-M stream image's compiled-in data: weights.bin's on-board record and a bounded set of
recorded flights (stream files, docs/formats.md "Stream file"), as C++ constants.

    python -m quadfdi.runtimes.mcu_stream_src --weights W --out DIR STREAM.bin [STREAM.bin ...]

W is an export folder's weights.bin (formats.export_folder: the folder's manifest and hashes are checked).

Writes DIR/fwref_stream_limits.h (the stream's capacities: -DFWREF_STREAM_LIMITS_HEADER for every
unit of the image), DIR/fwref_stream_data.hpp (the record as ``kParams``, its alarm.rotor_side as the alarm's
``rotor_mask``: the image reports the motor under rule 5 as the host does; ``kParamsCnode`` /
``kParamsGru`` / ``kParamsSgru`` the same with each network's policy of the record's alarm.models,
what the image runs each model with, as fwref_stream --model does) and
DIR/fwref_stream_data.cpp (per flight: cells, the columns its stream carries, its vehicle record when the
stream carries one (a reference profile: embedded in flash, 100 bytes, loaded into the Stream at the flight's
reset), times, samples). Exit 2 and
one line on a file it cannot use. Used by firmware_ref/mcu (FWREF_STREAMS) for mcu/stream_main.cpp.

Besides weights.bin's four models (runtimes/mcu_weights_src.py), the stream image carries, as constant structs in
fwref_stream_data.cpp:
- the streaming GRU (``kSgruF32``, ``kSgruI8``) when the export holds sgru_weights.bin beside W
  (formats/sgru_weights.py; its on-board record must be W's, its dims within W's GRU limits);
- the motor heads (``kCnodeMotorF32`` ... ``kGruMotorI8``) when W holds the sections cnode_motor /
  gru_motor; the header says which with FWREF_STREAM_HAS_SGRU / _CNODE_MOTOR / _GRU_MOTOR (0 or 1);
- the streaming CNODE (``kScnodeF32``, ``kScnodeI8``: the bytes of scnode_weights.bin and scnode_weights_i8.bin,
  bound in place by fwref/scnode_file.hpp) when the export holds both (its channels and classes W's, its latent
  and width within W's CNODE limits; FWREF_STREAM_HAS_SCNODE), run with the record's single policy (``kParamsScnode``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.channels import profile_enum
from quadfdi.core.contracts import cpp_policy_values
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.export_folder import Export
from quadfdi.formats.stream import read_stream
from quadfdi.formats.onboard import max_alarm_n, policy_of
from quadfdi.runtimes.mcu_scnode_src import file_dims, word_array
from quadfdi.runtimes.mcu_weights_src import FileError, section_body

PROG = "python -m quadfdi.runtimes.mcu_stream_src"


def _floats(a: np.ndarray) -> str:
    return ",".join(f"{float(v)!r}f" if np.isfinite(v) else "NAN" for v in np.asarray(a, np.float32).ravel())


def _doubles(a: np.ndarray) -> str:
    return ",".join(repr(float(v)) for v in np.asarray(a, np.float64).ravel())


# (weights file model, precision, constant's name, its C++ struct, the header's flag)
EXTRA = (("sgru", "fp32", "kSgruF32", "GruF32", "SGRU"), ("sgru", "int8", "kSgruI8", "GruI8", "SGRU"),
         ("cnode_motor", "fp32", "kCnodeMotorF32", "CnodeMotorF32", "CNODE_MOTOR"),
         ("cnode_motor", "int8", "kCnodeMotorI8", "CnodeMotorI8", "CNODE_MOTOR"),
         ("gru_motor", "fp32", "kGruMotorF32", "GruMotorF32", "GRU_MOTOR"),
         ("gru_motor", "int8", "kGruMotorI8", "GruMotorI8", "GRU_MOTOR"))


def rotor_mask(rec: dict, classes: int) -> str:
    """The record's alarm.rotor_side as fwref::AlarmParams::rotor_mask (bit c: class c reports a motor;
    every bit for a record written before the flags), hex; refused unless it covers the model's K classes."""
    flags = rec.get("rotor_side")
    if flags is None:
        return "0xFFFFFFFF"
    if len(flags) != classes:
        raise QuadfdiError(f"the on-board record's alarm.rotor_side has {len(flags)} classes, the model {classes}")
    return f"0x{sum(1 << c for c, f in enumerate(flags) if f):08X}"


def params(rec: dict, classes: int, a: dict) -> str:
    """A fwref::StreamParams initializer: the record's stream and the alarm policy ``a``."""
    return f"""fwref::StreamParams{{fwref::Profile::{profile_enum(rec['profile'])}, {rec['window']}, {rec['stride']},
    {len(rec['raw_channels'])}, {len(rec['channels'])}, {classes}, {rec['sample_dt_s']!r},
    fwref::AlarmParams{{{cpp_policy_values(a)},
                       {rec['healthy']}, {classes}, {rotor_mask(rec, classes)}u}}}}"""


SCNODE_FILES = (("kScnodeF32", "scnode_weights.bin"), ("kScnodeI8", "scnode_weights_i8.bin"))


def header(rec: dict, classes: int, flights: int, extra: dict | None = None, scnode: dict | None = None) -> str:
    extra = extra or {}
    flags = "".join(f"#define FWREF_STREAM_HAS_{flag} {int(any(e[4] == flag and (e[0], e[1]) in extra for e in EXTRA))}\n"
                    for flag in ("SGRU", "CNODE_MOTOR", "GRU_MOTOR")) + f"#define FWREF_STREAM_HAS_SCNODE {int(bool(scnode))}\n"
    decls = "".join(f"extern const fwref::{typ} {var};\n" for m, p, var, typ, _ in EXTRA if (m, p) in extra)
    decls += "".join(f"extern const Blob {var};\n" for var in (scnode or {}))
    return f"""// GENERATED by `python -m quadfdi.runtimes.mcu_stream_src`; do not edit.
#pragma once
#include <cstddef>
#include <cstdint>
#include "fwref/cnode.hpp"
#include "fwref/gru.hpp"
#include "fwref/motor.hpp"
#include "fwref/stream.hpp"
{flags}
namespace fwref_stream_data {{
struct Blob {{
  const unsigned char* data;  // a file's bytes (4-byte aligned)
  std::size_t size;
}};
{decls}
// kParams: the record's single policy; kParams<Net>: the network's own (its alarm.models row, else the same).
constexpr fwref::StreamParams kParams = {params(rec, classes, rec['alarm'])};
constexpr fwref::StreamParams kParamsCnode = {params(rec, classes, policy_of(rec, 'cnode')[0])};
constexpr fwref::StreamParams kParamsGru = {params(rec, classes, policy_of(rec, 'gru')[0])};
constexpr fwref::StreamParams kParamsSgru = {params(rec, classes, policy_of(rec, 'sgru')[0])};
constexpr fwref::StreamParams kParamsScnode = kParams;  // alarm.models has no streaming CNODE row
struct Flight {{
  const char* name;
  int cells;
  std::uint64_t carried;  // bit r: the stream carries raw column r (the stream file's flags; Stream::set_carried)
  const fwref::VehicleRecord* vehicle;  // the stream's vehicle record (Stream::set_vehicle), null: none
  int samples;
  const double* t;      // (samples)
  const float* values;  // (samples, raw channels)
}};
constexpr int kFlightCount = {flights};
extern const Flight kFlights[kFlightCount];
}}  // namespace fwref_stream_data
"""


def source(streams: list, extra: dict | None = None, scnode: dict | None = None) -> str:
    out = ['// GENERATED by `python -m quadfdi.runtimes.mcu_stream_src`; do not edit.', '#include <cmath>',
           '#include "fwref_stream_data.hpp"', "", "namespace fwref_stream_data {"]
    for m, p, var, _, _ in EXTRA:
        if (m, p) in (extra or {}):
            out.append(section_body(m, p, extra[(m, p)], var))
    for var, blob in (scnode or {}).items():
        out.append(word_array(f"{var}Words", blob)
                   + f"extern const Blob {var} = {{reinterpret_cast<const unsigned char*>({var}Words), {len(blob)}u}};")
    out.append("namespace {")
    for i, rs in enumerate(streams):
        out.append(f"const double kT{i}[] = {{{_doubles(rs.time)}}};")
        out.append(f"const float kV{i}[] = {{{_floats(rs.values)}}};")
        if rs.vehicle is not None:
            out.append(f"const fwref::VehicleRecord kVehicle{i} = {{{{{_floats(rs.vehicle)}}}}};")
    out += ["}  // namespace", "const Flight kFlights[kFlightCount] = {"]
    out += [f'    {{"{rs.source[:40]}", {rs.cells}, {carried_bits(rs)}u, {"nullptr" if rs.vehicle is None else f"&kVehicle{i}"}, '
            f'{len(rs.time)}, kT{i}, kV{i}}},' for i, rs in enumerate(streams)]
    out += ["};", "}  // namespace fwref_stream_data", ""]
    return "\n".join(out)


def carried_bits(rs) -> str:
    """The stream's carried flags as Flight::carried (bit r: column r), hex."""
    flags = rs.carried_flags
    if len(flags) > 64 and not flags[64:].all():
        raise QuadfdiError(f"stream {rs.source}: a channel past the 64th is not carried")
    return f"0x{sum(1 << r for r, f in enumerate(flags[:64]) if f) | (0 if len(flags) >= 64 else ~0 << len(flags)) & (2**64 - 1):016X}"


def extra_sections(wf, folder: Path) -> dict:
    """{(model, precision): Section} of the streaming GRU (sgru_weights.bin in ``folder``) and of the
    motor heads weights.bin holds (module docstring); a streaming GRU file that does not fit is refused."""
    from quadfdi.formats.sgru_weights import FILE_NAME, read_sgru_weights

    out = {(m, p): wf.section(m, p) for m, p, *_ in EXTRA if m != "sgru" and wf.has(m, p)}
    path = folder / FILE_NAME
    if path.is_file():
        sw = read_sgru_weights(path)
        same = {k: t.array.tobytes() for k, t in sw.onboard.tensors.items()} == \
            {k: t.array.tobytes() for k, t in wf.onboard.tensors.items()} and sw.onboard.dims == wf.onboard.dims
        gru = wf.section("gru", "fp32").dims
        if not same:
            raise QuadfdiError(f"{path}: its on-board record is not {folder / 'weights.bin'}'s (re-run `quadfdi export sgru`)")
        if sw.fp32.dims[0] != gru[0] or sw.fp32.dims[2] != gru[2] or sw.fp32.dims[3] > gru[3]:
            raise QuadfdiError(f"{path}: channels, classes or hidden {sw.fp32.dims[:4]} do not fit the image's GRU limits {gru[:4]}")
        out.update({("sgru", "fp32"): sw.fp32, ("sgru", "int8"): sw.int8})
    return out


def scnode_blobs(wf, folder: Path) -> dict[str, bytes]:
    """{constant: bytes} of the streaming CNODE's weights files beside weights.bin (both, or none: {}); refused
    unless its channels and classes are the record's model's and its latent and width within W's CNODE limits."""
    paths = [folder / name for _, name in SCNODE_FILES]
    if not all(p.is_file() for p in paths):
        return {}
    blobs = {var: p.read_bytes() for (var, _), p in zip(SCNODE_FILES, paths)}
    cnode = wf.section("cnode", "fp32").dims  # C, W, K, H, L, ...
    for (var, name), blob in zip(SCNODE_FILES, blobs.values()):
        d = file_dims(blob, str(folder / name), flight=False)
        if (d["FWREF_MAX_CHANNELS"], d["FWREF_MAX_CLASSES"]) != (cnode[0], cnode[2]) or \
                d["FWREF_MAX_CNODE_HIDDEN"] > cnode[3] or d["FWREF_MAX_LATENT"] > cnode[4]:
            raise QuadfdiError(f"{folder / name}: channels, classes, latent, width {tuple(d.values())} do not fit the "
                               f"image's CNODE limits (C {cnode[0]}, K {cnode[2]}, L <= {cnode[4]}, H <= {cnode[3]})")
    return blobs


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    ap.add_argument("--weights", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("streams", nargs="+")
    args = ap.parse_args(argv)
    try:
        export = Export.open(Path(args.weights).parent)
        if export.weights_path.resolve() != Path(args.weights).resolve():
            raise QuadfdiError(f"{args.weights} is not its export folder's weights.bin")
        wf, rec = export.weights(), export.onboard()
        classes = int(wf.section("cnode", "fp32").dims[2])
        rotor_mask(rec, classes)  # refuses flags that do not cover the model's classes, before writing
        extra = extra_sections(wf, Path(args.weights).parent)
        scnode = scnode_blobs(wf, Path(args.weights).parent)
        streams = [read_stream(p) for p in args.streams]
        for p, rs in zip(args.streams, streams):
            if rs.names != rec["raw_channels"] or rs.profile != rec["profile"]:
                raise QuadfdiError(f"{p}: its channels or profile are not the on-board record's")
    except (QuadfdiError, OSError, FileError) as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    limits = ("// GENERATED by `python -m quadfdi.runtimes.mcu_stream_src`; do not edit "
              "(-DFWREF_STREAM_LIMITS_HEADER).\n"
              f"#define FWREF_MAX_RAW_CHANNELS {len(rec['raw_channels'])}\n#define FWREF_MAX_ALARM_N {max_alarm_n(rec)}\n")
    for name, text in (("fwref_stream_limits.h", limits),
                       ("fwref_stream_data.hpp", header(rec, classes, len(streams), extra, scnode)),
                       ("fwref_stream_data.cpp", source(streams, extra, scnode))):
        path = out / name
        if not path.is_file() or path.read_text() != text:
            path.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
