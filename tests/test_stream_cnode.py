"""The streaming CNODE (models/stream_cnode.py, train/stream_cnode_*.py, export/onnx_scnode.py,
fwref/cnode_step.hpp): the step is classic RK4 on the linearly interpolated control, the state carried
across truncated-backpropagation cuts, its training command and prediction set, the masked profile, the
one-step ONNX graphs, and the C++ step against ONNX Runtime (int8 bit for bit). Tiny settings."""

from __future__ import annotations

import dataclasses
import subprocess

import numpy as np
import pytest
import torch
from conftest import copy_run

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture: the cached host build)

TINY_FILE = {"epochs": 2, "latent": 6, "hidden": 30, "segment": 120, "tbptt": 40, "warmup": 10, "batch": 50}
TINY_ARGS = ["--set", "scnode.batch=6", "--hidden", "8", "--set", "scnode.hidden=20"]


def _cli(*argv: str):
    from quadfdi.cli import build_parser

    args = build_parser(list(argv)).parse_args(list(argv))
    return args.func(args)


@pytest.fixture(scope="module")
def scnode_run(small_run, tmp_path_factory):
    from quadfdi.core.config import dumps_toml, load_config, replace_section

    out = copy_run(small_run, tmp_path_factory.mktemp("scnode") / "run")
    cfg = load_config(out / "config.toml")
    (out / "config.toml").write_text(dumps_toml(replace_section(cfg, "scnode", **TINY_FILE)))
    assert _cli("train", "scnode", "--run", str(out), *TINY_ARGS) == 0
    assert _cli("export", "scnode", "--run", str(out)) == 0
    return out


def _model(seed: int = 0, leak: bool = True):
    from quadfdi.models.stream_cnode import StreamCNODE

    torch.manual_seed(seed)
    m = StreamCNODE(5, latent=4, hidden=7, n_classes=3, leak=leak)
    m.set_normalisation(np.arange(5, dtype=np.float32), np.full(5, 2.0, np.float32))
    return m.eval()


def test_one_step_is_classic_rk4_on_the_linearly_interpolated_control():
    from quadfdi.models.solvers import fixed_method

    m = _model()
    x = torch.randn(3, 2, 5, dtype=torch.float64) * 3
    m = m.double()
    # the same step written out: u(s) linear between the two normalised samples, f on [z, u] concatenated
    torch.manual_seed(1)
    zi = torch.randn(3, 4, dtype=torch.float64)
    got, _ = m.features(x[:, 1:], z0=zi, x_prev=x[:, 0])
    u0, u1 = ((x[:, 0] - m.mean) / m.std), ((x[:, 1] - m.mean) / m.std)

    def f(s, z):
        u = u0 + (u1 - u0) * (s / m.dt)
        return m.field(z, u) - z * m.decay()

    spec = fixed_method("rk4")
    assert spec.stage_offsets == (0.0, 0.5, 0.5, 1.0)  # classic, not torchdiffeq's 3/8 rule
    h, z = m.dt, zi
    k1 = f(0.0, z)
    k2 = f(h / 2, z + h / 2 * k1)
    k3 = f(h / 2, z + h / 2 * k2)
    k4 = f(h, z + h * k3)
    want = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert torch.allclose(got[:, 0], want, atol=1e-12)
    # the 3/8 rule (stages at h/3, 2h/3) is a different step: the test tells them apart
    k2b = f(h / 3, z + h / 3 * k1)
    k3b = f(2 * h / 3, z + h * (k2b - k1 / 3))
    k4b = f(h, z + h * (k1 - k2b + k3b))
    three_eighths = z + h / 8 * (k1 + 3 * k2b + 3 * k3b + k4b)
    assert (three_eighths - want).abs().max() > 1e-9


def test_state_and_previous_sample_carried_across_a_cut_give_the_uncut_stream():
    m = _model()
    x = torch.randn(2, 30, 5) * 2
    whole, z_end = m.features(x)
    a, za = m.features(x[:, :13])
    b, zb = m.features(x[:, 13:], za, x[:, 12])
    assert torch.allclose(torch.cat([a, b], 1), whole, atol=1e-6) and torch.allclose(zb, z_end, atol=1e-6)
    # without the previous sample the cut holds the 14th sample instead: another stream
    c, _ = m.features(x[:, 13:], za)
    assert (c[:, 0] - whole[:, 13]).abs().max() > 1e-5
    # the first sample of a stream is held: its step equals one with itself as the previous sample
    assert torch.allclose(m.features(x[:, :1])[0], m.features(x[:, :1], None, x[:, 0])[0])


