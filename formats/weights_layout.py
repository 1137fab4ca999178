"""weights.bin's tensor list, written once: per model the section dimensions and the ordered tensors.

Everything that writes, reads or binds weights.bin takes the layout from here: the Python writer
and reader (formats/weights_bin.py), the C++ binder (firmware_ref/src/weights_file.cpp, through the
generated header firmware_ref/include/fwref/weights_layout_gen.hpp) and the Cortex-M constant-array
generator (runtimes/mcu_weights_src.py). Regenerate the header after a change here:

    python -m quadfdi.formats.weights_layout --header

A test checks that the committed header equals what this module generates, and that the compiled
C++ binder prints back this table (fwref_contracts).

Tensor kinds:
- ``vec``: float32 of the given shape in both precisions;
- ``index``: int32 in both precisions;
- ``mat``: a matrix (out, in), float32 in the fp32 section, int8 with one scale per row (axis 0,
  zero points 0) in the int8 section;
- ``scalar``: float32 (1,), bound in C++ as a float value.
Shapes are products of a section dimension and an integer factor: "C", "3H", "4N", "1".
"""

from __future__ import annotations

import re
import sys
from dataclasses import dataclass

import numpy as np

from quadfdi.core.contracts import header_cli
from quadfdi.core.resources import firmware_sources
from quadfdi.core.rk4 import RK4_C, RK4_CONSTANT_NAMES
from quadfdi.formats.binfmt import MODELS as BIN_MODELS, N_DIMS

MAGIC = b"QFDIWTS\0"
VERSION = 1
# reference.bin shares the container (export/reference_bin.py): its identifiers live here too, so the
# generated header takes both from one module.
REFERENCE_MAGIC = b"QFDIREF\0"
REFERENCE_VERSION = 1
PRECISIONS = ("fp32", "int8")
STAGES_PER_STEP = len(RK4_C)  # field evaluations per classic RK4 step


@dataclass(frozen=True)
class Dim:
    """Entry ``index`` of a section's dims u32[8]: symbol, C++ field of the model's dims struct, and
    either the build limit it must not exceed or the formula it must equal (other dims)."""

    symbol: str
    index: int
    field: str
    what: str  # in error messages
    limit: str | None = None  # C++ constant of fwref/config.hpp
    macro: str | None = None  # the macro that sets it
    derived: tuple[str, int, int] | None = None  # (symbol, a, b): value = a * dims[symbol] + b


@dataclass(frozen=True)
class TensorSpec:
    name: str
    kind: str
    shape: tuple[str, ...]
    field: str | None  # member of the C++ model struct; None: in the file, not used by C++
    int8_only: bool = False


@dataclass(frozen=True)
class ModelLayout:
    model: str
    cpp_dims: str  # C++ dims struct
    cpp_types: dict[str, str]  # precision -> C++ model struct
    dims: tuple[Dim, ...]
    tensors: tuple[TensorSpec, ...]

    def specs(self, precision: str) -> tuple[TensorSpec, ...]:
        return tuple(t for t in self.tensors if precision == "int8" or not t.int8_only)


_C = Dim("C", 0, "channels", "channels", "kMaxChannels", "FWREF_MAX_CHANNELS")
_W = Dim("W", 1, "window", "window", "kMaxWindow", "FWREF_MAX_WINDOW")
_K = Dim("K", 2, "classes", "classes", "kMaxClasses", "FWREF_MAX_CLASSES")

