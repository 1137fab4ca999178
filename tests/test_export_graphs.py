"""Export graphs, tested as ONNX Runtime's quantization tests do: structure, element types, numbers.

Tiny random models and synthetic windows (no trained run): the structure and the arithmetic do
not depend on training. The helpers at the top are shared by the other test_export_* files.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass

import numpy as np
import onnx
import pytest
import torch
from onnx import TensorProto, numpy_helper

from export.calibrate import WindowReader, collect_ranges
from export.graph import Built
from export.onnx_cnode import build_cnode, calibration_probes, cnode_params, quantize_cnode
from export.onnx_gru import CALIBRATION_PROBES, build_gru_fp32, build_gru_int8, gru_params, quantize_gru
from export.verify import int8_vs_fp32, ort_outputs, parity, session, torch_logits
from train.models import CNODE, GRUClassifier, SolverSpec

C, W = 5, 80
OPSET = 18


def synthetic_windows(n: int, seed: int, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    """Raw telemetry-like windows (n, W, C): a random walk around ``mean`` with spread ``std``."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0, 0.25, (n, W, C)), axis=1) + rng.normal(0, 1, (n, 1, C))
    return (mean + std * walk).astype(np.float32)


@dataclass
class Tiny:
    cnode: CNODE
    gru: GRUClassifier
    steps: int
    calib: np.ndarray
    x: np.ndarray
    cp: object
    gp: object
    cq: object
    gq: object
    cnode_fp32: Built
    cnode_int8: Built
    gru_fp32: Built
    gru_int8: Built


