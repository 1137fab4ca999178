"""Quantization coverage of a graph: ops by type and precision, MACs in int8, initializer bytes.

Counted from the ONNX file itself (shape inference with the symbolic batch axis), not from the
builder's intentions, so a product that silently stayed float shows up. MACs are per window:
a (MatMul | MatMulInteger) node contributes K * prod(output dims other than the batch axis); a
GRU node W * 3H * (C + H); a node in a Scan's body its own count times the Scan's steps. Elementwise operators (normalisation, tanh, sigmoid, the RK4
combinations, the rescales) are counted as nodes, not as MACs.
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from quadfdi.export.graph import BATCH, all_initializers

# Targets of an int8 graph against its fp32 graph: nearly all multiply-accumulates in int8; and
# constant bytes: int8 weights take a quarter of their fp32 bytes, the scales, biases and
# normalisation that stay float add a little, hence at most 35 %.
INT8_MAC_SHARE_TARGET = 0.95
INITIALIZER_BYTES_RATIO_TARGET = 0.35

_TYPE = {TensorProto.FLOAT: "fp32", TensorProto.INT8: "int8", TensorProto.INT32: "int32",
         TensorProto.INT64: "int64", TensorProto.UINT8: "uint8"}

# Why each kind of float constant stays float in an int8 graph (matched on the initializer name).
FP32_REASONS = (
    ("scale", "quantization scales: QuantizeLinear and the int32 -> float rescale take float scales"),
    ("norm.", "normalisation of the raw float telemetry, elementwise before the first quantization"),
    ("bias", "added to the float result of the rescaled int32 product; an int32 bias would need one "
             "copy per activation scale (the CNODE has 4N stage scales)"),
    ("rk4.", "RK4 step constants: the latent state and the stage combinations stay float32 so that "
             "rounding does not accumulate over 4N stages"),
    ("gru.h0", "initial hidden state (zeros)"),
)


def _standard_nodes(graph: onnx.GraphProto) -> None:
    """In place: each com.microsoft.MatMulIntegerToFloat of ``graph`` and of its subgraphs (a Scan's
    body) becomes MatMulInteger -> Cast(float), same output name."""
    nodes = []
    for n in graph.node:
        for a in n.attribute:
            if a.type == onnx.AttributeProto.GRAPH:
                _standard_nodes(a.g)
        if n.op_type != "MatMulIntegerToFloat":
            nodes.append(n)
            continue
        tmp = n.output[0] + ".acc"
        nodes += [helper.make_node("MatMulInteger", list(n.input[:2]), [tmp]),
                  helper.make_node("Cast", [tmp], list(n.output), to=TensorProto.FLOAT)]
    del graph.node[:]
    graph.node.extend(nodes)


def _standard_only(model: onnx.ModelProto) -> onnx.ModelProto:
    """A copy for ONNX's shape inference, which knows no contrib operator (``_standard_nodes``)."""
    m = onnx.ModelProto()
    m.CopyFrom(model)
    _standard_nodes(m.graph)
    del m.opset_import[:]
    m.opset_import.extend([o for o in model.opset_import if o.domain in ("", "ai.onnx")])
    return m


def _value_infos(graph: onnx.GraphProto) -> list:
    """The typed values of ``graph`` and of its subgraphs (their names are unique in our graphs)."""
    out = list(graph.value_info) + list(graph.input) + list(graph.output)
    for n in graph.node:
        out += [vi for a in n.attribute if a.type == onnx.AttributeProto.GRAPH for vi in _value_infos(a.g)]
    return out


def tensor_shapes(model: onnx.ModelProto) -> dict[str, tuple[int, list]]:
    """Name -> (element type, dims) of every typed tensor of ``model``, subgraphs included."""
    inferred = onnx.shape_inference.infer_shapes(_standard_only(model), strict_mode=True)
    out: dict[str, tuple[int, list]] = {}
    for vi in _value_infos(inferred.graph):
        t = vi.type.tensor_type
        out[vi.name] = (t.elem_type, [d.dim_param if d.dim_param else d.dim_value for d in t.shape.dim])
    for init in all_initializers(inferred.graph):
        out[init.name] = (init.data_type, list(init.dims))
    return out


def executed_nodes(graph: onnx.GraphProto, shapes: dict) -> list[tuple[onnx.NodeProto, int]]:
    """(node, times it runs per window): 1 for a node of ``graph``; a Scan's body nodes run once per
    step (its first scanned input's length along axis 0, the default scan axis), the Scan itself once."""
    out = []
    for node in graph.node:
        out.append((node, 1))
        if node.op_type == "Scan":
            n_state = len(node.input) - next(a.i for a in node.attribute if a.name == "num_scan_inputs")
            steps = int(shapes[node.input[n_state]][1][0])
            body = next(a.g for a in node.attribute if a.name == "body")
            out += [(n, steps * k) for n, k in executed_nodes(body, shapes)]
    return out


def _per_window(dims: list) -> int:
    n = 1
    for d in dims:
        if d == BATCH:
            continue
        if not isinstance(d, int) or d <= 0:
            raise ValueError(f"cannot count MACs: unknown dimension {d!r}")
        n *= d
    return n


def node_macs(node: onnx.NodeProto, shapes: dict) -> int:
    if node.op_type in ("MatMul", "MatMulInteger", "MatMulIntegerToFloat", "Gemm"):
        k = shapes[node.input[0]][1][-1]
        return int(k) * _per_window(shapes[node.output[0]][1])
    if node.op_type == "GRU":
        seq = shapes[node.input[0]][1][0]
        _, three_h, c = shapes[node.input[1]][1]
        h = shapes[node.input[2]][1][2]
        return int(seq) * int(three_h) * (int(c) + int(h))
    return 0


