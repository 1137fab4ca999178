"""weights.bin: every number the C++ reference needs, one section per (model, precision).

Container: formats/binfmt.py (magic b"QFDIWTS\\0", version 1). Sections, in this order:
cnode fp32, cnode int8, gru fp32, gru int8. Section ``dims`` (u32[8]):

    [0] C channels  [1] W window  [2] K classes  [3] hidden width (CNODE field H, GRU H)
    [4] L latent (GRU 0)  [5] N RK4 steps (GRU 0)  [6] S = 2N + 1 stage times (GRU 0)  [7] 0

Matrices are in PyTorch's (out, in) layout, y = W x + b; int8 weights are symmetric per output
row (quant_axis 0, zero points 0). The tensors of each section, their order, dtypes and shapes are
the table of formats/weights_layout.py (docs/formats.md prints it); the writer builds sections from
it and the reader checks every file against it. Meaning of the int8-only tensors: the static
activation scales; ``act.u.scale`` (C,) is folded into the int8 ``encoder.weight`` and
``lin1_u.weight`` (they hold W diag(s_u), quantized per row), ``act.x_norm.scale`` of the GRU into
``gru.weight_ih``. ``rk4.consts`` = core.rk4.rk4_constants(1/N), in RK4_CONSTANT_NAMES order.

A net with a motor head (models.motor) adds, after these four and in this order, its sections
"cnode_motor" / "gru_motor" fp32 and int8 (dims [0] F features, [1] M = 4 motors): the head's
weight (M, F) and bias (M,); the int8 head uses the class head's activation scale (act.z1.scale,
act.h.scale). A file without a head is byte for byte what it was before the head existed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core.atomic import write_bytes
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rk4 import rk4_constants
from quadfdi.formats.binfmt import Section, pack, read_file
from quadfdi.formats.weights_layout import (LAYOUTS, MAGIC, MOTOR_SECTION_ORDER, SECTION_ORDER, VERSION, check_dims, dims_of,
                                   dtype_of, shape_of)



# CnodeParams, CnodeQuant, GruParams, GruQuant: the parameter objects of quadfdi.export.onnx_cnode and
# .onnx_gru (duck-typed here: a format imports no stage).
def cnode_dims(p: CnodeParams) -> tuple[int, ...]:
    return dims_of("cnode", {"C": p.n_channels, "W": p.window, "K": p.n_classes, "H": p.hidden, "L": p.latent,
                             "N": p.steps})


def gru_dims(p: GruParams) -> tuple[int, ...]:
    return dims_of("gru", {"C": p.n_channels, "W": p.window, "K": p.n_classes, "H": p.hidden})


def _section(model: str, precision: str, dims: tuple[int, ...], values: dict[str, object]) -> Section:
    """A section in the table's order; ``values`` maps each tensor name to an array, or for an int8
    matrix to (int8 array, per-row scales). Every shape and dtype is checked against the table."""
    s = Section(model, precision, dims)
    for spec in LAYOUTS[model].specs(precision):
        value, want = values[spec.name], dtype_of(spec, precision)
        if want == np.int8:
            q, scales = value
            s.add(spec.name, q, np.int8, scales, axis=0)
        else:
            s.add(spec.name, np.reshape(value, -1) if spec.kind == "scalar" else value, want)
        got = s.tensors[spec.name].array
        if got.shape != shape_of(model, spec, dims) or got.dtype != want:
            raise ValueError(f"{model} {precision} tensor {spec.name}: {got.dtype} {got.shape}, the layout says "
                             f"{want} {shape_of(model, spec, dims)} {spec.shape}")
    return s


def cnode_section(p: CnodeParams, q: CnodeQuant | None) -> Section:
    v: dict[str, object] = {
        "norm.mean": p.mean, "norm.std": p.std, "interp": (q.interp_q, q.interp_scale) if q else p.interp,
        "stage_index": p.stage_index, "stage_times": p.times, "rk4.consts": rk4_constants(1.0 / p.steps),
        "encoder.bias": p.encoder_b, "lin1.bias": p.lin1_b, "lin2.bias": p.lin2_b, "head.bias": p.head_b}
    for name, w, qw in (("encoder.weight", p.encoder_w, q and q.encoder), ("lin1_z.weight", p.lin1_wz, q and q.lin1_z),
                        ("lin1_u.weight", p.lin1_wu, q and q.lin1_u), ("lin2.weight", p.lin2_w, q and q.lin2),
                        ("head.weight", p.head_w, q and q.head)):
        v[name] = (qw.q, qw.scale) if qw else w
    if q:
        v.update({"act.x_norm.scale": q.s_x, "act.u.scale": q.s_u, "act.stage.scale": q.s_z,
                  "act.hidden.scale": q.s_hid, "act.z1.scale": q.s_z1})
    return _section("cnode", "int8" if q else "fp32", cnode_dims(p), v)


def gru_section(p: GruParams, q: GruQuant | None, model: str = "gru") -> Section:
    """The windowed GRU's section, or with ``model`` "sgru" the streaming GRU's (the same tensors, W = 1)."""
    v: dict[str, object] = {"norm.mean": p.mean, "norm.std": p.std, "gru.bias_ih": p.b_ih, "gru.bias_hh": p.b_hh,
                            "head.bias": p.head_b}
    for name, w, qw in (("gru.weight_ih", p.w_ih, q and q.w_ih), ("gru.weight_hh", p.w_hh, q and q.w_hh),
                        ("head.weight", p.head_w, q and q.head)):
        v[name] = (qw.q, qw.scale) if qw else w
    if q:
        v.update({"act.x_norm.scale": q.s_x, "act.h.scale": q.s_h})
    return _section(model, "int8" if q else "fp32", gru_dims(p), v)


def motor_sections(net: str, w, b, qw) -> list[Section]:
    """The fp32 and int8 motor-head sections of ``net`` (none when ``w`` is None)."""
    if w is None:
        return []
    dims = dims_of(f"{net}_motor", {"F": int(w.shape[1]), "M": int(w.shape[0])})
    return [_section(f"{net}_motor", "fp32", dims, {"motor_head.weight": w, "motor_head.bias": b}),
            _section(f"{net}_motor", "int8", dims, {"motor_head.weight": (qw.q, qw.scale), "motor_head.bias": b})]


def weights_bytes(cp: CnodeParams, cq: CnodeQuant, gp: GruParams, gq: GruQuant,
                  onboard: Section | None = None) -> bytes:
    """The model sections in SECTION_ORDER, the motor heads' (MOTOR_SECTION_ORDER) of the nets that
    have one, then the on-board record (formats/onboard.py) if given."""
    sections = {("cnode", "fp32"): cnode_section(cp, None), ("cnode", "int8"): cnode_section(cp, cq),
                ("gru", "fp32"): gru_section(gp, None), ("gru", "int8"): gru_section(gp, gq)}
    motor = motor_sections("cnode", cp.motor_w, cp.motor_b, cq.motor) + motor_sections("gru", gp.motor_w, gp.motor_b, gq.motor)
    return pack(MAGIC, VERSION, [sections[k] for k in SECTION_ORDER] + motor + ([onboard] if onboard is not None else []))


def write_weights(path: str | Path, cp: CnodeParams, cq: CnodeQuant, gp: GruParams, gq: GruQuant,
                  onboard: Section | None = None) -> bytes:
    """Write weights.bin atomically; returns its bytes."""
    data = weights_bytes(cp, cq, gp, gq, onboard)
    write_bytes(path, data)
    return data


@dataclass(frozen=True)
class WeightsFile:
    version: int
    sections: list[Section]

    @property
    def onboard(self) -> Section | None:
        """The on-board record (formats/onboard.py); None in a file written before it."""
        last = self.sections[-1] if self.sections else None
        return last if last is not None and (last.model, last.precision) == ("none", "none") else None

    def has(self, model: str, precision: str) -> bool:
        """Whether the file holds the section (e.g. a net's optional "cnode_motor" head)."""
        return any((s.model, s.precision) == (model, precision) for s in self.sections)

    def section(self, model: str, precision: str) -> Section:
        for s in self.sections:
            if (s.model, s.precision) == (model, precision):
                return s
        raise QuadfdiError(f"weights file holds no {model} {precision} section")


def check_layout(sections: list[Section], where: str) -> None:
    """Every section of the table, in its order, each holding exactly the table's tensors with the
    dtype and shape its dims imply, optionally followed by the on-board record; otherwise a one-line
    QuadfdiError."""
    from quadfdi.formats.onboard import KIND as ONBOARD, check_onboard

    if sections and (sections[-1].model, sections[-1].precision) == ONBOARD:
        check_onboard(sections[-1], where)
        sections = sections[:-1]
    got = [(s.model, s.precision) for s in sections]
    base, extra = got[:len(SECTION_ORDER)], got[len(SECTION_ORDER):]
    motor_ok = [k for k in MOTOR_SECTION_ORDER if k[0] in {m for m, _ in extra}] == extra  # whole heads, in order
    if base != list(SECTION_ORDER) or not motor_ok:
        raise QuadfdiError(f"{where} holds sections {got}, the layout is {list(SECTION_ORDER)} "
                           f"(then optionally {list(MOTOR_SECTION_ORDER)}; re-run `quadfdi export`)")
    for s in sections:
        label = f"{where}: section {s.model} {s.precision}"
        bad = check_dims(s.model, s.dims)
        if bad:
            raise QuadfdiError(f"{label}: {bad}")
        specs = LAYOUTS[s.model].specs(s.precision)
        if list(s.tensors) != [t.name for t in specs]:
            raise QuadfdiError(f"{label} holds tensors {list(s.tensors)}, the layout is {[t.name for t in specs]}")
        for spec in specs:
            t, shape, dtype = s.tensors[spec.name], shape_of(s.model, spec, s.dims), dtype_of(spec, s.precision)
            if t.array.dtype != dtype or t.array.shape != shape:
                raise QuadfdiError(f"{label}: tensor '{spec.name}' is {t.array.dtype} {t.array.shape}, expected "
                                   f"{dtype} {shape} {spec.shape}")
            if dtype == np.int8 and (t.axis != 0 or np.any(t.zero_points != 0)):
                raise QuadfdiError(f"{label}: tensor '{spec.name}' is not symmetric int8 with one scale per row")


def read_weights(path: str | Path) -> WeightsFile:
    """Parse and check weights.bin against the layout table; a foreign, truncated, corrupted or
    differently laid out file is a one-line QuadfdiError."""
    version, sections = read_file(path, MAGIC, VERSION, "weights file")
    check_layout(sections, f"weights file {path}")
    return WeightsFile(version, sections)
