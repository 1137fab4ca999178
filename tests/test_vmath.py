"""The host's fp32 vector math (fwref/vmath_f32.hpp) is bit-identical to the scalar code it replaces:
fwref_vmath compares tanh_n / logistic_n with tanh_approx / logistic_approx (clamp edges, +-0, NaN,
+-inf, denormals, a walk over the float32 bit patterns) and gemv_f32_eigen with Eigen's lazyProduct
(every column count 1..140, rows 1..9), bit for bit; and the CNODE's int8 vector math
(fwref/vmath_i8.hpp) with numerics.hpp's scalar expressions: QuantizeLinear's round-half-even ties,
saturation bounds and NaN, rescale + tanh + quantize, rescale + bias, the control path's channels
and its nonzero search; it exits 1 on any difference."""

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


def test_vector_tanh_logistic_and_gemv_are_bit_identical_to_the_scalar_code(host_build):
    res = subprocess.run([str(host_build / "fwref_vmath")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr
    out = res.stdout
    for fn in ("tanh", "logistic"):
        m = re.search(rf"^{fn}: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) > 1_000_000, out
    m = re.search(r"^gemv: (\d+) of (\d+) differ$", out, re.M)
    assert m and int(m.group(1)) == 0 and int(m.group(2)) == 140 * sum(range(1, 10)), out
    m = re.search(r"^all_finite: (\d+) of (\d+) differ$", out, re.M)
    assert m and int(m.group(1)) == 0 and int(m.group(2)) > 3000, out
    i8_min = {"quantize": 10_000_000, "rescale_tanh_quantize+rescale_bias": 19_000, "hidden_rows": 3_000_000,
              "control_row": 14_000, "nonzero": 300}
    for check, least in i8_min.items():  # int8: codes and floats element for element, guards after n kept
        m = re.search(rf"^{re.escape(check)}: (\d+) of (\d+) differ$", out, re.M)
        assert m and int(m.group(1)) == 0 and int(m.group(2)) >= least, out
    flags = _cpu_flags()
    if {"avx2", "fma"} <= flags:  # the host build is -march=native: the vector path must be the one compared
        assert "vmath kernel: avx2-fma" in out and "vmath_i8 kernel: avx2" in out, out
        if "avx512f" not in flags:  # Eigen's packet is 8 floats: the 4-row kernel replaces its product
            assert "gemv kernel: eigen-order-avx2-4row" in out, out