def test_the_leak_keeps_a_long_stream_bounded():
    """A field that saturates in z has no restoring force: without the leak a constant input drives the
    state away linearly; with the (initial) leak the state settles."""
    x = torch.full((1, 2000, 5), 7.0)
    with torch.no_grad():
        for leak in (False, True):
            m = _model(leak=leak)
            torch.nn.init.constant_(m.field.lin2.bias, 0.5)
            zs, _ = m.features(x)
            late = zs[0, -1].abs().max().item()
            assert (late < 2.0) if leak else (late > 20.0), (leak, late)


def test_macs_and_signature():
    from quadfdi.models.stream_cnode import stream_from_signature, stream_signature

    m = _model()
    assert m.macs_per_step() == 4 * 2 * 4 * 7 + 7 * 5 + 4 * 3
    sig = stream_signature(m)
    assert sig == {"kind": "scnode", "n_channels": 5, "latent": 4, "hidden": 7, "n_classes": 3, "dt": 0.0625,
                   "leak": True}
    assert stream_signature(stream_from_signature(sig)) == sig
    with pytest.raises(ValueError, match="not a streaming CNODE"):
        stream_from_signature({**sig, "kind": "sgru"})


def test_train_scnode_settings_and_prediction_set(scnode_run):
    from quadfdi.core.jsonio import read_json
    from quadfdi.formats.dataset import gather_windows, load_dataset, window_index
    from quadfdi.formats.predictions import check_prediction_set, read_index
    from quadfdi.train.config import StreamCnodeConfig
    from quadfdi.train.data import evaluation_rows
    from quadfdi.train.stream_cnode_run import load_checkpoint

    want = {**dataclasses.asdict(StreamCnodeConfig()), **TINY_FILE, "batch": 6, "hidden": 8}
    model, blob = load_checkpoint(scnode_run / "scnode_train0.pt")
    rec = read_json(scnode_run / "predictions" / "scnode_sim0_train0.json")
    assert blob["config"] == want and rec["settings"] == want and blob["profile"] == "paper"
    assert (model.latent, model.hidden) == (6, 8)
    ds = load_dataset(scnode_run / "dataset.npz")
    entry = [e for e in read_index(scnode_run) if e["model"] == "scnode"]
    pred = dict(np.load(scnode_run / entry[0]["predictions"]))
    check_prediction_set(pred, "scnode")
    traj, start = window_index(ds, evaluation_rows(ds))
    w = gather_windows(ds, traj, start)
    assert np.array_equal(pred["traj"], w.traj) and np.array_equal(pred["y_true"], w.y)
    f = int(w.traj[0])
    with torch.no_grad():
        logits, _ = model(torch.from_numpy(ds["telemetry"][f][None]))
    ends = w.start[w.traj == f] + ds.config.sim.window - 1
    want_p = torch.softmax(logits[0, ends].double(), -1).numpy()
    assert np.allclose(want_p, pred["proba"][w.traj == f], atol=1e-6)
    rows = {r["model"]: r for r in rec["compute"]}
    # L = 6, H = 8, C = 23, K = 4: 4*2*6*8 + 8*23 + 6*4 = 592 MACs per sample, 25 samples per second
    assert rows["scnode"]["macs_per_decision"] == 592 and rows["scnode"]["macs_per_s"] == pytest.approx(592 * 25)


def test_train_scnode_bad_setting_is_a_one_line_error_before_any_write(small_run, tmp_path):
    from quadfdi.core.errors import QuadfdiError

    out = copy_run(small_run, tmp_path / "run")
    for args, key in ((["--latent", "0"], "scnode.latent"), (["--dt", "2.0"], "scnode.dt"),
                      (["--set", "scnode.zero_start=1.5"], "scnode.zero_start")):
        with pytest.raises(QuadfdiError, match=key) as exc:
            _cli("train", "scnode", "--run", str(out), *args)
        assert "\n" not in str(exc.value) and not (out / "predictions").exists()


def test_train_scnode_masked_profile_draws_a_pattern_per_segment(flightlog_export, tmp_path):
    from quadfdi.core.profiles import channel_names, mask_layout
    from quadfdi.train.stream_cnode_run import load_checkpoint

    out = copy_run(flightlog_export.parent, tmp_path / "run")
    assert _cli("train", "scnode", "--run", str(out), "--set", "train.profile=flightlog-mask", "--epochs", "1",
                "--latent", "4", "--hidden", "8", "--segment", "100", "--tbptt", "50", "--warmup", "5") == 0
    model, blob = load_checkpoint(out / "scnode_train0.pt")
    assert blob["profile"] == "flightlog-mask" and blob["channel_names"] == channel_names("flightlog-mask", [])
    avail = list(mask_layout("flightlog-mask")[2].values())
    assert np.all(model.mean.numpy()[avail] == 0) and np.all(model.std.numpy()[avail] == 1)
    assert _cli("export", "scnode", "--run", str(out)) == 0


