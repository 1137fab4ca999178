"""A run's int8 GRU as the unrolled graph (export/onnx_gru_unrolled.py: 12 nodes per step, the alternative
to the exported Scan), to time beside the exported graph (docs/bench.md, "The int8 GRU in one Scan"):

    python lab/gru_unrolled_graph.py RUN OUT.onnx
    python lab/ort_batch_timing.py RUN --models gru --batch 1 --extra unrolled=OUT.onnx

The graphs are rebuilt from the run's checkpoints with the export's own calibration (the rebuilt
Scan graph must equal RUN/export/gru.int8.onnx byte for byte, else nothing is written), and the
two graphs' outputs are compared on every test window: they must be bit-identical.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.atomic import write_bytes
from quadfdi.core.rundir import RunDir
from quadfdi.export.calibrate import select_windows
from quadfdi.export.onnx_gru_unrolled import build_gru_int8_unrolled
from quadfdi.export.run import _load_models, build_graphs
from quadfdi.runtimes.ort import session
from quadfdi.formats.dataset import load_dataset, make_windows
from quadfdi.models.checkpoint import load_checkpoint
from quadfdi.models.inputs import profile_of, profiled_dataset


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 2
    run, out = RunDir(Path(argv[0])), Path(argv[1])
    manifest_path = run.root / "export" / "manifest.json"
    if not manifest_path.is_file():
        print(f"error: {manifest_path} not found: run quadfdi export --run {run.root} first", file=sys.stderr)
        return 1
    ecfg = json.loads(manifest_path.read_text())["config"]["export"]
    profile = profile_of(load_checkpoint(run.checkpoint("cnode"), "cnode")[1])
    ds = profiled_dataset(load_dataset(run.dataset), profile)
    cnode, _, gru, _ = _load_models(run, ds, ecfg["steps"])
    train_w, test_w = make_windows(ds, "train"), make_windows(ds, "test")
    calib = train_w.x[select_windows(len(train_w), ecfg["calib_windows"])]
    g = build_graphs(cnode, gru, calib, ecfg["steps"], ecfg["opset"])
    shipped = (run.export / "gru.int8.onnx").read_bytes()
    if g.gru_int8.model.SerializeToString() != shipped:
        print(f"error: the rebuilt Scan graph differs from {run.export / 'gru.int8.onnx'}: re-export the run",
              file=sys.stderr)
        return 1
    unrolled = build_gru_int8_unrolled(g.gru_params, g.gru_quant, ecfg["opset"]).model.SerializeToString()
    feed = {"telemetry": test_w.x}
    a, b = session(shipped).run(None, feed), session(unrolled).run(None, feed)
    same = all(x.tobytes() == y.tobytes() for x, y in zip(a, b))
    print(f"{len(test_w.x)} test windows: Scan and unrolled outputs bit-identical: {same}")
    if not same:
        n = int(np.sum(np.any(a[0] != b[0], axis=1)))
        print(f"error: {n} windows differ; nothing written", file=sys.stderr)
        return 1
    write_bytes(out, unrolled)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
