"""firmware_ref: host parity (reference.bin, the test split against ONNX Runtime), the programs'
error contract under AddressSanitizer + UBSan, the weights generator, and the Cortex-M4/M7 builds
under QEMU. Builds happen once per session (tests/test_firmware_fixtures.py)."""

from __future__ import annotations

import random
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from quadfdi.formats.binfmt import pack
from quadfdi.formats.weights_bin import MAGIC, read_weights
from quadfdi.parity import compare
from quadfdi.runtimes import fwref, ort as ort_rt
from quadfdi.runtimes.build import mcu_build_dir
from quadfdi.parity.mcu import run_cpu
from quadfdi.runtimes.mcu import qemu_command, tools_missing
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import load_dataset, make_windows
from tests.test_firmware_fixtures import asan_build, fw_run, host_build  # noqa: F401 (fixtures)

SANITIZER_MARKERS = ("AddressSanitizer", "runtime error", "LeakSanitizer", "UndefinedBehaviorSanitizer")


def infer(build: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(build / "fwref_infer"), *args], capture_output=True, text=True, timeout=300)


def assert_one_line_error(res: subprocess.CompletedProcess, code: int, match: str = "") -> None:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == code, (res.returncode, res.stderr)
    assert len(lines) == 1, res.stderr  # exactly one line: no sanitizer report, no trace
    assert lines[0].startswith("fwref_infer: "), lines[0]
    assert not any(m in res.stderr for m in SANITIZER_MARKERS)
    assert match in lines[0], (match, lines[0])


def test_windows(run: Path) -> np.ndarray:
    return make_windows(load_dataset(run / "dataset.npz"), "test").x


test_windows.__test__ = False  # a helper, not a test


# ------------------------------------------------------------------------------ host parity


def test_fwref_parity_on_reference_bin(fw_run, host_build):
    """Every intermediate tensor (CNODE z0, all RK4 stage states, z1; GRU hidden states) and the
    logits, fp32 against PyTorch and int8 against ONNX Runtime, within the documented tolerances."""
    export = fw_run / "export"
    res = subprocess.run([str(host_build / "fwref_parity"), "--weights", str(export / "weights.bin"),
                          "--reference", str(export / "reference.bin")], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    rows = [ln for ln in res.stdout.splitlines() if ln.startswith(("cnode", "gru"))]
    names = {tuple(r.split()[:3]) for r in rows}
    for prec in ("fp32", "int8"):
        for t in ("x_norm", "u", "z0", "stages", "z1", "logits"):
            assert ("cnode", prec, t) in names
        for t in ("x_norm", "h", "logits"):
            assert ("gru", prec, t) in names
    assert all(r.endswith(" OK") for r in rows), res.stdout
    assert "all 18 tensors OK" in res.stdout


def test_fwref_parity_fails_loudly_on_another_models_reference(fw_run, host_build, tmp_path):
    """A reference.bin whose numbers are not this model's: NOT OK lines and exit 1 (llm.c style)."""
    from quadfdi.formats.reference_bin import MAGIC as REF_MAGIC, read_reference

    ref = read_reference(fw_run / "export" / "reference.bin")
    for sec in ref.sections:
        if sec.model == "gru" and sec.precision == "int8":
            sec.tensors["logits"].array[...] += 0.5  # half a unit: many logit steps
    bad = tmp_path / "reference.bin"
    bad.write_bytes(pack(REF_MAGIC, 1, ref.sections))
    res = subprocess.run([str(host_build / "fwref_parity"), "--weights", str(fw_run / "export" / "weights.bin"),
                          "--reference", str(bad)], capture_output=True, text=True)
    assert res.returncode == 1
    failed = [ln.split()[:3] for ln in res.stdout.splitlines() if ln.startswith(("cnode", "gru")) and
              ln.endswith("NOT OK")]
    assert failed == [["gru", "int8", "logits"]]
    assert "1 of 18 tensors NOT OK" in res.stdout


def test_fwref_infer_matches_onnx_runtime_on_the_test_split(fw_run, host_build):
    """Batch 1 per window on both sides; C++ fp32 within 1e-4 * max(1, max|logit|) with 100 %
    argmax, int8 within the documented logit steps with >= 99.9 % argmax, and bit-identical where
    ONNX Runtime runs its FMA3 kernels (the C++ RK4 and the graph's both follow core.rk4.RK4_PROGRAM)."""
    export, x = fw_run / "export", test_windows(fw_run)
    weights = read_weights(export / "weights.bin")
    art = {"cnode": ("cnode_rk4_8.onnx", "cnode_rk4_8.int8.onnx"), "gru": ("gru.onnx", "gru.int8.onnx")}
    for model, (f32, i8) in art.items():
        cpp = fwref.cpp_outputs(export / "weights.bin", model, False, x, build_dir=host_build)[0]
        ort = ort_rt.outputs(export / f32, x, ["logits"], batch=1)[0]
        m = compare.pair_metrics(cpp, ort)
        assert compare.fp32_target(m)["passed"], (model, m)
        cpp8 = fwref.cpp_outputs(export / "weights.bin", model, True, x, build_dir=host_build)[0]
        ort8 = ort_rt.outputs(export / i8, x, ["logits"], batch=1)[0]
        m8 = compare.pair_metrics(cpp8, ort8)
        t = compare.int8_target(cpp8, ort8, compare.logit_steps(weights, model), m8)
        assert t["passed"], (model, m8, t)
        if _cpu_has_fma():  # ONNX Runtime's x86-64 FMA3 kernels: the same float32 program, the same bits
            assert np.array_equal(cpp8, ort8), model


def _ort_unary(op: str, x: np.ndarray) -> np.ndarray:
    import onnx
    from onnx import TensorProto, helper

    from quadfdi.runtimes.ort import session

    g = helper.make_graph([helper.make_node(op, ["x"], ["y"])], op,
                          [helper.make_tensor_value_info("x", TensorProto.FLOAT, [None])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, [None])])
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 18)])
    m.ir_version = 10
    onnx.checker.check_model(m)
    return session(m.SerializeToString()).run(None, {"x": x})[0]


