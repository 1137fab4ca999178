"""`quadfdi parity`: the stage end to end on a small exported run, its report, its failure modes,
and its pair metrics against scikit-learn."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import mean_squared_error
from sklearn.metrics.pairwise import cosine_similarity

from export.weights_bin import read_weights
from parity import compare, runners
from parity.mcu import tools_missing
from parity.run import parity_run
from quadfdi.cli import STAGES, main
from core.errors import QuadfdiError
from core.npzio import read_npz
from core.rundir import open_run
from tests.test_firmware_fixtures import fw_run, host_build  # noqa: F401 (fixtures)

PAIRS = ("cpp_fp32_vs_ort_fp32", "cpp_fp32_vs_torch", "ort_fp32_vs_torch", "cpp_int8_vs_ort_int8",
         "cpp_int8_vs_cpp_fp32", "ort_int8_vs_ort_fp32")


@pytest.fixture(autouse=True)
def parity_stage(monkeypatch):
    """Until quadfdi/cli.py lists the stage, register it for these tests (a no-op afterwards)."""
    if "parity" not in STAGES:
        monkeypatch.setitem(STAGES, "parity", "parity.cli")


def copy_run(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("parity"))
    return dst


@pytest.fixture(scope="module")
def parity_done(fw_run, host_build, tmp_path_factory):
    run = copy_run(fw_run, tmp_path_factory.mktemp("parity") / "run")
    if "parity" not in STAGES:  # the autouse fixture is function-scoped
        STAGES["parity"] = "parity.cli"
        try:
            rc = main(["parity", "--run", str(run), "--no-mcu"])
        finally:
            del STAGES["parity"]
    else:
        rc = main(["parity", "--run", str(run), "--no-mcu"])
    assert rc == 0
    return run


def test_parity_report(parity_done):
    out = parity_done / "parity"
    assert sorted(p.name for p in out.iterdir()) == ["logits.npz", "parity.json", "parity.md"]
    r = json.loads((out / "parity.json").read_text())
    assert r["passed"] and not r["problems"] and r["schema_version"] == 1
    assert r["fwref_parity"]["passed"] and r["fwref_parity"]["output"][-1] == "fwref_parity: all 18 tensors OK"
    assert r["mcu"] == {"skipped": "not requested (--no-mcu)"}
    assert r["export_steps"] == 8
    for model in ("cnode", "gru"):
        pairs = r["models"][model]
        assert tuple(pairs) == PAIRS
        for m in pairs.values():
            assert m["windows"] == r["test_windows"] > 0
            assert {"max_abs_diff", "rmse", "rel_l2", "cosine", "argmax_agreement"} <= set(m)
        assert pairs["cpp_fp32_vs_ort_fp32"]["target"]["passed"]
        assert pairs["cpp_fp32_vs_ort_fp32"]["argmax_agreement"] == 1.0
        t8 = pairs["cpp_int8_vs_ort_int8"]["target"]
        assert t8["passed"] and t8["max_diff_steps"] <= compare.INT8_TOL_STEPS
    md = (out / "parity.md").read_text()
    assert "C++ int8 vs ONNX Runtime int8" in md and "**Result: pass**" in md and "fwref_parity: all 18" in md


def test_report_metrics_equal_scikit_learn(parity_done):
    r = json.loads((parity_done / "parity" / "parity.json").read_text())
    lg = read_npz(parity_done / "parity" / "logits.npz")
    for model in ("cnode", "gru"):
        for pair, m in r["models"][model].items():
            a_key, b_key = pair.split("_vs_")
            a, b = lg[f"{model}_{a_key}"].astype(np.float64), lg[f"{model}_{b_key}"].astype(np.float64)
            assert m["rmse"] == pytest.approx(np.sqrt(mean_squared_error(b.ravel(), a.ravel())), rel=1e-9, abs=1e-15)
            assert m["cosine"] == pytest.approx(cosine_similarity(a.reshape(1, -1), b.reshape(1, -1))[0, 0], abs=1e-12)
            assert m["argmax_agreement"] == np.mean(a.argmax(1) == b.argmax(1))


def test_pair_metrics_on_known_values():
    b = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 2.0, 0.0, 0.0]])
    a = b + np.array([[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 3.0, 0.0]])  # window 1's argmax moves to class 2
    m = compare.pair_metrics(a, b)
    assert m["max_abs_diff"] == 3.0 and m["rmse"] == pytest.approx(np.sqrt(9 / 8))
    assert m["rel_l2"] == pytest.approx(3 / np.sqrt(5)) and m["argmax_agreement"] == 0.5
    assert m["bitwise_identical_windows"] == 1 and m["cosine"] == pytest.approx(5 / (np.sqrt(5) * np.sqrt(14)))


def test_a_missed_target_writes_the_report_then_fails(fw_run, host_build, tmp_path, monkeypatch):
    """ONNX Runtime's int8 GRU logits moved by three times the tolerance: the int8 target fails, the
    report says so, and the stage raises a one-line error naming the pair."""
    run_dir = copy_run(fw_run, tmp_path / "run")
    real = runners.ort_logits
    shift = 3 * compare.INT8_TOL_STEPS * compare.logit_steps(read_weights(run_dir / "export" / "weights.bin"), "gru")

    def shifted(path, x):
        out = real(path, x)
        return (out + shift.astype(np.float32)) if path.name == "gru.int8.onnx" else out

    monkeypatch.setattr(runners, "ort_logits", shifted)
    run, cfg = open_run(run_dir)
    with pytest.raises(QuadfdiError, match="gru cpp_int8_vs_ort_int8") as info:
        parity_run(run, cfg, log=lambda _: None, mcu=False)
    assert "\n" not in str(info.value)
    r = json.loads((run_dir / "parity" / "parity.json").read_text())
    assert not r["passed"] and not r["models"]["gru"]["cpp_int8_vs_ort_int8"]["target"]["passed"]
    assert r["models"]["cnode"]["cpp_int8_vs_ort_int8"]["target"]["passed"]
    assert "**Result: FAIL**" in (run_dir / "parity" / "parity.md").read_text()


def test_missing_export_is_a_one_line_error(fw_run, tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(fw_run / "config.toml", run / "config.toml")
    assert main(["parity", "--run", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "export is missing" in err[0]


def test_mcu_only_updates_the_report(parity_done):
    """`quadfdi parity --mcu` after a host run: mcu.json, and the Cortex-M table in parity.json/md."""
    missing = tools_missing()
    if missing:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {missing}")
    assert main(["parity", "--run", str(parity_done), "--mcu"]) == 0
    out = parity_done / "parity"
    mcu = json.loads((out / "mcu.json").read_text())
    assert mcu["passed"] and set(mcu["cpus"]) == {"cortex-m4", "cortex-m7"}
    r = json.loads((out / "parity.json").read_text())
    assert r["passed"] and r["mcu"]["cpus"]["cortex-m4"]["models"]["cnode_int8"]["flash_bytes"] <= 64 * 1024
    md = (out / "parity.md").read_text()
    assert "| cortex-m7 (mps2-an500) | gru int8 |" in md and "**met**" in md


def test_tolerances_agree_between_python_and_cpp():
    """parity/compare.py mirrors firmware_ref/include/fwref/parity.hpp."""
    import re

    text = (Path(__file__).resolve().parents[1] / "firmware_ref" / "include" / "fwref" / "parity.hpp").read_text()
    consts = {k: float(v) for k, v in re.findall(r"constexpr double (\w+) = ([0-9.eE+-]+);", text)}
    assert consts == {"kF32RelTol": compare.FP32_REL_TOL, "kI8TolSteps": compare.INT8_TOL_STEPS}
