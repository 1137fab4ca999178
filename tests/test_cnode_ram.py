"""An int8 CNODE too wide for its int16 weight copies within the Cortex-M static-RAM target (16 KiB): the
Cortex-M step of `quadfdi parity` builds it again without them (lin1_z, lin2 read as int8 from flash) and
it passes there, every tensor as the host's, V's rows in the three-row ring (fwref/cnode.hpp)."""
from __future__ import annotations

import pytest

from quadfdi.parity.mcu import TARGETS, run_cpu
from quadfdi.runtimes.mcu import tools_missing
from tests.conftest import trained_export_run

# latent 16, hidden 256: the int16 copies alone are (256 * 16 + 16 * 256) * 2 = 16,384 B, the whole target
WIDE = ("train.epochs=1", "train.threads=1", "train.latent=16", "train.hidden=256", "train.gru_hidden=16")


def test_a_cnode_too_wide_for_its_int16_copies_is_built_without_them(small_run, tmp_path):
    missing = tools_missing()
    if missing:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {missing}")
    export = trained_export_run(small_run, tmp_path / "wide", *WIDE) / "export"
    lines: list[str] = []
    r = run_cpu("cortex-m4", export / "weights.bin", export / "reference.bin", log=lines.append)
    bound = TARGETS["cnode_int8"]["static_ram_bytes"]
    m = r["models"]["cnode_int8"]
    assert r["passed"] and all(t["ok"] for t in r["tensors"]) and len(r["tensors"]) == 18, r["output"]
    assert m["int16_weight_copies"] is False and m["static_ram_bytes"] <= bound
    first = m["with_int16_copies"]
    assert first["static_ram_bytes"] > bound  # why it was rebuilt, said in the log
    assert first["static_ram_bytes"] - m["static_ram_bytes"] >= (256 * 16 + 16 * 256) * 2
    assert any("rebuilt without them" in ln for ln in lines), lines
    # the int8 kernel on flash does more work per MAC than the int16 one
    assert m["instructions_per_inference"] > first["instructions_per_inference"]
