"""`quadfdi bench --quick` end to end on a tiny exported run: bench.json holds every field of its
contract (docs/bench.md); `quadfdi report` assembles report.md from every stage's own section
(absent stages say "Not run", a corrupt stage file is a one-line error); bad input is one line.
No timing assertions."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pytest

from tests.conftest import ROOT, copy_run, quadfdi, random_weight_run
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

LATENCY_KEYS = {"model", "runtime", "precision", "solver", "threads", "spinning", "batch", "p50_us", "p90_us",
                "p99_us", "throughput_wps"}
MEMORY_KEYS = {"model", "runtime", "precision", "solver", "item", "value", "unit", "source"}
LIMIT_KEYS = {"peak_gflops", "l2_gbps", "ort_call_us", "peak_gflops_2t", "peak_int8_gops", "ort_node_us", "caches"}
TOP_KEYS = {"schema_version", "producer", "command", "machine", "limits", "models", "latency", "ort_pairs",
            "cpp_pairs", "floors", "targets", "memory", "solvers", "profiles", "windows", "counts", "timing_s"}


def quadfdi_report(run: Path) -> subprocess.CompletedProcess:
    """``quadfdi report --run RUN`` through the real dispatcher."""
    return quadfdi("report", "--run", str(run))


def quadfdi_bench(*args: str) -> subprocess.CompletedProcess:
    """``quadfdi bench ...`` through the real dispatcher."""
    return quadfdi("bench", *args)


@pytest.fixture(scope="module")
def exported_run(small_run, tmp_path_factory) -> Path:
    """The session's simulated run + random-weight checkpoints, exported with N = 2 (in process)."""
    from quadfdi.core.config import replace_section
    from quadfdi.core.rundir import open_run
    from quadfdi.export.run import export_run

    out = random_weight_run(small_run, tmp_path_factory.mktemp("bench") / "run")
    run, cfg = open_run(out)
    export_run(run, replace_section(cfg, "export", steps=2, calib_windows=64), log=lambda s: None)
    return out


@pytest.fixture(scope="module")
def benched(exported_run, host_build) -> Path:  # noqa: F811 (the C++ rows: the cached host build made first)
    # timings on a test machine are not under test (test_pipeline does the same): with the other test
    # worker on the second core the peak probe reads low, the floors come out too high, and a floor
    # violation (reported in bench.json either way) must not fail the stage here
    args = ["--run", str(exported_run), "--quick", "--set", "bench.fail_below_floor=false"]
    res = quadfdi_bench(*args)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "bench: wrote" in res.stdout
    assert not (exported_run / "report.md").exists()  # report.md is the app layer's, not bench's
    res = quadfdi_report(exported_run)
    assert res.returncode == 0, res.stderr[-3000:]
    return exported_run


