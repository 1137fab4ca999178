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

from quadfdi.export.calibrate import WindowReader, collect_ranges
from quadfdi.export.coverage import tensor_shapes
from quadfdi.export.graph import Built, all_initializers, all_nodes
from quadfdi.export.onnx_cnode import build_cnode, calibration_probes, cnode_params, quantize_cnode
from quadfdi.export.onnx_gru import CALIBRATION_PROBES, build_gru_fp32, build_gru_int8, gru_params, quantize_gru
from quadfdi.export.verify import int8_vs_fp32, parity
from quadfdi.runtimes.ort import outputs, session
from quadfdi.runtimes.pytorch import torch_logits

from quadfdi.models.networks import CNODE, GRUClassifier, SolverSpec


def ort_outputs(sess, x):
    """(logits, proba) of windows ``x``."""
    return outputs(sess, x, ["logits", "proba"])


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
    # fp32: P@x and lin1_u (all stage times at once) MatMul; encoder, head + 2 per stage Gemm.
    assert fp32["MatMul"] == 2 and fp32["Gemm"] == 8 * steps + 2
    assert fp32["Tanh"] == int8["Tanh"] == 4 * steps + 1  # z0 + one per stage
    assert fp32["Split"] == int8["Split"] == 1  # V's 2N+1 rows, once
    assert fp32["Sum"] == int8["Sum"] == steps  # ((k1 + 2 k2) + 2 k3) + k4, one node per step
    # Muls per step: 3 stage inputs + h/6, 2 k2 and 2 k3 coming from lin2; when N is a power of two
    # lin2 also folds half_h and h, leaving k2 * half_h and the h/6 (export.onnx_cnode.field_scales).
    assert fp32["Mul"] == int8["Mul"] == (2 if steps in (1, 2, 4, 8) else 4) * steps
    # int8: every product one MatMulIntegerToFloat (P@x too: P is exact); no float product left.
    assert int8["MatMulIntegerToFloat"] == 8 * steps + 4
    assert int8["MatMulInteger"] == int8["MatMul"] == int8["Gemm"] == int8["Cast"] == 0
    assert int8["Add"] == 8 * steps  # 3 stage inputs, the new state, and the row of V per stage
    # QuantizeLinear: x_norm, U, z1 + 2 per stage (its state, its tanh output); x_norm and U per
    # channel as Div then QuantizeLinear with scale 1 (ORT's per-axis kernel goes element by element).
    assert int8["QuantizeLinear"] == 8 * steps + 3 and int8["Div"] == 3
    for model in (t.cnode_fp32.model, t.cnode_int8.model):  # no control flow, no data-dependent indexing
        counts = op_counts(model)
        assert not {"Loop", "If", "Scan", "GatherElements", "GatherND"} & set(counts)
        gathers = [n for n in model.graph.node if n.op_type == "Gather"]  # row 0 of U (+ int8: the samples P reads)
        assert len(gathers) == (1 if model is t.cnode_fp32.model else 2)
        assert all(n.input[1] in inits(model) for n in gathers)  # constant indices


@pytest.mark.parametrize("steps", [1, 3, 8])
def test_ort_optimized_node_counts(steps):
    """Nodes after ONNX Runtime's optimizer (what it dispatches per call, ~0.4 us each): fp32 fuses
    each stage's Gemm + Tanh (FusedGemm), 2 nodes per evaluation + 9 per RK4 step; int8 has 6 per
    evaluation (QuantizeLinear, MatMulIntegerToFloat, Add row of V, Tanh, QuantizeLinear,
    MatMulIntegerToFloat) + the same 9 (7 when N is a power of two); the int8 GRU one Scan whose body
    (12 nodes, run once per step) is not in the graph's own count."""
    from quadfdi.runtimes.ort import optimized_nodes

    t = make_tiny(steps=steps)
    full = {k: optimized_nodes(getattr(t, k).model.SerializeToString())
            for k in ("cnode_fp32", "cnode_int8", "gru_fp32", "gru_int8")}
    count = {k: v["total"] for k, v in full.items()}
    pow2 = steps in (1, 2, 4, 8)  # 2 nodes fewer per step (field_scales)
    assert count["cnode_fp32"] == 11 + (15 if pow2 else 17) * steps  # N = 8: 131 (was 278)
    assert count["cnode_int8"] == 17 + (31 if pow2 else 33) * steps  # N = 8: 265 (with the Gather of the samples P reads)
    # int8 GRU: the 80 steps in one Scan (ONNX Runtime pays per node; unrolled: 972 nodes, 12 per step x 80 + 12):
    # 14 nodes, the 12-node step once in its body.
    assert count["gru_int8"] == 14 and full["gru_int8"]["Scan"] == 1 and full["gru_int8"]["body"] == 12
    assert all(full[k]["body"] == 0 for k in ("cnode_fp32", "cnode_int8", "gru_fp32"))
    assert count["gru_fp32"] <= 8


