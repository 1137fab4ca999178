"""The streaming CNODE's step on the Cortex-M4 under QEMU (``quadfdi parity --scnode``, runtimes/mcu_scnode.py):
every sample of the replay flight against ONNX Runtime (int8 bit for bit), the traced cycles per step held to
the image's -icount count, the report; and the generator's refusal of a foreign file."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.runtimes.mcu import tools_missing
from tests.test_stream_cnode import _cli, scnode_run  # noqa: F401 (fixture: the tiny trained and exported run)


@pytest.fixture(scope="module")
def mcu_report(scnode_run):  # noqa: F811
    missing = tools_missing()
    if missing:
        pytest.skip(missing)
    assert _cli("parity", "--run", str(scnode_run), "--scnode") == 0
    from quadfdi.core.jsonio import read_json

    return read_json(scnode_run / "parity" / "scnode_mcu.json")


def test_scnode_on_the_m4_is_onnx_runtime_bit_for_bit(mcu_report, scnode_run):  # noqa: F811
    rep = np.load(scnode_run / "export" / "scnode_replay.npz")
    p = mcu_report["parity"]
    assert p["int8"]["bit_identical_samples"] == p["int8"]["samples"] == len(rep["logits"]) == 200
    assert p["fp32"]["passed"] and p["fp32"]["argmax_agreement"] == 1.0 and p["fp32"]["max_abs_diff"] < 1e-4
    assert mcu_report["passed"] and mcu_report["dims"]["latent"] == 6 and mcu_report["dims"]["hidden"] == 8


def test_scnode_m4_cycles_per_step(mcu_report, scnode_run):  # noqa: F811
    for prec in ("fp32", "int8"):
        c = mcu_report["cost"][prec]
        assert c["traced_steps"] == 64 and c["trace_vs_icount"]["within"]
        # every estimated cycle is at least an instruction; the step is far under 1 % of 40 ms at this width
        assert c["cycles_max"] >= c["instructions_max"] - c["trace_vs_icount"]["slack"] > 0
        assert c["meets_target"] and c["duty"] == pytest.approx(c["cycles_max"] / (0.04 * 168e6))
        assert sum(c["worst_step"]["class_cycles"].values()) == c["worst_step"]["cycles"]
    md = (scnode_run / "parity" / "scnode_mcu.md").read_text()
    assert "200/200" in md and "met by" in md


def test_generator_refuses_a_foreign_file(tmp_path):
    from quadfdi.runtimes.mcu_scnode_src import main

    bad = tmp_path / "bad.bin"
    bad.write_bytes(b"QSGRU1\0\0" + bytes(40))
    assert main(["--out", str(tmp_path / "gen"), str(bad)]) == 2
    assert not (tmp_path / "gen" / "fwref_scnode_data.cpp").exists()
