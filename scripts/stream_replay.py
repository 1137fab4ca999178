"""Replay simulated test flights through ``fwref_stream`` (firmware_ref's streaming runtime) against
the Python window path, and time every push (docs/firmware.md "Streaming"): a measurement, not a test.

    PYTHONPATH=. python scripts/stream_replay.py RUN/export DATASET.npz [PER_CLASS [MODELS]]

MODELS: comma-separated, default every model the export has (cnode,gru[,sgru]).

For PER_CLASS (default 2) test flights of each class: the stream file (formats/stream.py), the
window path's windows (detect/streamref.py), ONNX Runtime's and fwref_infer's logits on them, and
fwref_stream's line per stride with --timings. Checks (AssertionError otherwise): the same status at
every stride, logits bit-identical to fwref_infer, fp32 within FP32_CPP_REL_TOL of ORT; counts int8
rows differing from ORT and fp32 vote flips against core.alarm on ORT's probabilities. Prints per
model and precision the strides, those counts and the latency of a push without a decision and of
a push that decides (p50, p99, microseconds; this machine as it is, other load included).
With the export's sgru_weights.bin (``quadfdi export sgru``) the streaming GRU too ("sgru"): its
reference is ONNX Runtime's one-step graph stepped under the on-board rules (detect/streamref.py
``stepped_of`` / ``sgru_logits``); its push is one GRU step (per sample); and when RUN holds the
Python evaluation's prediction set predictions/sgru_sim*_train0.npz (``quadfdi train sgru``), the
largest difference between the stream's fp32 probabilities and that set's on the same strides.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import quadfdi.formats.dataset as sim_dataset
from quadfdi.core.alarm import run_alarm
from quadfdi.formats.onboard import policy_of
from quadfdi.core.contracts import FP32_CPP_REL_TOL
from quadfdi.detect.run import softmax
from quadfdi.bench.stream_latency import split_timings
from quadfdi.detect.runtimes import cpp_logits, ort_logits
from quadfdi.formats.stream import from_dataset, read_stream, write_stream
from quadfdi.formats.export_folder import Export
from quadfdi.detect.streamref import read_lines, sgru_logits, stepped_of, windows_of
from quadfdi.formats.manifest import load_manifest
from quadfdi.runtimes.build import HOST_BUILD, build_host


def _stream(export: Path, path: Path, net: str, prec: str, tmp: Path, k: int) -> tuple[dict, np.ndarray]:
    weights = export / ("sgru_weights.bin" if net == "sgru" else "weights.bin")
    res = subprocess.run([str(HOST_BUILD / "fwref_stream"), "--weights", str(weights), "--model", net, "--in",
                          str(path), "--timings", str(tmp / "t.f64")] + (["--int8"] if prec == "int8" else []),
                         capture_output=True, text=True, check=True)
    return read_lines(res.stdout, k), np.fromfile(tmp / "t.f64")


def _evaluation_gap(export: Path, path: Path, out: dict) -> float | None:
    """max |stream proba - prediction set proba| on this flight's strides (None without the set)."""
    sets = sorted((export.parent / "predictions").glob("sgru_sim*_train0.npz"))
    if not sets:
        return None
    z = np.load(sets[0])
    mine = z["traj"] == int(path.stem[1:])  # f<row>.bin
    assert mine.sum() == len(out["proba"]), (mine.sum(), len(out["proba"]))
    return float(np.abs(out["proba"] - z["proba"][mine]).max())


