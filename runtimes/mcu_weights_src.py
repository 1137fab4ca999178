"""The Cortex-M build's constant arrays, generated from weights.bin (and reference.bin): a step of
firmware_ref/mcu/CMakeLists.txt, which runs it with the interpreter it was configured with.

    python -m quadfdi.runtimes.mcu_weights_src --weights <weights.bin> [--reference <reference.bin>]
                                               [--manifest <manifest.json>] --out <folder>

Writes into <folder>:
  fwref_limits.h              FWREF_MAX_* = the model's own dimensions (fwref/config.hpp reads it
                              through -DFWREF_LIMITS_HEADER), so no buffer is larger than needed;
  fwref_weights.hpp           extern const fwref::CnodeF32 kCnodeF32, kCnodeI8, kGruF32, kGruI8;
  fwref_weights_<model>_<precision>.cpp   each section's tensors as const arrays (flash) and the
                              model struct pointing at them (constant-initialised: flash, not RAM);
  fwref_reference.hpp/.cpp    (with --reference) the reference windows and every expected tensor,
                              for the QEMU parity harness (mcu/parity_main.cpp).

The files are read with the project's own readers (formats.weights_bin.read_weights,
formats.reference_bin.read_reference: every container and layout check), and each model struct is
initialised in the order of the layout table formats/weights_layout.py, which the generated header
fwref/weights_layout_gen.hpp pins to the structs' member order. An unusable file exits 2 with one
line on stderr. Floats are written as C++17 hexadecimal literals: exact. A file is rewritten only
when its text changes, so an unchanged weights.bin rebuilds nothing. With --manifest, weights.bin
(and reference.bin) must have the sha256 export/manifest.json records for them. A generated file
replaces only a regular file (a symlink or FIFO there is refused) and gets the user's umask.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from quadfdi.core.cliargs import one_line_main
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.reference_bin import read_reference
from quadfdi.formats.weights_bin import read_weights
from quadfdi.formats.weights_layout import LAYOUTS, MODELS, SECTION_ORDER, dtype_of

PROG = "python -m quadfdi.runtimes.mcu_weights_src"

CTYPES = {"float32": "float", "int8": "std::int8_t", "int32": "std::int32_t"}


class FileError(Exception):
    """An unusable input file; printed as one line."""


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


def section_unit(model: str, precision: str, section) -> str:
    """One generated .cpp: the arrays of one section and the model struct that points at them,
    initialised in the layout table's order (dims first)."""
    return (f'#include "fwref_weights.hpp"\n\nnamespace fwref_data {{\n'
            f"{section_body(model, precision, section)}}}  // namespace fwref_data\n")


def section_body(model: str, precision: str, section, var: str | None = None) -> str:
    """The arrays of one section (an anonymous namespace) and ``const fwref::<struct> <var>`` pointing
    at them: any layout of formats/weights_layout.py (the streaming GRU's and the motor heads' too:
    runtimes/mcu_stream_src.py), ``var`` by default k<struct>."""
    layout = LAYOUTS[model]
    prefix = f"{model}_{'f32' if precision == 'fp32' else 'i8'}"
    parts, fields = [], ["{" + ", ".join(str(section.dims[d.index]) for d in layout.dims) + "}"]
    for spec in layout.specs(precision):
        if spec.field is None:
            continue
        t = section.tensors[spec.name]
        cname = ident(prefix, spec.name)
        if spec.kind == "scalar":
            fields.append(c_float(float(t.array.reshape(-1)[0])))
            continue
        parts.append(c_array(CTYPES[dtype_of(spec, precision).name], cname, t.array.ravel().tolist()))
        if spec.kind != "mat":
            fields.append(cname)
        elif precision == "int8":
            parts.append(c_array("float", cname + "_scale", t.scales.tolist()))
            fields.append(f"{{{cname}, {cname}_scale, {t.array.shape[0]}, {t.array.shape[1]}}}")
        else:
            fields.append(f"{{{cname}, {t.array.shape[0]}, {t.array.shape[1]}}}")
    typ = layout.cpp_types[precision]
    var = var or "k" + typ
    init = ",\n    ".join(fields)
    return (f'namespace {{\n{"".join(parts)}}}  // namespace\n\n'
            f"const fwref::{typ} {var} = {{\n    {init}\n}};\n\n")


HEADER = "// GENERATED by `python -m quadfdi.runtimes.mcu_weights_src` from {src}; do not edit.\n"


def limits_header(weights) -> str:
    """Every FWREF_MAX_* macro of the layout's dims set to the largest value this file holds."""
    macros: dict[str, int] = {}
    for model, layout in MODELS.items():
        fp32 = weights.section(model, "fp32").dims
        if weights.section(model, "int8").dims != fp32:
            raise FileError(f"{model} fp32 and int8 sections have different dimensions")
        for d in layout.dims:
            if d.macro:
                macros[d.macro] = max(macros.get(d.macro, 0), int(fp32[d.index]))
    return ("// The model's own dimensions as the build's maxima: no buffer holds more than this model needs.\n"
            "#pragma once\n" + "".join(f"#define {k} {v}\n" for k, v in macros.items()))