def test_cnode_weights_stored_once(tiny):
    fp32, int8 = inits(tiny.cnode_fp32.model), inits(tiny.cnode_int8.model)
    names = ("encoder", "lin1_u", "lin1_z", "lin2", "head")

    def constants_of(model, *ops):
        return [n.input[1] for n in model.graph.node if n.op_type in ops and n.input[1] in inits(model)]

    # 8N + 4 products read 6 matrices: the interpolation matrix and five weights, each stored once.
    used = constants_of(tiny.cnode_fp32.model, "MatMul", "Gemm") + ["interp"]
    assert len(used) == 8 * tiny.steps + 4
    assert set(used) == {"interp", "lin1_u.weight_t"} | {f"{w}.weight" for w in names if w != "lin1_u"}
    used = [n.input[0] if n.input[0] == "interp.q" else n.input[1] for n in tiny.cnode_int8.model.graph.node
            if n.op_type == "MatMulIntegerToFloat"]
    assert len(used) == 8 * tiny.steps + 4 and set(used) == {"interp.q"} | {f"{w}.weight_q" for w in names}
    weights_q = {k: v for k, v in int8.items() if k.endswith(".weight_q")}
    assert len(weights_q) == 5 and all(v.dtype == np.int8 for v in weights_q.values())
    # P_q is A of a u8 x s8 product (ONNX Runtime's fast kernel): uint8, the same codes as weights.bin's int8.
    read = int8["window.samples_read"]  # the int8 graph keeps P's columns of the samples it reads, no other
    assert int8["interp.q"].dtype == np.uint8 and np.array_equal(int8["interp.q"], tiny.cq.interp_q[:, read])
    assert tiny.cq.interp_q[:, read].any(axis=0).all() and not np.delete(tiny.cq.interp_q, read, axis=1).any()
    assert len(read) <= 4 * tiny.steps  # 2 samples around each of the 2N - 1 inner stage times, + both ends
    # No float weight matrix left in the int8 graph: every float constant is a vector (or (S, 1)).
    floats = {k: v for k, v in int8.items() if v.dtype == np.float32}
    assert all(sum(d > 1 for d in v.shape) <= 1 for v in floats.values()), {k: v.shape for k, v in floats.items()}
    assert sum(v.nbytes for v in int8.values()) <= 0.45 * sum(v.nbytes for v in fp32.values())


def test_every_integer_product_is_u8_by_s8(tiny):
    """Both int8 graphs take ONNX Runtime's fast u8 x s8 kernel for every integer product (its s8 x s8
    kernel took the CNODE's P @ x_norm from 16 % to 6 % of the batch-96 kernel time; docs/bench.md)."""
    from quadfdi.export.onnx_cnode import interp_code_type

    for built in (tiny.cnode_int8, tiny.gru_int8):
        elem = {k: v[0] for k, v in tensor_shapes(built.model).items()}  # the Scan body's tensors too
        pairs = Counter((elem[n.input[0]], elem[n.input[1]]) for n in all_nodes(built.model.graph)
                        if n.op_type in ("MatMulIntegerToFloat", "MatMulInteger"))
        assert set(pairs) == {(TensorProto.UINT8, TensorProto.INT8)}, pairs
    assert sum(n.op_type == "MatMulIntegerToFloat" for n in all_nodes(tiny.gru_int8.model.graph)) == 4  # body: 1
    assert interp_code_type(np.array([[0, 3], [-1, 2]], np.int8)) is np.int8  # a negative code stays int8


