"""`quadfdi export` end to end on a small simulated run with random-weight checkpoints."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import pytest

from quadfdi.formats.manifest import ARTIFACT_KEYS, check_files, load_manifest
from quadfdi.formats.reference_bin import read_reference
from quadfdi.formats.weights_bin import read_weights
from quadfdi.formats.dataset import load_dataset, make_windows
from tests.conftest import quadfdi, random_weight_run

def quadfdi_export(*args: str) -> subprocess.CompletedProcess:
    return quadfdi("export", *args)


@pytest.fixture(scope="module")
def exported(small_run, tmp_path_factory) -> Path:
    run = random_weight_run(small_run, tmp_path_factory.mktemp("export") / "run")
    res = quadfdi_export("--run", str(run), "--steps", "2")
    assert res.returncode == 0, res.stderr
    assert "verification passed" in res.stdout
    return run


def test_export_writes_every_file_and_a_passing_manifest(exported):
    folder = exported / "export"
    m = load_manifest(folder / "manifest.json")
    assert m["artifacts"] == {"cnode_fp32": "cnode_rk4_2.onnx", "cnode_int8": "cnode_rk4_2.int8.onnx",
                              "gru_fp32": "gru.onnx", "gru_int8": "gru.int8.onnx"}
    expected = set(m["artifacts"].values()) | {"weights.bin", "reference.bin", "coverage.md", "manifest.json"}
    assert {p.name for p in folder.iterdir()} == expected  # no side files: every ONNX is self-contained
    check_files(m, folder)
    assert m["solver"]["steps"] == 2 and m["solver"]["method"] == "rk4" and len(m["solver"]["stage_times"]) == 5
    assert m["opset"] >= 17 and m["window"] == 80 and m["class_names"][0] == "Healthy"
    assert len(m["channels"]) == 23 and m["channels"][12] == {"name": "V_b", "unit": "V"}
    assert len(m["normalisation"]["cnode"]["mean"]) == 23
    v = m["verification"]
    assert v["passed"] and v["cnode_fp32_vs_pytorch"]["passed"] and v["gru_fp32_vs_pytorch"]["passed"]
    assert v["test_windows"] == len(make_windows(load_dataset(exported / "dataset.npz"), "test"))
    for key in ARTIFACT_KEYS:
        assert 0.0 <= m["metrics"][key]["macro_f1"] <= 1.0
        assert v["batch_independence"][key]["max_abs_logit_diff"] == 0.0
        sess = ort.InferenceSession(str(folder / m["artifacts"][key]), providers=["CPUExecutionProvider"])
        assert sess.run(["logits"], {"telemetry": np.zeros((2, 80, 23), np.float32)})[0].shape == (2, 4)
    for model in ("cnode", "gru"):
        s = m["quantization"]["coverage"][model]["summary"]
        assert s["int8_mac_share"] >= 0.95 and s["initializer_bytes_ratio"] <= 0.35 and s["meets_targets"]
    assert "| MatMulIntegerToFloat | int8 |" in (folder / "coverage.md").read_text()
    enc = m["quantization"]["encoding"]  # which activation type per model, and which contrib ops
    assert enc["cnode"]["activations"] == "uint8" and enc["cnode"]["weight_bits"] == 7
    assert enc["gru"] == {"activations": "uint8", "activation_zero_point": 128, "weight_bits": 7,
                          "weight_range": [-63, 63], "contrib_ops": ["com.microsoft.MatMulIntegerToFloat"],
                          "subgraph_ops": ["Scan"]}  # the recurrence in one Scan
    assert enc["cnode"]["contrib_ops"] == ["com.microsoft.MatMulIntegerToFloat"] and enc["cnode"]["subgraph_ops"] == []
    w = read_weights(folder / "weights.bin")
    assert w.section("cnode", "int8").dims[5] == 2
    ref = read_reference(folder / "reference.bin")
    assert ref.section("none", "none")["telemetry"].shape == (4, 80, 23)
    onnx.checker.check_model(str(folder / "cnode_rk4_2.int8.onnx"), full_check=True)


def test_missing_checkpoint_is_a_one_line_error_and_writes_nothing(small_run, tmp_path):
    run = random_weight_run(small_run, tmp_path / "run", kinds=("cnode",))
    res = quadfdi_export("--run", str(run))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "gru.pt does not exist" in lines[0], res.stderr
    assert not (run / "export").exists()


def test_bad_steps_is_a_one_line_error(small_run, tmp_path):
    run = random_weight_run(small_run, tmp_path / "run")
    res = quadfdi_export("--run", str(run), "--steps", "0")
    assert res.returncode == 2 and "export.steps must be positive" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_a_wrong_gru_graph_stops_the_export_before_anything_is_written(small_run, tmp_path, monkeypatch):
    """The pipeline's own parity check catches a GRU exported with linear_before_reset=0."""
    import functools

    import quadfdi.export.run as export_run_module
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.core.rundir import open_run

    run_dir = random_weight_run(small_run, tmp_path / "run")
    wrong = functools.partial(export_run_module.build_gru_fp32, linear_before_reset=0)
    monkeypatch.setattr(export_run_module, "build_gru_fp32", wrong)
    run, cfg = open_run(run_dir, ["export.steps=1", "export.calib_windows=64"])
    with pytest.raises(QuadfdiError, match=r"verification failed, nothing written: gru_fp32_vs_pytorch .* on \d+ "
                                           r"windows \(at most \d+ may be, each within float32 rounding\)"):
        export_run_module.export_run(run, cfg, log=lambda s: None)
    assert not (run_dir / "export").exists()