def make_tiny(steps: int = 3, seed: int = 0, opset: int = OPSET) -> Tiny:
    """Random-weight CNODE and GRU with their four graphs, calibrated on synthetic windows."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    cnode = CNODE(C, window=W, latent=6, hidden=8, solver=SolverSpec("rk4", steps))
    gru = GRUClassifier(C, hidden=6, window=W)
    for m in (cnode, gru):
        m.set_normalisation(mean, std)
        with torch.no_grad():  # larger weights than the default init: logits of order 1
            for name, p in m.named_parameters():
                p.mul_(3.0 if "weight" in name else 1.0)
        m.eval()
    calib, x = synthetic_windows(64, seed + 1, mean, std), synthetic_windows(24, seed + 2, mean, std)
    cp, gp = cnode_params(cnode, steps), gru_params(gru)
    cf, gf = build_cnode(cp, opset), build_gru_fp32(gp, opset)
    cq = quantize_cnode(cp, collect_ranges(cf, calibration_probes(cp), WindowReader(calib, batch=32)))
    gq = quantize_gru(gp, collect_ranges(gf, CALIBRATION_PROBES, WindowReader(calib, batch=32)))
    return Tiny(cnode, gru, steps, calib, x, cp, gp, cq, gq, cf, build_cnode(cp, opset, cq), gf,
                build_gru_int8(gp, gq, opset))


def run(built: Built, x: np.ndarray) -> np.ndarray:
    return ort_outputs(session(built.model.SerializeToString()), x)[0]


def op_counts(model: onnx.ModelProto) -> Counter:
    return Counter(n.op_type for n in model.graph.node)


def inits(model: onnx.ModelProto) -> dict[str, np.ndarray]:
    return {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}


@pytest.fixture(scope="module")
def tiny() -> Tiny:
    return make_tiny()


# ----------------------------------------------------------------------------- contract


def test_every_graph_passes_full_check_and_has_the_io_contract(tiny):
    for built in (tiny.cnode_fp32, tiny.cnode_int8, tiny.gru_fp32, tiny.gru_int8):
        m = built.model
        onnx.checker.check_model(m, full_check=True)
        assert m.opset_import[0].version >= 17 and m.ir_version <= 13
        (inp,) = m.graph.input
        dims = [d.dim_param or d.dim_value for d in inp.type.tensor_type.shape.dim]
        assert inp.name == "telemetry" and inp.type.tensor_type.elem_type == TensorProto.FLOAT
        assert dims == ["batch", W, C]
        assert [o.name for o in m.graph.output] == ["logits", "proba"]
        assert all(i.data_location != TensorProto.EXTERNAL for i in m.graph.initializer)
        sess = session(m.SerializeToString())
        for b in (1, 3):  # dynamic batch
            logits, proba = ort_outputs(sess, tiny.x[:b])
            assert logits.shape == proba.shape == (b, 4)
            np.testing.assert_allclose(proba.sum(1), 1.0, rtol=1e-6)


def test_opset_17_works_too():
    t = make_tiny(steps=1, opset=17)
    for built in (t.cnode_fp32, t.cnode_int8, t.gru_fp32, t.gru_int8):
        onnx.checker.check_model(built.model, full_check=True)
        assert built.model.opset_import[0].version == 17
    np.testing.assert_allclose(run(t.cnode_fp32, t.x), torch_logits(t.cnode, t.x), atol=1e-5)


# ----------------------------------------------------------------------------- structure


@pytest.mark.parametrize("steps", [1, 2, 5])
def test_cnode_op_counts_grow_linearly_with_n(steps):
    t = make_tiny(steps=steps)
    fp32, int8 = op_counts(t.cnode_fp32.model), op_counts(t.cnode_int8.model)
    # fp32: P@x, encoder, lin1_u (all stage times at once), head + 2 per stage (lin1_z, lin2).
    assert fp32["MatMul"] == 8 * steps + 4
    assert fp32["Tanh"] == int8["Tanh"] == 4 * steps + 1  # z0 + one per stage
    assert fp32["Split"] == int8["Split"] == 1  # V's 2N+1 rows, once
    # int8: the same products, every one on MatMulInteger; no float product left.
    assert int8["MatMulInteger"] == 8 * steps + 4 and int8["MatMul"] == 0 and int8["Gemm"] == 0
    # QuantizeLinear: x_norm, U, z1 + 2 per stage (its state, its tanh output).
    assert int8["QuantizeLinear"] == 8 * steps + 3
    for counts in (fp32, int8):  # no control flow, no data-dependent indexing
        assert not {"Loop", "If", "Scan", "Gather", "GatherElements", "GatherND"} & set(counts)


def test_cnode_weights_stored_once(tiny):
    fp32, int8 = inits(tiny.cnode_fp32.model), inits(tiny.cnode_int8.model)
    names = ("encoder", "lin1_u", "lin1_z", "lin2", "head")

    def constants_of(model, op):
        return [i for n in model.graph.node if n.op_type == op for i in n.input if i in inits(model)]

    # 8N + 4 products read 6 matrices: the interpolation matrix and five weights, each stored once.
    used = constants_of(tiny.cnode_fp32.model, "MatMul")
    assert len(used) == 8 * tiny.steps + 4 and set(used) == {"interp"} | {f"{w}.weight_t" for w in names}
    used = constants_of(tiny.cnode_int8.model, "MatMulInteger")
    assert len(used) == 8 * tiny.steps + 4 and set(used) == {"interp.q"} | {f"{w}.weight_q" for w in names}
    weights_q = {k: v for k, v in int8.items() if k.endswith(".weight_q") or k == "interp.q"}
    assert len(weights_q) == 6 and all(v.dtype == np.int8 for v in weights_q.values())
    # No float weight matrix left in the int8 graph: every float constant is a vector (or (S, 1)).
    floats = {k: v for k, v in int8.items() if v.dtype == np.float32}
    assert all(sum(d > 1 for d in v.shape) <= 1 for v in floats.values()), {k: v.shape for k, v in floats.items()}
    assert sum(v.nbytes for v in int8.values()) <= 0.45 * sum(v.nbytes for v in fp32.values())


def test_gru_structure():
    t = make_tiny(steps=1)
    fp32, int8 = op_counts(t.gru_fp32.model), op_counts(t.gru_int8.model)
    assert fp32["GRU"] == 1
    (node,) = [n for n in t.gru_fp32.model.graph.node if n.op_type == "GRU"]
    assert {a.name: a.i for a in node.attribute}["linear_before_reset"] == 1
    # int8: unrolled over W steps; the input projection of all steps is one integer product.
    assert int8["GRU"] == 0 and int8["MatMul"] == 0
    assert int8["MatMulInteger"] == W + 2  # x projection, one per step, head
    assert int8["Sigmoid"] == 2 * W and int8["Tanh"] == W
    weights_q = {k for k, v in inits(t.gru_int8.model).items() if v.dtype == np.int8 and v.ndim == 2}
    assert weights_q == {"gru.ih.weight_q", "gru.hh.weight_q", "head.weight_q"}


def test_cnode_graph_is_the_rk4_program(tiny):
    """The unrolled graph is core.rk4.rk4_step evaluated on graph values: its RK4 constants are
    rk4_constants(1/N) under RK4_CONSTANT_NAMES, multiplied in RK4_PROGRAM's order every step."""
    from core.rk4 import RK4_CONSTANT_NAMES, rk4_constants

    names = {f"rk4.{n}": n for n in RK4_CONSTANT_NAMES}
    for built in (tiny.cnode_fp32, tiny.cnode_int8):
        init = inits(built.model)
        consts = [init[f"rk4.{n}"] for n in RK4_CONSTANT_NAMES]
        assert all(c.dtype == np.float32 and c.shape == () for c in consts)
        assert np.array_equal(np.array(consts), rk4_constants(1.0 / tiny.steps))
        muls = [names[n.input[1]] for n in built.model.graph.node if n.op_type == "Mul" and n.input[1] in names]
        assert muls == ["half_h", "half_h", "h", "two", "two", "h_over_6"] * tiny.steps