def test_int8_cnode_normalises_only_the_samples_p_reads_and_probes_all(tiny):
    """The int8 graph runs Sub and Div on the Gather of the samples P reads; the x_norm probe (for
    reference.bin) adds the whole (B, W, C) normalisation only to the probed copy, bit for bit."""
    main = tiny.cnode_int8.model
    (sub,) = [n for n in main.graph.node if n.op_type == "Sub"]
    assert sub.input[0] != "telemetry" and "x_norm" not in {o for n in main.graph.node for o in n.output}
    sess = session(tiny.cnode_int8.with_probes(["x_norm"]).SerializeToString())
    logits, xn = sess.run(["logits", tiny.cnode_int8.probes["x_norm"][0]], {"telemetry": tiny.x})
    expect = (tiny.x - tiny.cp.mean) / tiny.cp.std  # float32 numpy: the same two operations
    assert xn.shape == tiny.x.shape and np.array_equal(xn, expect)
    assert np.array_equal(logits, ort_outputs(session(main.SerializeToString()), tiny.x)[0])


def test_gru_structure():
    t = make_tiny(steps=1)
    fp32, int8 = op_counts(t.gru_fp32.model), op_counts(t.gru_int8.model)
    assert fp32["GRU"] == 1
    (node,) = [n for n in t.gru_fp32.model.graph.node if n.op_type == "GRU"]
    assert {a.name: a.i for a in node.attribute}["linear_before_reset"] == 1
    # int8: one Scan over the W steps, its body one step; the input projection of all steps is one
    # integer product (two: rows r,z and rows n), outside the Scan.
    assert int8["GRU"] == 0 and int8["MatMul"] == 0 and int8["MatMulInteger"] == 0 and int8["Scan"] == 1
    assert int8["MatMulIntegerToFloat"] == 3  # x projection (rows r,z and rows n), head
    (scan,) = [n for n in t.gru_int8.model.graph.node if n.op_type == "Scan"]
    body = Counter(n.op_type for n in next(a.g for a in scan.attribute if a.name == "body").node)
    assert body == {"QuantizeLinear": 1, "MatMulIntegerToFloat": 1, "Split": 2, "Add": 3, "Sigmoid": 1, "Mul": 2,
                    "Tanh": 1, "Sub": 1}  # r and z in one Sigmoid per step
    every = {i.name: numpy_helper.to_array(i) for i in all_initializers(t.gru_int8.model.graph)}  # + the body's
    weights_q = {k: v for k, v in every.items() if v.dtype == np.int8 and v.ndim == 2}
    assert set(weights_q) == {"gru.ih_rz.weight_q", "gru.ih_n.weight_q", "step/gru.hh.weight_q", "head.weight_q"}
    assert np.array_equal(np.concatenate([weights_q["gru.ih_rz.weight_q"], weights_q["gru.ih_n.weight_q"]], 1).T,
                          t.gq.w_ih.q)  # W_ih stored once, split by rows
    # uint8 activations (zero point 128) beside 7-bit weights: u8 x s8 sums exact on every CPU.
    assert all(np.abs(v.astype(int)).max() <= 63 for v in weights_q.values())
    quant = [n for n in all_nodes(t.gru_int8.model.graph) if n.op_type == "QuantizeLinear"]
    zps = every
    assert all(len(zps[n.input[1]].shape) == 0 for n in quant)  # per-tensor: no per-axis QuantizeLinear
    assert all(zps[n.input[2]].dtype == np.uint8 and np.all(zps[n.input[2]] == 128) for n in quant)


