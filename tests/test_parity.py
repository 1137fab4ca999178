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

from quadfdi.formats.weights_bin import read_weights
from quadfdi.parity import compare
from quadfdi.runtimes import ort as ort_rt
from quadfdi.runtimes.mcu import tools_missing
from quadfdi.parity.run import parity_run
from quadfdi.cli import STAGES, main
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.npzio import read_npz
from quadfdi.core.rundir import open_run
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
    real = ort_rt.outputs  # what the stage calls: the logits first, then the motor head's if any
    shift = 3 * compare.INT8_TOL_STEPS * compare.logit_steps(read_weights(run_dir / "export" / "weights.bin"), "gru")

    def shifted(path, x, names, batch=ort_rt.CHUNK):
        out = real(path, x, names, batch)
        return [out[0] + shift.astype(np.float32), *out[1:]] if path.name == "gru.int8.onnx" else out

    monkeypatch.setattr(ort_rt, "outputs", shifted)
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
    check_stream_table(out, r)


def check_stream_table(out: Path, parity_json: dict) -> None:
    """mcu_stream.json (parity/stream.py): every model's strides as the host's on both cores; the M4
    trace's instructions equal -icount's within one SysTick tick per push; cycles >= instructions;
    the worst decision's time and the duty cycle follow from the counts, the clock and the period."""
    t = json.loads((out / "mcu_stream.json").read_text())
    assert t["passed"] and not t["problems"] and parity_json["mcu"]["stream"]["passed"]
    assert set(t["cores"]) == {"cortex-m4", "cortex-m7"} and t["cycle_model"]["traced_cores"] == ["cortex-m4"]
    assert len(t["flights"]["dataset_rows"]) == 2 and t["sample_period_ms"] == pytest.approx(40.0)
    stride, period_s = t["stride"], t["sample_period_ms"] / 1e3
    for cpu, core in t["cores"].items():
        assert set(core["models"]) == {"cnode_fp32", "cnode_int8", "gru_fp32", "gru_int8"}
        assert 39.0 < core["instructions_per_tick"] < 41.0
        for key, m in core["models"].items():
            h = core["host_check"][key]
            assert h["strides"] > 0 and (key.endswith("fp32") or h["vote_flips"] == 0)
            ins, mhz = m["instructions"], t["clock_mhz"][cpu]
            assert 0 < ins["push_mean"] <= ins["push_max"] and 0 < ins["decision_mean"] <= ins["decision_max"]
            assert m["decisions"] == 2 * 3 and m["pushes"] + m["decisions"] + m["other_strides"] == m["samples"]
            assert m["worst_decision_ms"] == pytest.approx(ins["decision_max"] / mhz / 1e3)
            assert m["duty"] == pytest.approx((ins["decision_mean"] + (stride - 1) * ins["push_mean"])
                                              / (stride * period_s * mhz * 1e6), rel=1e-3)
            if cpu != "cortex-m4":
                assert "cycles" not in m
                continue
            c, chk = m["cycles"], m["trace_check"]
            # per push one tick (40 instructions) and rounding, and 2 calibration ticks in 100,001 over the count
            slack = lambda total, n: n * 41 + -(-2 * total // core["calibration_ticks"])  # noqa: E731
            assert chk["within"] and 99_990 < core["calibration_ticks"] < 100_010
            for part in ("decisions", "pushes"):
                n, ic = chk[part]["n"], chk[part]["icount"]
                assert n > 0 and abs(chk[part]["trace"] - ic) <= slack(ic, n) == chk[part]["slack"]
            assert abs(chk["decision_max"]["trace"] - ins["decision_max"]) <= slack(ins["decision_max"], 1)
            assert c["decision_max"] >= chk["decision_max"]["trace"] >= 0.9999 * ins["decision_max"]
            assert c["per_instruction"] >= 1.0 and c["decision_mean"] >= 0.9999 * ins["decision_mean"]
            assert c["push_mean"] >= ins["push_mean"] - 41
            assert c["worst_decision_ms"] == pytest.approx(c["decision_max"] / mhz / 1e3)
            assert c["duty"] == pytest.approx((c["decision_mean"] + (stride - 1) * c["push_mean"])
                                              / (stride * period_s * mhz * 1e6), rel=1e-3)
            w = c["worst_decision"]
            assert sum(w["class_cycles"].values()) == w["cycles"] <= c["decision_max"]
            assert w["class_cycles"]["branch_refills"] == w["taken_branches"] * t["cycle_model"]["refill_cycles"]
    md = (out / "parity.md").read_text()
    assert "## On-board streaming cost (Cortex-M under QEMU)" in md and "**as the host**" in md
    assert md.count("| GRU int8 |") == 1 and md.count("| CNODE fp32 |") == 1


# ------------------------------------------------------------------------------ contracts written once


def test_generated_headers_are_current(tmp_path):
    """Every committed generated C++ header is what its Python table generates now (regenerate:
    `python -m quadfdi.core.contracts --header`, `python -m quadfdi.core.channels --header` and
    `python -m quadfdi.formats.weights_layout --header`, `python -m quadfdi.core.vehicle_record --header`,
    `python -m quadfdi.core.causal --header`)."""
    from quadfdi.core import causal, channels, contracts, vehicle_record
    from quadfdi.formats import weights_layout

    modules = (contracts, channels, weights_layout, vehicle_record, causal)
    generated = sorted(p.name for p in contracts.HEADER_PATH.parent.glob("*_gen.hpp"))
    assert generated == sorted(m.HEADER_PATH.name for m in modules), "a *_gen.hpp without its generator here"
    for module in modules:
        fresh = tmp_path / module.HEADER_PATH.name
        assert contracts.header_cli(["--header", str(fresh)], module.HEADER_PATH, module.cpp_header, "m") == 0
        assert module.HEADER_PATH.read_text() == fresh.read_text(), f"stale {module.HEADER_PATH.name}: regenerate it"
        assert module.HEADER_PATH.read_text().startswith("// GENERATED by `python -m ")


def expected_contract_lines() -> list[str]:
    """What fwref_contracts must print, from the Python tables alone."""
    from quadfdi.core import contracts
    from quadfdi.core.rk4 import RK4_CONSTANT_NAMES
    from quadfdi.export import reference_bin
    from quadfdi.formats.weights_layout import LAYOUTS, MAGIC, MOTOR_SECTION_ORDER, SECTION_ORDER, VERSION, dtype_of

    lines = [f"weights {MAGIC.rstrip(bytes(1)).decode()} {VERSION}",
             f"reference {reference_bin.MAGIC.rstrip(bytes(1)).decode()} {reference_bin.VERSION}"]
    for model, precision in SECTION_ORDER + MOTOR_SECTION_ORDER:  # then the optional motor-head sections
        layout = LAYOUTS[model]
        lines.append(f"section {model} {precision}")
        for d in layout.dims:
            if d.derived:
                sym, a, b = d.derived
                lines.append(f"dim {d.symbol} {d.index} = {a}{sym} + {b}")
            else:
                lines.append(f"dim {d.symbol} {d.index} limit {d.macro}")
        for spec in layout.specs(precision):
            lines.append(f"tensor {spec.name} {dtype_of(spec, precision).name} ({','.join(spec.shape)})")
    lines += [f"class {k} {n}" for k, n in zip(contracts.CLASS_LABELS, contracts.CLASS_NAMES)]
    lines += [f"split {k} {v}" for k, v in contracts.SPLITS.items()]
    lines += [f"tolerance {k} {v!r}" for k, v in contracts.TOLERANCES.items()]
    lines.append(f"parity fp32 {contracts.FP32_CPP_REL_TOL!r} int8 {contracts.INT8_TOL_STEPS!r}")
    lines += [f"rk4 {i} {n}" for i, n in enumerate(RK4_CONSTANT_NAMES)]
    lines.append("rk4_consts_index " + " ".join(str(i) for i in range(len(RK4_CONSTANT_NAMES))))
    return lines + expected_table_lines()


def expected_table_lines() -> list[str]:
    """fwref_contracts' lines of the classes, section codes, policy keys, channels and profiles."""
    from quadfdi.core import contracts
    from quadfdi.core.channels import CHANNELS, PROFILE_TABLE, stream_raw

    lines = [f"known_class {i} {n} rotor {int(r)}" for i, (n, r) in enumerate(contracts.CLASS_TABLE)]
    lines += [f"model_code {code} {name}" + (" policy" if name in contracts.POLICY_NETWORKS else "")
              for name, code in sorted(contracts.MODEL_CODES.items(), key=lambda kv: kv[1])]
    lines += [f"policy_key {i} {k}" for i, k in enumerate(contracts.POLICY_KEYS)]
    values = dict(zip(contracts.POLICY_KEYS, (0.25, 1, 2, 3, True)))  # the C++ tool's positional AlarmParams
    lines.append("alarm_params " + " ".join(str(int(values[k])) if k != "threshold" else "0.25" for k in
                                            ("threshold", "k", "n", "clear_m", "latch")))
    lines += [f"channel {c.id} {c.name}" for c in CHANNELS]
    lines += [f"profile {p.id} {p.name} raw {','.join(stream_raw(p)) if p.raw else ''} model "
              f"{','.join(c.name for c in p.model) if p.raw else ''}" for p in PROFILE_TABLE]
    return lines


def test_cpp_contracts_equal_the_python_tables(host_build):
    """The compiled C++ binder (member types visited through the generated table), the tolerances
    its parity rule uses, the classes, split codes and RK4 constants agree with the Python tables."""
    import subprocess

    res = subprocess.run([str(host_build / "fwref_contracts")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    got = res.stdout.splitlines()
    want = expected_contract_lines()
    numeric = ("tolerance ", "parity ")
    assert [ln for ln in got if not ln.startswith(numeric)] == [ln for ln in want if not ln.startswith(numeric)]
    for g, w in zip([ln for ln in got if ln.startswith(numeric)], [ln for ln in want if ln.startswith(numeric)]):
        gp, wp = g.split(), w.split()
        assert [x for x in gp if not x[0].isdigit()] == [x for x in wp if not x[0].isdigit()], (g, w)
        assert [float(x) for x in gp if x[0].isdigit()] == [float(x) for x in wp if x[0].isdigit()], (g, w)
    assert len(got) == len(want)


def test_parity_tolerances_come_from_the_contracts():
    from quadfdi.core import contracts
    from quadfdi.export import verify

    assert compare.FP32_REL_TOL == contracts.FP32_CPP_REL_TOL
    assert (compare.INT8_ARGMAX_MIN, compare.INT8_TOL_STEPS) == (contracts.INT8_ARGMAX_MIN, contracts.INT8_TOL_STEPS)
    assert verify.FP32_REL_TOL == contracts.FP32_ORT_VS_TORCH_REL_TOL
    assert contracts.FP32_ORT_VS_TORCH_REL_TOL < contracts.FP32_CPP_REL_TOL  # two entries, two pairs
