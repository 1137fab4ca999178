"""The export stage: checkpoints + dataset of a run -> runs/<name>/export/.

Everything is built and verified in memory first; only when the fp32 graphs match PyTorch are
the files staged, and they are published as one unit with the stage record (core.stage), so a
failed, killed or overlapping export never leaves a manifest beside files it does not describe.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import onnx
import torch

from quadfdi.core.atomic import ensure_dir, write_bytes
from quadfdi.core.config import Config
from quadfdi.core.contracts import ROTOR_SIDE_CLASSES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import RunDir
from quadfdi.core.stage import stage
from quadfdi.export.calibrate import WindowReader, collect_ranges, select_windows
from quadfdi.export.coverage import compare, coverage, fp32_constants, markdown
from quadfdi.export.graph import IR_VERSION, Built
from quadfdi.export.manifest import (MODEL_KINDS, artifact_names, build_manifest, encoding_of, manifest_class_names,
                                     motor_entry, profile_entry)
from quadfdi.formats.manifest import write_manifest
from quadfdi.export.quantize import weight_qmax
from quadfdi.export.onnx_cnode import CnodeParams, CnodeQuant, build_cnode, calibration_probes, cnode_params, quantize_cnode
from quadfdi.export.onnx_gru import (CALIBRATION_PROBES, GruParams, GruQuant, build_gru_fp32, build_gru_int8, gru_params,
                             quantize_gru)
from quadfdi.export.reference_bin import pick_windows, reference_bytes
from quadfdi.export.verify import batch_independence, int8_vs_fp32, judged_parity, motor_verification
from quadfdi.runtimes.ort import outputs, session
from quadfdi.core.reportmd import over_bound_clause
from quadfdi.runtimes.pytorch import torch_logits
from quadfdi.formats.onboard import onboard_section
from quadfdi.export.alarm_policies import Policies, policies_of
from quadfdi.export.deployment import Deployment, deployment_of
from quadfdi.formats.weights_bin import weights_bytes
from quadfdi.formats.dataset import Dataset, class_names, load_dataset, make_windows
from quadfdi.models.inputs import profile_of
from quadfdi.train.vehicle_ref import profiled
from quadfdi.models.checkpoint import check_dataset_matches, checkpoint_class_names, load_checkpoint
from quadfdi.train.metrics import compute_metrics
from quadfdi.models.networks import SolverSpec


@dataclass
class Graphs:
    """The four deployed graphs and what they were built from (parameters, int8 quantization)."""

    cnode_fp32: Built
    cnode_int8: Built
    gru_fp32: Built
    gru_int8: Built
    cnode_params: CnodeParams
    cnode_quant: CnodeQuant
    gru_params: GruParams
    gru_quant: GruQuant


def _check(model: onnx.ModelProto, what: str) -> bytes:
    try:
        onnx.checker.check_model(model, full_check=True)
    except onnx.checker.ValidationError as exc:
        raise QuadfdiError(f"{what}: onnx.checker rejects the built graph: {str(exc).splitlines()[0]}") from None
    return model.SerializeToString()


def _load_models(run: RunDir, ds: Dataset, steps: int) -> tuple[torch.nn.Module, dict, torch.nn.Module, dict]:
    models = []
    for kind in MODEL_KINDS:
        path = run.checkpoint(kind)
        model, blob = load_checkpoint(path, kind)
        check_dataset_matches(blob, ds.channel_names, str(path))
        if checkpoint_class_names(blob) != list(class_names(ds.arrays)):
            raise QuadfdiError(f"{path}: the model's classes {checkpoint_class_names(blob)} are not the dataset's "
                               f"{list(class_names(ds.arrays))}: re-run quadfdi train")
        if int(model.window) != ds.config.sim.window:
            raise QuadfdiError(f"{path}: the model takes windows of {model.window} samples, the dataset's are "
                               f"{ds.config.sim.window}")
        models += [model, blob]
    models[0].solver = SolverSpec(method="rk4", steps=steps)  # classic RK4, N steps: what the graph unrolls
    return tuple(models)  # type: ignore[return-value]


def build_graphs(cnode: torch.nn.Module, gru: torch.nn.Module, calib: np.ndarray, steps: int, opset: int) -> Graphs:
    """fp32 graphs of both models, their activation ranges over ``calib`` windows, the int8 graphs."""
    cp, gp = cnode_params(cnode, steps), gru_params(gru)
    cf, gf = build_cnode(cp, opset), build_gru_fp32(gp, opset)
    cq = quantize_cnode(cp, collect_ranges(cf, calibration_probes(cp), WindowReader(calib)))
    gq = quantize_gru(gp, collect_ranges(gf, CALIBRATION_PROBES, WindowReader(calib)))
    return Graphs(cf, build_cnode(cp, opset, cq), gf, build_gru_int8(gp, gq, opset), cp, cq, gp, gq)


_FP32_CHECKS = ("cnode_fp32_vs_pytorch", "gru_fp32_vs_pytorch", "cnode_motor_fp32_vs_pytorch", "gru_motor_fp32_vs_pytorch")


def _require_parity(verification: dict, log: Callable[[str], None]) -> None:
    """Stop on an fp32 graph that disagrees with PyTorch; report int8 against fp32 (a target only)."""
    for key in (k for k in _FP32_CHECKS if k in verification):
        v = verification[key]
        if not v["passed"]:
            raise QuadfdiError(f"verification failed, nothing written: {key} max abs logit difference "
                               f"{v['max_abs_logit_diff']:.3g} > {v['bound']:.3g}{over_bound_clause(v)}")
    for key in ("cnode_int8_vs_fp32", "gru_int8_vs_fp32"):
        v = verification[key]
        log(f"export: {key}: argmax agreement {100 * v['argmax_agreement']:.2f} %, macro F1 "
            f"{v['macro_f1_fp32_points']:.2f} -> {v['macro_f1_int8_points']:.2f} "
            f"(drop {v['macro_f1_drop_points']:+.2f} points, target <= {v['macro_f1_drop_target_points']})"
            + ("" if v["meets_target"] else "  [target missed]"))


def coverage_of(graphs: Graphs, log: Callable[[str], None]) -> dict[str, dict]:
    """Per model: the coverage of its fp32 and int8 graphs and the int8 graph's summary."""
    cov = {}
    for model in MODEL_KINDS:
        fp32 = coverage(getattr(graphs, f"{model}_fp32").model)
        int8_model = getattr(graphs, f"{model}_int8").model
        int8 = coverage(int8_model)
        cov[model] = {"fp32": fp32, "int8": int8, "summary": compare(fp32, int8, fp32_constants(int8_model))}
        s = cov[model]["summary"]
        log(f"export: {model} int8 coverage {100 * s['int8_mac_share']:.2f} % of MACs, initializers "
            f"{100 * s['initializer_bytes_ratio']:.1f} % of fp32")
    return cov