def test_cnode_graph_is_the_rk4_program(tiny):
    """The unrolled graph is core.rk4.rk4_step evaluated on graph values: its RK4 constants are
    rk4_constants(1/N) under RK4_CONSTANT_NAMES, multiplied in RK4_PROGRAM's order every step.
    k2 and k3 are held doubled (lin2's scales and bias times 2, exact), so ``two * k`` needs no
    node and ``half_h * k2`` multiplies 2 k2 by half_h / 2 (exact)."""
    from quadfdi.core.rk4 import RK4_CONSTANT_NAMES, rk4_constants

    names = {f"rk4.{n}": n for n in RK4_CONSTANT_NAMES} | {"rk4.half_h/2": "half_h/2"}
    for built in (tiny.cnode_fp32, tiny.cnode_int8):
        init = inits(built.model)
        consts = [init[f"rk4.{n}"] for n in RK4_CONSTANT_NAMES]
        assert all(c.dtype == np.float32 and c.shape == () for c in consts)
        assert np.array_equal(np.array(consts), rk4_constants(1.0 / tiny.steps))
        assert init["rk4.half_h/2"] == init["rk4.half_h"] / np.float32(2)
        muls = [names[n.input[1]] for n in built.model.graph.node if n.op_type == "Mul" and n.input[1] in names]
        assert muls == ["half_h", "half_h/2", "half_h", "h_over_6"] * tiny.steps
    init = inits(tiny.cnode_int8.model)
    assert np.array_equal(init["lin2.weight_scale_x2"], init["lin2.weight_scale"] * 2)
    assert np.array_equal(init["lin2.bias_x2"], init["lin2.bias"] * 2)


def test_weights_bin_rk4_constants_are_the_graphs(tiny, tmp_path):
    from quadfdi.core.rk4 import RK4_CONSTANT_NAMES
    from quadfdi.formats.weights_bin import read_weights, write_weights

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


@pytest.mark.parametrize("steps", [3, 4])
def test_rk4_graph_representation_is_bit_exact(steps):
    """The RK4 combination as the graph writes it (Sum nodes, field outputs held at a power of two)
    gives the same float32 bits as RK4_PROGRAM written out in numpy, on the int8 graph's own stage
    states: each probed stage state e+1 is recomputed from states and field outputs of the graph."""
    from quadfdi.core.rk4 import rk4_constants

    t = make_tiny(steps=steps)
    sess = session(t.cnode_int8.with_probes([f"stage{e}" for e in range(4 * steps)] + ["z1"]).SerializeToString())
    names = [t.cnode_int8.probes[f"stage{e}"][0] for e in range(4 * steps)] + [t.cnode_int8.probes["z1"][0]]
    st = sess.run(names, {"telemetry": t.x})
    half, h, two, h6 = (np.float32(v) for v in rk4_constants(1.0 / steps))
    # The field outputs (lin2 of every evaluation) as the graph holds them, from a copy of the model
    # that outputs them too; the program is then run on them in numpy.
    lin2 = [n.output[0] for n in t.cnode_int8.model.graph.node
            if n.op_type == "MatMulIntegerToFloat" and n.input[1] == "lin2.weight_q"]
    assert len(lin2) == 4 * steps
    m = onnx.ModelProto()
    m.CopyFrom(t.cnode_int8.model)
    for n in lin2:
        m.graph.output.append(onnx.helper.make_tensor_value_info(n, TensorProto.FLOAT, None))
    ks = session(m.SerializeToString()).run(lin2, {"telemetry": t.x})
    from quadfdi.export.onnx_cnode import field_scales

    sig = [np.float32(c) for c in field_scales(1.0 / steps)]  # lin2 holds sig[i] * k
    z = st[0]
    for k in range(steps):
        k1, k2, k3, k4 = (ks[4 * k + i] / sig[i] for i in range(4))  # exact: powers of two
        assert np.array_equal(z, st[4 * k])
        assert np.array_equal(z + k1 * half, st[4 * k + 1])
        assert np.array_equal(z + k2 * half, st[4 * k + 2])
        assert np.array_equal(z + k3 * h, st[4 * k + 3])
        z = z + (((k1 + k2 * two) + k3 * two) + k4) * h6
    assert np.array_equal(z, st[-1])
