"""``quadfdi run`` end to end on a tiny config: every stage's files, every report section, and the
README's deployment block regenerated from the run (``quadfdi readme``)."""

from __future__ import annotations

import json
import shutil
import tomllib
from pathlib import Path

import pytest

from tests.conftest import ROOT, SMALL_SIM, quadfdi

# The paper's pipeline at toy sizes: each stage runs for real (C++ build, QEMU, ONNX Runtime,
# the solver study, the bench's worker processes), only the counts are small.
TINY = [*SMALL_SIM, "--set", "train.epochs=1",
        "--set", "solvers.sample=2", "--set", "solvers.steps=[1, 8]", "--set", "solvers.rtols=[1e-2]",
        "--set", 'solvers.fixed_methods=["rk4"]', "--set", 'solvers.adaptive_methods=["dopri5"]',
        "--set", 'solvers.jump="on"', "--set", 'solvers.controls=["point"]',
        "--set", "bench.windows=6", "--set", "bench.warmup=1", "--set", "bench.warmup_s=0.05",
        "--set", "bench.batch=8", "--set", "bench.batches=2", "--set", "bench.budget_s=0.5",
        "--set", "bench.min_samples=2", "--set", "bench.threads=[1]", "--set", "bench.profile_windows=4",
        "--set", "bench.callgrind_windows=1",
        # timings on a test machine are not under test: a floor violation is reported, not fatal here
        "--set", "bench.fail_below_floor=false"]

FILES = ("config.toml", "dataset.npz", "cnode.pt", "gru.pt", "metrics.json", "export/manifest.json",
         "export/weights.bin", "parity/parity.json", "parity/mcu.json", "parity/mcu_stream.json", "solvers/solvers.json", "bench.json",
         "predictions/index.json", "evaluation/evaluation.json", "realism/realism.json", "report.md")
SECTIONS = ("## Simulation", "## Training", "## Evaluation", "## Export", "## Parity", "## Bench", "## Solvers", "## Realism")


@pytest.fixture(scope="module")
def whole_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("pipeline") / "tiny"
    # A few minutes on an idle 2-core machine; the limit leaves room for a loaded one.
    res = quadfdi("run", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out), *TINY, timeout=2400)
    assert res.returncode == 0, res.stderr[-3000:]
    assert "stage times: sim" in res.stdout
    return out


def test_run_writes_every_stage_file_and_report_section(whole_run):
    missing = [f for f in FILES if not (whole_run / f).is_file()]
    assert not missing, missing
    text = (whole_run / "report.md").read_text()
    positions = [text.index(s) for s in SECTIONS]
    assert positions == sorted(positions)  # the pipeline's order
    assert "Not run" not in text
    stored = tomllib.loads((whole_run / "config.toml").read_text())  # the overrides are stored
    assert stored["bench"]["windows"] == 6 and stored["train"]["epochs"] == 1
    chosen = json.loads((whole_run / "evaluation/evaluation.json").read_text())["models"]
    per_net = json.loads((whole_run / "export/manifest.json").read_text())["alarm_per_model"]
    for net in ("cnode", "gru"):  # the export carries the policy evaluate chose for each network
        assert per_net[net]["source"].startswith("evaluation.json sha256 ")
        assert per_net[net]["policy"] == chosen[net]["policy"]


def test_readme_block_is_rewritten_from_the_run(whole_run, tmp_path):
    readme = tmp_path / "README.md"
    shutil.copy(ROOT / "README.md", readme)
    before = readme.read_text()
    res = quadfdi("readme", "--run", str(whole_run), "--readme", str(readme))
    assert res.returncode == 0, res.stderr
    after = readme.read_text()
    start, end = "<!-- deployment:start -->", "<!-- deployment:end -->"
    assert before.split(start)[0] == after.split(start)[0] and before.split(end)[1] == after.split(end)[1]
    block = after.split(start)[1].split(end)[0]
    bench = json.loads((whole_run / "bench.json").read_text())
    assert f"quadfdi readme --run {whole_run}" in block and bench["machine"]["cpu"] in block
    assert "| CNODE |" in block and "| GRU |" in block and "CNODE int8" in block


def test_readme_without_the_block_is_one_line(whole_run, tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("# no markers here\n")
    res = quadfdi("readme", "--run", str(whole_run), "--readme", str(readme))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "deployment:start" in res.stderr and readme.read_text() == "# no markers here\n"
