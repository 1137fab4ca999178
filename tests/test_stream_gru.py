"""The streaming GRU (train/stream_gru*.py): its training command, prediction set, step = sequence,
the compute comparison, and its one-step ONNX export. Tiny settings on the session's small run."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from conftest import copy_run

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture: the cached host build, shared with the firmware tests)

TINY = ["--epochs", "2", "--hidden", "8", "--segment", "120", "--tbptt", "40", "--warmup", "10", "--batch", "6"]
# The same tiny settings from the three places the command reads them: the run's [sgru] section
# (config.toml), --set, and a flag (which wins over both).
TINY_FILE = {"epochs": 2, "hidden": 30, "segment": 120, "tbptt": 40, "warmup": 10, "batch": 50}
TINY_ARGS = ["--set", "sgru.batch=6", "--hidden", "8", "--set", "sgru.hidden=20"]


def _cli(*argv: str):
    """Run a quadfdi command in this process (a subprocess would cost seconds of imports): parse it
    with the real parser, call its function."""
    from quadfdi.cli import build_parser

    args = build_parser(list(argv)).parse_args(list(argv))
    return args.func(args)


@pytest.fixture(scope="module")
def sgru_run(small_run, tmp_path_factory):
    from quadfdi.core.config import dumps_toml, load_config, replace_section

    out = copy_run(small_run, tmp_path_factory.mktemp("sgru") / "run")
    cfg = load_config(out / "config.toml")
    (out / "config.toml").write_text(dumps_toml(replace_section(cfg, "sgru", **TINY_FILE)))
    assert _cli("train", "sgru", "--run", str(out), *TINY_ARGS) == 0
    return out


def test_train_sgru_settings_come_from_the_sgru_section_then_set_then_flags(sgru_run):
    from quadfdi.core.jsonio import read_json
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    want = {**dataclasses.asdict(StreamFitConfig()), **TINY_FILE, "batch": 6, "hidden": 8}
    _, blob = load_stream_checkpoint(sgru_run / "sgru_train0.pt")
    assert blob["config"] == want
    assert read_json(sgru_run / "predictions" / "sgru_sim0_train0.json")["settings"] == want


def test_train_sgru_writes_a_prediction_set_at_the_window_ends(sgru_run):
    from quadfdi.formats.predictions import check_prediction_set, read_index
    from quadfdi.formats.dataset import gather_windows, load_dataset, window_index
    from quadfdi.train.data import evaluation_rows
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    ds = load_dataset(sgru_run / "dataset.npz")
    entry = [e for e in read_index(sgru_run) if e["model"] == "sgru"]
    assert len(entry) == 1 and entry[0]["train_seed"] == 0
    pred = dict(np.load(sgru_run / entry[0]["predictions"]))
    check_prediction_set(pred, "sgru")
    traj, start = window_index(ds, evaluation_rows(ds))
    w = gather_windows(ds, traj, start)
    # same windows, same order, same labels as the windowed models' sets (train/predsets.py)
    assert np.array_equal(pred["traj"], w.traj) and np.array_equal(pred["y_true"], w.y)
    assert np.array_equal(pred["t_end"], w.t_end)
    assert np.allclose(pred["proba"].sum(1), 1.0, atol=1e-5)
    # the probability at a window end is the stream's, started at h = 0 at take-off, one step per sample
    model, blob = load_stream_checkpoint(sgru_run / "sgru_train0.pt")
    assert blob["architecture"] == {"kind": "sgru", "n_channels": ds.n_channels, "hidden": 8, "n_classes": 4}
    f = int(w.traj[0])
    h = torch.zeros(1, model.hidden)
    tel = torch.from_numpy(ds["telemetry"][f])
    ends = set((w.start[w.traj == f] + ds.config.sim.window - 1).tolist())
    got = []
    for t in range(tel.shape[0]):
        logits, h = model.step(tel[t:t + 1], h)
        if t in ends:
            got.append(torch.softmax(logits.double(), -1).numpy()[0])
    # step by step (one-sample sequences) vs whole-flight nn.GRU: same cell, float32 order of sums only
    assert np.allclose(np.array(got), pred["proba"][w.traj == f], atol=1e-5)


def test_train_sgru_bad_setting_is_a_one_line_error_before_any_write(small_run, tmp_path):
    from quadfdi.core.errors import QuadfdiError

    out = copy_run(small_run, tmp_path / "run")
    with pytest.raises(QuadfdiError, match="hidden") as exc:  # the CLI prints it on one line, exits 2
        _cli("train", "sgru", "--run", str(out), "--hidden", "0")
    assert "\n" not in str(exc.value) and not (out / "predictions").exists()


def test_step_labels_follow_the_window_label_rule(small_run):
    from quadfdi.formats.dataset import load_dataset, make_windows
    from quadfdi.train.stream_gru_fit import step_labels

    ds = load_dataset(small_run / "dataset.npz")
    w = make_windows(ds, "test")
    lab = step_labels(ds, np.unique(w.traj))
    rows = {int(r): i for i, r in enumerate(np.unique(w.traj))}
    got = lab[[rows[int(t)] for t in w.traj], w.start + ds.config.sim.window - 1]
    assert np.array_equal(got, w.y) and (w.y > 0).any() and (w.y == 0).any()


def test_compute_per_second_of_flight(sgru_run):
    from quadfdi.core.jsonio import read_json
    from quadfdi.formats.dataset import load_dataset

    stride = load_dataset(sgru_run / "dataset.npz").config.sim.stride

    rec = read_json(sgru_run / "predictions" / "sgru_sim0_train0.json")
    rows = {r["model"]: r for r in rec["compute"]}
    # H = 8, C = 23 (paper channels), K = 4: 3*8*(23+8) + 8*4 = 776 MACs per sample, 25 samples per s
    assert rows["sgru"]["macs_per_decision"] == 776 and rows["sgru"]["macs_per_s"] == pytest.approx(776 * 25)
    # windowed GRU (H 80, W 80): 80*3*80*(23+80) + 80*4 = 1 977 920 per window, a window per stride
    assert rows["gru"]["macs_per_s"] == pytest.approx(1977920 * 25 / stride)
    assert rows["gru"]["ratio_to_gru"] == 1.0 and rows["sgru"]["ratio_to_gru"] < 0.01


def test_export_sgru_one_step_onnx_matches_pytorch_on_a_replayed_flight(sgru_run):
    import onnx

    from quadfdi.core.jsonio import read_json
    from quadfdi.runtimes.ort import session
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    assert _cli("export", "sgru", "--run", str(sgru_run)) == 0
    m = onnx.load(str(sgru_run / "export" / "sgru_step.onnx"))
    assert m.ir_version <= 13 and [i.name for i in m.graph.input] == ["sample", "h"]
    assert [o.name for o in m.graph.output] == ["logits", "proba", "h_new"]
    rec = read_json(sgru_run / "export" / "sgru_export.json")["fp32_vs_torch"]
    assert rec["passed"] and rec["steps"] == 200 and rec["max_abs_state_diff"] < 1e-4
    # int8: a graph of integer products, close to fp32 on the replay (recorded)
    m8 = onnx.load(str(sgru_run / "export" / "sgru_step.int8.onnx"))
    assert sum(n.op_type == "MatMulIntegerToFloat" for n in m8.graph.node) == 4 and m8.ir_version <= 13
    i8 = read_json(sgru_run / "export" / "sgru_export.json")["int8_vs_fp32"]
    print("int8 vs fp32 on the replay:", i8)
    assert i8["argmax_agreement_vs_fp32"] >= 0.9
    # the state really is carried: feeding h = 0 at every step gives other logits than the replay
    rep = np.load(sgru_run / "export" / "sgru_replay.npz")
    sess = session(str(sgru_run / "export" / "sgru_step.onnx"))
    model, _ = load_stream_checkpoint(sgru_run / "sgru_train0.pt")
    zero = np.zeros((len(rep["telemetry"]), model.hidden), np.float32)
    memoryless = sess.run(["logits"], {"sample": rep["telemetry"], "h": zero})[0]
    assert np.abs(memoryless[1:] - rep["logits"][1:]).max() > 1e-3
    assert np.allclose(memoryless[0], rep["logits"][0], atol=1e-5)  # step 0 starts from h = 0 in both


def test_export_sgru_refuses_a_wrong_step_graph_and_writes_nothing(sgru_run, tmp_path, monkeypatch):
    """A one-step graph of the other GRU variant (linear_before_reset=0) parts from PyTorch on the replayed
    flight beyond float32 rounding: one line, naming the steps, and no export file written."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.export import sgru_run as export_sgru
    from tests.test_fp32_rounding import set_gru_variant

    run = copy_run(sgru_run, tmp_path / "run", ("config.toml", "dataset.npz", ".stages/sim.json", "sgru_train0.pt"))
    built = export_sgru.build_sgru_fp32

    def wrong(params, opset):
        b = built(params, opset)
        set_gru_variant(b.model, 0)
        return b

    monkeypatch.setattr(export_sgru, "build_sgru_fp32", wrong)
    with pytest.raises(QuadfdiError, match=r"sgru_step\.onnx differs from PyTorch on flight \d+: .* on \d+ step"):
        _cli("export", "sgru", "--run", str(run))
    assert not (run / "export").exists() or not any((run / "export").iterdir())