def test_weights_bin_rk4_constants_are_the_graphs(tiny, tmp_path):
    from core.rk4 import RK4_CONSTANT_NAMES
    from export.weights_bin import read_weights, write_weights

    write_weights(tmp_path / "w.bin", tiny.cp, tiny.cq, tiny.gp, tiny.gq)
    w = read_weights(tmp_path / "w.bin")
    for prec, built in (("fp32", tiny.cnode_fp32), ("int8", tiny.cnode_int8)):
        init = inits(built.model)
        assert np.array_equal(w.section("cnode", prec)["rk4.consts"], [init[f"rk4.{n}"] for n in RK4_CONSTANT_NAMES])


# ----------------------------------------------------------------------------- numbers


@pytest.mark.parametrize("steps", [1, 4, 8])
def test_cnode_fp32_matches_pytorch_classic_rk4(steps):
    t = make_tiny(steps=steps)
    ref = torch_logits(t.cnode, t.x)
    v = parity(run(t.cnode_fp32, t.x), ref)
    assert v["passed"], v
    # The check is sharp enough to tell classic RK4 from another scheme: the same weights
    # integrated by midpoint with the same number of evaluations give other logits.
    t.cnode.solver = SolverSpec("midpoint", 2 * steps)
    assert not parity(run(t.cnode_fp32, t.x), torch_logits(t.cnode, t.x))["passed"]


def test_gru_fp32_matches_pytorch(tiny):
    v = parity(run(tiny.gru_fp32, tiny.x), torch_logits(tiny.gru, tiny.x))
    assert v["passed"], v


def test_gru_with_linear_before_reset_0_fails_the_parity_check(tiny):
    wrong = build_gru_fp32(tiny.gp, OPSET, linear_before_reset=0)
    v = parity(run(wrong, tiny.x), torch_logits(tiny.gru, tiny.x))
    assert not v["passed"] and v["max_abs_logit_diff"] > 100 * v["bound"], v


def test_int8_close_to_fp32(tiny):
    """Stated tolerance, with s = max(1, max |logit|): median |int8 - fp32| <= 0.02 s and max <= 0.15 s
    on these random, deliberately large-weighted models (measured: median <= 0.01 s, max <= 0.1 s).
    A trained model's figures are in the manifest (argmax agreement and macro-F1 change)."""
    for f, q in ((tiny.cnode_fp32, tiny.cnode_int8), (tiny.gru_fp32, tiny.gru_int8)):
        lf, lq = run(f, tiny.x), run(q, tiny.x)
        s = max(1.0, float(np.abs(lf).max()))
        assert np.median(np.abs(lq - lf)) <= 0.02 * s and np.abs(lq - lf).max() <= 0.15 * s
        assert not np.array_equal(lq, lf)  # it really is another computation
        rep = int8_vs_fp32(lq, lf, lf.argmax(1))
        assert rep["argmax_agreement"] >= 0.9, rep


def test_int8_window_does_not_depend_on_its_batch(tiny):
    outlier = tiny.x[:1] * 1000.0  # saturates every static scale
    for built in (tiny.cnode_int8, tiny.gru_int8):
        sess = session(built.model.SerializeToString())
        alone = ort_outputs(sess, tiny.x[:2])[0]
        mixed = ort_outputs(sess, np.concatenate([tiny.x[:1], outlier, tiny.x[1:2]]))[0]
        assert np.array_equal(alone[0], mixed[0]) and np.array_equal(alone[1], mixed[2])


def test_interp_matrix_is_exact_in_int8(tiny):
    """Classic RK4 with N steps samples the path at multiples of 1/(2N) of the 79 sample
    intervals: every weight is k/(2N), so int8 with scale 1/(2N) holds P without rounding."""
    assert tiny.cq.interp_exact
    expect = np.rint(tiny.cp.interp.astype(np.float64) * 2 * tiny.steps)
    assert np.array_equal(tiny.cq.interp_q.astype(np.int64), expect)
    assert np.allclose(tiny.cq.interp_scale, 1 / (2 * tiny.steps))
