"""weights.bin: every number the C++ reference needs, one section per (model, precision).

Container: export/binfmt.py (magic b"QFDIWTS\\0", version 1). Sections, in this order:
cnode fp32, cnode int8, gru fp32, gru int8. Section ``dims`` (u32[8]):

    [0] C channels  [1] W window  [2] K classes  [3] hidden width (CNODE field H, GRU H)
    [4] L latent (GRU 0)  [5] N RK4 steps (GRU 0)  [6] S = 2N + 1 stage times (GRU 0)  [7] 0

Matrices are in PyTorch's (out, in) layout, y = W x + b; int8 weights are symmetric per output
row (quant_axis 0, zero points 0). Tensors of each section (docs/formats.md lists them with
shapes):

- every section: ``norm.mean``, ``norm.std`` (C,) -- x_norm = (x - mean) / std.
- CNODE: ``interp`` (S, W) (int8 in the int8 section, exact 1/D scales when possible),
  ``stage_index`` (4N,) int32 (row of ``interp`` for evaluation e = 4k + i), ``stage_times`` (S,),
  ``rk4.consts`` (4,) float32 = [h/2, h, 2, h/6] as the graphs use them, ``encoder.weight`` (L, C),
  ``encoder.bias``, ``lin1_z.weight`` (H, L), ``lin1_u.weight`` (H, C), ``lin1.bias`` (H,),
  ``lin2.weight`` (L, H), ``lin2.bias``, ``head.weight`` (K, L), ``head.bias``; int8 only: the
  static activation scales ``act.x_norm.scale`` (C,), ``act.u.scale`` (1,), ``act.stage.scale``
  (4N,), ``act.hidden.scale`` (1,), ``act.z1.scale`` (1,). ``act.u.scale`` (C,) is folded into the
  int8 ``encoder.weight`` and ``lin1_u.weight`` (they hold W diag(s_u), quantized per row).
- GRU: ``gru.weight_ih`` (3H, C), ``gru.weight_hh`` (3H, H) (gate rows r, z, n as in PyTorch),
  ``gru.bias_ih``, ``gru.bias_hh`` (3H,), ``head.weight`` (K, H), ``head.bias``; int8 only:
  ``act.x_norm.scale`` (C,) (folded into the int8 ``gru.weight_ih``: W_ih diag(s_x)),
  ``act.h.scale`` (1,).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from export.binfmt import Section, pack, read_file
from export.onnx_cnode import CnodeParams, CnodeQuant
from export.onnx_gru import GruParams, GruQuant
from core.atomic import write_bytes
from core.errors import QuadfdiError

MAGIC = b"QFDIWTS\0"
VERSION = 1
SECTION_ORDER = (("cnode", "fp32"), ("cnode", "int8"), ("gru", "fp32"), ("gru", "int8"))


def cnode_dims(p: CnodeParams) -> tuple[int, ...]:
    return (p.n_channels, p.window, p.n_classes, p.hidden, p.latent, p.steps, len(p.times), 0)


def gru_dims(p: GruParams) -> tuple[int, ...]:
    return (p.n_channels, p.window, p.n_classes, p.hidden, 0, 0, 0, 0)


def rk4_consts(steps: int) -> np.ndarray:
    """[h/2, h, 2, h/6] in float32, the constants of train.solvers.rk4_step in the graphs."""
    h = 1.0 / steps
    return np.array([0.5 * h, h, 2.0, h / 6.0], np.float32)


def cnode_section(p: CnodeParams, q: CnodeQuant | None) -> Section:
    s = Section("cnode", "int8" if q else "fp32", cnode_dims(p))
    s.add("norm.mean", p.mean, np.float32)
    s.add("norm.std", p.std, np.float32)
    if q:
        s.add("interp", q.interp_q, np.int8, q.interp_scale, axis=0)
    else:
        s.add("interp", p.interp, np.float32)
    s.add("stage_index", p.stage_index, np.int32)
    s.add("stage_times", p.times, np.float32)
    s.add("rk4.consts", rk4_consts(p.steps))
    mats = (("encoder.weight", p.encoder_w, q and q.encoder), ("lin1_z.weight", p.lin1_wz, q and q.lin1_z),
            ("lin1_u.weight", p.lin1_wu, q and q.lin1_u), ("lin2.weight", p.lin2_w, q and q.lin2),
            ("head.weight", p.head_w, q and q.head))
    biases = {"encoder.weight": ("encoder.bias", p.encoder_b), "lin1_u.weight": ("lin1.bias", p.lin1_b),
              "lin2.weight": ("lin2.bias", p.lin2_b), "head.weight": ("head.bias", p.head_b)}
    for name, w, qw in mats:
        if qw:
            s.add(name, qw.q, np.int8, qw.scale, axis=0)
        else:
            s.add(name, w, np.float32)
        if name in biases:
            s.add(*biases[name], np.float32)
    if q:
        s.add("act.x_norm.scale", q.s_x, np.float32)
        s.add("act.u.scale", q.s_u, np.float32)
        s.add("act.stage.scale", q.s_z, np.float32)
        s.add("act.hidden.scale", np.atleast_1d(q.s_hid), np.float32)
        s.add("act.z1.scale", np.atleast_1d(q.s_z1), np.float32)
    return s


def gru_section(p: GruParams, q: GruQuant | None) -> Section:
    s = Section("gru", "int8" if q else "fp32", gru_dims(p))
    s.add("norm.mean", p.mean, np.float32)
    s.add("norm.std", p.std, np.float32)
    for name, w, qw in (("gru.weight_ih", p.w_ih, q and q.w_ih), ("gru.weight_hh", p.w_hh, q and q.w_hh)):
        if qw:
            s.add(name, qw.q, np.int8, qw.scale, axis=0)
        else:
            s.add(name, w, np.float32)
    s.add("gru.bias_ih", p.b_ih, np.float32)
    s.add("gru.bias_hh", p.b_hh, np.float32)
    if q:
        s.add("head.weight", q.head.q, np.int8, q.head.scale, axis=0)
    else:
        s.add("head.weight", p.head_w, np.float32)
    s.add("head.bias", p.head_b, np.float32)
    if q:
        s.add("act.x_norm.scale", q.s_x, np.float32)
        s.add("act.h.scale", np.atleast_1d(q.s_h), np.float32)
    return s


def weights_bytes(cp: CnodeParams, cq: CnodeQuant, gp: GruParams, gq: GruQuant) -> bytes:
    return pack(MAGIC, VERSION, [cnode_section(cp, None), cnode_section(cp, cq), gru_section(gp, None),
                                 gru_section(gp, gq)])


def write_weights(path: str | Path, cp: CnodeParams, cq: CnodeQuant, gp: GruParams, gq: GruQuant) -> bytes:
    """Write weights.bin atomically; returns its bytes."""
    data = weights_bytes(cp, cq, gp, gq)
    write_bytes(path, data)
    return data


@dataclass(frozen=True)
class WeightsFile:
    version: int
    sections: list[Section]

    def section(self, model: str, precision: str) -> Section:
        for s in self.sections:
            if (s.model, s.precision) == (model, precision):
                return s
        raise QuadfdiError(f"weights file holds no {model} {precision} section")


def read_weights(path: str | Path) -> WeightsFile:
    """Parse and check weights.bin; a foreign, truncated or corrupted file is a one-line QuadfdiError."""
    version, sections = read_file(path, MAGIC, VERSION, "weights file")
    return WeightsFile(version, sections)
