"""weights.bin, reference.bin and manifest.json: round trips, bad files, and the int8 arithmetic.

``emulate_*_int8`` redo the int8 graphs in numpy from weights.bin ALONE, following
docs/formats.md ("int8 arithmetic") step by step: what the C++ reference implements. Matching
ONNX Runtime proves both that the file carries every number needed and that the documented
arithmetic is the one ONNX Runtime runs.
"""

from __future__ import annotations

import json
import struct
import zlib

import numpy as np
import pytest
import torch

from quadfdi.formats.binfmt import Section, pack
from quadfdi.formats.manifest import SCHEMA_VERSION, load_manifest
from quadfdi.export.reference_bin import reference_bytes
from quadfdi.formats.reference_bin import read_reference
from quadfdi.formats.weights_bin import MAGIC, read_weights, write_weights
from quadfdi.core.errors import QuadfdiError
from tests.test_export_graphs import make_tiny, run

F = np.float32


@pytest.fixture(scope="module")
def tiny():
    return make_tiny(steps=3)


@pytest.fixture(scope="module")
def weights_file(tiny, tmp_path_factory):
    path = tmp_path_factory.mktemp("w") / "weights.bin"
    write_weights(path, tiny.cp, tiny.cq, tiny.gp, tiny.gq)
    return path


# ----------------------------------------------------------------------------- weights.bin


def test_weights_round_trip(tiny, weights_file):
    w = read_weights(weights_file)
    assert [(s.model, s.precision) for s in w.sections] == [("cnode", "fp32"), ("cnode", "int8"),
                                                             ("gru", "fp32"), ("gru", "int8")]
    cf, ci = w.section("cnode", "fp32"), w.section("cnode", "int8")
    p, q = tiny.cp, tiny.cq
    assert cf.dims == (5, 80, 4, 8, 6, 3, 7, 0)
    assert np.array_equal(cf["lin1_z.weight"], p.lin1_wz) and cf["lin1_z.weight"].dtype == np.float32
    assert np.array_equal(cf["interp"], p.interp) and np.array_equal(cf["stage_index"], p.stage_index)
    t = ci.tensors["lin2.weight"]
    assert t.array.dtype == np.int8 and np.array_equal(t.array, q.lin2.q) and np.array_equal(t.scales, q.lin2.scale)
    assert t.axis == 0 and np.all(t.zero_points == 0)
    assert np.array_equal(ci.tensors["interp"].array, q.interp_q) and np.array_equal(ci["act.stage.scale"], q.s_z)
    gi = w.section("gru", "int8")
    assert np.array_equal(gi.tensors["gru.weight_hh"].array, tiny.gq.w_hh.q)
    assert np.array_equal(w.section("gru", "fp32")["gru.weight_ih"], tiny.gp.w_ih)
    # Dequantized int8 weights are within half a step of the float ones.
    deq = ci.tensors["lin2.weight"].dequant()
    assert np.all(np.abs(deq - p.lin2_w) <= 0.5 * q.lin2.scale[:, None] + 1e-7)


def _one_line_error(path, match):
    with pytest.raises(QuadfdiError, match=match) as info:
        read_weights(path)
    assert "\n" not in str(info.value)