def replay(export: Path, path: Path, record: dict, manifest: dict, net: str, prec: str, tmp: Path) -> dict:
    sw = windows_of(read_stream(path), record)
    if net == "sgru":
        hidden = int(np.load(export / "sgru_replay.npz")["h"].shape[1])
        stepped, sw.decided = stepped_of(sw, record["window"])
        onnx = export / ("sgru_step.int8.onnx" if prec == "int8" else "sgru_step.onnx")
        ort = sgru_logits(onnx, sw.x, stepped, hidden)[sw.ends][sw.decided]
        cpp = None
    else:
        x = sw.windows(record["window"])
        ort = ort_logits(export / manifest["artifacts"][f"{net}_{prec}"], x)
        cpp = cpp_logits(export / "weights.bin", net, prec == "int8", x)
    out, t = _stream(export, path, net, prec, tmp, ort.shape[1])
    assert (out["index"] == sw.ends).all() and ((out["status"] == "decided") == sw.decided).all()
    got = out["logits"][sw.decided]
    assert cpp is None or (got == cpp).all(), (net, prec, path)
    if prec == "fp32":
        assert np.abs(got - ort).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(ort).max())
    proba = np.zeros((len(sw.ends), ort.shape[1]))
    proba[:, record["healthy"]] = 1.0
    proba[sw.decided] = softmax(ort)
    a = policy_of(record, net)[0]  # the net's policy (alarm.models), as fwref_stream --model picks it
    tr = run_alarm(proba[None], a["threshold"], a["k"], a["n"], a["clear_m"], a["latch"], healthy=record["healthy"],
                   valid=sw.decided[None])
    flips = out["vote"] != tr.votes[0]
    if not flips.any():
        assert (out["active"] == tr.active[0]).all() and (out["cls"] == tr.cls[0]).all()
    evaluation = _evaluation_gap(export, path, out) if net == "sgru" and prec == "fp32" else None
    split = split_timings(t, out["index"], out["status"] == "decided")
    rel = float(np.abs(got - ort).max() / max(1.0, np.abs(ort).max())) if len(got) else 0.0
    return {"evaluation": evaluation, "rel": rel, "strides": len(sw.ends), "decided": int(sw.decided.sum()), "int8_diff": int((got != ort).any(axis=1).sum())
            if prec == "int8" else 0, "flips": int(flips.sum()), "push": split["push"], "decision": split["decision"]}


def main(argv: list[str]) -> int:
    export, dataset = Path(argv[0]), Path(argv[1])
    per_class = int(argv[2]) if len(argv) > 2 else 2
    build_host(HOST_BUILD, log=lambda _: None)
    record, manifest = Export.open(export).onboard(), load_manifest(export / "manifest.json")
    ds = sim_dataset.load_dataset(dataset)
    test = [i for i, s in enumerate(ds["split_names"]) if str(s).startswith("test")]
    flights = [int(i) for c in range(len(ds["class_names"]))
               for i in np.flatnonzero(np.isin(ds["split"], test) & (ds["fault_class"] == c))[:per_class]]
    with tempfile.TemporaryDirectory(prefix="stream-replay-") as d:
        tmp = Path(d)
        paths = []
        for f in flights:
            paths.append(tmp / f"f{f}.bin")
            write_stream(paths[-1], from_dataset(dataset, f, record, ds))  # one load for every flight
        print(f"{export} ({record['profile']}): test flights {flights}")
        nets = ("cnode", "gru") + (("sgru",) if (export / "sgru_weights.bin").is_file() else ())
        for net in argv[3].split(",") if len(argv) > 3 else nets:
            for prec in ("fp32", "int8"):
                rs = [replay(export, p, record, manifest, net, prec, tmp) for p in paths]
                push = np.concatenate([r["push"] for r in rs]) * 1e6
                dec = np.concatenate([r["decision"] for r in rs]) * 1e6
                rel = max(r["rel"] for r in rs)
                gaps = [r["evaluation"] for r in rs if r["evaluation"] is not None]
                if gaps:
                    print(f"sgru fp32: stream vs the evaluation's prediction set, max |proba diff| {max(gaps):.2g}"
                          f" over {len(gaps)} flights")
                print(f"{net} {prec}: {sum(r['strides'] for r in rs)} strides, {sum(r['decided'] for r in rs)} decided,"
                      f" int8 rows != ORT {sum(r['int8_diff'] for r in rs)}, max |C++ - ORT| / max(1, |ORT|) {rel:.2g},"
                      f" vote flips {sum(r['flips'] for r in rs)};"
                      f" push p50/p99 {np.percentile(push, 50):.2f}/{np.percentile(push, 99):.2f} us, decision"
                      f" p50/p99 {np.percentile(dec, 50):.1f}/{np.percentile(dec, 99):.1f} us", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