def _cpu_has_fma() -> bool:
    try:
        return " fma " in Path("/proc/cpuinfo").read_text().replace("\n", " ")
    except OSError:
        return False


def test_activations_match_onnx_runtime(host_build, tmp_path):
    """tanh and sigmoid are MLAS's rational approximations with fused multiply-adds: bit-identical to
    ONNX Runtime's Tanh and Sigmoid on an x86-64 CPU with FMA3 (its kernels there), within a few
    ulps anywhere, and within 1e-6 of the exact functions."""
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-20, 20, 200_000), rng.normal(0, 1.5, 200_000), rng.uniform(-1e-3, 1e-3, 20_000),
                        [0.0, -0.0, 9.0, -9.0, 18.0, -18.0, 1e-40, -1e-40, 3e38, -3e38]]).astype(np.float32)
    src, dst = tmp_path / "x.f32", tmp_path / "y.f32"
    x.tofile(src)
    res = subprocess.run([str(host_build / "fwref_activations"), "--in", str(src), "--out", str(dst)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    ours = np.fromfile(dst, "<f4").reshape(2, -1)
    for k, (op, exact) in enumerate((("Tanh", np.tanh), ("Sigmoid", lambda v: 1 / (1 + np.exp(-v))))):
        ort = _ort_unary(op, x)
        if _cpu_has_fma():
            assert np.array_equal(ours[k], ort), op
        assert np.abs(ours[k] - ort).max() <= 5e-7, op
        with np.errstate(over="ignore"):
            assert np.abs(ours[k] - exact(x.astype(np.float64))).max() < 1e-6, op


# ------------------------------------------------------------------------------ the error contract (sanitizers)


@pytest.fixture(scope="module")
def windows_file(fw_run, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("win") / "windows.f32"
    test_windows(fw_run)[:6].astype("<f4").tofile(path)
    return path


def test_sanitizer_build_runs_every_model_and_matches_release(fw_run, asan_build, host_build, windows_file, tmp_path):
    weights = fw_run / "export" / "weights.bin"
    for model in ("cnode", "gru"):
        for flag in ([], ["--int8"]):
            outs = []
            for build in (asan_build, host_build):
                out = tmp_path / f"{build.name}-{model}{''.join(flag)}.f32"
                res = infer(build, "--weights", str(weights), "--model", model, *flag, "--in", str(windows_file),
                            "--out", str(out))
                assert res.returncode == 0 and not res.stderr, res.stderr
                outs.append(np.fromfile(out, "<f4").reshape(6, 4))
            if flag:  # integer sums and the same float32 operation order: identical bits
                assert np.array_equal(outs[0], outs[1])
            else:
                assert np.allclose(outs[0], outs[1], atol=1e-5)


def test_sanitizer_build_parity_allocates_nothing_during_inference(fw_run, asan_build):
    """The sanitizer build has assertions on: fwref_parity forbids Eigen heap allocation around every
    inference (EIGEN_RUNTIME_NO_MALLOC), so an allocation would abort the run."""
    export = fw_run / "export"
    res = subprocess.run([str(asan_build / "fwref_parity"), "--weights", str(export / "weights.bin"),
                          "--reference", str(export / "reference.bin")], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert not any(m in res.stderr for m in SANITIZER_MARKERS)


def _sections(data: bytes) -> list[tuple[int, int]]:
    """(start, size) of each section of a container."""
    pos, out = 24, []
    for _ in range(struct.unpack_from("<I", data, 12)[0]):
        size = struct.unpack_from("<I", data, pos + 4)[0]
        out.append((pos, size))
        pos += size
    return out


def _fix_crcs(blob: bytearray, sections: list[tuple[int, int]]) -> bytes:
    """Recompute every section CRC and the file CRC, so that a corruption reaches the size checks."""
    for start, size in sections:
        struct.pack_into("<I", blob, start + size - 4, zlib.crc32(bytes(blob[start:start + size - 4])))
    struct.pack_into("<I", blob, len(blob) - 4, zlib.crc32(bytes(blob[:-4])))
    return bytes(blob)


def _tensor_headers(data: bytes) -> list[tuple[int, tuple[str, bool]]]:
    """Offset of every tensor record of a weights.bin, with the (model, int8) its section binds."""
    models, out = {1: "cnode", 2: "gru"}, []
    for start, _ in _sections(data):
        model, precision = struct.unpack_from("<II", data, start + 8)
        if model not in models:
            continue  # the on-board record (formats/onboard.py): no model binds it
        pos = start + 52
        for _ in range(struct.unpack_from("<I", data, start + 48)[0]):
            out.append((pos, (models[model], precision == 2)))
            nbytes, n_scales = struct.unpack_from("<I", data, pos + 80)[0], struct.unpack_from("<I", data, pos + 76)[0]
            pos += 84 + nbytes + (-nbytes) % 4 + 8 * n_scales
    return out


ALL_MODELS = (("cnode", True), ("gru", False))


def _bad_weights(fw_run: Path) -> dict[str, tuple[bytes, str, tuple]]:
    """name -> (file bytes, expected text in the error line, the (model, int8) runs that must refuse it)."""
    data = (fw_run / "export" / "weights.bin").read_bytes()
    n = len(data)
    cases = {f"truncated_{k}": (data[:k], "truncated", ALL_MODELS) for k in (0, 10, 24, 100, n // 2, n - 4, n - 1)}
    cases["trailing_bytes"] = (data + b"\0" * 8, "trailing bytes", ALL_MODELS)
    cases["zip"] = (b"PK\x03\x04" + data[4:], "not a quadfdi weights file", ALL_MODELS)
    cases["reference_bin"] = ((fw_run / "export" / "reference.bin").read_bytes(), "not a quadfdi weights file",
                              ALL_MODELS)
    newer = bytearray(data)
    struct.pack_into("<I", newer, 8, 2)
    cases["version_2"] = (bytes(newer), "format version 2", ALL_MODELS)
    for frac in (0.001, 0.3, 0.7, 0.999):
        flipped = bytearray(data)
        flipped[int(frac * (n - 5))] ^= 0x10
        cases[f"bitflip_{frac}"] = (bytes(flipped), "CRC-32", ALL_MODELS)
    # Valid CRCs, impossible headers: the size and layout checks, not the CRC, must catch these. Each
    # changes one field of one tensor record to another value; the run that binds that tensor's
    # section must refuse the file (every tensor of a section is checked, used or not).
    secs, heads = _sections(data), _tensor_headers(data)
    rng = random.Random(0)
    k = 0
    while k < 24:
        head, run = heads[rng.randrange(len(heads))]
        field = rng.choice([48, 52, 56, 60, 64, 68, 72, 76, 80])  # dtype, ndim, shape[4], axis, n_scales, data_bytes
        value = rng.choice([0, 1, 3, 5, 255, 4000, 0x7FFFFFFF, 0xFFFFFFFF])
        if struct.unpack_from("<I", data, head + field)[0] == value:
            continue  # the same value: not a corruption
        blob = bytearray(data)
        struct.pack_into("<I", blob, head + field, value)
        cases[f"header_{k}"] = (_fix_crcs(blob, secs), "", (run,))
        k += 1
    blob = bytearray(data)
    struct.pack_into("<I", blob, secs[1][0] + 48, 10 ** 6)  # n_tensors of the cnode int8 section
    cases["n_tensors"] = (_fix_crcs(blob, secs), "tensors", ALL_MODELS)
    return cases


def test_bad_weights_give_one_line_and_exit_2(fw_run, asan_build, windows_file, tmp_path):
    """Every corrupted file is refused, by C++ (one line, exit 2, no output) and by Python."""
    out = tmp_path / "logits.f32"
    for name, (blob, match, runs) in _bad_weights(fw_run).items():
        bad = tmp_path / f"{name}.bin"
        bad.write_bytes(blob)
        with pytest.raises(QuadfdiError):
            read_weights(bad)
        for model, int8 in runs:
            out.unlink(missing_ok=True)
            res = infer(asan_build, "--weights", str(bad), "--model", model, *(["--int8"] if int8 else []),
                        "--in", str(windows_file), "--out", str(out))
            assert_one_line_error(res, 2, match)
            assert "weights file" in res.stderr, (name, res.stderr)
            assert not out.exists(), name


def _weights_with(fw_run: Path, edit) -> bytes:
    w = read_weights(fw_run / "export" / "weights.bin")
    sections = [s for s in w.sections]
    edit(sections)
    return pack(MAGIC, 1, sections)


def test_consistent_files_with_wrong_contents_are_refused(fw_run, asan_build, windows_file, tmp_path):
    """Files that pass every CRC and size check but do not describe a usable model."""

    def drop(name, model, prec):
        def edit(secs):
            next(s for s in secs if (s.model, s.precision) == (model, prec)).tensors.pop(name)
        return edit

    def replace(name, model, prec, fn):
        def edit(secs):
            s = next(s for s in secs if (s.model, s.precision) == (model, prec))
            t = s.tensors[name]
            s.tensors[name] = type(t)(name, fn(t.array), t.scales, t.zero_points, t.axis)
        return edit

    def dims(model, prec, index, value):
        def edit(secs):
            s = next(s for s in secs if (s.model, s.precision) == (model, prec))
            d = list(s.dims)
            d[index] = value
            s.dims = tuple(d)
        return edit

    def only_cnode(secs):
        secs[:] = [s for s in secs if s.model == "cnode"]

    cases = [
        (drop("head.bias", "cnode", "int8"), "cnode", True, "lacks tensor 'head.bias'"),
        (replace("gru.weight_hh", "gru", "fp32", lambda a: a[:, :-1].copy()), "gru", False, "expected float32 (240, 80)"),
        (replace("lin2.weight", "cnode", "fp32", lambda a: a[:-1].copy()), "cnode", False, "expected float32 (40, 64)"),
        (replace("stage_index", "cnode", "int8", lambda a: a + 100), "cnode", True, "consistency check"),
        (replace("norm.std", "gru", "int8", lambda a: a * 0), "gru", True, "consistency check"),
        (replace("act.h.scale", "gru", "int8", lambda a: a * np.float32("nan")), "gru", True, "consistency check"),
        (dims("cnode", "fp32", 3, 300), "cnode", False, "maximum is 256"),
        (dims("cnode", "int8", 6, 18), "cnode", True, "2N + 1"),
        (dims("gru", "fp32", 0, 0), "gru", False, "channels 0"),
        (only_cnode, "gru", False, "holds no gru fp32 section"),
    ]
    out = tmp_path / "logits.f32"
    for k, (edit, model, int8, match) in enumerate(cases):
        path = tmp_path / f"w{k}.bin"
        path.write_bytes(_weights_with(fw_run, edit))
        res = infer(asan_build, "--weights", str(path), "--model", model, *(["--int8"] if int8 else []),
                    "--in", str(windows_file), "--out", str(out))
        assert_one_line_error(res, 2, match)
        assert not out.exists()


def test_bad_inputs_give_one_line_exit_2_and_leave_the_output_alone(fw_run, asan_build, tmp_path):
    weights = str(fw_run / "export" / "weights.bin")
    x = test_windows(fw_run)[:3].astype("<f4")
    per = x[0].nbytes
    out = tmp_path / "logits.f32"
    out.write_bytes(b"old")  # an existing output must survive a failed run untouched
    cases = {"empty": (b"", "0 bytes"), "extra": (x.tobytes() + b"\0\0\0\0", f"{3 * per + 4} bytes"),
             "short": (x.tobytes()[:-4], "not a whole positive number"), }
    nan, inf = x.copy(), x.copy()
    nan[1, 3, 5] = np.nan
    inf[2, 79, 0] = -np.inf
    cases["nan"] = (nan.tobytes(), "window 1 holds NaN or Inf (first at sample 3, channel 5)")
    cases["inf"] = (inf.tobytes(), "window 2 holds NaN or Inf (first at sample 79, channel 0)")
    for name, (blob, match) in cases.items():
        src = tmp_path / f"{name}.f32"
        src.write_bytes(blob)
        for model, flag in (("cnode", []), ("gru", ["--int8"])):
            res = infer(asan_build, "--weights", weights, "--model", model, *flag, "--in", str(src), "--out", str(out))
            assert_one_line_error(res, 2, match)
            assert out.read_bytes() == b"old"
    res = infer(asan_build, "--weights", weights, "--model", "gru", "--in", str(tmp_path / "none.f32"), "--out", str(out))
    assert_one_line_error(res, 2, "does not exist")
    good = tmp_path / "good.f32"
    good.write_bytes(x.tobytes())
    res = infer(asan_build, "--weights", weights, "--model", "gru", "--in", str(good),
                "--out", str(tmp_path / "no" / "such" / "dir.f32"))
    assert_one_line_error(res, 2, "cannot write")
    assert sorted(p.name for p in tmp_path.iterdir() if ".tmp." in p.name) == []  # no temp file left


def test_usage_errors_exit_1(asan_build, tmp_path):
    for args, match in (([], "required"), (["--model", "lstm", "--weights", "w", "--in", "i", "--out", "o"], "lstm"),
                        (["--frobnicate"], "unknown argument"), (["--weights"], "needs a value"),
                        (["--repeat", "0", "--weights", "w", "--model", "gru", "--in", "i", "--out", "o"], "--repeat")):
        assert_one_line_error(infer(asan_build, *args), 1, match)
    res = infer(asan_build, "--help")
    assert res.returncode == 0 and "usage: fwref_infer" in res.stdout


def test_timings_option(fw_run, host_build, windows_file, tmp_path):
    out, t = tmp_path / "l.f32", tmp_path / "t.f64"
    res = infer(host_build, "--weights", str(fw_run / "export" / "weights.bin"), "--model", "cnode", "--int8",
                "--in", str(windows_file), "--out", str(out), "--repeat", "3", "--timings", str(t))
    assert res.returncode == 0, res.stderr
    seconds = np.fromfile(t, "<f8").reshape(6, 3)
    assert np.all(seconds > 0) and np.all(np.isfinite(seconds))


# ------------------------------------------------------------------------------ int8 kernels


def _cpu_flags() -> set[str]:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def _kernels(build: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(build / "fwref_kernels"), *args], capture_output=True, text=True, timeout=300)


def _check_lines(res: subprocess.CompletedProcess) -> dict[str, str]:
    return {ln.split()[1]: ln for ln in res.stdout.splitlines() if ln.startswith("CHECK ")}


def test_every_int8_kernel_this_cpu_runs_gives_the_portable_accumulators(host_build, asan_build):
    """fwref_kernels --check: each kernel the CPU runs (and the dispatched entry point) against the
    portable loop on random data, every column count 1..100 and longer ones (not multiples of the
    vector width), 1..13, 16, 24, 32, 40, 56, 64 and 240 rows (the w8 kernel's panels of 1..4 blocks of 16
    rows, with and without a tail), and the extremes (x = -128 against w = +-127, x = 127, zeros).
    Under the sanitizer build too, where the inputs are exact-size heap blocks (no read past a row)."""
    for build in (host_build, asan_build):
        res = _kernels(build, "--check")
        assert res.returncode == 0, res.stdout + res.stderr
        lines = _check_lines(res)
        assert "portable" in lines and any(k.startswith("dispatched:") for k in lines), res.stdout
        assert all(ln.endswith(" OK") and "mismatches=0" in ln for ln in lines.values()), res.stdout
        if "avx2" in _cpu_flags():
            assert "avx2" in lines, res.stdout
        if {"avx2", "fma"} <= _cpu_flags():  # the CNODE field in one call's entry (the avx2 products)
            assert "avx2field" in lines, res.stdout
        # the packed int16 copies (FWREF_CNODE_W_INT16 / FWREF_GRU_WHH_INT16, on by default) per kernel
        assert {f"w16:{k}" for k in lines if not k.startswith(("dispatched:", "w16:", "w8:"))} <= set(lines), res.stdout
        # the GRU's and CNODE's packed int8 copy for vpdpbusd (fwref/kernels_w8_vnni.hpp): its layout's reference, and
        # the kernel itself wherever the CPU runs avx512vnni
        assert "w8:portable" in lines and (("w8:avx512vnni" in lines) == ("avx512vnni" in lines)), res.stdout
        assert not any(m in res.stderr for m in SANITIZER_MARKERS), res.stderr


def test_avx512_vnni_kernel_gives_the_portable_accumulators(host_build):
    flags = _cpu_flags()
    if not {"avx512f", "avx512vl", "avx512_vnni"} <= flags:
        pytest.skip("this CPU has no AVX-512 VNNI (+VL): the vpdpbusd kernel cannot run here "
                    "(/proc/cpuinfo flags lack avx512_vnni or avx512vl)")
    res = _kernels(host_build, "--check", "--kernel", "avx512vnni")
    assert res.returncode == 0 and "CHECK avx512vnni" in res.stdout and " OK" in res.stdout, res.stdout
    lines = _check_lines(res)  # and the models' packed int8 copy on vpdpbusd (fwref/kernels_w8_vnni.hpp)
    assert lines["w8:avx512vnni"].endswith(" OK") and "mismatches=0" in lines["w8:avx512vnni"], res.stdout


def test_kernel_info_names_the_cpu_flags_and_the_dispatched_kernel(host_build):
    res = subprocess.run([str(host_build / "fwref_parity"), "--kernel-info"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    info = dict(ln.split(": ", 1) for ln in res.stdout.splitlines() if ": " in ln)
    assert set(info) >= {"cpu_flags", "fp32_build", "int8_kernel", "int8_kernels", "gru_int8_products",
                         "cnode_int8_products"}, res.stdout
    want = {"avx512vnni": "w8-vpdpbusd", "portable": "portable"}.get(info["int8_kernel"], "w16-vpmaddwd")
    field = "-field" if info["int8_kernel"] == "avx2field" else ""  # the CNODE's field in one call on AVX2
    assert info["gru_int8_products"] == want and info["cnode_int8_products"] == want + field, res.stdout
    runs = {kv.split("=")[0] for kv in info["int8_kernels"].split() if kv.endswith("=runs")}
    assert info["int8_kernel"] in runs and "portable" in runs
    flags = _cpu_flags()
    if "avx2" in flags:
        assert info["int8_kernel"] in ("avx2", "avx2field", "avx512vnni") and "avx2=1" in info["cpu_flags"]
    if {"avx2", "fma"} <= flags and "avx512_vnni" not in flags:  # an AVX2-only host: the fused field is the choice
        assert info["int8_kernel"] == "avx2field" and "avx2field" in runs, res.stdout


def test_forced_portable_kernel_gives_the_same_logits(fw_run, host_build, windows_file, tmp_path):
    """FWREF_I8_KERNEL=portable (the reference loop; for the GRU the whole portable step, src/gru.cpp),
    avx2 (the host steps on the int16 copies), avx2field (the same, the CNODE's field in one call on them,
    fwref/field_w16_avx2.hpp) and the dispatched kernel (on an AVX-512 VNNI CPU both
    models' products on the int8 copies, src/gru.cpp and src/cnode_w8.cpp): identical int8 logits, each
    setting on the product path it names."""
    import os

    weights = fw_run / "export" / "weights.bin"
    kernels = ("portable", "avx2", "avx2field", "")
    for kernel in kernels:  # which path each setting runs (fwref_parity --kernel-info)
        res = subprocess.run([str(host_build / "fwref_parity"), "--kernel-info"], capture_output=True, text=True,
                             env=dict(os.environ, FWREF_I8_KERNEL=kernel))
        info = dict(ln.split(": ", 1) for ln in res.stdout.splitlines() if ": " in ln)
        vnni = info["int8_kernel"] == "avx512vnni"
        want = {"portable": "portable", "avx2": "w16-vpmaddwd", "avx2field": "w16-vpmaddwd"}.get(
            kernel, "w8-vpdpbusd" if vnni else "w16-vpmaddwd")
        field = "-field" if info["int8_kernel"] == "avx2field" else ""
        assert info["cnode_int8_products"] == want + field and want == info["gru_int8_products"], (kernel, res.stdout)
        if kernel == "avx2field" and {"avx2", "fma"} <= _cpu_flags():
            assert field, res.stdout
    for model in ("cnode", "gru"):
        outs = []
        for kernel in kernels:
            out = tmp_path / f"{model}{kernel}.f32"
            res = subprocess.run([str(host_build / "fwref_infer"), "--weights", str(weights), "--model", model, "--int8",
                                  "--in", str(windows_file), "--out", str(out)], capture_output=True, text=True,
                                 env=dict(os.environ, FWREF_I8_KERNEL=kernel))
            assert res.returncode == 0, res.stderr
            outs.append(np.fromfile(out, "<f4"))
        assert all(np.array_equal(outs[0], o) for o in outs[1:]), model


# ------------------------------------------------------------------------------ the generator


def test_generator_refuses_a_corrupted_weights_file(fw_run, tmp_path):
    data = (fw_run / "export" / "weights.bin").read_bytes()
    bad = tmp_path / "w.bin"
    for blob in (data[:100], data[:-1] + bytes([data[-1] ^ 1])):
        bad.write_bytes(blob)
        res = subprocess.run([sys.executable, "-m", "quadfdi.runtimes.mcu_weights_src", "--weights", str(bad),
                              "--out", str(tmp_path / "gen")], capture_output=True, text=True)
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
        assert res.stderr.startswith("python -m quadfdi.runtimes.mcu_weights_src: error:")


def test_generated_arrays_are_exact(fw_run, tmp_path):
    """Hexadecimal float literals: every compiled-in value is the file's float32, bit for bit."""
    from quadfdi.runtimes import mcu_weights_src

    mcu_weights_src.generate(fw_run / "export" / "weights.bin", None, tmp_path)
    text = (tmp_path / "fwref_weights_gru_f32.cpp").read_text()
    body = text.split("gru_f32_gru_weight_hh[19200] = {")[1].split("};")[0]
    values = np.array([float.fromhex(v.strip().rstrip("f")) for v in body.split(",")], np.float64)
    want = read_weights(fw_run / "export" / "weights.bin").section("gru", "fp32")["gru.weight_hh"].ravel()
    assert np.array_equal(values.astype(np.float32), want)
    assert "#define FWREF_MAX_GRU_HIDDEN 80" in (tmp_path / "fwref_limits.h").read_text()


# ------------------------------------------------------------------------------ Cortex-M under QEMU


@pytest.mark.parametrize("cpu", ["cortex-m4", "cortex-m7"])
def test_cortex_m_parity_under_qemu(fw_run, cpu):
    """Cross-build with the run's weights compiled in, run the parity harness under QEMU
    (semihosting, -icount shift=0), check every tensor, the memory targets and the measurements;
    then run the minimal image of the int8 CNODE (exit code = its inference status)."""
    missing = tools_missing()
    if missing:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {missing}")
    export = fw_run / "export"
    r = run_cpu(cpu, export / "weights.bin", export / "reference.bin", log=lambda _: None)
    assert r["exit_code"] == 0 and r["passed"], r["output"]
    assert len(r["tensors"]) == 18 and all(t["ok"] for t in r["tensors"])
    assert 39.0 < r["calibration"]["instructions_per_tick"] < 41.0  # 25 MHz SysTick, 1 ns per instruction
    m = r["models"]
    assert m["cnode_int8"]["flash_bytes"] <= 64 * 1024 and m["cnode_int8"]["static_ram_bytes"] <= 16 * 1024
    for key, v in m.items():
        assert v["instructions_per_inference"] > 0 and v["stack_peak_bytes"] > 0, key
        assert 0 < v["weights_bytes"] < v["flash_bytes"], key
    # int8 weights are about a quarter of fp32 ones (plus float scales and biases)
    assert m["gru_int8"]["weights_bytes"] < 0.35 * m["gru_fp32"]["weights_bytes"]
    elf = mcu_build_dir(cpu) / "fwref_min_cnode_i8.elf"  # built by run_cpu above
    res = subprocess.run(qemu_command(cpu, elf), capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    # The Cortex-M kernels on shapes no model has (rows 1..13: the 4-row passes' tail rows; odd
    # column counts), each against its portable reference, exactly (mcu/kernels_main.cpp; < 1 s).
    res = subprocess.run(qemu_command(cpu, mcu_build_dir(cpu) / "fwref_mcu_kernels.elf"), capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 0, res.stdout + res.stderr
    # 13 row counts x the listed column counts up to min(41, the widest product): 234 with the default dims
    assert int(res.stdout.split("KERNELS PASS cases=")[1].split()[0]) >= 13 * 12, res.stdout
    assert "cortex-m-dsp-4row cortex-m-vfp-4row" in res.stdout  # the assembly kernels ran, not the fallbacks


def test_fwref_infer_in_chunks_gives_the_logits_of_one_call(fw_run, host_build):
    """A split too large for the C++ reader's 1024 MiB input limit is fed in chunks: windows are
    independent, so the chunked logits (and motor logits) are the single call's, bit for bit."""
    export, x = fw_run / "export", test_windows(fw_run)[:50]
    exe, weights = host_build / "fwref_infer", export / "weights.bin"
    for model in ("cnode", "gru"):
        for int8 in (False, True):
            whole = fwref.fwref_infer(exe, weights, model, int8, x)
            per_window = x[0].size * 4
            chunked = fwref.fwref_infer(exe, weights, model, int8, x, max_bytes=7 * per_window + 3)  # 8 calls
            assert np.array_equal(whole[0], chunked[0]), (model, int8)
