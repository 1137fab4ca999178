"""A run folder received from someone else is input like any other: its stage records and publish
journal must never make quadfdi touch a file outside the folder, and one damaged record must block
only what reads that stage's outputs. Each case is a crafted copy of a tiny simulated run."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from tests.faultkit import cli, copy_run, one_line_error


def _record(run: Path, stage: str) -> dict:
    return json.loads((run / ".stages" / f"{stage}.json").read_text())


def _outside(tmp_path: Path) -> tuple[Path, Path]:
    """A file beside the run folder and one at an absolute path elsewhere: the victims."""
    near = tmp_path / "beside.txt"
    far = tmp_path / "elsewhere" / "victim.txt"
    far.parent.mkdir()
    for p in (near, far):
        p.write_text("not quadfdi's\n")
    return near, far


def test_a_record_naming_files_outside_the_run_never_deletes_them(fault_sims, tmp_path):
    """`quadfdi report` republishes its stage and removes what the old record listed and the new one
    does not: a crafted old record listing ../beside.txt and an absolute path must not delete them."""
    run = copy_run(fault_sims["old"], tmp_path / "run")
    near, far = _outside(tmp_path)
    res = cli("report", "--run", str(run))
    assert res.returncode == 0, res.stderr
    rec = _record(run, "report")
    rec["outputs"] += [{"path": "../beside.txt", "sha256": "0" * 64, "bytes": 1},
                       {"path": str(far), "sha256": "0" * 64, "bytes": 1}]
    (run / ".stages" / "report.json").write_text(json.dumps(rec))
    res = cli("report", "--run", str(run))
    assert res.returncode == 0, res.stderr
    assert near.read_text() == far.read_text() == "not quadfdi's\n"
    assert all(not e["path"].startswith(("/", "..")) for e in _record(run, "report")["outputs"])  # repaired


def test_a_crafted_publish_journal_is_removed_not_rolled_forward(fault_sims, tmp_path):
    """`quadfdi check` finishes an interrupted publish; a journal whose record moves a planted file to
    ../planted.txt or deletes ../beside.txt is a damaged publish: deleted, and the folder still verifies."""
    run = copy_run(fault_sims["old"], tmp_path / "run")
    near, _ = _outside(tmp_path)
    pub = run / ".publish" / "sim"
    pub.mkdir(parents=True)
    (pub / "x").mkdir()
    (pub / "x" / "planted.txt").write_text("planted\n")
    rec = _record(run, "sim")
    rec["outputs"] = [{"path": "../planted.txt", "sha256": "0" * 64, "bytes": 8}]
    (pub / "record.json").write_text(json.dumps(rec))
    old = _record(run, "sim")
    old["outputs"].append({"path": "../beside.txt", "sha256": "0" * 64, "bytes": 1})
    res = cli("check", "--run", str(run))
    assert res.returncode == 0, res.stderr
    assert "removed a damaged publish of sim" in res.stdout
    assert not (tmp_path / "planted.txt").exists() and near.is_file() and not pub.exists()


def test_a_symlinked_folder_leading_out_is_refused(fault_sims, tmp_path):
    """A record listing linked/x where linked/ is a symlink to a folder outside: check refuses to read
    (or, re-publishing, to delete) through it."""
    from quadfdi.core.records import sha256_file

    run = copy_run(fault_sims["old"], tmp_path / "run")
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.copy(run / "config.toml", outside / "config.toml")
    os.symlink(outside, run / "linked")
    rec = _record(run, "sim")
    rec["outputs"].append({"path": "linked/config.toml", "sha256": sha256_file(outside / "config.toml"), "bytes": 1})
    (run / ".stages" / "sim.json").write_text(json.dumps(rec))
    res = cli("check", "--run", str(run))
    one_line_error(res)
    assert "leads out of" in res.stderr


def test_a_damaged_record_blocks_only_its_own_stage(fault_sims, tmp_path):
    """An unreadable .stages/bench.json: a stage that reads only sim's outputs still runs, check names
    the damaged record and says the other stages are intact; an unreadable record of a stage that is
    re-run (report) is replaced by the re-run."""
    run = copy_run(fault_sims["old"], tmp_path / "run")
    (run / ".stages" / "bench.json").write_text("{ not json")
    res = cli("sim", "plot", "--run", str(run), "--traj", "0")
    assert res.returncode == 0, res.stderr[-2000:]
    res = cli("check", "--run", str(run))
    one_line_error(res)
    assert ".stages/bench.json" in res.stderr and "re-run quadfdi bench" in res.stderr and "sim:" in res.stderr
    (run / ".stages" / "bench.json").unlink()
    assert cli("report", "--run", str(run)).returncode == 0
    (run / ".stages" / "report.json").write_text("[]")
    assert cli("report", "--run", str(run)).returncode == 0
    res = cli("check", "--run", str(run))
    assert res.returncode == 0 and "report:" in res.stdout, res.stderr


class _Planted:
    """A class no checkpoint may carry: its pickle names this module's global."""


def test_a_pickle_planted_in_a_checkpoint_runs_nothing_and_gives_no_torch_advice(tmp_path):
    import pytest
    import torch

    from quadfdi.core.errors import QuadfdiError
    from quadfdi.models.checkpoint import load_checkpoint

    path = tmp_path / "cnode.pt"
    torch.save({"version": 1, "architecture": {"kind": "cnode"}, "payload": _Planted()}, path)
    with pytest.raises(QuadfdiError) as exc:
        load_checkpoint(path, "cnode")
    text = str(exc.value)
    assert "pickled objects" in text and "weights_only" not in text and "\n" not in text


def test_a_foreign_file_in_the_shard_cache_is_named_not_a_traceback(fault_sims, tmp_path):
    import numpy as np

    from quadfdi.core.npzio import write_npz

    run = copy_run(fault_sims["old"], tmp_path / "run")
    shards = sorted((run / "cache" / "sim").glob("*.npz"))
    assert shards
    write_npz(shards[0], {"something": np.arange(3.0)})  # a valid npz of another content, under the shard's name
    res = cli("sim", "--out", str(run), "--set", "sim.n_traj=4", "--set", "sim.duration_s=8.0",
              "--set", "sim.onset_frac=[0.1, 0.3]", "--set", "sim.ramp_frac=[0.2, 0.4]")
    one_line_error(res)
    assert "is not a shard of this simulation" in res.stderr and shards[0].name in res.stderr


def test_an_output_folder_that_is_a_file_is_refused_before_the_compute(fault_sims, tmp_path):
    """figures/ replaced by a regular file: the stage that writes into it refuses before computing, naming
    the file, and no later command is left saying "File exists"."""
    run = copy_run(fault_sims["old"], tmp_path / "run")
    assert cli("sim", "plot", "--run", str(run), "--traj", "0").returncode == 0
    shutil.rmtree(run / "figures")
    (run / "figures").write_text("a file where the figures folder was\n")
    res = cli("sim", "plot", "--run", str(run), "--traj", "0")
    one_line_error(res)
    assert "figures is a file" in res.stderr
    res = cli("check", "--run", str(run))
    assert "File exists" not in res.stderr
