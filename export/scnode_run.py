"""``quadfdi export scnode --run RUN``: the streaming CNODE's one-step ONNX graphs, checked on a replayed
flight, and the files the C++ step (fwref/cnode_step.hpp) reads.

Writes into ``<run>/export/``:
- ``scnode_step.onnx`` / ``scnode_step.int8.onnx``: the one-step graphs (export/onnx_scnode.py), int8
  scales calibrated on every sample of the first ``CALIB_FLIGHTS`` training flights (streams from z = 0);
- ``scnode_replay.npz``: the replayed flight (the first test flight with a fault, export/sgru_run.py
  ``replay_flight``, on the checkpoint's profile, under its own mask pattern) and ONNX Runtime's answers,
  stepped one sample at a time from z = 0 carrying its own state: ``telemetry`` (T, C), ``logits``,
  ``z`` (fp32), ``logits_int8``, ``z_int8``, ``traj``;
- ``scnode_fw.bin`` / ``scnode_fw_i8.bin``: weights and flight for ``fwref_scnode`` (``fw_bytes``: the
  versioned layout of docs/formats.md "scnode_fw.bin"); ``scnode_weights.bin`` / ``scnode_weights_i8.bin`` the
  same without a flight (T = 0): what ``fwref_stream --model scnode --step-weights`` runs beside weights.bin;
- ``scnode_export.json``: ONNX Runtime fp32 against PyTorch's whole-flight stream (``export.verify.judged_parity``
  on the logits of every step, steps past the bound judged against float32 rounding; the state's max abs
  difference), int8 against fp32 on the replay
  (argmax agreement, macro F1 of both over every sample's label), the calibration, and ``onboard``: whether
  weights.bin's on-board record (``quadfdi export``) feeds the streaming CNODE's channels, else why not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.core.atomic import ensure_dir, write_bytes
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import write_json
from quadfdi.core.npzio import write_npz
from quadfdi.export.graph import IR_VERSION
from quadfdi.export.onnx_scnode import (INPUTS, OUTPUTS, ScnodeParams, ScnodeQuant, build_scnode, calibrate,
                                        quantize_scnode, scnode_params)
from quadfdi.export.sgru_run import replay_flight
from quadfdi.export.verify import stream_check
from quadfdi.formats.dataset import load_dataset
from quadfdi.models.inputs import profile_of, profiled_dataset
from quadfdi.runtimes.ort import session

CALIB_FLIGHTS = 64
FW_MAGIC, FW_VERSION = b"QSCNODE\0", 1
PRECISION = {"fp32": 1, "int8": 2}


def fw_bytes(p: ScnodeParams, q: ScnodeQuant | None, tel: np.ndarray) -> bytes:
    """``fwref_scnode``'s input: magic, int32 version, precision (1 fp32, 2 int8), C, L, H, K, T, leak (0/1), then the
    float32 tensors and (int8) the int8 matrices, row-major (docs/formats.md "scnode_fw.bin")."""
    head = np.array([FW_VERSION, PRECISION["int8" if q else "fp32"], p.n_channels, p.latent, p.hidden,
                     p.n_classes, len(tel), int(p.decay is not None)], "<i4")
    decay = [] if p.decay is None else [p.decay]
    if q is None:
        floats = [p.mean, p.std, p.rk4, p.lin1_wz, p.lin1_wu, p.lin1_b, p.lin2_w, p.lin2_b, *decay, p.head_w, p.head_b,
                  tel]
        ints = []
    else:
        floats = [p.mean, p.std, p.rk4, q.s_x, np.reshape(q.s_z, 1), np.reshape(q.s_hid, 1), q.lin1_u.scale, p.lin1_b,
                  q.lin1_z.scale, q.lin2.scale, p.lin2_b, *decay, q.head.scale, p.head_b, tel]
        ints = [q.lin1_u.q, q.lin1_z.q, q.lin2.q, q.head.q]
    return (FW_MAGIC + head.tobytes() + b"".join(np.ascontiguousarray(a, "<f4").tobytes() for a in floats)
            + b"".join(np.ascontiguousarray(a, np.int8).tobytes() for a in ints))


def ort_replay(onnx_bytes: bytes, tel: np.ndarray, latent: int) -> tuple[np.ndarray, np.ndarray]:
    """ONNX Runtime stepped through ``tel`` (T, C) from z = 0, its own state carried: logits (T, K), z (T, L)."""
    sess = session(onnx_bytes)
    z = np.zeros((1, latent), np.float32)
    logits, states = [], []
    for t in range(len(tel)):
        lg, _, z = sess.run(list(OUTPUTS), {"z": z, "prev": tel[max(t - 1, 0)][None], "sample": tel[t:t + 1]})
        logits.append(lg[0])
        states.append(z[0])
    return np.array(logits, np.float32), np.array(states, np.float32)


@torch.no_grad()
def torch_replay(model, tel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PyTorch's whole-flight stream from z = 0: logits (T, K) and states (T, L)."""
    zs, _ = model.features(torch.from_numpy(tel)[None])
    return model.head(zs)[0].numpy(), zs[0].numpy()