def test_bench_json_holds_every_field(benched):
    bench = json.loads((benched / "bench.json").read_text())
    assert TOP_KEYS <= set(bench)
    assert bench["schema_version"] == 1 and bench["quick"] is True
    assert LIMIT_KEYS <= set(bench["limits"])
    assert bench["limits"]["peak_gflops"] > 0 and bench["limits"]["l2_gbps"] > 0 and bench["limits"]["ort_call_us"] > 0
    recs = bench["latency"]
    for r in recs:
        assert LATENCY_KEYS <= set(r), r
        assert r["runtime"] in ("torch", "ort", "cpp") and r["precision"] in ("fp32", "int8")
        assert r["batch"] in (1, 96)
        assert r["p50_us"] > 0 and r["throughput_wps"] > 0
    settings = {(r["runtime"], r["model"], r["precision"], r["solver"]) for r in recs}
    expected = {("torch", "cnode", "fp32", "rk4-2"), ("torch", "cnode", "fp32", "dopri5-1e-3"),
                ("torch", "gru", "fp32", "gru")}
    expected |= {("ort", m, p, "rk4-2" if m == "cnode" else "gru") for m in ("cnode", "gru") for p in ("fp32", "int8")}
    expected |= {("cpp", m, p, "rk4-2" if m == "cnode" else "gru") for m in ("cnode", "gru") for p in ("fp32", "int8")}
    assert settings == expected
    assert all(r.get("spinning") is False for r in recs if r["runtime"] == "ort")
    assert all(r.get("spinning") is None for r in recs if r["runtime"] != "ort")
    from quadfdi.bench.latency import Counts
    from quadfdi.bench.timing.cpp import CPP_PROCESSES  # the C++ timings pool several processes (its module doc)
    from quadfdi.bench.config import BenchConfig
    quick = Counts.of(BenchConfig(), quick=True)
    assert all(r["n_calls"] == CPP_PROCESSES * (quick.n if r["batch"] == 1 else quick.batches)
               for r in recs if r["runtime"] == "cpp")
    assert len([r for r in recs if r["batch"] == 1]) == len([r for r in recs if r["batch"] == 96])
    assert all("x_floor" in r for r in recs if r["batch"] == 1)
    assert {(f["model"], f["precision"]) for f in bench["floors"]} == {(m, p) for m in ("cnode", "gru")
                                                                       for p in ("fp32", "int8")}
    for m in bench["memory"]:
        assert MEMORY_KEYS <= set(m), m
    items = {(m["item"], m["runtime"]) for m in bench["memory"]}
    assert ("parameters", None) in items and ("file_bytes", "ort") in items
    assert ("peak_rss_above_baseline_batch1_bytes", "ort") in items
    assert ("peak_rss_above_baseline_batch1_bytes", "torch") in items
    assert bench["solvers"] == [] and "no solver study" in bench["solvers_meta"]["note"]  # no solvers/solvers.json
    stream = bench["stream"]  # bench/stream.py: measured with the C++ reference, else skipped with a reason
    assert len(stream["latency"]) == 4 and len(stream["flights"]) == 1
    pairs = bench["ort_pairs"]  # bench/ort_pairs.py: fp32 and int8 interleaved in one process, per model
    assert set(pairs) == {"cnode", "gru"} and all([p["batch"] for p in v] == [1, 96] for v in pairs.values())
    for p in (p for v in pairs.values() for p in v):
        assert p["rounds"] >= quick.min_samples and p["fp32_p50_us"] > 0 and p["int8_p50_us"] > 0
        assert 0 < p["int8_over_fp32_p10"] <= p["int8_over_fp32_median"] <= p["int8_over_fp32_p90"]
    ort_rows = [t for t in bench["targets"] if t["target"].startswith("ORT int8")]
    assert len(ort_rows) == 4 and all("interleaved in one process" in t["detail"] for t in ort_rows)
    cpp_pairs = bench["cpp_pairs"]  # bench/cpp_pairs.py: fwref_pair, or skipped with the reason
    assert set(cpp_pairs) == {"cnode", "gru"} and all(v[0]["batch"] == 1 for v in cpp_pairs.values())
    assert all(v[0]["rounds"] == quick.n // 4 and v[0]["int8_over_fp32_median"] > 0 for v in cpp_pairs.values())
    cpp_rows = [t for t in bench["targets"] if "as fast as fp32" in t["target"]]
    assert len(cpp_rows) == 2 and all("in one process (fwref_pair)" in t["detail"] for t in cpp_rows)
    assert ("static_ram_bytes", "cpp") in items
    assert {t["model"] for t in bench["targets"]} == {"cnode", "gru"}
    assert all({"target", "measured", "threshold", "met"} <= set(t) for t in bench["targets"])


def test_skip_cpp_measures_python_and_ort_only_and_says_why(exported_run, tmp_path):
    """``--skip-cpp`` (a machine without the C++ toolchain, or a quicker pass): no C++ row, pair or stream, each
    part that needs the C++ reference skipped with the reason; the report still assembles and says so."""
    run = tmp_path / "skipcpp"
    shutil.copytree(exported_run, run, ignore=shutil.ignore_patterns("bench.json", "report.md", "figures"))
    res = quadfdi_bench("--run", str(run), "--quick", "--skip-cpp", "--set", "bench.fail_below_floor=false")
    assert res.returncode == 0, res.stderr[-3000:]
    bench = json.loads((run / "bench.json").read_text())
    assert " --quick --skip-cpp" in bench["command"]
    assert {r["runtime"] for r in bench["latency"]} == {"torch", "ort"}
    # weights.bin's size is a file's, read without the C++; the sizes of a built binary are not there
    assert {m["item"] for m in bench["memory"] if m["runtime"] == "cpp"} == {"file_bytes"}
    assert any("--skip-cpp" in s for s in bench["skipped"])
    for part in ("cpp_pairs", "stream"):
        assert set(bench[part]) == {"skipped"} and "--skip-cpp" in bench[part]["skipped"], part
    assert not any("as fast as fp32" in t["target"] for t in bench["targets"])  # the C++ int8 targets need fwref_pair
    res = quadfdi_report(run)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "C++ reference not measured: --skip-cpp" in (run / "report.md").read_text()


def test_report_assembles_every_stage_present(benched):
    text = (benched / "report.md").read_text()
    for heading in ("# quadfdi run report", "## Simulation", "## Export", "## Bench: latency, memory, limits",
                    "### int8 against fp32 in one process", "### Floors", "### Machine limits",
                    "### Memory"):
        assert heading in text, heading
    assert "## Training and test metrics\n\nNot run: no metrics.json" in text  # this run has no metrics.json
    assert "## Parity\n\nNot run:" in text
    for fig in ("bench_latency.png", "bench_throughput.png"):
        assert (benched / "figures" / fig).is_file()
        assert f"figures/{fig}" in text


def test_report_command_rewrites_from_the_files(benched):
    (benched / "report.md").unlink()
    (benched / "figures" / "bench_latency.png").unlink()
    res = quadfdi_report(benched)
    assert res.returncode == 0, res.stderr
    assert (benched / "figures" / "bench_latency.png").is_file()  # redrawn from bench.json
    assert (benched / "report.md").is_file() and "## Bench" in (benched / "report.md").read_text()


def test_report_of_a_run_with_only_a_dataset(small_run, tmp_path):
    from quadfdi.report import write_run_report

    run = tmp_path / "simonly"
    copy_run(small_run, run)
    text = write_run_report(run).read_text()
    assert "## Simulation" in text and "Not run: no dataset.npz" not in text
    for heading, file in (("## Bench: latency, memory, limits", "bench.json"), ("## Export", "export/manifest.json"),
                          ("## Training and test metrics", "metrics.json"), ("## Parity", "parity/parity.json")):
        assert f"{heading}\n\nNot run: no {file} in this run" in text, heading
    assert "## Headline" not in text  # no stage with headline numbers has run


def test_bad_input_is_one_line(exported_run, tmp_path):
    res = quadfdi_bench("--run", str(tmp_path / "nope"))
    assert res.returncode == 2 and res.stderr.startswith("quadfdi bench: error:")
    assert len(res.stderr.strip().splitlines()) == 1
    res = quadfdi_bench()
    assert res.returncode == 2 and "--run" in res.stderr
    noexport = tmp_path / "noexport"
    noexport.mkdir()
    shutil.copy(exported_run / "config.toml", noexport / "config.toml")
    shutil.copy(exported_run / "dataset.npz", noexport / "dataset.npz")
    res = quadfdi_bench("--run", str(noexport), "--quick")
    assert res.returncode == 2 and "export" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = quadfdi_bench("--run", str(exported_run), "--quick", "--cpus", "0,999")
    assert res.returncode == 2 and "--cpus" in res.stderr
    bad = tmp_path / "badbench"
    bad.mkdir()
    (bad / "bench.json").write_text("{truncated")
    res = quadfdi_report(bad)
    assert res.returncode == 2 and res.stderr.startswith("quadfdi report: error:") and "bench.json" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    res = quadfdi_report(tmp_path / "nope")
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    res = quadfdi_bench("solvers", "--run", str(exported_run))  # the solver study is no longer bench's
    assert res.returncode == 2


@pytest.mark.parametrize("stage_file", ["metrics.json", "history.json", "export/manifest.json", "parity/parity.json",
                                        "bench.json", "dataset.npz"])
def test_a_corrupt_stage_file_is_a_one_line_error(small_run, tmp_path, stage_file):
    """Report assembly never swallows: a truncated file of any stage stops it with one line naming the file."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.report import run_report_markdown

    run = tmp_path / "corrupt"
    copy_run(small_run, run)
    if stage_file == "history.json":  # read with the training section, which needs metrics.json
        (run / "metrics.json").write_text(json.dumps({"gru": {"macro_f1": 0.5}}))
    (run / stage_file).parent.mkdir(parents=True, exist_ok=True)
    (run / stage_file).write_text("{truncated")
    with pytest.raises(QuadfdiError) as err:
        run_report_markdown(run)
    assert Path(stage_file).name in str(err.value) and len(str(err.value).splitlines()) == 1


def test_a_foreign_bench_json_is_a_one_line_error(tmp_path):
    from quadfdi.bench.report import report_section
    from quadfdi.core.errors import QuadfdiError

    (tmp_path / "bench.json").write_text(json.dumps({"schema_version": 7}))
    with pytest.raises(QuadfdiError, match="schema version 1"):
        report_section(tmp_path)


def test_cortex_m_numbers_come_from_mcu_json(tmp_path):
    from quadfdi.bench.memory import mcu_records

    (tmp_path / "parity").mkdir()
    model = {"flash_bytes": 12000, "weights_bytes": 9000, "static_ram_bytes": 3000, "stack_peak_bytes": 400,
             "instructions_per_inference": 123456}
    (tmp_path / "parity" / "mcu.json").write_text(json.dumps(
        {"cpus": {"cortex-m4": {"machine": "mps2-an386", "models": {"cnode_int8": model, "gru_fp32": model}}}}))
    recs, raw = mcu_records(tmp_path)
    assert raw["cpus"]["cortex-m4"]["machine"] == "mps2-an386"
    got = {(r["runtime"], r["model"], r["precision"], r["item"]): r["value"] for r in recs}
    assert got[("cortex-m4", "cnode", "int8", "flash_bytes")] == 12000
    assert got[("cortex-m4", "gru", "fp32", "static_ram_bytes")] == 3000
    assert len(recs) == 8  # flash, weights, static RAM, stack for each of the two models
    assert mcu_records(tmp_path / "nothing") == ([], None)


def test_solver_records_of_a_run_without_the_study(tmp_path):
    from quadfdi.bench.run import solver_records

    records, meta = solver_records(tmp_path)
    assert records == [] and "solvers/solvers.json absent" in meta["note"]


def test_report_sections_in_stage_order(small_run, tmp_path):
    """The real stage modules, in the pipeline's order; a stage that has not run says so."""
    from quadfdi.report import run_report_markdown

    run = tmp_path / "nostudy"
    run.mkdir()
    shutil.copy(small_run / "config.toml", run / "config.toml")
    text = run_report_markdown(run)
    order = [text.index(h) for h in ("## Simulation", "## Training", "## Export", "## Parity", "## Bench",
                                     "## Solvers\n\nNot run: no solvers/solvers.json")]
    assert order == sorted(order)


def test_pipeline_runs_every_stage_in_order(tmp_path):
    from quadfdi.core.config import load_config
    from quadfdi.core.rundir import create_run
    from quadfdi.pipeline import STAGES, run_stages

    assert [name for name, _ in STAGES] == ["sim", "plots", "train", "study", "baselines", "evaluate", "export",
                                            "parity", "solvers", "bench", "realism", "report"]
    calls = []
    fake = tuple((name, lambda run, cfg, name=name, **kw: calls.append((name, run.root))) for name, _ in STAGES)
    run = create_run(tmp_path / "r", load_config(None))
    timings = run_stages(run, load_config(None), fake, log=lambda s: None)
    assert [c[0] for c in calls] == [name for name, _ in STAGES] and set(timings) == {n for n, _ in STAGES}


def test_help_prints_no_rest_markup():
    res = quadfdi("--help")
    assert res.returncode == 0 and "``" not in res.stdout and "report" in res.stdout


def test_bench_config_section(tmp_path):
    from quadfdi.core.config import load_config
    from quadfdi.core.errors import QuadfdiError

    cfg = load_config(ROOT / "configs" / "paper.toml", ["bench.windows=50", "bench.threads=[1]"])
    assert (cfg.bench.windows, cfg.bench.threads, cfg.bench.batch, cfg.bench.cpus) == (50, (1,), 96, "0,1")
    for bad, word in (("bench.threads=[]", "bench.threads"), ("bench.windows=0", "bench.windows"),
                      ("bench.cpus='a,b'", "bench.cpus"), ("bench.warmups=3", "unknown key bench.warmups")):
        with pytest.raises(QuadfdiError, match=word):
            load_config(None, [bad])


def test_counts_follow_the_config():
    from quadfdi.bench.latency import Counts
    from quadfdi.bench.config import BenchConfig

    c = Counts.of(BenchConfig(windows=40, warmup=4, batch=8, batches=3, budget_s=2.0, min_samples=3), quick=False)
    assert (c.n, c.warmup, c.batch, c.batches, c.budget_s, c.min_samples) == (40, 4, 8, 3, 2.0, 3)
    q = Counts.of(BenchConfig(batch=8), quick=True)
    assert (q.n, q.batch) == (20, 8)
