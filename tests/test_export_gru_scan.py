"""The int8 GRU in one Scan (export/onnx_gru.py) against the unrolled graph it replaced
(export/onnx_gru_unrolled.py): bit-identical outputs, every step's hidden state, MACs and coverage.

The C++ int8 reference is checked against ONNX Runtime int8 bit for bit (tests/test_parity.py, and
``quadfdi parity`` on a run); since the two graphs agree bit for bit here, that check carries over.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_export_graphs import OPSET, W, make_tiny
from test_motor_head import _tiny_with_heads

from quadfdi.export.coverage import coverage
from quadfdi.export.onnx_gru_unrolled import build_gru_int8_unrolled
from quadfdi.export.reference_bin import gru_int8_tensors
from quadfdi.runtimes.ort import session


@pytest.fixture(scope="module")
def tiny():
    return make_tiny(steps=1)


def _outputs(model, x: np.ndarray) -> list[np.ndarray]:
    return session(model.SerializeToString()).run(None, {"telemetry": x})


def _windows(t) -> np.ndarray:
    """The test windows, one that saturates every static scale, and one with x_norm exactly 0."""
    return np.concatenate([t.x, t.x[:1] * 1000.0, np.broadcast_to(t.gp.mean, (1, W, t.gp.mean.size))]).astype(np.float32)


def test_scan_outputs_equal_the_unrolled_graph_bit_for_bit(tiny):
    x = _windows(tiny)
    unrolled = build_gru_int8_unrolled(tiny.gp, tiny.gq, OPSET)
    scan, ref = _outputs(tiny.gru_int8.model, x), _outputs(unrolled.model, x)
    assert [a.shape for a in scan] == [b.shape for b in ref] == [(len(x), 4)] * 2
    for a, b in zip(scan, ref):
        assert a.tobytes() == b.tobytes()  # bit for bit (also tells -0.0 from 0.0)
    for b in (1, 3):  # a window's result does not depend on the batch it is in
        assert _outputs(tiny.gru_int8.model, x[:b])[0].tobytes() == ref[0][:b].tobytes()


def test_every_steps_hidden_state_equals_the_unrolled_graph(tiny):
    """reference.bin's h (B, W, H) from the Scan graph's probe equals the unrolled graph's h0..h79."""
    x = _windows(tiny)
    got = gru_int8_tensors(tiny.gru_int8, tiny.gp, x)
    unrolled = build_gru_int8_unrolled(tiny.gp, tiny.gq, OPSET)
    keys = [f"h{t}" for t in range(W)]
    sess = session(unrolled.with_probes(keys).SerializeToString())
    hs = sess.run([unrolled.probes[k][0] for k in keys], {"telemetry": x})
    expect = np.stack([h.reshape(len(x), -1) for h in hs], axis=1)
    assert got["h"].shape == (len(x), W, tiny.gp.hidden) and got["h"].tobytes() == expect.tobytes()
    # |h| <= 1 up to float32 rounding of (h - n) * z + n (measured 1.0000001 on the saturating window)
    assert np.abs(got["h"]).max() <= np.float32(1) + 4 * np.finfo(np.float32).eps
    assert not np.array_equal(got["h"][:, 0], got["h"][:, -1])


def test_shipped_graph_has_no_per_step_output_and_probing_leaves_logits_alone(tiny):
    """The per-step hidden state (an Identity in the body, 5 % of the batch-1 time) exists only in
    the probed copy, a second Scan; the shipped Scan carries the state and outputs nothing per step."""
    (scan,) = [n for n in tiny.gru_int8.model.graph.node if n.op_type == "Scan"]
    body = next(a.g for a in scan.attribute if a.name == "body")
    assert len(scan.output) == 1 and len(body.output) == 1 and len(body.node) == 12
    # the body reads only its inputs, its own tensors and its own constants (1.23x faster at batch 1
    # than reading the outer graph's initializers), W_hh among them and stored once in the model
    own = {i.name for i in body.input} | {o for n in body.node for o in n.output} | {t.name for t in body.initializer}
    assert all(i in own for n in body.node for i in n.input if i)
    assert "step/gru.hh.weight_q" in own and "gru.hh.weight_q" not in {t.name for t in tiny.gru_int8.model.graph.initializer}
    probed = tiny.gru_int8.with_probes(["h_all"])
    assert sum(n.op_type == "Scan" for n in probed.graph.node) == 2
    assert _outputs(probed, tiny.x)[0].tobytes() == _outputs(tiny.gru_int8.model, tiny.x)[0].tobytes()


def test_coverage_counts_the_body_once_per_step(tiny):
    """MACs per window are the unrolled graph's (the body's product runs W times), all int8."""
    scan, unrolled = coverage(tiny.gru_int8.model), coverage(build_gru_int8_unrolled(tiny.gp, tiny.gq, OPSET).model)
    for k in ("macs_per_window", "int8_macs_per_window", "int8_mac_share"):
        assert scan[k] == unrolled[k], k
    count = {(r["op"], r["precision"]): r["count"] for r in scan["ops"]}
    assert count[("MatMulIntegerToFloat", "int8")] == W + 3 and count[("Sigmoid", "fp32")] == W
    assert scan["nodes"] < 20 < 900 < unrolled["nodes"]


def test_motor_head_equals_the_unrolled_graph():
    _, _, x, graphs, (_, _, gp, gq) = _tiny_with_heads()
    scan, ref = _outputs(graphs["gru_int8"].model, x), _outputs(build_gru_int8_unrolled(gp, gq, OPSET).model, x)
    assert len(scan) == 3  # logits, proba, motor_logits
    assert all(a.tobytes() == b.tobytes() for a, b in zip(scan, ref))


def test_bench_profile_counts_the_body_per_step_and_not_the_scan(tiny, tmp_path):
    """bench's ONNX Runtime profile summary: the body's nodes once per step; the Scan's own event
    (which spans its body) left out, so the kernel shares still sum to one."""
    from quadfdi.bench.timing.ort import summarise_ort_profile
    from quadfdi.runtimes.ort import session as ort_session

    s = ort_session(tiny.gru_int8.model.SerializeToString(), profile_prefix=str(tmp_path / "prof"))
    for _ in range(2):
        s.run(None, {"telemetry": tiny.x[:1]})
    summary = summarise_ort_profile(s.end_profiling())
    ops = {r["op"]: r for r in summary["by_op"]}
    assert "Scan" not in ops and ops["Sigmoid"]["nodes_per_call"] == W and ops["Tanh"]["nodes_per_call"] == W
    assert ops["MatMulIntegerToFloat"]["nodes_per_call"] == W + 3
    assert abs(sum(r["kernel_share"] for r in summary["by_op"]) - 1.0) < 1e-9
