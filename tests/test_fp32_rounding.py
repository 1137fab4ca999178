"""fp32 parity where float32 rounding is amplified: the export's self-check (export.verify.judged_parity),
the streaming exports' on a replayed flight, and parity's C++ against ONNX Runtime target
(parity.run.judge_fp32), all by runtimes.pytorch.rounding_judgement.

Random GRUs whose recurrent weights are scaled to the edge of chaos: on a few windows the 80-step
recurrence amplifies float32 rounding until ONNX Runtime and PyTorch, both correct, part by more than
the fp32 bound. Those windows are judged against the spread that float32 rounding gives the float64
result; a graph with the wrong GRU variant (linear_before_reset=0) stays far outside it.
"""

from __future__ import annotations

import numpy as np
import torch

from quadfdi.export import scnode_run, sgru_run
from quadfdi.export.onnx_gru import build_gru_fp32, gru_params
from quadfdi.export.onnx_sgru import build_sgru_fp32, sgru_params
from quadfdi.core.contracts import ROUNDING_FACTOR
from quadfdi.export.verify import judged_parity, parity
from quadfdi.models.motor import attach_motor_head
from quadfdi.models.networks import CNODE, GRUClassifier, SolverSpec
from quadfdi.models.stream_cnode import StreamCNODE
from quadfdi.models.stream_gru import StreamGRU
from quadfdi.parity import compare
from quadfdi.parity.run import judge_fp32
from quadfdi.core.reportmd import over_bound_clause
from quadfdi.runtimes.pytorch import rounding_spread, torch_logits, torch_motor_logits
from tests.test_export_graphs import OPSET, C, W, run, synthetic_windows

# (seed, hidden, recurrent weight scale): each puts some of 256 windows over the fp32 bound
EDGE = [(seed, hidden, scale) for seed in (0, 1) for hidden, scale in ((6, 7.5), (6, 8.5), (16, 7.5), (16, 8))]


def edge_gru(seed: int, hidden: int, scale: float) -> tuple[GRUClassifier, np.ndarray]:
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    gru = GRUClassifier(C, hidden=hidden, window=W)
    gru.set_normalisation(mean, std)
    with torch.no_grad():
        for name, p in gru.named_parameters():
            p.mul_(scale if "weight_hh" in name else (3.0 if "weight" in name else 1.0))
    gru.eval()
    return gru, synthetic_windows(256, seed + 2, mean, std)


def test_float32_rounding_tells_a_correct_graph_from_a_wrong_one():
    """Over the windows past the bound, ONNX Runtime's distance from the float64 result in units of the
    rounding spread: every correct graph's within ROUNDING_FACTOR, every wrong graph's beyond it."""
    ratios: dict[int, list[float]] = {1: [], 0: []}
    for seed, hidden, scale in EDGE:
        gru, x = edge_gru(seed, hidden, scale)
        ref = torch_logits(gru, x)
        for lbr in ratios:
            ort = run(build_gru_fp32(gru_params(gru), OPSET, linear_before_reset=lbr), x)
            over = np.flatnonzero(np.abs(ort - ref).max(1) > parity(ort, ref)["bound"])[:16]
            if len(over):
                exact, spread = rounding_spread(gru, x[over])
                ratios[lbr] += list(np.abs(ort[over] - exact).max(1) / spread)
    assert len(ratios[1]) >= 10, "the fixtures no longer reach the edge of chaos"
    assert len(ratios[0]) == 16 * len(EDGE)
    assert max(ratios[1]) <= ROUNDING_FACTOR < min(ratios[0]), (max(ratios[1]), min(ratios[0]))


def test_one_ill_conditioned_window_passes_within_rounding_and_fails_beyond_it():
    """ONNX Runtime's logits stood in by the float64 result moved on one window: by half its rounding
    spread away from PyTorch (over the bound, within rounding: passes; plain parity does not), then by
    ten spreads (fails, saying by how much)."""
    gru, x = edge_gru(0, 16, 8.0)
    ref = torch_logits(gru, x)
    exact, spread = rounding_spread(gru, x)
    bound = parity(ref, ref)["bound"]
    i = int(np.argmax(spread))
    assert spread[i] > 4 * bound  # an ill-conditioned window
    away = np.sign(exact[i] - ref[i]) + (exact[i] == ref[i])
    for moved, passes in ((0.5, True), (10.0, False)):
        logits = ref.copy()
        logits[i] = (exact[i] + moved * spread[i] * away).astype(np.float32)
        v = judged_parity(logits, ref, gru, x)
        assert not parity(logits, ref)["passed"]
        assert v["windows_over_bound"] == 1 and v["passed"] is passes, v
        assert (v["over_bound_rounding_ratio"] <= ROUNDING_FACTOR) is passes