def weights_header() -> str:
    decls = "".join(f"extern const fwref::{t} k{t};\n" for m, p in SECTION_ORDER for t in [MODELS[m].cpp_types[p]])
    return ("#pragma once\n// The four models of weights.bin as constant structs in flash (one .cpp per section).\n"
            '#include "fwref/cnode.hpp"\n#include "fwref/gru.hpp"\n'
            '#include "fwref/weights_layout_gen.hpp"  // pins the member order used below\n\n'
            "namespace fwref_data {\n" + decls +
            "}  // namespace fwref_data\n")


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
    inputs = next((s.tensors for s in sections if s.model == "none"), None)
    if inputs is None or "telemetry" not in inputs or "label" not in inputs:
        raise FileError("reference file has no inputs section with 'telemetry' and 'label'")
    tel = inputs["telemetry"].array
    private, rows = [], []
    for sec in sections:
        if sec.model == "none":
            continue
        for name in ("x_norm", "u", "z0", "stages", "z1", "h", "logits"):
            if name in sec.tensors:
                values = sec.tensors[name].array.ravel().tolist()
                cname = ident("ref", sec.model, sec.precision, name)
                private.append(c_array("float", cname, values))
                rows.append(f'{{"{sec.model}", "{sec.precision}", "{name}", {cname}, {len(values)}}}')
    labels = ", ".join(map(str, inputs["label"].array.tolist()))
    table = ",\n    ".join(rows)
    return ('#include "fwref_reference.hpp"\n\nnamespace fwref_ref {\nnamespace {\n' + "".join(private) +
            "}  // namespace\n\n" + c_array("float", "kTelemetry", tel.ravel().tolist()) +
            f"alignas(4) const int kLabels[{tel.shape[0]}] = {{{labels}}};\n"
            f"const int kWindows = {tel.shape[0]};\nconst int kTensorCount = {len(rows)};\n"
            f"const Tensor kTensors[] = {{\n    {table}\n}};\n}}  // namespace fwref_ref\n")


def write_if_changed(path: Path, text: str) -> None:
    if path.is_symlink() or (path.exists() and not path.is_file()):
        raise FileError(f"refusing to write {path}: it is a symlink, folder or special file, not a regular file")
    if path.is_file() and path.read_text() == text:
        return
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    mask = os.umask(0o022)  # mkstemp makes 0600: the user's umask instead (read by set and restore)
    os.umask(mask)
    os.chmod(tmp, 0o666 & ~mask)
    os.replace(tmp, path)


def check_manifest(manifest: Path, files: dict[str, Path]) -> None:
    """Each of ``files`` ({name in the manifest: path}) must have the sha256 the manifest records."""
    import hashlib

    from quadfdi.core.jsonio import read_json

    try:
        listed = read_json(manifest, "manifest").get("files", {})
    except (QuadfdiError, AttributeError) as exc:
        raise FileError(f"manifest {manifest} cannot be read: {exc}") from None
    for name, path in files.items():
        want = (listed.get(name) or {}).get("sha256") if isinstance(listed, dict) else None
        if not want:
            raise FileError(f"manifest {manifest} has no sha256 for {name} (files.{name}.sha256)")
        try:
            got = hashlib.sha256(path.read_bytes()).hexdigest()
        except OSError as exc:
            raise FileError(f"cannot read {path}: {exc.strerror}") from None
        if got != want:
            raise FileError(f"{path}: sha256 {got[:16]}... differs from {want[:16]}... recorded in {manifest} "
                            f"(files.{name}.sha256)")


def generate(weights: Path, reference: Path | None, out: Path, manifest: Path | None = None) -> list[Path]:
    if manifest is not None:
        check_manifest(manifest, {"weights.bin": weights, **({"reference.bin": reference} if reference else {})})
    try:
        w = read_weights(weights)
        ref = read_reference(reference).sections if reference is not None else None
    except QuadfdiError as exc:
        raise FileError(str(exc)) from None
    out.mkdir(parents=True, exist_ok=True)
    head = HEADER.format(src=weights.name)
    files = {"fwref_limits.h": head + limits_header(w), "fwref_weights.hpp": head + weights_header()}
    for model, prec in SECTION_ORDER:
        name = f"fwref_weights_{model}_{'f32' if prec == 'fp32' else 'i8'}.cpp"
        files[name] = head + section_unit(model, prec, w.section(model, prec))
    if ref is not None:
        files["fwref_reference.hpp"] = HEADER.format(src=reference.name) + REFERENCE_HPP
        files["fwref_reference.cpp"] = HEADER.format(src=reference.name) + reference_unit(ref)
    for name, text in files.items():
        write_if_changed(out / name, text)
    return [out / n for n in files]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    ap.add_argument("--weights", required=True, type=Path)
    ap.add_argument("--reference", type=Path, default=None)
    ap.add_argument("--manifest", type=Path, default=None, help="export/manifest.json: check the files' sha256")
    ap.add_argument("--out", required=True, type=Path)
    args = ap.parse_args(argv)

    def body() -> None:
        generate(args.weights, args.reference, args.out, args.manifest)

    return one_line_main(PROG, body, (FileError,))


if __name__ == "__main__":
    sys.exit(main())