def test_truncated_foreign_and_corrupted_weights(weights_file, tmp_path):
    data = weights_file.read_bytes()
    bad = tmp_path / "weights.bin"
    bad.write_bytes(data[: len(data) // 2])
    _one_line_error(bad, r"weights.bin is truncated \(or has trailing bytes\): its header says \d+ bytes")
    bad.write_bytes(data[:10])
    _one_line_error(bad, "weights.bin is truncated: 10 bytes")
    bad.write_bytes(b"PK\x03\x04" + data[4:])  # e.g. a zip
    _one_line_error(bad, "not a quadfdi weights file")
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0x40
    bad.write_bytes(bytes(flipped))
    _one_line_error(bad, "CRC-32")
    newer = bytearray(data)
    newer[8:12] = struct.pack("<I", 2)
    bad.write_bytes(bytes(newer))
    _one_line_error(bad, "format version 2, this reader reads version 1")
    _one_line_error(tmp_path / "missing.bin", "does not exist")


def test_reader_refuses_files_that_differ_from_the_layout(weights_file, tmp_path):
    """A well-formed container whose sections or tensors are not formats/weights_layout.py's."""
    from quadfdi.formats.weights_layout import SECTION_ORDER

    def variant(edit):
        w = read_weights(weights_file)
        edit(w.sections)
        path = tmp_path / "w.bin"
        path.write_bytes(pack(MAGIC, 1, w.sections))
        return path

    def reorder(secs):
        t = secs[0].tensors
        t["norm.std"] = t.pop("norm.mean")

    def reshape(secs):
        t = secs[2].tensors["gru.bias_ih"]
        secs[2].tensors["gru.bias_ih"] = type(t)("gru.bias_ih", t.array[:-1].copy())

    def int8_as_float(secs):
        t = secs[3].tensors["head.weight"]
        secs[3].tensors["head.weight"] = type(t)("head.weight", t.dequant())

    def extra(secs):
        secs[1].add("extra", np.zeros(2, np.float32))

    def stage_times(secs):
        secs[0].dims = secs[0].dims[:6] + (secs[0].dims[6] + 2, 0)

    cases = [(lambda secs: secs.reverse(), "holds sections"),
             (lambda secs: secs[1].tensors.pop("act.z1.scale"), "holds tensors"),
             (reorder, "holds tensors"), (reshape, r"expected float32 \(18,\) \('3H',\)"),
             (int8_as_float, "expected int8"), (extra, "holds tensors"), (stage_times, "expected 2N \\+ 1")]
    for edit, match in cases:
        _one_line_error(variant(edit), match)
    assert [(s.model, s.precision) for s in read_weights(weights_file).sections] == list(SECTION_ORDER)


def test_section_sizes_are_checked_even_with_a_valid_crc(tmp_path):
    """A writer bug (a tensor claiming more bytes than it has) is caught by the size checks."""
    s = Section("gru", "fp32", (1, 2, 3))
    s.add("a", np.arange(6, dtype=np.float32).reshape(2, 3))
    blob = bytearray(pack(MAGIC, 1, [s])[:-4])  # without the file CRC
    # data_bytes of tensor "a": file header (24) + section header (52) + its offset in the record (80)
    struct.pack_into("<I", blob, 24 + 52 + 80, 4000)
    struct.pack_into("<I", blob, len(blob) - 4, zlib.crc32(bytes(blob[24:-4])))  # fix both CRCs
    blob += struct.pack("<I", zlib.crc32(bytes(blob)))
    (tmp_path / "w.bin").write_bytes(bytes(blob))
    _one_line_error(tmp_path / "w.bin", "says 4000 data bytes")


# ----------------------------------------------------------------------------- int8 arithmetic


def q8(x, s):
    """QuantizeLinear, zero point 0: round(x / s) half to even in float32, saturated to int8."""
    return np.clip(np.rint(np.asarray(x, F) / np.asarray(s, F)), -128, 127).astype(np.int64)


def product(xq, t, s_a=None, bias=None):
    """(float(acc) * float32(s_a * s_w)) + b (MatMulIntegerToFloat's order), s_a = 1 for a folded
    activation scale (float32(1 * s_w) = s_w)."""
    acc = xq @ t.array.astype(np.int64).T  # int32 in the graph; |acc| < 2^24, exact in float32
    mult = (F(1) if s_a is None else F(s_a)) * t.scales  # float32 product, formed first
    y = acc.astype(F) * mult
    return y if bias is None else y + bias


def emulate_cnode_int8(sec, x):
    T = {k: v for k, v in sec.tensors.items()}
    a = {k: v.array for k, v in T.items()}
    xn = (x.astype(F) - a["norm.mean"]) / a["norm.std"]
    xq = q8(xn, a["act.x_norm.scale"])
    acc = np.einsum("sw,bwc->bsc", a["interp"].astype(np.int64), xq)
    u = acc.astype(F) * (T["interp"].scales[:, None] * a["act.x_norm.scale"])
    uq = q8(u, a["act.u.scale"])
    z = np.tanh(product(uq[:, 0], T["encoder.weight"], None, a["encoder.bias"]))
    v = product(uq, T["lin1_u.weight"], None, a["lin1.bias"])
    half, h, two, h6 = a["rk4.consts"]
    s_z, s_hid, idx = a["act.stage.scale"], a["act.hidden.scale"][0], a["stage_index"]
    evals = iter(range(len(idx)))

    def f(z):
        e = next(evals)
        pre = product(q8(z, s_z[e]), T["lin1_z.weight"], s_z[e], v[:, idx[e]])
        return product(q8(np.tanh(pre), s_hid), T["lin2.weight"], s_hid, a["lin2.bias"])

    for _ in range(len(idx) // 4):  # models.solvers.rk4_step, expression by expression
        k1 = f(z)
        k2 = f(z + k1 * half)
        k3 = f(z + k2 * half)
        k4 = f(z + k3 * h)
        z = z + (((k1 + k2 * two) + k3 * two) + k4) * h6
    s1 = a["act.z1.scale"][0]
    return product(q8(z, s1), T["head.weight"], s1, a["head.bias"])


def emulate_gru_int8(sec, x):
    T = sec.tensors
    a = {k: v.array for k, v in T.items()}
    xn = (x.astype(F) - a["norm.mean"]) / a["norm.std"]
    gx = product(q8(xn, a["act.x_norm.scale"]), T["gru.weight_ih"], None, a["gru.bias_ih"])
    hid = gx.shape[-1] // 3
    s_h = a["act.h.scale"][0]
    h = np.zeros((x.shape[0], hid), F)
    sig = lambda v: F(1) / (F(1) + np.exp(-v))  # noqa: E731
    for t in range(x.shape[1]):
        gh = product(q8(h, s_h), T["gru.weight_hh"], s_h, a["gru.bias_hh"])
        r = sig(gx[:, t, :hid] + gh[:, :hid])
        z = sig(gx[:, t, hid:2 * hid] + gh[:, hid:2 * hid])
        n = np.tanh(gx[:, t, 2 * hid:] + gh[:, 2 * hid:] * r)
        h = (h - n) * z + n
    return product(q8(h, s_h), T["head.weight"], s_h, a["head.bias"])


def test_documented_int8_arithmetic_reproduces_onnx_runtime(tiny, weights_file):
    """From weights.bin alone. tanh/sigmoid differ between numpy and ONNX Runtime by an ulp at
    times, which can move a value across a rounding boundary: most windows agree to the bit."""
    w = read_weights(weights_file)
    x = np.concatenate([tiny.x, tiny.calib[:40]])
    cases = (("cnode", emulate_cnode_int8, tiny.cnode_int8), ("gru", emulate_gru_int8, tiny.gru_int8))
    for model, emulate, built in cases:
        ort_logits = run(built, x)
        ours = emulate(w.section(model, "int8"), x)
        diff = np.abs(ours - ort_logits).max(axis=1)
        assert np.mean(diff <= 1e-6) >= 0.9, (model, diff)
        assert diff.max() <= 0.05 * max(1.0, float(np.abs(ort_logits).max())), (model, diff.max())


# ----------------------------------------------------------------------------- reference.bin


def test_reference_file(tiny, tmp_path):
    x, y = tiny.x[:3], np.array([0, 2, 1])
    path = tmp_path / "reference.bin"
    path.write_bytes(reference_bytes(x, y, np.arange(3), tiny.cnode, tiny.cp, tiny.cnode_int8, tiny.gru, tiny.gp,
                                     tiny.gru_int8))
    ref = read_reference(path)
    inp = ref.section("none", "none")
    assert np.array_equal(inp["telemetry"], x) and list(inp["label"]) == [0, 2, 1]
    cf, ci = ref.section("cnode", "fp32"), ref.section("cnode", "int8")
    n_stages = 4 * tiny.steps
    assert cf["stages"].shape == ci["stages"].shape == (3, n_stages, 6)
    assert cf.dims[5] == tiny.steps and cf.dims[7] == 3
    with torch.no_grad():
        assert np.allclose(cf["logits"], tiny.cnode(torch.from_numpy(x)).numpy(), atol=1e-6)
    # Stage 0 of step 0 is z0; the int8 values are the int8 graph's own.
    assert np.array_equal(cf["stages"][:, 0], cf["z0"]) and np.array_equal(ci["stages"][:, 0], ci["z0"])
    assert np.array_equal(ci["logits"], run(tiny.cnode_int8, x))
    gf, gi = ref.section("gru", "fp32"), ref.section("gru", "int8")
    assert gf["h"].shape == gi["h"].shape == (3, 80, 6)
    assert np.array_equal(gi["logits"], run(tiny.gru_int8, x))
    assert np.allclose(gf["logits"], gf["h"][:, -1] @ tiny.gp.head_w.T + tiny.gp.head_b, atol=1e-5)


# ----------------------------------------------------------------------------- manifest


def test_manifest_of_another_schema_version_is_refused(tmp_path):
    path = tmp_path / "manifest.json"
    path.write_text(json.dumps({"schema_version": SCHEMA_VERSION + 1, "artifacts": {}}))
    with pytest.raises(QuadfdiError, match=f"schema version {SCHEMA_VERSION + 1}, this quadfdi reads") as info:
        load_manifest(path)
    assert "\n" not in str(info.value)
    path.write_text('{"schema_version": 1, "artif')
    with pytest.raises(QuadfdiError, match="cannot be read as JSON"):
        load_manifest(path)
    with pytest.raises(QuadfdiError, match="does not exist"):
        load_manifest(tmp_path / "none.json")
