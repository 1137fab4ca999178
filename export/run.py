"""The export stage: checkpoints + dataset of a run -> runs/<name>/export/.

Everything is built and verified in memory first; only when the fp32 graphs match PyTorch are
the files written (each atomically), manifest.json last, so a failed export never leaves a
manifest that describes files it did not check.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import onnx
import torch

from export.calibrate import WindowReader, collect_ranges, select_windows
from export.coverage import compare, coverage, fp32_constants, markdown
from export.graph import IR_VERSION, Built
from export.manifest import SCHEMA_VERSION, artifact_names, file_entry, write_manifest
from export.onnx_cnode import build_cnode, calibration_probes, cnode_params, quantize_cnode
from export.onnx_gru import CALIBRATION_PROBES, build_gru_fp32, build_gru_int8, gru_params, quantize_gru
from export.reference_bin import pick_windows, reference_bytes
from export.verify import batch_independence, int8_vs_fp32, ort_outputs, parity, session, torch_logits
from export.weights_bin import weights_bytes
from core.atomic import ensure_dir, write_bytes
from core.config import Config
from core.contracts import CLASS_NAMES
from core.errors import QuadfdiError
from core.rundir import RunDir
from sim.dataset import Dataset, load_dataset, make_windows
from train.checkpoint import check_dataset_matches, load_checkpoint
from train.metrics import compute_metrics
from train.models import SolverSpec

INT8_SCHEME = (
    "weights int8 symmetric per output channel (zero point 0, [-127, 127]); activations int8 symmetric "
    "(zero point 0, saturated to [-128, 127]) with static scales: max|x|/127 over calibration windows of the "
    "training split (normalised telemetry per channel, control path, latent state per RK4 stage, z1), 1/127 "
    "for tanh outputs and the GRU hidden state; QuantizeLinear (x / s, round half to even) -> MatMulInteger "
    "(int32) -> Cast -> Mul(s_activation) -> Mul(s_weight[out]) -> Add(bias); elementwise ops in float32"
)


@dataclass
class Graphs:
    cnode_fp32: Built
    cnode_int8: Built
    gru_fp32: Built
    gru_int8: Built


def _check(model: onnx.ModelProto, what: str) -> bytes:
    try:
        onnx.checker.check_model(model, full_check=True)
    except onnx.checker.ValidationError as exc:
        raise QuadfdiError(f"{what}: onnx.checker rejects the built graph: {str(exc).splitlines()[0]}") from None
    return model.SerializeToString()


def _load_models(run: RunDir, ds: Dataset, steps: int) -> tuple[torch.nn.Module, dict, torch.nn.Module, dict]:
    models = []
    for kind in ("cnode", "gru"):
        path = run.checkpoint(kind)
        model, blob = load_checkpoint(path, kind)
        check_dataset_matches(blob, ds.channel_names, str(path))
        if int(model.window) != ds.config.sim.window:
            raise QuadfdiError(f"{path}: the model takes windows of {model.window} samples, the dataset's are "
                               f"{ds.config.sim.window}")
        models += [model, blob]
    models[0].solver = SolverSpec(method="rk4", steps=steps)  # classic RK4, N steps: what the graph unrolls
    return tuple(models)  # type: ignore[return-value]


def export_run(run: RunDir, cfg: Config, log: Callable[[str], None] = print) -> dict:
    """Build, calibrate, verify and write every export artifact of ``run``; return the manifest."""
    t0 = time.perf_counter()
    ecfg = cfg.export
    steps, opset = ecfg.steps, ecfg.opset
    ds = load_dataset(run.dataset)
    cnode, cblob, gru, gblob = _load_models(run, ds, steps)
    train_w, test_w = make_windows(ds, "train"), make_windows(ds, "test")
    if len(train_w) == 0 or len(test_w) == 0:
        raise QuadfdiError(f"{run.dataset} has no {'training' if len(train_w) == 0 else 'test'} windows to "
                           f"calibrate or verify on")

    cp, gp = cnode_params(cnode, steps), gru_params(gru)
    cf, gf = build_cnode(cp, opset), build_gru_fp32(gp, opset)
    calib_idx = select_windows(len(train_w), ecfg.calib_windows)
    calib = train_w.x[calib_idx]
    cq = quantize_cnode(cp, collect_ranges(cf, calibration_probes(cp), WindowReader(calib)))
    gq = quantize_gru(gp, collect_ranges(gf, CALIBRATION_PROBES, WindowReader(calib)))
    graphs = Graphs(cf, build_cnode(cp, opset, cq), gf, build_gru_int8(gp, gq, opset))
    names = artifact_names(steps)
    blobs = {key: _check(getattr(graphs, key).model, names[key]) for key in names}
    log(f"export: built and checked 4 graphs (CNODE classic RK4 N={steps}, opset {opset}) "
        f"in {time.perf_counter() - t0:.1f} s")

    verification, metrics, outputs = verify_all(blobs, cnode, gru, test_w, ds)
    for key in ("cnode_fp32_vs_pytorch", "gru_fp32_vs_pytorch"):
        v = verification[key]
        if not v["passed"]:
            raise QuadfdiError(f"verification failed, nothing written: {key} max abs logit difference "
                               f"{v['max_abs_logit_diff']:.3g} > {v['bound']:.3g}")
    for key in ("cnode_int8_vs_fp32", "gru_int8_vs_fp32"):
        v = verification[key]
        log(f"export: {key}: argmax agreement {100 * v['argmax_agreement']:.2f} %, macro F1 "
            f"{v['macro_f1_fp32_points']:.2f} -> {v['macro_f1_int8_points']:.2f} "
            f"(drop {v['macro_f1_drop_points']:+.2f} points, target <= {v['macro_f1_drop_target_points']})"
            + ("" if v["meets_target"] else "  [target missed]"))

    cov = {}
    for model in ("cnode", "gru"):
        fp32 = coverage(getattr(graphs, f"{model}_fp32").model)
        int8 = coverage(getattr(graphs, f"{model}_int8").model)
        cov[model] = {"fp32": fp32, "int8": int8,
                      "summary": compare(fp32, int8, fp32_constants(getattr(graphs, f"{model}_int8").model))}
        s = cov[model]["summary"]
        log(f"export: {model} int8 coverage {100 * s['int8_mac_share']:.2f} % of MACs, initializers "
            f"{100 * s['initializer_bytes_ratio']:.1f} % of fp32")

    ref_idx = pick_windows(test_w.y, ecfg.reference_windows)
    files = {names[k]: blobs[k] for k in names}
    files["weights.bin"] = weights_bytes(cp, cq, gp, gq)
    files["reference.bin"] = reference_bytes(test_w.x[ref_idx], test_w.y[ref_idx], ref_idx, cnode, cp,
                                             graphs.cnode_int8, gru, gp, graphs.gru_int8)
    files["coverage.md"] = markdown(cov).encode()

    manifest = {
        "schema_version": SCHEMA_VERSION,
        "producer": "quadfdi export",
        "channels": [{"name": n, "unit": str(u)} for n, u in zip(ds.channel_names, ds["channel_units"])],
        "n_channels": ds.n_channels,
        "window": int(cnode.window),
        "sample_dt_s": ds.config.sim.sample_dt_s,
        "class_names": list(CLASS_NAMES),
        "normalisation": {"formula": "x_norm = (x - mean) / std, per channel, inside every graph",
                          "cnode": cblob["normalisation"], "gru": gblob["normalisation"]},
        "solver": {"method": "rk4", "scheme": "classic RK4 (stages 0, h/2, h/2, h; weights 1/6, 2/6, 2/6, 1/6)",
                   "steps": steps, "t_span": [0.0, 1.0], "stage_times": cp.times.tolist(),
                   "control": "U = interp @ x_norm, one constant (2N+1, W) linear-interpolation matrix"},
        "opset": opset,
        "ir_version": IR_VERSION,
        "io": {"input": {"name": "telemetry", "dtype": "float32", "shape": ["batch", int(cnode.window), ds.n_channels],
                         "units": "raw (as the dataset's channel units)"},
               "outputs": [{"name": "logits", "dtype": "float32", "shape": ["batch", len(CLASS_NAMES)]},
                           {"name": "proba", "dtype": "float32", "shape": ["batch", len(CLASS_NAMES)]}]},
        "artifacts": names,
        "files": {name: file_entry(data) for name, data in files.items()},
        "models": {"cnode": {**cblob["architecture"], "macs_per_window": cov["cnode"]["fp32"]["macs_per_window"]},
                   "gru": {**gblob["architecture"], "macs_per_window": cov["gru"]["fp32"]["macs_per_window"]}},
        "quantization": {
            "scheme": INT8_SCHEME,
            "calibration": {"split": "train", "windows": int(len(calib_idx)), "method": "max |x| (MinMax)",
                            "reader": "export.calibrate.WindowReader (onnxruntime CalibrationDataReader)"},
            "cnode_interp_exact": bool(cq.interp_exact),
            "coverage": {m: {"summary": c["summary"], "int8_ops": c["int8"]["ops"], "fp32_ops": c["fp32"]["ops"],
                             "int8_nodes": c["int8"]["nodes"], "fp32_nodes": c["fp32"]["nodes"],
                             "int8_initializer_bytes": c["int8"]["initializer_bytes"],
                             "fp32_initializer_bytes": c["fp32"]["initializer_bytes"]} for m, c in cov.items()},
        },
        "verification": verification,
        "metrics": metrics,
        "reference": {"test_index": ref_idx.tolist(), "labels": test_w.y[ref_idx].tolist()},
        "config": cfg.to_dict(),
    }
    out = ensure_dir(run.export)
    for name, data in files.items():
        write_bytes(out / name, data)
    write_manifest(out / "manifest.json", manifest)
    log(f"export: wrote {len(files) + 1} files into {out} in {time.perf_counter() - t0:.1f} s")
    return manifest


def verify_all(blobs: dict[str, bytes], cnode: torch.nn.Module, gru: torch.nn.Module, test, ds: Dataset):
    """ORT (all four graphs) against PyTorch and int8 against fp32 on the whole test split."""
    x = test.x
    ref = {"cnode": torch_logits(cnode, x), "gru": torch_logits(gru, x)}
    logits, proba, indep = {}, {}, {}
    for key, data in blobs.items():
        sess = session(data)
        logits[key], proba[key] = ort_outputs(sess, x)
        indep[key] = batch_independence(sess, x, logits[key])
    verification = {
        "test_windows": int(len(x)),
        "cnode_fp32_vs_pytorch": parity(logits["cnode_fp32"], ref["cnode"]),
        "gru_fp32_vs_pytorch": parity(logits["gru_fp32"], ref["gru"]),
        "cnode_int8_vs_fp32": int8_vs_fp32(logits["cnode_int8"], logits["cnode_fp32"], test.y),
        "gru_int8_vs_fp32": int8_vs_fp32(logits["gru_int8"], logits["gru_fp32"], test.y),
        "batch_independence": indep,
    }
    verification["passed"] = bool(verification["cnode_fp32_vs_pytorch"]["passed"]
                                  and verification["gru_fp32_vs_pytorch"]["passed"])

    def metrics_of(p: np.ndarray) -> dict:
        return compute_metrics(test.y, p, test.traj, test.t_end, ds["fault_class"], ds["detectable_s"])

    metrics = {key: metrics_of(proba[key]) for key in blobs}
    return verification, metrics, logits
