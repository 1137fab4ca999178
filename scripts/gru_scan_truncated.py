"""Timing-only variants of an exported int8 GRU Scan graph, to split its batch-1 time (docs/bench.md,
"The int8 GRU in one Scan"): the body cut after its first 3 nodes (QuantizeLinear,
MatMulIntegerToFloat, Split; the state becomes gh_n), and the body replaced by one Neg of the state.
Their outputs mean nothing; only their time does.

    PYTHONPATH=. python scripts/gru_scan_truncated.py RUN/export/gru.int8.onnx OUTDIR
    PYTHONPATH=. python scripts/ort_batch_timing.py RUN --models gru --batch 1 --reps 400 \\
        --extra body_QL_MM_Split=OUTDIR/body_3.onnx --extra body_1_Neg=OUTDIR/body_neg.onnx
"""

from __future__ import annotations

import sys
from pathlib import Path

import onnx
from onnx import helper


def truncated(model: onnx.ModelProto, keep: int | None) -> onnx.ModelProto:
    """A copy whose Scan body keeps its first ``keep`` nodes (the state = the last one's 2nd output),
    or, with ``keep`` None, is one Neg of the state."""
    m = onnx.ModelProto()
    m.CopyFrom(model)
    scan = next(n for n in m.graph.node if n.op_type == "Scan")
    body = next(a.g for a in scan.attribute if a.name == "body")
    nodes = list(body.node)
    del body.node[:]
    if keep:
        body.node.extend(nodes[:keep])
        body.output[0].name = nodes[keep - 1].output[1]
    else:
        body.node.append(helper.make_node("Neg", [body.input[0].name], ["body.neg_h"]))
        body.output[0].name = "body.neg_h"
    return m


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 2
    src, out = Path(argv[0]), Path(argv[1])
    model = onnx.load(str(src))
    if not any(n.op_type == "Scan" for n in model.graph.node):
        print(f"error: {src} has no Scan node (an int8 GRU exported before the Scan?)", file=sys.stderr)
        return 1
    out.mkdir(parents=True, exist_ok=True)
    for name, keep in (("body_3.onnx", 3), ("body_neg.onnx", None)):
        onnx.save(truncated(model, keep), str(out / name))
        print(f"wrote {out / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