CNODE = ModelLayout(
    "cnode", "CnodeDims", {"fp32": "CnodeF32", "int8": "CnodeI8"},
    (_C, _W, _K, Dim("H", 3, "hidden", "hidden", "kMaxCnodeHidden", "FWREF_MAX_CNODE_HIDDEN"),
     Dim("L", 4, "latent", "latent", "kMaxLatent", "FWREF_MAX_LATENT"),
     Dim("N", 5, "steps", "steps N", "kMaxSteps", "FWREF_MAX_STEPS"),
     Dim("S", 6, "stage_times", "stage times", derived=("N", 2, 1))),
    (TensorSpec("norm.mean", "vec", ("C",), "mean"),
     TensorSpec("norm.std", "vec", ("C",), "std"),
     TensorSpec("interp", "mat", ("S", "W"), "interp"),
     TensorSpec("stage_index", "index", (f"{STAGES_PER_STEP}N",), "stage_index"),
     TensorSpec("stage_times", "vec", ("S",), None),
     TensorSpec("rk4.consts", "vec", (str(len(RK4_CONSTANT_NAMES)),), "rk4"),
     TensorSpec("encoder.weight", "mat", ("L", "C"), "encoder_w"),
     TensorSpec("encoder.bias", "vec", ("L",), "encoder_b"),
     TensorSpec("lin1_z.weight", "mat", ("H", "L"), "lin1_z"),
     TensorSpec("lin1_u.weight", "mat", ("H", "C"), "lin1_u"),
     TensorSpec("lin1.bias", "vec", ("H",), "lin1_b"),
     TensorSpec("lin2.weight", "mat", ("L", "H"), "lin2_w"),
     TensorSpec("lin2.bias", "vec", ("L",), "lin2_b"),
     TensorSpec("head.weight", "mat", ("K", "L"), "head_w"),
     TensorSpec("head.bias", "vec", ("K",), "head_b"),
     TensorSpec("act.x_norm.scale", "vec", ("C",), "s_x", True),
     TensorSpec("act.u.scale", "vec", ("C",), "s_u", True),
     TensorSpec("act.stage.scale", "vec", (f"{STAGES_PER_STEP}N",), "s_stage", True),
     TensorSpec("act.hidden.scale", "scalar", ("1",), "s_hidden", True),
     TensorSpec("act.z1.scale", "scalar", ("1",), "s_z1", True)),
)

GRU = ModelLayout(
    "gru", "GruDims", {"fp32": "GruF32", "int8": "GruI8"},
    (_C, _W, _K, Dim("H", 3, "hidden", "hidden", "kMaxGruHidden", "FWREF_MAX_GRU_HIDDEN")),
    (TensorSpec("norm.mean", "vec", ("C",), "mean"),
     TensorSpec("norm.std", "vec", ("C",), "std"),
     TensorSpec("gru.weight_ih", "mat", ("3H", "C"), "w_ih"),
     TensorSpec("gru.weight_hh", "mat", ("3H", "H"), "w_hh"),
     TensorSpec("gru.bias_ih", "vec", ("3H",), "b_ih"),
     TensorSpec("gru.bias_hh", "vec", ("3H",), "b_hh"),
     TensorSpec("head.weight", "mat", ("K", "H"), "head_w"),
     TensorSpec("head.bias", "vec", ("K",), "head_b"),
     TensorSpec("act.x_norm.scale", "vec", ("C",), "s_x", True),
     TensorSpec("act.h.scale", "scalar", ("1",), "s_h", True)),
)

MODELS: dict[str, ModelLayout] = {"cnode": CNODE, "gru": GRU}
SECTION_ORDER: tuple[tuple[str, str], ...] = tuple((m, p) for m in MODELS for p in PRECISIONS)


def _motor_layout(net: str, feature: Dim) -> ModelLayout:
    """The motor head of ``net`` (models.motor): motor_logits (M = 4) = W features + b, where the
    features are what the class head reads (CNODE z1, GRU h_W); int8 with the class head's
    activation scale (act.z1.scale / act.h.scale of the net's int8 section)."""
    title = net.capitalize()
    return ModelLayout(
        f"{net}_motor", f"{title}MotorDims", {"fp32": f"{title}MotorF32", "int8": f"{title}MotorI8"},
        (feature, Dim("M", 1, "motors", "motors", "kMotors", "FWREF_MOTORS")),
        (TensorSpec("motor_head.weight", "mat", ("M", "F"), "w"),
         TensorSpec("motor_head.bias", "vec", ("M",), "b")))


