"""The vehicle record on the Cortex-M4 under QEMU: the stream image replays flightlog-phys test flights of the
tiny fleet (tests/conftest.py physics_export), each with its vehicle's record compiled in beside its samples and
loaded at the flight's reset (parity/stream.py), every stride held against the host's fwref_stream on the same
stream files (int8 bit-identical, fp32 within the parity tolerance); the worst decision of each model by the M4
cycle table stays within one 40 ms sample period. flightlog-phys holds every channel of flightlog-ref (the
deviations from the record) and adds the causal physics channels, so one export covers both on-board paths."""

from __future__ import annotations

import pytest

from quadfdi.runtimes.mcu import tools_missing
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)


def test_cortex_m4_stream_with_the_vehicle_record(physics_export, host_build):  # noqa: F811
    missing = tools_missing()
    if missing:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {missing}")
    from quadfdi.parity import stream as parity_stream
    from quadfdi.parity.mcu import run_cpu

    inputs = parity_stream.stream_inputs(physics_export.parent, host_build)
    assert not isinstance(inputs, str), inputs
    assert inputs.streams and all(rs.vehicle is not None for rs in inputs.streams.values())
    out = run_cpu("cortex-m4", physics_export / "weights.bin", physics_export / "reference.bin", log=lambda _: None,
                  stream=inputs)
    assert out["passed"] and out["tensors"], out["exit_meaning"]
    s = out["stream"]
    assert not s["problems"], s["problems"]
    assert {k for k in s["host_check"]} >= {"cnode_fp32", "cnode_int8", "gru_fp32", "gru_int8"}
    for key, h in s["host_check"].items():
        assert h["strides"] > 0 and (key.endswith("fp32") or h["vote_flips"] == 0), (key, h)
    worst = {k: m["cycles"]["worst_decision_ms"] for k, m in s["models"].items()}
    assert max(worst.values()) < 40.0, worst
    print("worst decision (M4 cycles): " + ", ".join(f"{k} {v:.2f} ms" for k, v in worst.items()))