def test_export_scnode_graphs(scnode_run):
    import onnx

    from quadfdi.core.jsonio import read_json
    from quadfdi.runtimes.ort import session

    m = onnx.load(str(scnode_run / "export" / "scnode_step.onnx"))
    assert m.ir_version <= 13 and [i.name for i in m.graph.input] == ["z", "prev", "sample"]
    assert [o.name for o in m.graph.output] == ["logits", "proba", "z_new"]
    rec = read_json(scnode_run / "export" / "scnode_export.json")
    assert rec["fp32_vs_torch"]["passed"] and rec["fp32_vs_torch"]["steps"] == 200
    assert rec["fp32_vs_torch"]["max_abs_state_diff"] < 1e-4
    m8 = onnx.load(str(scnode_run / "export" / "scnode_step.int8.onnx"))
    ops = [n.op_type for n in m8.graph.node]
    # two control products (previous and new sample), 4 stages x (lin1_z, lin2), the head: all integer
    assert ops.count("MatMulIntegerToFloat") == 11 and "Gemm" not in ops and "MatMul" not in ops
    assert ops.count("Tanh") == 4 and m8.ir_version <= 13
    assert {t.name: t.data_type for t in m8.graph.initializer}["lin2.weight_q"] == onnx.TensorProto.INT8
    assert rec["int8_vs_fp32"]["argmax_agreement_vs_fp32"] >= 0.9
    # the state is carried: z = 0 at every step gives other logits than the replay
    rep = np.load(scnode_run / "export" / "scnode_replay.npz")
    tel = rep["telemetry"]
    zero = np.zeros((len(tel), rep["z"].shape[1]), np.float32)
    prev = np.concatenate([tel[:1], tel[:-1]])
    memoryless = session(str(scnode_run / "export" / "scnode_step.onnx")).run(
        ["logits"], {"z": zero, "prev": prev, "sample": tel})[0]
    assert np.abs(memoryless[1:] - rep["logits"][1:]).max() > 1e-3
    assert np.allclose(memoryless[0], rep["logits"][0], atol=1e-6)


def _fwref(host_build, src, out):  # noqa: F811
    return subprocess.run([str(host_build / "fwref_scnode"), str(src), str(out)], capture_output=True, text=True,
                          timeout=60, check=False)


def test_fwref_scnode_matches_onnx_runtime_over_the_flight(scnode_run, host_build):  # noqa: F811
    from quadfdi.core.jsonio import read_json

    exp = scnode_run / "export"
    rep = np.load(exp / "scnode_replay.npz")
    t, k = rep["logits"].shape
    res = _fwref(host_build, exp / "scnode_fw.bin", exp / "out.f32")
    assert res.returncode == 0, res.stderr
    got = np.fromfile(exp / "out.f32", "<f4").reshape(t, -1)
    bound = read_json(exp / "scnode_export.json")["fp32_vs_torch"]["bound"]  # export/verify.py's fp32 tolerance
    assert np.abs(got[:, :k] - rep["logits"]).max() <= bound and np.abs(got[:, k:] - rep["z"]).max() < 1e-4
    assert (got[:, :k].argmax(1) == rep["logits"].argmax(1)).all()
    res = _fwref(host_build, exp / "scnode_fw_i8.bin", exp / "out.f32")
    assert res.returncode == 0, res.stderr
    got8 = np.fromfile(exp / "out.f32", "<f4").reshape(t, -1)
    # int8: logits and carried state bit-identical to ONNX Runtime's int8 graph at every sample
    assert np.array_equal(got8[:, :k], rep["logits_int8"]) and np.array_equal(got8[:, k:], rep["z_int8"])


def test_fwref_scnode_refuses_bad_input(scnode_run, host_build):  # noqa: F811
    exp = scnode_run / "export"
    data = (exp / "scnode_fw.bin").read_bytes()
    nan = bytearray(data)
    nan[-4:] = np.array([np.nan], "<f4").tobytes()
    cases = {"non-finite": bytes(nan), "magic": b"QSGRU1\0\0" + bytes(40), "size": data[:-4],
             "version": data[:8] + np.int32(2).tobytes() + data[12:]}
    for what, blob in cases.items():
        (exp / "bad.bin").write_bytes(blob)
        res = _fwref(host_build, exp / "bad.bin", exp / "bad.out")
        assert res.returncode == 1 and what in res.stderr and res.stderr.count("\n") == 1, (what, res.stderr)
        assert not (exp / "bad.out").exists()