# Optional sections, after the four above and in this order, only for a net with a motor head
# (an additive change: a file without them is byte for byte what it was).
MOTOR_MODELS: dict[str, ModelLayout] = {
    "cnode_motor": _motor_layout("cnode", Dim("F", 0, "features", "features (latent L)", "kMaxLatent", "FWREF_MAX_LATENT")),
    "gru_motor": _motor_layout("gru", Dim("F", 0, "features", "features (hidden H)", "kMaxGruHidden", "FWREF_MAX_GRU_HIDDEN")),
}
MOTOR_SECTION_ORDER: tuple[tuple[str, str], ...] = tuple((m, p) for m in MOTOR_MODELS for p in PRECISIONS)
# The streaming GRU (models/stream_gru.py): the GRU's tensors with W = 1, in its own weights file
# (formats/sgru_weights.py), never in weights.bin. Not in the generated header: C++ binds it to the
# GRU's structs (WeightsFile::bind_sgru), so the header stays what it was.
STREAM_MODELS: dict[str, ModelLayout] = {"sgru": ModelLayout("sgru", GRU.cpp_dims, GRU.cpp_types, GRU.dims, GRU.tensors)}
LAYOUTS: dict[str, ModelLayout] = {**MODELS, **MOTOR_MODELS, **STREAM_MODELS}
_EXTENT = re.compile(r"^(\d*)([A-Z]?)$")


def parse_extent(text: str) -> tuple[int, str | None]:
    """"3H" -> (3, "H"); "C" -> (1, "C"); "4" -> (4, None)."""
    m = _EXTENT.match(text)
    if m is None or not (m.group(1) or m.group(2)):
        raise ValueError(f"bad extent {text!r}")
    return int(m.group(1) or 1), m.group(2) or None


def dims_of(model: str, values: dict[str, int]) -> tuple[int, ...]:
    """The section's dims u32[8] from ``{symbol: value}`` (derived dims computed, unused entries 0)."""
    layout = LAYOUTS[model]
    out = [0] * N_DIMS
    for d in layout.dims:
        if d.derived:
            sym, a, b = d.derived
            out[d.index] = a * values[sym] + b
        else:
            out[d.index] = int(values[d.symbol])
    return tuple(out)


def shape_of(model: str, spec: TensorSpec, dims: tuple[int, ...]) -> tuple[int, ...]:
    """The shape ``spec`` has in a section with these ``dims``."""
    index = {d.symbol: d.index for d in LAYOUTS[model].dims}
    out = []
    for e in spec.shape:
        factor, sym = parse_extent(e)
        out.append(factor * (int(dims[index[sym]]) if sym else 1))
    return tuple(out)


def dtype_of(spec: TensorSpec, precision: str) -> np.dtype:
    if spec.kind == "index":
        return np.dtype(np.int32)
    if spec.kind == "mat" and precision == "int8":
        return np.dtype(np.int8)
    return np.dtype(np.float32)


def check_dims(model: str, dims: tuple[int, ...]) -> str | None:
    """None if ``dims`` are a consistent section header for ``model``, else what is wrong."""
    by = {d.symbol: d for d in LAYOUTS[model].dims}
    for d in LAYOUTS[model].dims:
        v = int(dims[d.index])
        if d.derived:
            sym, a, b = d.derived
            want = a * int(dims[by[sym].index]) + b
            if v != want:
                return f"{d.what} is {v}, expected {a}{sym} + {b} = {want}"
        elif v == 0:
            return f"{d.what} is 0"
    return None


# ---------------------------------------------------------------------------------- the C++ header

# In firmware_ref's sources, found as package data (a checkout: the tracked firmware_ref/include/fwref/).
HEADER_PATH = firmware_sources() / "include" / "fwref" / "weights_layout_gen.hpp"
_CPP_KIND = {"vec": "kVec", "index": "kIndex", "mat": "kMat", "scalar": "kScalar"}

