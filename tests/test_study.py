"""`quadfdi train study --readme`: the table between the results markers is replaced, every other
byte of the README is kept; a README without the markers is refused before any training."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tests.conftest import ROOT, copy_run, quadfdi
from quadfdi.train.study import README_END, README_START

TINY = ("--set", "train.epochs=1", "--set", "train.batch_size=48")


def _split(data: bytes) -> tuple[bytes, bytes, bytes]:
    """(up to and with the start marker, between the markers, from the end marker on)."""
    start, end = README_START.encode(), README_END.encode()
    assert data.count(start) == 1 and data.count(end) == 1
    head, rest = data.split(start)
    middle, tail = rest.split(end)
    return head + start, middle, end + tail


def _run_copy(small_run: Path, out: Path) -> Path:
    copy_run(small_run, out)
    return out


@pytest.fixture(scope="module")
def study(small_run, tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    run = _run_copy(small_run, root / "run")
    readme = root / "README.md"
    shutil.copy(ROOT / "README.md", readme)
    res = quadfdi("train", "study", "--run", str(run), "--seeds", "0,1", "--readme", str(readme), *TINY)
    assert res.returncode == 0, res.stderr
    return run, readme


def test_study_rewrites_only_the_table_between_the_markers(study):
    run, readme = study
    head0, middle0, tail0 = _split((ROOT / "README.md").read_bytes())
    head1, middle1, tail1 = _split(readme.read_bytes())
    assert head1 == head0 and tail1 == tail0  # every byte outside the markers is kept
    assert middle1 != middle0
    table = (run / "results.md").read_text()
    assert middle1 == b"\n" + table.encode()  # exactly the study's table, as written to results.md
    assert "(seeds 0, 1; mean ± std over seeds)" in table
    for row in ("| Neural ODE (quadfdi) |", "| GRU (quadfdi) |", "| LogReg baseline (quadfdi) |"):
        assert table.count(row) == 2  # Table 3 and Table 4


def test_study_writes_seeds_json(study):
    run, _ = study
    seeds = json.loads((run / "seeds.json").read_text())
    assert seeds["seeds"] == [0, 1] and len(seeds["seconds_per_seed"]) == 2
    assert set(seeds) >= {"cnode", "gru", "baseline"}
    assert len(seeds["cnode"]["macro_f1"]) == 2
    assert len(seeds["baseline"]["macro_f1"]) == 2  # seed 0's from the train stage, seed 1's from its cnode job


def test_one_job_per_seed_fits_the_baseline(small_run):
    """Every network of a seed would fit the same baseline: the first job of the seed does, the others
    skip it; a seed whose other network the train stage holds takes the baseline from there."""
    from quadfdi.core.config import load_config
    from quadfdi.core.rundir import RunDir
    from quadfdi.train.study_jobs import seed_model_jobs

    cfg = load_config(small_run / "config.toml")
    jobs = seed_model_jobs(RunDir(small_run), cfg, [0, 1], cache_root=small_run / "nowhere",
                           skip={("cnode", cfg.sim.seed, 0)})
    got = {(j.args[1].train.seed, j.args[2]): j.args[3] for j in jobs}
    assert got == {(0, "gru"): False, (1, "cnode"): True, (1, "gru"): False}


@pytest.mark.parametrize("content", ["# A README without the results markers\n", None])
def test_readme_without_markers_is_a_one_line_error_before_training(small_run, tmp_path, content):
    run = _run_copy(small_run, tmp_path / "run")
    readme = tmp_path / "README.md"
    if content is not None:
        readme.write_text(content)
    res = quadfdi("train", "study", "--run", str(run), "--seeds", "0", "--readme", str(readme), *TINY)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    if content is None:
        assert "does not exist" in lines[0] and not readme.exists()
    else:
        assert "has no results markers to replace" in lines[0]
        assert readme.read_text() == content
    # refused up front: nothing was trained, no study output was written
    assert not (run / "seeds.json").exists() and not (run / "results.md").exists()
    assert "train cnode" not in res.stdout