def export_run(run: RunDir, cfg: Config, log: Callable[[str], None] = print, alarm_from: str = "config",
               policies: Policies | None = None, deployment: Deployment | None = None) -> dict:
    """Build, calibrate, verify and publish every export artifact of ``run`` as one stage
    (core.stage: staged, then moved into export/ with the stage record); return the manifest.
    Files of an earlier export the new one does not have (another --steps) are removed.
    ``alarm_from``: each network's alarm policy from the config or evaluation.json (export.alarm_policies;
    refused before anything is written); ``policies``: those policies already read (``quadfdi export``
    reads them before importing torch), else read here. evaluation.json, when they came from it, is an
    input of the stage. ``deployment``: the windowed-or-streaming choice (export.deployment), read here
    when not given; evaluation.json, when the choice came from it, is an input of the stage too."""
    policies = policies or policies_of(run, cfg.alarm, alarm_from)
    deployment = deployment or deployment_of(run)
    sections = cfg.to_dict()
    with stage(run.root, "export", {"sim": sections["sim"], "export": sections["export"]},
               targets=("export/manifest.json", "export/weights.bin", "export/reference.bin")) as st:
        st.consume("dataset.npz", ("sim",))
        for kind in MODEL_KINDS:
            st.consume(f"{kind}.pt", ("sim",))
        policies.consume(st)
        deployment.consume(st)
        return _export_into(run, cfg, RunDir(st.out), log, policies, deployment)