def test_parity_judges_the_cpp_target_the_same_way():
    """C++ fp32 against ONNX Runtime fp32 (stood in by PyTorch's float32), the C++ logits moved on one
    ill-conditioned window as above: the target (1e-4 and argmax 100 %) missed, then judged."""
    gru, x = edge_gru(0, 16, 8.0)
    ort = torch_logits(gru, x)
    exact, spread = rounding_spread(gru, x)
    i = int(np.argmax(spread))
    away = np.sign(exact[i] - ort[i]) + (exact[i] == ort[i])
    for moved, passes in ((0.5, True), (10.0, False)):
        cpp = ort.copy()
        cpp[i] = (exact[i] + moved * spread[i] * away).astype(np.float32)
        pair = compare.pair_metrics(cpp, ort)
        pair["target"] = compare.fp32_target(pair)
        assert not pair["target"]["passed"]
        judge_fp32(pair, {"cpp_fp32": cpp, "ort_fp32": ort}, gru, x)
        t = pair["target"]
        assert t["windows_over_bound"] == 1 and t["passed"] is passes, t
        if not passes:
            assert t["over_bound_rounding_ratio"] > ROUNDING_FACTOR
            assert over_bound_clause(t) == (f"; on 1 window, {t['over_bound_rounding_ratio']:.3g} x its float32 "
                                            f"rounding spread (at most {ROUNDING_FACTOR:g})")


def test_a_graph_wrong_on_every_window_fails_before_any_rounding_is_weighed():
    gru, x = edge_gru(0, 6, 7.5)
    v = judged_parity(run(build_gru_fp32(gru_params(gru), OPSET, linear_before_reset=0), x), torch_logits(gru, x),
                      gru, x)
    assert not v["passed"] and v["windows_over_bound"] > v["over_bound_allowed"] == 1
    assert "over_bound_rounding_ratio" not in v


def test_the_rounding_spread_of_a_cnode_motor_head():
    """The motor head's float64 result agrees with PyTorch's float32 within the fp32 bound on a
    well-conditioned model, and rounding moves it by about a float32 ulp of its size."""
    torch.manual_seed(3)
    rng = np.random.default_rng(3)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    cnode = attach_motor_head(CNODE(C, window=W, latent=6, hidden=8, solver=SolverSpec("rk4", 2)))
    cnode.set_normalisation(mean, std)
    cnode.eval()
    x = synthetic_windows(16, 5, mean, std)
    ref = torch_motor_logits(cnode, x)
    exact, spread = rounding_spread(cnode, x, head="motor")
    assert parity(exact.astype(np.float32), ref)["passed"]
    scale = np.abs(exact).max(1)
    assert np.all(spread > 0) and np.all(spread < 1e-5 * np.maximum(1, scale))


# ------------------------------------------------------------------- a streaming network's replayed flight

STREAM_STEPS = 1500


def edge_stream(seed: int, hidden: int, scale: float, steps: int = STREAM_STEPS) -> tuple[StreamGRU, np.ndarray]:
    """A random streaming GRU, its recurrent weights scaled like ``edge_gru``'s, and one random-walk flight
    (steps, C) for it."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    model = StreamGRU(C, hidden=hidden)
    model.set_normalisation(mean, std)
    with torch.no_grad():
        for name, p in model.named_parameters():
            p.mul_(scale if "weight_hh" in name else (3.0 if "weight" in name else 1.0))
    model.eval()
    walk = np.cumsum(rng.normal(0, 0.1, (steps, C)), axis=0)
    walk = walk - walk.mean(0) + rng.normal(0, 1, C)
    return model, (mean + std * walk).astype(np.float32)


def set_gru_variant(graph, linear_before_reset: int) -> None:
    """Set the GRU nodes' ``linear_before_reset`` of the ONNX model ``graph`` in place."""
    for node in graph.graph.node:
        for a in node.attribute:
            if node.op_type == "GRU" and a.name == "linear_before_reset":
                a.i = linear_before_reset


