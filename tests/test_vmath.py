"""The host's fp32 vector math (fwref/vmath_f32.hpp): fwref_vmath compares tanh_n / logistic_n with
tanh_approx / logistic_approx bit for bit (clamp edges, +-0, NaN, +-inf, denormals, a walk over the
float32 bit patterns), and the fp32 gemv (matvec_f32 / matvec_bias_f32; every column count 1..140,
rows 1..17, with and without bias) two ways; it exits 1 on any failure.

The gemv is not Eigen's order (FMA chains, 8 rows per pass; 16 per pass on an AVX-512F
CPU, chosen at run time, both kernels checked there), so it is not compared with Eigen's product bit
for bit. What each kernel promises instead, and what is checked:
- its order, stated in fwref/vmath_f32.hpp, bit for bit against a scalar statement of that order
  (so its results do not depend on the row blocking, alignment or which rows % 8 path ran);
- its accuracy: within the rounding-error bound of that order, gamma(ceil(cols/8) + 3) * sum |w x|,
  of a double-precision sum; a bound, not a tolerance picked to pass (the worst ratio is printed).
How far that moves the models from ONNX Runtime is `quadfdi parity`'s check (FP32_CPP_REL_TOL).
On an AVX-512F CPU also the CNODE's column-major kernel (gemv_t: its order and bound) and its fused
field (bit for bit against the kernel's three separate steps); on an AVX-512 VNNI CPU the int8 CNODE's
field in one call (fwref/field_w8_vnni.hpp) against its five separate steps, and its control rows
(fwref/controls_avx512.hpp) against the AVX2 helpers, bit for bit; on an AVX2 + FMA CPU the int8 CNODE's
field in one call on AVX2 (fwref/field_w16_avx2.hpp) against the five separate steps of FWREF_I8_KERNEL=avx2,
bit for bit, its control rows in registers (fwref/controls_avx2.hpp) against the helpers and its lin1_u rows in one
call (fwref/linear_w16_avx2.hpp) against linear_i8_folded; and the fp32 CNODE's
field in one call on AVX2 (fwref/field_f32_avx2.hpp), bit for bit against a
scalar statement of its order and within that order's bound.

And the CNODE's int8 vector math (fwref/vmath_i8.hpp) with numerics.hpp's scalar expressions, bit
for bit: QuantizeLinear's round-half-even ties, saturation bounds and NaN, rescale + tanh + quantize,
rescale + bias, the control path's channels and its nonzero search; and the GRU's int8 step
(fwref/vmath_gru_i8.hpp) with its portable path's expressions: the input codes (ties, saturation
bounds, NaN/inf), the gates from the accumulators with the state update and the state's codes (every
hidden size 1..70 with the int32 extremes and NaN/inf mixed in, and millions of units of the GRU's
own shape)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)


def _cpu_flags() -> set[str]:
    for line in Path("/proc/cpuinfo").read_text().splitlines() if Path("/proc/cpuinfo").is_file() else []:
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


def test_vector_tanh_logistic_bit_identical_and_gemv_in_its_order_and_bound(host_build):
    res = subprocess.run([str(host_build / "fwref_vmath")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr
    out = res.stdout
    for fn in ("tanh", "logistic"):
        m = re.search(rf"^{fn}: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) > 1_000_000, out
    # per kernel: every cols 1..140 x rows 1..17, then 3 matrices over 32 KiB (240, 250, 129 rows) in both
    # pass orders; each kernel the CPU runs (fma-avx2-8row, and fma-avx512-16row on an AVX-512F CPU)
    rows_checked = 140 * sum(range(1, 18)) + 2 * (240 + 250 + 129)
    kernels = re.search(r"^gemv kernels checked: (.*)$", out, re.M).group(1).split()
    fma = [k for k in kernels if k.startswith("fma-")]
    m = re.search(r"^gemv order: (\d+) of (\d+) differ$", out, re.M)  # compared only for the FMA kernels
    assert m and int(m.group(1)) == 0 and int(m.group(2)) == rows_checked * len(fma), out
    m = re.search(r"^gemv bound: (\d+) of (\d+) exceed \(worst error / bound ([0-9.]+)\)$", out, re.M)
    assert m and int(m.group(1)) == 0 and int(m.group(2)) == rows_checked * len(kernels), out
    assert float(m.group(3)) <= 1.0, out
    m = re.search(r"^all_finite: (\d+) of (\d+) differ$", out, re.M)
    assert m and int(m.group(1)) == 0 and int(m.group(2)) > 3000, out
    i8_min = {"quantize": 10_000_000, "rescale_tanh_quantize+rescale_bias": 19_000, "hidden_rows": 3_000_000,
              "control_row": 14_000, "nonzero": 300,
              "gru_input_row": 19_000, "gru_gates": 19_000, "gru_gate_rows": 3_000_000}
    for check, least in i8_min.items():  # int8: codes and floats element for element, guards after n kept
        m = re.search(rf"^{re.escape(check)}: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) >= least, out
    flags = _cpu_flags()
    if {"avx2", "fma"} <= flags:  # the host build is -march=native: the vector path must be the one compared
        assert "vmath kernel: avx2-fma" in out and "vmath_i8 kernel: avx2" in out, out
        assert "fma-avx2-8row" in kernels, out
        # the AVX-512F kernel is chosen at run time where the CPU has it (the AVX2 one stays checked)
        want = "fma-avx512-16row" if "avx512f" in flags else "fma-avx2-8row"
        assert f"gemv kernel: {want}" in out and (want in kernels), out
    if "avx512f" in flags:  # the CNODE's column-major copies and fused field (fwref/kernels_f32_avx512.hpp)
        m = re.search(r"^gemv_t order: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == 140 * (sum(range(1, 21)) + 33 + 40 + 64 + 65 + 100), out
        m = re.search(r"^gemv_t bound: (\d+) of (\d+) exceed \(worst error / bound ([0-9.]+)\)$", out, re.M)
        assert m and int(m.group(1)) == 0 and float(m.group(3)) <= 1.0, out
        m = re.search(r"^field_t: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == 64 * sum(range(1, 65)), out
    if {"avx2", "fma"} <= flags:  # the fp32 CNODE field in one call on AVX2 (fwref/field_f32_avx2.hpp)
        m = re.search(r"^field_f32_avx2 order: (\d+) of (\d+) differ$", out, re.M)  # every H, L in 1..64
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == 64 * sum(range(1, 65)), out
        m = re.search(r"^field_f32_avx2 bound: (\d+) exceed \(worst error / bound ([0-9.]+)\)$", out, re.M)
        assert m and int(m.group(1)) == 0 and float(m.group(2)) <= 1.0, out
    if {"avx2", "fma"} <= flags:  # the int8 control rows in registers on AVX2 (fwref/controls_avx2.hpp)
        m = re.search(r"^control_row_avx2: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == sum(range(1, 33)) * (39 + 9), out
    if {"avx2", "fma"} <= flags:  # the int8 CNODE field in one call on AVX2 (fwref/field_w16_avx2.hpp)
        m = re.search(r"^field_w16: (\d+) of (\d+) differ$", out, re.M)  # 6 draws of every H, L in 8, 16, .., 64
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == 6 * 8 * sum(range(8, 65, 8)), out
        m = re.search(r"^linear_w16: (\d+) of (\d+) differ$", out, re.M)  # its lin1_u rows (fwref/linear_w16_avx2.hpp)
        n_rows = sum(r * (1 + (r + c + d) % 3) for r in range(8, 65, 8) for c in range(1, 33) for d in range(2))
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == n_rows, out
    else:
        print("skipped field_w16, linear_w16 and field_f32_avx2: this CPU has no AVX2 + FMA (the AVX2 paths cannot run here)")
    if {"avx512f", "avx512vl", "avx512_vnni"} <= flags:  # the int8 CNODE field in one call (fwref/field_w8_vnni.hpp)
        m = re.search(r"^field_w8: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == 64 * sum(range(1, 65)), out
        m = re.search(r"^control_row_avx512: (\d+) of (\d+) differ$", out, re.M)  # and its control rows
        assert m and int(m.group(1)) == 0 and int(m.group(2)) == sum(range(1, 33)) * (39 + 9), out
