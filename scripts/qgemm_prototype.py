"""A measured alternative, not the shipped graph: the int8 CNODE with each stage's
MatMulIntegerToFloat + Add (row of V) replaced by ONE ``com.microsoft.QGemm`` whose int32 C is the
row of V in the accumulator's units, ``Cast(Round(V / f32(s_z[e] * s_w)))`` (one Gather of V's rows
for all 4N evaluations, Div, Round, Cast, Reshape, Split). QGemm computes ``f32(acc + C) * f32(s_a
* s_w)``: another arithmetic than docs/formats.md prescribes, so the C++ reference and the Cortex-M
build would have to follow; this script only measures its node count and speed (docs/bench.md,
"ONNX Runtime nodes after its optimizer").

    PYTHONPATH=. python scripts/qgemm_prototype.py RUN/export/cnode_rk4_8.int8.onnx OUT.onnx
"""

from __future__ import annotations

import sys

import numpy as np
import onnx
from onnx import TensorProto, helper
from onnx import numpy_helper as nh

from quadfdi.export.graph import MS_DOMAIN


def stage_products(g: onnx.GraphProto) -> tuple[list, onnx.NodeProto, onnx.NodeProto]:
    """[(Add, its MatMulIntegerToFloat, row of V)] per evaluation, V's Split and its Reshape."""
    prod = {o: n for n in g.node for o in n.output}
    split = next(n for n in g.node if n.op_type == "Split")
    rows = {o: i for i, o in enumerate(split.output)}
    stages = [(n, prod[n.input[0]], rows[n.input[1]]) for n in g.node
              if n.op_type == "Add" and n.input[1] in rows and prod[n.input[0]].op_type == "MatMulIntegerToFloat"]
    return stages, split, prod[split.input[0]]


def v_int32(v_name: str, rows: list[int], mult: np.ndarray, hidden: int, pre: str) -> tuple[list, list]:
    """Initializers and nodes that turn V (B, S, H) into one int32 C per evaluation, ``{pre}.c{e}``
    (B, H) = Cast(Round(V[:, rows[e]] / mult[e])), and ``{pre}.bzp``, an int8 zero-point vector (H,)."""
    n_eval = len(rows)
    consts = [nh.from_array(np.array(rows, np.int64), f"{pre}.rows"), nh.from_array(mult[None], f"{pre}.mult"),
              nh.from_array(np.array([0, n_eval * hidden], np.int64), f"{pre}.shape"),
              nh.from_array(np.full(n_eval, hidden, np.int64), f"{pre}.split"),
              nh.from_array(np.zeros(hidden, np.int8), f"{pre}.bzp")]
    nodes = [helper.make_node("Gather", [v_name, f"{pre}.rows"], [f"{pre}.v"], axis=1),
             helper.make_node("Div", [f"{pre}.v", f"{pre}.mult"], [f"{pre}.vd"]),
             helper.make_node("Round", [f"{pre}.vd"], [f"{pre}.vr"]),
             helper.make_node("Cast", [f"{pre}.vr"], [f"{pre}.vi"], to=TensorProto.INT32),
             helper.make_node("Reshape", [f"{pre}.vi", f"{pre}.shape"], [f"{pre}.flat"]),
             helper.make_node("Split", [f"{pre}.flat", f"{pre}.split"], [f"{pre}.c{e}" for e in range(n_eval)], axis=1)]
    return consts, nodes


def splice(g: onnx.GraphProto, replace, gone: set, v_name: str, prep: list) -> None:
    """The graph's nodes in order, each replaced by ``replace(n)`` when that is not None, dropped
    when its id is in ``gone``, and ``prep`` inserted after the node that makes ``v_name``."""
    nodes = []
    for n in g.node:
        new = replace(n)
        if new is not None:
            nodes.extend(new)
        elif id(n) not in gone:
            nodes.append(n)
            if v_name in n.output:
                nodes.extend(prep)
    del g.node[:]
    g.node.extend(nodes)


def rewrite(m: onnx.ModelProto) -> onnx.ModelProto:
    g = m.graph
    init = {t.name: nh.to_array(t) for t in g.initializer}
    stages, split, reshape = stage_products(g)
    v_name = reshape.input[0]
    hidden = init[stages[0][1].input[3]].shape[0]
    mult = np.stack([(np.float32(init[mm.input[2]]) * init[mm.input[3]]).astype(np.float32) for _, mm, _ in stages])
    consts, prep = v_int32(v_name, [r for _, _, r in stages], mult, hidden, "qg")
    g.initializer.extend(consts)
    by_add = {id(add): (mm, e) for e, (add, mm, _) in enumerate(stages)}
    gone = {id(split), id(reshape)} | {id(mm) for _, mm, _ in stages}

    def replace(n: onnx.NodeProto) -> list | None:
        if id(n) not in by_add:
            return None
        mm, e = by_add[id(n)]  # QGemm(A, a_scale, a_zp, B, b_scale, b_zp, C): float output
        return [helper.make_node("QGemm", [mm.input[0], mm.input[2], mm.input[4], mm.input[1], mm.input[3],
                                           "qg.bzp", f"qg.c{e}"], [n.output[0]], domain=MS_DOMAIN)]

    splice(g, replace, gone, v_name, prep)
    return m


if __name__ == "__main__":
    onnx.save(rewrite(onnx.load(sys.argv[1])), sys.argv[2])
    print(f"wrote {sys.argv[2]}")