def stream_graph(model: StreamGRU, linear_before_reset: int = 1) -> bytes:
    """The export's one-step graph of ``model`` (export/onnx_sgru.py), its GRU variant set."""
    g = build_sgru_fp32(sgru_params(model), OPSET).model
    set_gru_variant(g, linear_before_reset)
    return g.SerializeToString()


def test_a_replayed_flight_past_the_bound_is_judged_step_by_step():
    """A correct one-step graph replayed with its state carried parts from PyTorch past the bound on a run of
    steps (plain parity fails; the judgement passes, each step within rounding); the wrong GRU variant puts
    every step past it and is refused by the share."""
    model, tel = edge_stream(1, 16, 7.5)
    ref, _ = sgru_run.torch_replay(model, tel)
    ort, _ = sgru_run.ort_replay(stream_graph(model), tel, model.hidden)
    v = judged_parity(ort, ref.astype(np.float64), model, tel[None], head="stream")
    assert not parity(ort, ref)["passed"] and v["passed"], v
    assert 10 < v["windows_over_bound"] <= v["over_bound_allowed"] == STREAM_STEPS // 2
    assert v["over_bound_rounding_ratio"] <= ROUNDING_FACTOR
    wrong, _ = sgru_run.ort_replay(stream_graph(model, 0), tel, model.hidden)
    w = judged_parity(wrong, ref.astype(np.float64), model, tel[None], head="stream")
    assert not w["passed"] and w["windows_over_bound"] == STREAM_STEPS and "over_bound_rounding_ratio" not in w
    assert over_bound_clause(w, "step") == f"; on {STREAM_STEPS} steps (at most {STREAM_STEPS // 2} may be, each " \
                                          "within float32 rounding)"


def test_one_step_beyond_rounding_fails_the_replay():
    """PyTorch's replay moved on its most ill-conditioned step by half its rounding spread (passes) and by ten
    (fails): the step is judged against the float64 replay of the whole flight."""
    model, tel = edge_stream(1, 16, 7.5)
    ref, _ = sgru_run.torch_replay(model, tel)
    exact, spread = rounding_spread(model, tel[None], head="stream")
    i = int(np.argmax(spread))
    assert spread[i] > 4 * parity(ref, ref)["bound"]  # an ill-conditioned step
    away = np.sign(exact[i] - ref[i]) + (exact[i] == ref[i])
    for moved, passes in ((0.5, True), (10.0, False)):
        logits = ref.copy()
        logits[i] = (exact[i] + moved * spread[i] * away).astype(np.float32)
        v = judged_parity(logits, ref.astype(np.float64), model, tel[None], head="stream")
        assert v["windows_over_bound"] == 1 and v["passed"] is passes, v


def test_the_rounding_spread_of_a_streaming_cnode_replay():
    """The streaming CNODE's float64 replay (head "stream", the export's judgement of scnode_step.onnx) agrees
    with PyTorch's float32 replay within the fp32 bound on a well-conditioned model, at every step."""
    torch.manual_seed(4)
    rng = np.random.default_rng(4)
    mean, std = rng.normal(0, 5, C).astype(np.float32), rng.uniform(0.5, 3, C).astype(np.float32)
    model = StreamCNODE(C, latent=6, hidden=8)
    model.set_normalisation(mean, std)
    model.eval()
    tel = (mean + std * np.cumsum(rng.normal(0, 0.1, (200, C)), axis=0)).astype(np.float32)
    ref, _ = scnode_run.torch_replay(model, tel)
    exact, spread = rounding_spread(model, tel[None], head="stream")
    assert exact.shape == ref.shape == (200, model.n_classes)
    assert parity(exact.astype(np.float32), ref)["passed"]
    assert np.all(spread > 0) and np.all(spread < 1e-5 * np.maximum(1, np.abs(exact).max(1)))
