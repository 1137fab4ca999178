"""The motor head (models.motor): targets and switches, the checkpoint round trip,
the loss, the exported graphs' second output (fp32 against PyTorch, int8 against fp32), the
manifest entry, and detect's motor rules. Tiny random models, no training run (cheap)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from quadfdi.train.config import TrainConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.alarm import rotor_columns
from quadfdi.detect.motor import window_motor
from quadfdi.export.calibrate import WindowReader, collect_ranges
from quadfdi.export.manifest import motor_entry
from quadfdi.export.onnx_cnode import build_cnode, calibration_probes, cnode_params, quantize_cnode
from quadfdi.export.onnx_gru import CALIBRATION_PROBES, build_gru_fp32, build_gru_int8, gru_params, quantize_gru
from quadfdi.export.verify import motor_verification, parity
from quadfdi.runtimes.ort import outputs, session
from quadfdi.runtimes.pytorch import torch_logits
from tests.test_export_graphs import C, OPSET, W, synthetic_windows
from quadfdi.models.checkpoint import load_checkpoint, save_checkpoint
from quadfdi.train.loop import train_model
from quadfdi.models.networks import CNODE, GRUClassifier, SolverSpec, build_model, model_signature
from quadfdi.models.threads import torch_threads
from quadfdi.core.contracts import ROTOR_SIDE_CLASSES
from quadfdi.models.motor import (attach_motor_head, motor_loss, motor_targets, predict_motor_proba,
                         rotor_side, wants_motor_head)

REALISTIC = ["Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault"]


def test_rotor_side_classes_and_the_switch():
    assert rotor_side(REALISTIC).tolist() == [False, False, True, True, True]
    assert wants_motor_head("auto", REALISTIC) and not wants_motor_head("off", REALISTIC)
    assert not wants_motor_head("auto", ["Healthy", "BatteryFault"])
    assert TrainConfig().motor_head == "off"  # the paper config keeps every output
    with pytest.raises(QuadfdiError, match="motor_head"):
        TrainConfig(motor_head="on").validate()


def test_targets_are_the_flights_motor_on_rotor_side_windows_only():
    fault_motor = np.array([-1, 2, 0, -1, 3])
    y = np.array([0, 2, 4, 1, 0, 3])  # Healthy, Motor, Propeller, Battery, Healthy (pre-onset), Overheat
    traj = np.array([0, 1, 2, 3, 4, 4])
    assert motor_targets(y, traj, fault_motor, REALISTIC).tolist() == [-1, 2, 0, -1, -1, 3]
    with pytest.raises(ValueError, match="fault_motor"):
        motor_targets(np.array([2]), np.array([0]), fault_motor, REALISTIC)  # a motor fault without a motor
    logits = torch.tensor([[5.0, 0, 0, 0], [0, 0, 5.0, 0]], requires_grad=True)
    assert motor_loss(logits, torch.tensor([-1, -1])).item() == 0.0
    # only the second window counts: -log softmax = log(1 + 3 e^-5); a wrong first target adds its 5.02 / 2
    assert motor_loss(logits, torch.tensor([-1, 2])).item() == pytest.approx(np.log(1 + 3 * np.exp(-5)), rel=1e-6)
    assert motor_loss(logits, torch.tensor([1, 2])).item() == pytest.approx((5 + 2 * np.log(1 + 3 * np.exp(-5))) / 2,
                                                                            rel=1e-6)


def test_no_head_keeps_the_model_and_the_head_is_drawn_last():
    torch.manual_seed(3)
    plain = build_model("gru", C, TrainConfig(gru_hidden=6), window=W, n_classes=5)
    torch.manual_seed(3)
    head = attach_motor_head(build_model("gru", C, TrainConfig(gru_hidden=6), window=W, n_classes=5))
    assert "motor_head.weight" not in plain.state_dict() and "n_motors" not in model_signature(plain)
    for k, v in plain.state_dict().items():
        assert torch.equal(v, head.state_dict()[k])  # the other layers' initial weights are unchanged
    assert model_signature(head)["n_motors"] == 4 and head.motor_head.weight.shape == (4, 6)


@pytest.mark.parametrize("kind", ["gru", "cnode"])
def test_checkpoint_round_trip_and_training_moves_the_head(kind, tmp_path):
    from quadfdi.formats.dataset import Windows

    torch.manual_seed(0)
    cfg = TrainConfig(latent=6, hidden=8, gru_hidden=6, epochs=1, batch_size=16, steps=2, motor_head="auto")
    model = attach_motor_head(build_model(kind, C, cfg, window=W, n_classes=5))
    rng = np.random.default_rng(0)
    x = synthetic_windows(32, 1, np.zeros(C, np.float32), np.ones(C, np.float32))
    y = rng.integers(0, 5, 32)
    motor = np.where(rotor_side(REALISTIC)[y], rng.integers(0, 4, 32), -1)
    w = Windows(x, y, np.arange(32), np.zeros(32, np.int64), np.zeros(32))
    before = model.motor_head.weight.detach().clone()
    with torch_threads(1):  # one thread, as training runs (oversubscribed OpenMP makes the GRU ~50x slower)
        train_model(model, w, w, cfg, np.ones(5, np.float32), log=lambda _: None, motor=motor)
    assert not torch.equal(before, model.motor_head.weight)
    with pytest.raises(ValueError, match="motor"):
        train_model(model, w, w, cfg, np.ones(5, np.float32), log=lambda _: None)
    save_checkpoint(tmp_path / "m.pt", model, {}, [f"c{i}" for i in range(C)], class_names=REALISTIC)
    back, blob = load_checkpoint(tmp_path / "m.pt", kind)
    assert blob["architecture"]["n_motors"] == 4
    p = predict_motor_proba(back, x)
    assert p.shape == (32, 4) and np.allclose(p.sum(1), 1)
    np.testing.assert_array_equal(p, predict_motor_proba(model, x))


def _tiny_with_heads(steps: int = 2):
    torch.manual_seed(1)
    rng = np.random.default_rng(1)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    cnode = attach_motor_head(CNODE(C, window=W, latent=6, hidden=8, n_classes=5, solver=SolverSpec("rk4", steps)))
    gru = attach_motor_head(GRUClassifier(C, hidden=6, window=W, n_classes=5))
    for m in (cnode, gru):
        m.set_normalisation(mean, std)
        with torch.no_grad():  # logits of order 1, as test_export_graphs does
            for name, p in m.named_parameters():
                p.mul_(3.0 if "weight" in name else 1.0)
        m.eval()
    calib, x = synthetic_windows(64, 2, mean, std), synthetic_windows(24, 3, mean, std)
    cp, gp = cnode_params(cnode, steps), gru_params(gru)
    cf, gf = build_cnode(cp, OPSET), build_gru_fp32(gp, OPSET)
    cq = quantize_cnode(cp, collect_ranges(cf, calibration_probes(cp), WindowReader(calib, batch=32)))
    gq = quantize_gru(gp, collect_ranges(gf, CALIBRATION_PROBES, WindowReader(calib, batch=32)))
    graphs = {"cnode_fp32": cf, "cnode_int8": build_cnode(cp, OPSET, cq), "gru_fp32": gf,
              "gru_int8": build_gru_int8(gp, gq, OPSET)}
    return cnode, gru, x, graphs, (cp, cq, gp, gq)


def test_graphs_output_motor_logits_matching_pytorch():
    cnode, gru, x, graphs, _ = _tiny_with_heads()
    for key, built in graphs.items():
        assert [o.name for o in built.model.graph.output] == ["logits", "proba", "motor_logits"], key
    sessions = {k: session(b.model.SerializeToString()) for k, b in graphs.items()}
    v = motor_verification(sessions, {"cnode": cnode, "gru": gru}, x)
    for kind in ("cnode", "gru"):
        assert v[f"{kind}_motor_fp32_vs_pytorch"]["passed"], v
        # int8 against fp32: the same quantized representation as the class head, so the argmax
        # mostly agrees on random weights; the bound is loose on purpose (a broken scale gives ~0.25)
        assert v[f"{kind}_motor_int8_vs_fp32"]["argmax_agreement"] >= 0.7, v
        # the class head is unchanged by the second output
        assert parity(sessions[f"{kind}_fp32"].run(["logits"], {"telemetry": x})[0],
                      torch_logits(cnode if kind == "cnode" else gru, x))["passed"]
    # a wrong head weight is caught
    gru.motor_head.weight.data[0, 0] += 1.0
    assert not parity(outputs(sessions["gru_fp32"], x, ["motor_logits"])[0],
                      gru.motor_head(gru.features(torch.from_numpy(x))).detach().numpy())["passed"]


def test_manifest_entry_only_with_a_head():
    arch = {"cnode": {"architecture": {"kind": "cnode", "n_motors": 4}}, "gru": {"architecture": {"kind": "gru"}}}
    e = motor_entry(arch, list(ROTOR_SIDE_CLASSES))
    assert e["models"] == ["cnode"] and e["output"] == "motor_logits" and e["rotor_side_classes"][0] == "MotorFault"
    assert motor_entry({k: {"architecture": {}} for k in ("cnode", "gru")}, []) is None


def test_detect_motor_rules():
    rotor = rotor_columns(REALISTIC, list(ROTOR_SIDE_CLASSES))
    # windows: decided Battery, Motor (motor 3), Propeller (motor 1), Propeller (motor 1), undecided
    proba = np.array([[0.1, 0.8, 0.05, 0.0, 0.05], [0.1, 0.1, 0.7, 0.0, 0.1], [0.2, 0.0, 0.1, 0.0, 0.7],
                      [0.6, 0.0, 0.1, 0.0, 0.3], [np.nan] * 5])
    mp = np.array([[0.9, 0.1, 0, 0], [0.1, 0.1, 0.7, 0.1], [0.6, 0.2, 0.1, 0.1], [0.5, 0.3, 0.1, 0.1], [np.nan] * 4])
    assert window_motor(proba, mp, 0, rotor).tolist() == [0, 3, 1, 1, 0]  # window 3: fault class Propeller
    assert window_motor(proba, None, 0, rotor).tolist() == [0] * 5
    # an alarm's motor: core.alarm's rule (summed over the voting windows; rotor-side classes only)
    from quadfdi.core.alarm import alarm_episodes, reported_motor, run_alarm

    assert rotor_side(REALISTIC).tolist() == rotor.tolist() == rotor_columns(REALISTIC).tolist()  # one table
    tr = run_alarm(proba[None, 1:4], 0.35, 1, 1, 1, healthy=0, motor_proba=mp[None, 1:4])
    # classes summed: Motor 0.9 < Propeller 1.1; motors summed: 1.2, 0.6, 0.9, 0.3 -> motor 1
    assert alarm_episodes(tr, np.arange(3.0)[None], proba[None, 1:4], rotor=rotor)[0]["motor"] == 0
    assert alarm_episodes(tr, np.arange(3.0)[None], proba[None, 1:4])[0]["motor"] == -1  # no rotor columns
    assert reported_motor([4, 1, -1, 2], [2, 2, -1, -1], rotor).tolist() == [2, -1, -1, -1]  # battery: none


def test_weights_bin_carries_the_heads_in_optional_trailing_sections(tmp_path):
    from dataclasses import replace

    from quadfdi.formats.binfmt import pack
    from quadfdi.formats.weights_bin import read_weights, weights_bytes
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    _, gru, _, _, (cp, cq, gp, gq) = _tiny_with_heads()
    (tmp_path / "w.bin").write_bytes(weights_bytes(cp, cq, gp, gq))
    wf = read_weights(tmp_path / "w.bin")
    assert [(s.model, s.precision) for s in wf.sections][4:] == [
        ("cnode_motor", "fp32"), ("cnode_motor", "int8"), ("gru_motor", "fp32"), ("gru_motor", "int8")]
    sec = wf.section("gru_motor", "int8")
    assert sec.dims[:2] == (6, 4) and sec.tensors["motor_head.weight"].array.dtype == np.int8
    np.testing.assert_array_equal(wf.section("gru_motor", "fp32")["motor_head.weight"],
                                  gru.motor_head.weight.detach().numpy())
    # without heads: the four sections of before, and a lone or misordered head is refused
    plain = weights_bytes(replace(cp, motor_w=None, motor_b=None), cq, replace(gp, motor_w=None, motor_b=None), gq)
    (tmp_path / "p.bin").write_bytes(plain)
    assert len(read_weights(tmp_path / "p.bin").sections) == 4
    for bad in ([0, 1, 2, 3, 5], [0, 1, 2, 3, 6, 7, 4, 5]):
        (tmp_path / "b.bin").write_bytes(pack(MAGIC, VERSION, [wf.sections[i] for i in bad]))
        with pytest.raises(QuadfdiError, match="optionally"):
            read_weights(tmp_path / "b.bin")
