"""Builds manifest.json for the export stage (the format and its reader: quadfdi.formats.manifest)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from quadfdi.core.alarm import AlarmConfig
from quadfdi.core.contracts import CLASS_NAMES
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.manifest import SCHEMA_VERSION, file_entry

MODEL_KINDS = ("cnode", "gru")

INT8_SCHEME = (
    "weights int8 symmetric per output channel (zero point 0; [-127, 127], or [-63, 63] (7 bits) beside uint8 "
    "activations); activations symmetric with static scales, int8 (zero point 0) or uint8 (zero point 128, the "
    "same integer sums) per model (quantization.encoding): max|x|/127 over calibration windows of the "
    "training split (normalised telemetry per channel, control path, latent state per RK4 stage, z1), 1/127 "
    "for tanh outputs and the GRU hidden state; QuantizeLinear (x / s, round half to even) -> "
    "com.microsoft.MatMulIntegerToFloat: y = f32(acc) * f32(s_activation * s_weight[out]) + bias; "
    "elementwise ops in float32"
)


def encoding_of(act: str, weight_qmax: int, model) -> dict:
    """quantization.encoding.<model>: the activation type and zero point, the weights' range, and
    the operators outside the ONNX domain that the int8 graph uses, and those that run a subgraph
    (``Scan``: the int8 GRU's recurrence)."""
    from quadfdi.export.graph import contrib_ops, subgraph_ops

    return {"activations": act, "activation_zero_point": 128 if act == "uint8" else 0,
            "weight_bits": 7 if weight_qmax == 63 else 8, "weight_range": [-int(weight_qmax), int(weight_qmax)],
            "contrib_ops": contrib_ops(model), "subgraph_ops": subgraph_ops(model)}


def artifact_names(steps: int) -> dict[str, str]:
    """File names of the four deployed graphs, relative to the export folder."""
    return {"cnode_fp32": f"cnode_rk4_{steps}.onnx", "cnode_int8": f"cnode_rk4_{steps}.int8.onnx",
            "gru_fp32": "gru.onnx", "gru_int8": "gru.int8.onnx"}


def manifest_class_names(checkpoints: dict[str, dict]) -> list[str]:
    """The exported models' classes, label order: the checkpoints' ``class_names`` (the paper's four
    for a checkpoint written before they were stored; export.run checks that both models agree)."""
    return [str(c) for c in checkpoints["cnode"].get("class_names", CLASS_NAMES)]


def _io(window: int, n_channels: int, n_classes: int, motor: dict | None = None) -> dict:
    extra = [{"name": motor["output"], "dtype": "float32", "shape": ["batch", motor["n_motors"]],
              "models": motor["models"]}] if motor else []
    return {"input": {"name": "telemetry", "dtype": "float32", "shape": ["batch", window, n_channels],
                      "units": "raw (as the dataset's channel units)"},
            "outputs": [{"name": "logits", "dtype": "float32", "shape": ["batch", n_classes]},
                        {"name": "proba", "dtype": "float32", "shape": ["batch", n_classes]}] + extra}


def motor_entry(checkpoints: dict[str, dict], rotor_side_classes: list[str]) -> dict | None:
    """manifest ``motor_head`` (None when no exported model has one): the models with the head, the
    output's name and width, the rotor-side classes (the alarm's motor is only given for those)
    and the numbering of the output's columns."""
    models = [k for k in MODEL_KINDS if "n_motors" in checkpoints[k]["architecture"]]
    if not models:
        return None
    return {"models": models, "output": "motor_logits", "n_motors": 4, "rotor_side_classes": list(rotor_side_classes),
            "numbering": "column m = rotor m + 1 (docs/ingest.md, motor numbering) = the dataset's fault_motor m"}


def _quantization(coverage: dict[str, dict], calib_windows: int, interp_exact: bool,
                  encoding: dict | None = None) -> dict:
    return {
        "scheme": INT8_SCHEME,
        "encoding": encoding or {},
        "calibration": {"split": "train", "windows": int(calib_windows), "method": "max |x| (MinMax)",
                        "reader": "export.calibrate.WindowReader (onnxruntime CalibrationDataReader)"},
        "cnode_interp_exact": bool(interp_exact),
        "coverage": {m: {"summary": c["summary"], "int8_ops": c["int8"]["ops"], "fp32_ops": c["fp32"]["ops"],
                         "int8_nodes": c["int8"]["nodes"], "fp32_nodes": c["fp32"]["nodes"],
                         "int8_initializer_bytes": c["int8"]["initializer_bytes"],
                         "fp32_initializer_bytes": c["fp32"]["initializer_bytes"]} for m, c in coverage.items()},
    }


def build_manifest(*, ds: Any, config: dict, checkpoints: dict[str, dict], window: int, steps: int, opset: int,
                   ir_version: int, stage_times: np.ndarray, files: dict[str, bytes],
                   coverage: dict[str, dict], calib_windows: int, interp_exact: bool, verification: dict,
                   metrics: dict, reference_index: np.ndarray, reference_labels: np.ndarray,
                   encoding: dict | None = None, profile: dict | None = None, alarm: dict | None = None,
                   motor: dict | None = None, alarm_per_model: dict | None = None, deployment=None) -> dict:
    """The manifest of one export (the keys listed in this module's docstring, in that order).

    ``ds``: the run's ``formats.dataset.Dataset``; ``checkpoints``: "cnode"/"gru" -> checkpoint blob
    (architecture, normalisation); ``coverage``: per model {"fp32", "int8", "summary"} of
    ``export.coverage``; ``files``: every file written beside the manifest, name -> bytes;
    ``encoding``: per model ``encoding_of`` (activation type, weight bits, contrib ops); ``motor``:
    ``motor_entry`` (None: no key, the manifest of a model without the head is as before);
    ``deployment``: export.deployment.Deployment (``deployment`` and, when null, ``deployment_note``).
    """
    out = {
        "schema_version": SCHEMA_VERSION,
        "producer": "quadfdi export",
        "channels": [{"name": n, "unit": str(u)} for n, u in zip(ds.channel_names, ds["channel_units"])],
        "n_channels": ds.n_channels,
        "window": int(window),
        "sample_dt_s": ds.config.sim.sample_dt_s,
        "class_names": manifest_class_names(checkpoints),
        "normalisation": {"formula": "x_norm = (x - mean) / std, per channel, inside every graph",
                          **{k: checkpoints[k]["normalisation"] for k in MODEL_KINDS}},
        "solver": {"method": "rk4", "scheme": "classic RK4 (stages 0, h/2, h/2, h; weights 1/6, 2/6, 2/6, 1/6)",
                   "steps": steps, "t_span": [0.0, 1.0], "stage_times": np.asarray(stage_times).tolist(),
                   "control": "U = interp @ x_norm, one constant (2N+1, W) linear-interpolation matrix"},
        "opset": opset,
        "ir_version": ir_version,
        "io": _io(int(window), ds.n_channels, len(manifest_class_names(checkpoints)), motor),
        "artifacts": artifact_names(steps),
        "files": {name: file_entry(data) for name, data in files.items()},
        "models": {k: {**checkpoints[k]["architecture"], "macs_per_window": coverage[k]["fp32"]["macs_per_window"]}
                   for k in MODEL_KINDS},
        "quantization": _quantization(coverage, calib_windows, interp_exact, encoding),
        "verification": verification,
        "metrics": metrics,
        "reference": {"test_index": np.asarray(reference_index).tolist(),
                      "labels": np.asarray(reference_labels).tolist()},
        "config": config,
        "profile": profile or profile_entry("paper"),
        "alarm": alarm if alarm is not None else AlarmConfig().policy(),
    }
    if alarm_per_model is not None:
        out["alarm_per_model"] = alarm_per_model
    if deployment is not None:
        out["deployment"] = deployment.entry
        if deployment.entry is None:
            out["deployment_note"] = deployment.note
    if motor is not None:
        out["motor_head"] = motor
    return out


def profile_entry(name: str, *blobs: dict) -> dict:
    """manifest ``profile``: the input channels' profile (core.profiles; ``paper`` = raw telemetry),
    each channel with its formula and raw channels, the hover filter's constants (core.hover) and
    the vibration quantity; every checkpoint given must carry the same profile."""
    from quadfdi.core import hover
    from quadfdi.core.profiles import PROFILES, VIBRATION, uses_hover

    found = {str(b.get("profile", "paper")) for b in blobs}
    if found and found != {name}:
        raise QuadfdiError(f"the exported models were trained with different channel profiles: {sorted(found)}")
    spec = PROFILES[name]
    return {"name": name,
            "channels": None if spec is None else [{"name": c.name, "unit": c.unit, "raw": list(c.raw),
                                                    "formula": c.formula} for c in spec],
            "vibration": VIBRATION.get(name),
            "hover": None if not uses_hover(name) else {
                "inputs": list(hover.INPUTS), "steady_samples": hover.STEADY_SAMPLES,
                "settle_samples": hover.SETTLE_SAMPLES,
                "vz_max": float(hover.VZ_MAX), "tilt_max": float(hover.TILT_MAX), "cmd_min": float(hover.CMD_MIN)}}