_PREAMBLE = """// GENERATED by `python -m quadfdi.formats.weights_layout --header` from formats/weights_layout.py; do not edit.
// weights.bin's layout: per model the section dims and the ordered tensors, and for each model
// struct a visit() that hands every member to a binder with its tensor's spec.
#pragma once

#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "fwref/cnode.hpp"
#include "fwref/config.hpp"
#include "fwref/gru.hpp"
#include "fwref/motor.hpp"

namespace fwref {
namespace layout {

constexpr char kMagic[9] = "@MAGIC@";  // + the terminating NUL: 8 bytes
constexpr std::uint32_t kVersion = @VERSION@;
// reference.bin (export/reference_bin.py) shares the container; fwref_parity reads it.
constexpr char kReferenceMagic[9] = "@REF_MAGIC@";
constexpr std::uint32_t kReferenceVersion = @REF_VERSION@;
constexpr const char* kSectionOrder[] = {@ORDER@};

// vec: float32; index: int32; mat: float32 (fp32 section) or int8 per row (int8 section);
// scalar: float32 (1,) bound as a value.
enum class Kind { kVec, kIndex, kMat, kScalar };

// One extent of a shape: factor * dims[dim], or the constant factor when dim is -1.
struct Extent {
  int dim;
  int factor;
};

struct TensorSpec {
  const char* name;
  Kind kind;
  int ndim;
  Extent shape[2];
  const char* shape_text;  // "(3H, C)"
  bool int8_only;
};

// dims[index]: at most ``limit`` (set by ``macro``), or when ``from`` >= 0 exactly a * dims[from] + b.
struct DimSpec {
  const char* symbol;
  const char* what;
  int index;
  int limit;
  const char* macro;
  int from;
  int a;
  int b;
};

inline int extent(const Extent& e, const std::uint32_t* dims) {
  return e.dim < 0 ? e.factor : e.factor * static_cast<int>(dims[e.dim]);
}

// A tensor of the file that the C++ models do not use (checked, not kept).
struct Unbound {};

// Member b starts where member a ends, give or take b's alignment padding.
constexpr bool follows(std::size_t b_offset, std::size_t a_offset, std::size_t a_size, std::size_t b_align) {
  return b_offset >= a_offset + a_size && b_offset < a_offset + a_size + b_align;
}

// The Cortex-M generator initialises each model struct in table order (dims first), so each
// struct's members must be exactly dims and the bound tensors, in table order.
#define FWREF_FOLLOWS(T, a, b) \\
  static_assert(follows(offsetof(T, b), offsetof(T, a), sizeof(T::a), alignof(decltype(T::b))), \\
                #T ": " #b " must follow " #a)
#define FWREF_LAST(T, a) \\
  static_assert(follows(sizeof(T), offsetof(T, a), sizeof(T::a), alignof(T)), #T ": " #a " must be the last member")

template <class Model>
struct Section;

@BODY@
}  // namespace layout
}  // namespace fwref

#undef FWREF_FOLLOWS
#undef FWREF_LAST
"""


def _cpp_shape(layout: ModelLayout, spec: TensorSpec) -> str:
    index = {d.symbol: d.index for d in layout.dims}
    parts = []
    for e in spec.shape:
        factor, sym = parse_extent(e)
        parts.append(f"{{{index[sym] if sym else -1}, {factor}}}")
    parts += ["{-1, 0}"] * (2 - len(parts))
    return ", ".join(parts)


def _cpp_tables(layout: ModelLayout, title: str) -> list[str]:
    """The dims and tensor tables of one model, and dims_from()."""
    dims = []
    for d in layout.dims:
        if d.derived:
            sym, a, b = d.derived
            src = next(x.index for x in layout.dims if x.symbol == sym)
            dims.append(f'    {{"{d.symbol}", "{d.what}", {d.index}, 0, nullptr, {src}, {a}, {b}}},')
        else:
            dims.append(f'    {{"{d.symbol}", "{d.what}", {d.index}, {d.limit}, "{d.macro}", -1, 0, 0}},')
    rows = [f'    {{"{t.name}", Kind::{_CPP_KIND[t.kind]}, {len(t.shape)}, {{{_cpp_shape(layout, t)}}}, '
            f'"({", ".join(t.shape)}{"," if len(t.shape) == 1 else ""})", {str(t.int8_only).lower()}}},'
            for t in layout.tensors]
    return [f"// ---- {layout.model}: section dims u32[8] and tensors, in file order", "",
            f"constexpr DimSpec k{title}Dims[] = {{", *dims, "};",
            f"constexpr int k{title}DimCount = {len(layout.dims)};",
            "", f"constexpr TensorSpec k{title}Tensors[] = {{", *rows, "};",
            f"constexpr int k{title}TensorCount = {len(layout.tensors)};", "",
            f"inline void dims_from(const std::uint32_t* v, {layout.cpp_dims}* d) {{",
            *[f"  d->{d.field} = static_cast<int>(v[{d.index}]);" for d in layout.dims], "}", ""]