def test_fwref_sgru_one_step_matches_onnx_runtime_on_the_replayed_flight(sgru_run, host_build):  # noqa: F811 (the fixture)
    import subprocess

    from quadfdi.core.jsonio import read_json

    if not (sgru_run / "export" / "sgru_fw.bin").exists():
        assert _cli("export", "sgru", "--run", str(sgru_run)) == 0
    out = sgru_run / "export" / "sgru_fw_out.f32"
    res = subprocess.run([str(host_build / "fwref_sgru"), str(sgru_run / "export" / "sgru_fw.bin"), str(out)],
                         capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    rep = np.load(sgru_run / "export" / "sgru_replay.npz")
    t, k = rep["logits"].shape
    got = np.fromfile(out, "<f4").reshape(t, -1)
    logits, h = got[:, :k], got[:, k:]
    # the fp32 tolerance of the windowed models (export/verify.py), over 200 carried steps
    bound = read_json(sgru_run / "export" / "sgru_export.json")["fp32_vs_torch"]["bound"]
    assert np.abs(logits - rep["logits"]).max() <= bound
    assert np.abs(h - rep["h"]).max() < 1e-4
    assert (logits.argmax(1) == rep["logits"].argmax(1)).all()
    # int8: bit-identical logits to ONNX Runtime's int8 graph at every sample
    res = subprocess.run([str(host_build / "fwref_sgru"), str(sgru_run / "export" / "sgru_fw_i8.bin"), str(out)],
                         capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    got8 = np.fromfile(out, "<f4").reshape(t, -1)[:, :k]
    assert np.array_equal(got8, rep["logits_int8"]), np.abs(got8 - rep["logits_int8"]).max()
    nan = bytearray((sgru_run / "export" / "sgru_fw.bin").read_bytes())
    nan[-4:] = np.array([np.nan], "<f4").tobytes()  # the last sample's last channel
    (sgru_run / "export" / "nan.bin").write_bytes(bytes(nan))
    res = subprocess.run([str(host_build / "fwref_sgru"), str(sgru_run / "export" / "nan.bin"), str(out)],
                         capture_output=True, text=True, check=False)
    assert res.returncode == 1 and "non-finite" in res.stderr  # fwref::step refuses it (kNonFiniteInput)
    bad = sgru_run / "export" / "bad.bin"
    bad.write_bytes(b"NOTSGRU1" + bytes(16))
    res = subprocess.run([str(host_build / "fwref_sgru"), str(bad), str(out)], capture_output=True, text=True, check=False)
    assert res.returncode == 1 and "magic" in res.stderr