def node_precision(node: onnx.NodeProto, shapes: dict) -> str:
    first = _TYPE.get(shapes.get(node.input[0], (0, []))[0], "?") if node.input else "?"
    if node.op_type == "QuantizeLinear":
        return "fp32->int8"
    if node.op_type in ("MatMulInteger", "MatMulIntegerToFloat"):
        return "int8"
    if node.op_type == "Cast":
        return f"{first}->{_TYPE.get(next(a.i for a in node.attribute if a.name == 'to'), '?')}"
    return first


def fp32_constants(model: onnx.ModelProto) -> list[dict]:
    """The float initializers of a graph (a Scan body's included), each with the reason it stays float."""
    out = []
    for init in all_initializers(model.graph):
        if init.data_type != TensorProto.FLOAT:
            continue
        why = next((r for key, r in FP32_REASONS if key in init.name), "float constant")
        arr = numpy_helper.to_array(init)
        out.append({"name": init.name, "shape": list(arr.shape), "bytes": int(arr.nbytes), "why": why})
    return out


def coverage(model: onnx.ModelProto) -> dict:
    """Ops per (type, precision) with counts (executions per window: a Scan body's node counts once
    per step) and MACs; int8 MAC share; initializer bytes by type; ``nodes``, the graph's own nodes."""
    shapes = tensor_shapes(model)
    rows: dict[tuple[str, str], dict] = defaultdict(lambda: {"count": 0, "macs": 0})
    for node, times in executed_nodes(model.graph, shapes):
        key = (node.op_type, node_precision(node, shapes))
        rows[key]["count"] += times
        rows[key]["macs"] += times * node_macs(node, shapes)
    total = sum(r["macs"] for r in rows.values())
    int8 = sum(r["macs"] for (op, prec), r in rows.items() if prec == "int8")
    init_bytes: dict[str, int] = defaultdict(int)
    for init in all_initializers(model.graph):
        init_bytes[_TYPE.get(init.data_type, str(init.data_type))] += int(numpy_helper.to_array(init).nbytes)
    return {
        "ops": [{"op": op, "precision": prec, "count": r["count"], "macs": r["macs"],
                 "mac_share": r["macs"] / total if total else 0.0}
                for (op, prec), r in sorted(rows.items())],
        "nodes": len(model.graph.node),
        "macs_per_window": int(total),
        "int8_macs_per_window": int(int8),
        "int8_mac_share": int8 / total if total else 0.0,
        "initializer_bytes": dict(sorted(init_bytes.items())),
        "initializer_bytes_total": int(sum(init_bytes.values())),
    }


def compare(fp32: dict, int8: dict, fp32_consts: list[dict]) -> dict:
    """The int8 graph's targets against its fp32 graph: MAC share and initializer bytes."""
    ratio = int8["initializer_bytes_total"] / fp32["initializer_bytes_total"]
    share = int8["int8_mac_share"]
    return {"int8_mac_share": share, "int8_mac_share_target": INT8_MAC_SHARE_TARGET,
            "initializer_bytes_ratio": ratio, "initializer_bytes_ratio_target": INITIALIZER_BYTES_RATIO_TARGET,
            "meets_targets": bool(share >= INT8_MAC_SHARE_TARGET and ratio <= INITIALIZER_BYTES_RATIO_TARGET),
            "fp32_constants": fp32_consts}


def markdown(models: dict[str, dict]) -> str:
    """coverage.md: one block per model (keys: fp32, int8, summary)."""
    lines = ["# Quantization coverage", "",
             "Counted from the exported ONNX files (`quadfdi export`). MACs are per window; elementwise",
             "operators count as nodes, not MACs.", ""]
    for name, m in models.items():
        s = m["summary"]
        lines += [f"## {name}", "",
                  f"- int8 share of MACs: {100 * s['int8_mac_share']:.2f} % of {m['int8']['macs_per_window']} "
                  f"(target >= {100 * s['int8_mac_share_target']:.0f} %)",
                  f"- initializer bytes: int8 graph {m['int8']['initializer_bytes_total']} B, fp32 graph "
                  f"{m['fp32']['initializer_bytes_total']} B, ratio {100 * s['initializer_bytes_ratio']:.1f} % "
                  f"(target <= {100 * s['initializer_bytes_ratio_target']:.0f} %); by type {m['int8']['initializer_bytes']}",
                  f"- nodes: int8 graph {m['int8']['nodes']}, fp32 graph {m['fp32']['nodes']}", "",
                  "| op | precision | count | MACs | share of MACs |", "| --- | --- | ---: | ---: | ---: |"]
        lines += [f"| {r['op']} | {r['precision']} | {r['count']} | {r['macs']} | {100 * r['mac_share']:.2f} % |"
                  for r in m["int8"]["ops"]]
        lines += ["", "Float constants of the int8 graph and why they stay float:", "",
                  "| constants | count | bytes | why |", "| --- | ---: | ---: | --- |"]
        groups: dict[str, list] = defaultdict(list)
        for c in s["fp32_constants"]:
            groups[c["why"]].append(c)
        for why, cs in groups.items():
            names = ", ".join(c["name"] for c in cs[:4]) + (", ..." if len(cs) > 4 else "")
            lines.append(f"| {names} | {len(cs)} | {sum(c['bytes'] for c in cs)} | {why} |")
        lines.append("")
    return "\n".join(lines)


def initializer_arrays(model: onnx.ModelProto) -> dict[str, np.ndarray]:
    return {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