def onboard_note(out: Path, channels: list[str]) -> dict:
    """Whether ``out``/weights.bin's on-board record feeds ``channels`` (fwref_stream --model scnode needs it)."""
    from quadfdi.formats.onboard import onboard_dict
    from quadfdi.formats.weights_bin import read_weights

    path = out / "weights.bin"
    if not path.is_file():
        return {"record": False, "why_not": f"{path.name} is missing: run `quadfdi export` for the on-board record"}
    rec = read_weights(path).onboard
    if rec is None:
        return {"record": False, "why_not": f"{path.name} has no on-board record (re-run `quadfdi export`)"}
    got = list(onboard_dict(rec)["channels"])
    if got != list(channels):
        return {"record": False, "why_not": f"{path.name}'s record feeds {len(got)} channels {got[:3]}..., the "
                                            f"streaming CNODE reads {len(channels)} {list(channels)[:3]}..."}
    return {"record": True}


def _int8_check(i8: np.ndarray, fp: np.ndarray, y: np.ndarray, n_calib: int) -> dict:
    labels = list(range(fp.shape[1]))
    f1 = {k: float(f1_score(y, v.argmax(1), labels=labels, average="macro", zero_division=0)) for k, v in
          (("fp32", fp), ("int8", i8))}
    return {"argmax_agreement_vs_fp32": float((i8.argmax(1) == fp.argmax(1)).mean()),
            "max_abs_logit_diff_vs_fp32": float(np.abs(i8 - fp).max()), "replay_macro_f1_fp32": f1["fp32"],
            "replay_macro_f1_int8": f1["int8"], "calib_flights": n_calib}


def export_scnode_run(root: str | Path, seed: int = 0, opset: int = 18) -> list[Path]:
    from quadfdi.train.stream_cnode_run import load_checkpoint
    from quadfdi.train.stream_gru_fit import step_labels

    root = Path(root)
    ckpt = root / f"scnode_train{seed}.pt"
    if not ckpt.is_file():
        raise QuadfdiError(f"{ckpt} is missing: run `quadfdi train scnode --run {root}` first")
    model, blob = load_checkpoint(ckpt)
    ds = profiled_dataset(load_dataset(root / "dataset.npz"), profile_of(blob), patterns=True)
    if list(blob["channel_names"]) != list(ds.channel_names):
        raise QuadfdiError(f"{ckpt} was trained on other channels than profile {profile_of(blob)!r} of {root / 'dataset.npz'}")
    params = scnode_params(model)
    calib = ds["telemetry"][np.flatnonzero(np.asarray(ds["split"]) == 0)[:CALIB_FLIGHTS]]
    ranges = calibrate(model, calib)
    quant = quantize_scnode(params, ranges)
    data = build_scnode(params, opset).model.SerializeToString()
    data8 = build_scnode(params, opset, quant).model.SerializeToString()
    row = replay_flight(ds)
    tel = np.ascontiguousarray(ds["telemetry"][row], dtype=np.float32)
    ort_logits, ort_z = ort_replay(data, tel, model.latent)
    i8_logits, i8_z = ort_replay(data8, tel, model.latent)
    ref_logits, ref_z = torch_replay(model, tel)
    # judged before anything is written: a refused export leaves no file
    check = stream_check("scnode_step.onnx", ort_logits, ref_logits, model, tel, row, np.abs(ort_z - ref_z).max())
    out = ensure_dir(root / "export")
    paths = [out / n for n in ("scnode_step.onnx", "scnode_step.int8.onnx", "scnode_replay.npz", "scnode_fw.bin",
                               "scnode_fw_i8.bin", "scnode_weights.bin", "scnode_weights_i8.bin", "scnode_export.json")]
    write_bytes(paths[0], data)
    write_bytes(paths[1], data8)
    write_npz(paths[2], {"telemetry": tel, "logits": ort_logits, "z": ort_z, "logits_int8": i8_logits, "z_int8": i8_z,
                         "traj": np.asarray(row, np.int64)})
    write_bytes(paths[3], fw_bytes(params, None, tel))
    write_bytes(paths[4], fw_bytes(params, quant, tel))
    write_bytes(paths[5], fw_bytes(params, None, tel[:0]))
    write_bytes(paths[6], fw_bytes(params, quant, tel[:0]))
    write_json(paths[7], {"onnx": paths[0].name, "int8_onnx": paths[1].name, "ir_version": IR_VERSION, "opset": opset,
                          "train_seed": seed, "profile": profile_of(blob), "inputs": list(INPUTS), "outputs": list(OUTPUTS),
                          "latent": params.latent, "hidden": params.hidden, "dt": params.dt,
                          "fp32_vs_torch": check, "int8_vs_fp32": _int8_check(i8_logits, ort_logits, step_labels(
                              ds, np.array([row]))[0], len(calib)),
                          "calibration": {"x_norm_max": ranges["x_norm"].tolist(), "z_max": float(ranges["z"])},
                          "onboard": onboard_note(out, list(ds.channel_names))})
    return paths