def _export_into(run: RunDir, cfg: Config, dest: RunDir, log: Callable[[str], None], policies: Policies,
                 deployment: Deployment) -> dict:
    t0 = time.perf_counter()
    ecfg = cfg.export
    steps, opset = ecfg.steps, ecfg.opset
    profile = profile_of(load_checkpoint(run.checkpoint("cnode"), "cnode")[1])
    ds = profiled(load_dataset(run.dataset), profile)  # the models' input channels
    cnode, cblob, gru, gblob = _load_models(run, ds, steps)
    train_w, test_w = make_windows(ds, "train"), make_windows(ds, "test")
    if len(train_w) == 0 or len(test_w) == 0:
        raise QuadfdiError(f"{run.dataset} has no {'training' if len(train_w) == 0 else 'test'} windows to "
                           f"calibrate or verify on")

    calib_idx = select_windows(len(train_w), ecfg.calib_windows)
    graphs = build_graphs(cnode, gru, train_w.x[calib_idx], steps, opset)
    names = artifact_names(steps)
    blobs = {key: _check(getattr(graphs, key).model, names[key]) for key in names}
    log(f"export: built and checked 4 graphs (CNODE classic RK4 N={steps}, opset {opset}) "
        f"in {time.perf_counter() - t0:.1f} s")

    verification, metrics, _ = verify_all(blobs, cnode, gru, test_w, ds)
    _require_parity(verification, log)
    cov = coverage_of(graphs, log)

    cp, cq, gp, gq = graphs.cnode_params, graphs.cnode_quant, graphs.gru_params, graphs.gru_quant
    ref_idx = pick_windows(test_w.y, ecfg.reference_windows)
    files = {names[k]: blobs[k] for k in names}
    onboard = onboard_section(profile, ds.channel_names, int(cnode.window), cfg.sim.stride, ds.config.sim.sample_dt_s,
                              policies.default, manifest_class_names({"cnode": cblob}), policies.per_network())
    files["weights.bin"] = weights_bytes(cp, cq, gp, gq, onboard)
    files["reference.bin"] = reference_bytes(test_w.x[ref_idx], test_w.y[ref_idx], ref_idx, cnode, cp,
                                             graphs.cnode_int8, gru, gp, graphs.gru_int8)
    files["coverage.md"] = markdown(cov).encode()

    manifest = build_manifest(
        ds=ds, config=cfg.to_dict(), checkpoints={"cnode": cblob, "gru": gblob}, window=int(cnode.window),
        steps=steps, opset=opset, ir_version=IR_VERSION, stage_times=cp.times, files=files, coverage=cov,
        calib_windows=len(calib_idx), interp_exact=cq.interp_exact, verification=verification,
        metrics=metrics, reference_index=ref_idx, reference_labels=test_w.y[ref_idx],
        profile=profile_entry(profile, cblob, gblob), alarm=policies.default, alarm_per_model=policies.per_model,
        motor=motor_entry({"cnode": cblob, "gru": gblob}, list(ROTOR_SIDE_CLASSES)), deployment=deployment,
        encoding={"cnode": encoding_of(cq.act, weight_qmax(cq.act), graphs.cnode_int8.model),
                  "gru": encoding_of(gq.act, weight_qmax(gq.act), graphs.gru_int8.model)})
    out = ensure_dir(dest.export)
    for name, data in files.items():
        write_bytes(out / name, data)
    write_manifest(out / "manifest.json", manifest)
    log(f"export: wrote {len(files) + 1} files into {run.export} in {time.perf_counter() - t0:.1f} s")
    return manifest


def verify_all(blobs: dict[str, bytes], cnode: torch.nn.Module, gru: torch.nn.Module, test, ds: Dataset):
    """ORT (all four graphs) against PyTorch and int8 against fp32 on the whole test split."""
    x = test.x
    ref = {"cnode": torch_logits(cnode, x), "gru": torch_logits(gru, x)}
    logits, proba, indep, sessions = {}, {}, {}, {}
    for key, data in blobs.items():
        sess = sessions[key] = session(data)
        logits[key], proba[key] = outputs(sess, x, ["logits", "proba"])
        indep[key] = batch_independence(sess, x, logits[key])
    verification = {
        "test_windows": int(len(x)),
        "cnode_fp32_vs_pytorch": judged_parity(logits["cnode_fp32"], ref["cnode"], cnode, x),
        "gru_fp32_vs_pytorch": judged_parity(logits["gru_fp32"], ref["gru"], gru, x),
        "cnode_int8_vs_fp32": int8_vs_fp32(logits["cnode_int8"], logits["cnode_fp32"], test.y),
        "gru_int8_vs_fp32": int8_vs_fp32(logits["gru_int8"], logits["gru_fp32"], test.y),
        "batch_independence": indep,
        **motor_verification(sessions, {"cnode": cnode, "gru": gru}, x),  # only models with a motor head
    }
    verification["passed"] = bool(all(verification[k]["passed"] for k in _FP32_CHECKS if k in verification))

    def metrics_of(p: np.ndarray) -> dict:
        return compute_metrics(test.y, p, test.traj, test.t_end, ds["fault_class"], ds["detectable_s"],
                               class_names(ds.arrays))

    metrics = {key: metrics_of(proba[key]) for key in blobs}
    return verification, metrics, logits
