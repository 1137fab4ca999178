"""firmware_ref's tanh and sigmoid against ONNX Runtime's `Tanh` and `Sigmoid`, bit for bit (docs/firmware.md,
"Arithmetic as implemented"): every 7th float32 with 2^-12 <= |x| < 32, both signs, through
`fwref_activations` and through a one-node ONNX graph; prints the mismatches of each.

    python lab/activations_vs_ort.py [--exe FWREF_ACTIVATIONS]

FWREF_ACTIVATIONS defaults to the host build of ``quadfdi.runtimes.build.build_host`` (built if missing).
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import onnxruntime as ort
from onnx import TensorProto, helper

from quadfdi.runtimes.build import build_host


OPS = ("Tanh", "Sigmoid")


def ort_ops(x: np.ndarray) -> list[np.ndarray]:
    """ONNX Runtime's Tanh and Sigmoid of x: one graph with both nodes, IR version 10 (what ORT reads)."""
    vec = [None]
    graph = helper.make_graph([helper.make_node(op, ["x"], [op]) for op in OPS], "activations",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, vec)],
                              [helper.make_tensor_value_info(op, TensorProto.FLOAT, vec) for op in OPS])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 18)], ir_version=10)
    sess = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
    return sess.run(list(OPS), {"x": x})


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--exe", type=Path, default=None, help="fwref_activations (default: the host build)")
    exe = ap.parse_args().exe or build_host(log=lambda _: None) / "fwref_activations"
    bits = np.arange(np.float32(2**-12).view(np.uint32), np.float32(32).view(np.uint32), 7, dtype=np.uint32)
    x = np.concatenate([bits.view(np.float32), -bits.view(np.float32)])
    with tempfile.TemporaryDirectory(prefix="quadfdi-act-") as tmp:
        xin, yout = Path(tmp) / "x.f32", Path(tmp) / "y.f32"
        x.tofile(xin)
        subprocess.run([str(exe), "--in", str(xin), "--out", str(yout)], check=True)
        ours = np.fromfile(yout, "<f4").reshape(2, -1)
    for k, (op, theirs) in enumerate(zip(OPS, ort_ops(x))):
        print(op, "mismatches", int(np.sum(ours[k] != theirs)), "of", len(x))


if __name__ == "__main__":
    main()