def _cpp_structs(layout: ModelLayout, title: str) -> list[str]:
    """Section<> of both model structs, one visit() for both, and the member-order checks."""
    m, types = layout.model, layout.cpp_types
    code = BIN_MODELS[m]
    lines = [f"template <std::uint32_t P>", f"struct {title}Section {{",
             f"  static constexpr std::uint32_t model = {code}, precision = P;",
             f'  static constexpr const char* label = P == 1 ? "{m} fp32" : "{m} int8";',
             f"  static constexpr const DimSpec* dims = k{title}Dims;",
             f"  static constexpr int dim_count = k{title}DimCount;",
             f"  static constexpr const TensorSpec* tensors = k{title}Tensors;",
             f"  static constexpr int tensor_count = k{title}TensorCount;", "};"]
    lines += [f"template <> struct Section<{types[p]}> : {title}Section<{i + 1}> {{}};"
              for i, p in enumerate(PRECISIONS)]
    common, int8 = [], []
    for i, t in enumerate(layout.tensors):
        member = f"m.{t.field}" if t.field else "Unbound{}"
        (int8 if t.int8_only else common).append(f"f({member}, k{title}Tensors[{i}]);")
    lines += ["", f"// Every tensor of a {m} section, in file order, with the member it binds to.",
              "template <class M, class F>",
              f"std::enable_if_t<std::is_same_v<std::remove_const_t<M>, {types['fp32']}> || "
              f"std::is_same_v<std::remove_const_t<M>, {types['int8']}>>",
              "visit(M& m, F& f) {", *[f"  {c}" for c in common],
              f"  if constexpr (Section<std::remove_const_t<M>>::precision == 2) {{", *[f"    {c}" for c in int8],
              "  }", "}", ""]
    common = ["dims"] + [t.field for t in layout.specs("fp32") if t.field]
    extra = [t.field for t in layout.specs("int8") if t.field and t.int8_only]
    macro = f"FWREF_{m.upper()}_ORDER"
    lines += [f"#define {macro}(T)                                  \\",
              '  static_assert(offsetof(T, dims) == 0, #T " starts with dims"); \\',
              *[f"  FWREF_FOLLOWS(T, {a}, {b}); \\" for a, b in zip(common, common[1:])], "",
              f"{macro}({types['fp32']});", f"FWREF_LAST({types['fp32']}, {common[-1]});",
              f"{macro}({types['int8']});",
              *[f"FWREF_FOLLOWS({types['int8']}, {a}, {b});" for a, b in zip(common[-1:] + extra, extra)],
              f"FWREF_LAST({types['int8']}, {(common + extra)[-1]});", f"#undef {macro}", ""]
    return lines


def cpp_header() -> str:
    """The text of fwref/weights_layout_gen.hpp."""
    body = []
    for layout in (*MODELS.values(), *MOTOR_MODELS.values()):
        title = "".join(w.capitalize() for w in layout.model.split("_"))
        body += _cpp_tables(layout, title) + _cpp_structs(layout, title)
    return (_PREAMBLE.replace("@MAGIC@", MAGIC.rstrip(b"\0").decode()).replace("@VERSION@", str(VERSION))
            .replace("@REF_MAGIC@", REFERENCE_MAGIC.rstrip(b"\0").decode())
            .replace("@REF_VERSION@", str(REFERENCE_VERSION))
            .replace("@ORDER@", ", ".join(f'"{m} {p}"' for m, p in SECTION_ORDER)).replace("@BODY@", "\n".join(body)))


if __name__ == "__main__":
    sys.exit(header_cli(sys.argv[1:], HEADER_PATH, cpp_header, "formats.weights_layout"))
