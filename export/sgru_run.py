"""``quadfdi export sgru --run RUN``: the streaming GRU's one-step ONNX graph, checked on a replayed
flight, and the files the C++ one-step GRU reads.

Writes into ``<run>/export/``:
- ``sgru_step.onnx``: the fp32 one-step graph (export/onnx_sgru.py), IR version ``export.graph.IR_VERSION``;
- ``sgru_step.int8.onnx``: the int8 one-step graph (export/onnx_sgru_int8.py), x_norm scales calibrated
  on every sample of the first ``CALIB_FLIGHTS`` training flights;
- ``sgru_replay.npz``: the replayed flight and ONNX Runtime's answer to it, for the C++ parity:
  ``telemetry`` (T, C) float32 raw samples (the first test flight with a fault, else the first test
  flight), ``logits`` (T, K) and ``h`` (T, H) float32, ONNX Runtime stepped one sample at a time
  from h = 0 carrying its own state, ``traj`` () the flight's dataset row;
- ``sgru_fw.bin``: the same flight and the weights for ``fwref_sgru`` (firmware_ref/tools/fwref_sgru.cpp):
  little-endian, b"QSGRU1\\0\\0", int32 C, H, K, T, then float32 mean, std, w_ih (3H, C), w_hh (3H, H),
  b_ih, b_hh, head_w (K, H), head_b, telemetry (T, C) (``fw_replay_bytes``);
- ``sgru_fw_i8.bin``: the same for the int8 step (magic QSGRU8, ``fw_replay_bytes_i8``), and in
  ``sgru_replay.npz`` ``logits_int8`` (T, K): ONNX Runtime's int8 graph on the flight;
- ``sgru_export.json``: the parity of that replay against PyTorch's whole-flight sequence
  (``export.verify.judged_parity`` on the logits at every step, steps past the bound judged against
  float32 rounding, and the state's max abs difference);
- ``sgru_weights.bin`` (formats/sgru_weights.py), when ``<run>/export/weights.bin`` holds the on-board
  record and the streaming GRU reads its model channels: the fp32 and int8 sections and a copy of the
  record, what fwref_stream --model sgru and the Cortex-M stream image run; sgru_export.json then
  records ``weights`` (its sha256 and that of the weights.bin whose record it copied), else why not.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from quadfdi.core.atomic import ensure_dir, write_bytes
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import write_json
from quadfdi.core.npzio import write_npz
from quadfdi.export.graph import IR_VERSION
from quadfdi.export.onnx_gru import quantize_gru
from quadfdi.export.onnx_sgru import build_sgru_fp32, sgru_params
from quadfdi.export.onnx_sgru_int8 import build_sgru_int8, calibrate_x_norm
from quadfdi.formats.sgru_weights import FILE_NAME as WEIGHTS_NAME, export_onboard, write_sgru_weights
from quadfdi.export.verify import stream_check
from quadfdi.runtimes.ort import session
from quadfdi.formats.dataset import load_dataset


def replay_flight(ds) -> int:
    """The dataset row replayed: the first test flight (split 2) with a fault, else the first test flight."""
    split, cls = np.asarray(ds["split"]), np.asarray(ds["fault_class"])
    rows = np.flatnonzero(split == 2)
    if len(rows) == 0:
        raise QuadfdiError("the dataset has no test flight to replay")
    faulty = rows[cls[rows] > 0]
    return int(faulty[0] if len(faulty) else rows[0])


FW_MAGIC = b"QSGRU1\0\0"
CALIB_FLIGHTS = 64


def fw_replay_bytes(p, tel: np.ndarray) -> bytes:
    """The ``fwref_sgru`` input: weights of GruParams ``p`` and the raw flight ``tel`` (T, C)."""
    dims = np.array([p.n_channels, p.hidden, p.n_classes, len(tel)], "<i4")
    parts = [p.mean, p.std, p.w_ih, p.w_hh, p.b_ih, p.b_hh, p.head_w, p.head_b, tel]
    return FW_MAGIC + dims.tobytes() + b"".join(np.ascontiguousarray(a, "<f4").tobytes() for a in parts)


FW_MAGIC_I8 = b"QSGRU8\0\0"


def fw_replay_bytes_i8(p, q, tel: np.ndarray) -> bytes:
    """The int8 ``fwref_sgru`` input: GruParams ``p``, GruQuant ``q`` and the raw flight ``tel`` (T, C)."""
    dims = np.array([p.n_channels, p.hidden, p.n_classes, len(tel)], "<i4")
    floats = [p.mean, p.std, q.s_x, np.reshape(q.s_h, 1), p.b_ih, p.b_hh, p.head_b, q.w_ih.scale, q.w_hh.scale,
              q.head.scale, tel]
    ints = [q.w_ih.q, q.w_hh.q, q.head.q]
    return (FW_MAGIC_I8 + dims.tobytes() + b"".join(np.ascontiguousarray(a, "<f4").tobytes() for a in floats)
            + b"".join(np.ascontiguousarray(a, np.int8).tobytes() for a in ints))


def ort_replay(onnx_bytes: bytes, tel: np.ndarray, hidden: int) -> tuple[np.ndarray, np.ndarray]:
    """Step ONNX Runtime through ``tel`` (T, C), one sample per run, its own state carried: logits, states."""
    sess = session(onnx_bytes)
    h = np.zeros((1, hidden), np.float32)
    logits, states = [], []
    for t in range(len(tel)):
        lg, _, h = sess.run(["logits", "proba", "h_new"], {"sample": tel[t:t + 1], "h": h})
        logits.append(lg[0])
        states.append(h[0])
    return np.array(logits, np.float32), np.array(states, np.float32)


@torch.no_grad()
def torch_replay(model, tel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """PyTorch's whole-flight sequence from h = 0: logits (T, K) and states (T, H)."""
    x = (torch.from_numpy(tel)[None] - model.mean) / model.std
    hs, _ = model.gru(x)
    return model.head(hs)[0].numpy(), hs[0].numpy()


