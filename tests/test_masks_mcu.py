"""The masked profile's model (tests/conftest.py masked_export) through parity: `quadfdi parity` on the host
(the whole test split, its flights under their mask patterns), then on the Cortex-M4 under QEMU the
reference windows and the stream image replaying flights under three patterns, every stride held
against the host's fwref_stream (int8 bit-identical, fp32 within the parity tolerance)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.core.contracts import SPLIT_TEST
from quadfdi.runtimes.mcu import tools_missing
from tests.conftest import quadfdi
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)


def _patterns(run) -> tuple[np.ndarray, np.ndarray]:
    """The masked run's test windows' flights and each dataset flight's pattern (models.inputs)."""
    from quadfdi.formats.dataset import load_dataset, make_windows
    from quadfdi.models.inputs import profiled_dataset

    ds = profiled_dataset(load_dataset(run / "dataset.npz"), "flightlog-mask")
    return make_windows(ds, "test").traj, ds["mask_pattern"]


def test_host_parity_on_the_masked_model(masked_export):
    res = quadfdi("parity", "--run", str(masked_export.parent), "--no-mcu")
    assert res.returncode == 0, res.stderr
    r = json.loads((masked_export.parent / "parity" / "parity.json").read_text())
    assert r["passed"]
    traj, pattern = _patterns(masked_export.parent)
    assert len({int(pattern[t]) for t in np.unique(traj)}) >= 3  # the test split holds several patterns


def test_cortex_m4_window_and_stream_parity_under_three_patterns(masked_export, host_build):  # noqa: F811
    missing = tools_missing()
    if missing:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {missing}")
    from quadfdi.core.profiles import flight_pattern
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset
    from quadfdi.parity import stream as parity_stream
    from quadfdi.parity.mcu import run_cpu

    run, ex = masked_export.parent, Export.open(masked_export)
    traj, pattern = _patterns(run)
    ref = json.loads((masked_export / "manifest.json").read_text())["reference"]["test_index"]
    assert len({int(pattern[traj[i]]) for i in ref}) >= 3  # reference.bin's windows: the Cortex-M window path
    ds, record = load_dataset(run / "dataset.npz"), ex.onboard()
    rows, seen = [], set()
    for row in np.flatnonzero(ds["split"] == SPLIT_TEST):
        name = flight_pattern(int(ds["traj_index"][row])).name
        if name not in seen and name != "all" and len(rows) < 3:
            rows.append(int(row)), seen.add(name)
    host = host_build / "fwref_stream"
    streams = {f"f{row}": parity_stream._cut_after_decisions(from_dataset(run / "dataset.npz", row, record, ds), host,
                                                             masked_export / "weights.bin", len(ex.class_names))
               for row in rows}
    assert len(seen) == 3 and all(not rs.carried_flags.all() for rs in streams.values()), seen
    inputs = parity_stream.StreamInputs(streams, record, host, rows)
    out = run_cpu("cortex-m4", masked_export / "weights.bin", masked_export / "reference.bin", log=lambda _: None,
                  stream=inputs)
    assert out["passed"] and out["tensors"], out["exit_meaning"]
    s = out["stream"]
    assert not s["problems"], s["problems"]
    assert {k for k in s["host_check"]} == {"cnode_fp32", "cnode_int8", "gru_fp32", "gru_int8"}
    for key, h in s["host_check"].items():
        assert h["strides"] > 0 and (key.endswith("fp32") or h["vote_flips"] == 0), (key, h)
    print(f"patterns {sorted(seen)}; worst decision (M4 cycles): "
          + ", ".join(f"{k} {m['cycles']['worst_decision_ms']:.2f} ms" for k, m in s["models"].items()))