def export_sgru_run(root: str | Path, seed: int = 0, opset: int = 18) -> list[Path]:
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    root = Path(root)
    ckpt = root / f"sgru_train{seed}.pt"
    if not ckpt.is_file():
        raise QuadfdiError(f"{ckpt} is missing: run `quadfdi train sgru --run {root}` first")
    model, blob = load_stream_checkpoint(ckpt)
    ds = load_dataset(root / "dataset.npz")
    if list(blob["channel_names"]) != list(ds.channel_names):
        raise QuadfdiError(f"{ckpt} was trained on other channels than {root / 'dataset.npz'}")
    params = sgru_params(model)
    built = build_sgru_fp32(params, opset)
    data = built.model.SerializeToString()
    calib = ds["telemetry"][np.flatnonzero(np.asarray(ds["split"]) == 0)[:CALIB_FLIGHTS]]
    quant = quantize_gru(params, {"x_norm": calibrate_x_norm(params, calib)})
    data8 = build_sgru_int8(params, quant, opset).model.SerializeToString()
    row = replay_flight(ds)
    tel = np.ascontiguousarray(ds["telemetry"][row], dtype=np.float32)
    ort_logits, ort_h = ort_replay(data, tel, model.hidden)
    ref_logits, ref_h = torch_replay(model, tel)
    i8_logits, _ = ort_replay(data8, tel, model.hidden)
    int8 = {"argmax_agreement_vs_fp32": float((i8_logits.argmax(1) == ort_logits.argmax(1)).mean()),
            "max_abs_logit_diff_vs_fp32": float(np.abs(i8_logits - ort_logits).max()), "calib_flights": len(calib)}
    # judged before anything is written: a refused export leaves no file
    check = stream_check("sgru_step.onnx", ort_logits, ref_logits, model, tel, row, np.abs(ort_h - ref_h).max())
    out = ensure_dir(root / "export")
    onboard_note = _write_onboard(out, params, quant, list(ds.channel_names))
    paths = [out / "sgru_step.onnx", out / "sgru_replay.npz", out / "sgru_fw.bin", out / "sgru_export.json",
             out / "sgru_step.int8.onnx", out / "sgru_fw_i8.bin"]
    write_bytes(paths[0], data)
    write_npz(paths[1], {"telemetry": tel, "logits": ort_logits, "h": ort_h, "logits_int8": i8_logits, "traj": np.asarray(row, np.int64)})
    write_bytes(paths[2], fw_replay_bytes(params, tel))
    write_bytes(paths[4], data8)
    write_bytes(paths[5], fw_replay_bytes_i8(params, quant, tel))
    write_json(paths[3], {"onnx": paths[0].name, "ir_version": IR_VERSION, "opset": opset, "train_seed": seed,
                          "inputs": ["sample", "h"], "outputs": ["logits", "proba", "h_new"],
                          "fp32_vs_torch": check, "int8_onnx": paths[4].name, "int8_vs_fp32": int8,
                          "weights": onboard_note})
    return paths + ([out / WEIGHTS_NAME] if "sha256" in onboard_note else [])


def _write_onboard(out: Path, params, quant, channels: list[str]) -> dict:
    """sgru_weights.bin beside the export's weights.bin, or (nothing written) why not."""
    import hashlib

    try:
        onboard = export_onboard(out, channels)
    except QuadfdiError as exc:
        (out / WEIGHTS_NAME).unlink(missing_ok=True)  # never a file whose record is not this export's
        return {"file": None, "why_not": str(exc)}
    data = write_sgru_weights(out / WEIGHTS_NAME, params, quant, onboard)
    return {"file": WEIGHTS_NAME, "sha256": hashlib.sha256(data).hexdigest(),
            "record_from_sha256": hashlib.sha256((out / "weights.bin").read_bytes()).hexdigest()}
