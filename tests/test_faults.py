"""Fault injection: SIGKILL/SIGTERM at named points of sim, train and export, overlapping writers,
a file-size limit standing in for a full disk, and outputs that are symlinks, FIFOs or folders.
After each, the next command finds the run folder in its old or its new published state."""

from __future__ import annotations

import fcntl
import os
import signal
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT
from tests.faultkit import TINY_SIM, assert_published, cli, copy_run, one_line_error, sim_cmd, snapshot

PAPER = str(ROOT / "configs/paper.toml")


@pytest.mark.parametrize("point,sig,expect", [
    ("staged", "TERM", "old"), ("before-publish", "KILL", "old"), ("mid-publish", "KILL", "new"),
    ("after-publish", "KILL", "new")])
def test_sim_killed_at_a_named_point(fault_sims, tmp_path, point, sig, expect):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    res = cli(*sim_cmd(run, 1), fault=f"sim:{point}:{sig}")
    if sig == "TERM":
        one_line_error(res)
        assert res.returncode == 143 and "terminated" in res.stderr
    else:
        assert res.returncode == -signal.SIGKILL
    states = {"old": snapshot(fault_sims["old"]), "new": snapshot(fault_sims["new"])}
    assert assert_published(run) == states[expect]


def test_failed_resimulation_keeps_the_old_config(fault_sims, tmp_path):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    before = snapshot(run)
    res = cli("sim", "--config", PAPER, "--out", str(run), *TINY_SIM, "--set", "sim.vehicle=unknown")
    one_line_error(res)
    assert assert_published(run, before)


def test_a_second_writer_waits_then_refuses_naming_the_holder(fault_sims, tmp_path):
    """The first sim stops (SIGSTOP) just before its publish, holding the lock; a second one refuses."""
    run = copy_run(fault_sims["old"], tmp_path / "run")
    before = snapshot(run)
    first = cli(*sim_cmd(run, 1), fault="sim:before-publish:STOP", wait=False)
    try:
        for _ in range(600):
            if Path(f"/proc/{first.pid}/stat").read_text().split()[2] == "T":
                break
            time.sleep(0.1)
        res = cli(*sim_cmd(run, 2))
        one_line_error(res)
        assert f"being written by another quadfdi command (pid {first.pid}" in res.stderr
    finally:
        first.kill()
        first.communicate()
    assert assert_published(run, before)


def test_a_stale_lock_file_of_a_dead_process_does_not_block(fault_sims, tmp_path):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    (run / ".lock").write_text("pid 999999, command 'quadfdi sim', started long ago\n")
    res = cli("check", "--run", str(run))
    assert res.returncode == 0, res.stderr


def test_lock_held_by_another_process(fault_sims, tmp_path):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    with open(run / ".lock", "a+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        fh.write("pid 1, command 'quadfdi export', started now\n")
        fh.flush()
        res = cli("train", "--run", str(run))
    one_line_error(res)
    assert "quadfdi export" in res.stderr


def test_full_disk_during_sim_leaves_the_old_state(fault_sims, tmp_path):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    before = snapshot(run)
    res = cli(*sim_cmd(run, 1), fsize=64_000)
    one_line_error(res)
    assert "File too large" in res.stderr
    assert assert_published(run, before)


def test_orphans_of_a_killed_run_are_removed(fault_sims, tmp_path):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    before = snapshot(run)
    (run / ".staging" / "sim.abc").mkdir(parents=True)
    (run / ".staging" / "sim.abc" / "dataset.npz").write_bytes(b"half")
    (run / ".dataset.npz.x1y2.tmp").write_bytes(b"half")
    assert assert_published(run, before)


@pytest.mark.parametrize("target,kind", [("config.toml", "symlink"), ("dataset.npz", "fifo"),
                                         ("dataset.npz", "folder")])
def test_sim_refuses_to_replace_a_non_regular_output(fault_sims, tmp_path, target, kind):
    run = copy_run(fault_sims["old"], tmp_path / "run")
    path = run / target
    keep = tmp_path / "precious"
    keep.write_text("user data\n")
    path.unlink()
    {"symlink": lambda: path.symlink_to(keep), "fifo": lambda: os.mkfifo(path), "folder": path.mkdir}[kind]()
    res = cli(*sim_cmd(run, 1))
    one_line_error(res)
    assert str(path) in res.stderr and "refusing to replace" in res.stderr
    assert keep.read_text() == "user data\n"
    assert path.is_symlink() or path.exists()


# ---- train and export: on the session's small run, trained (1 epoch) and fault_exported (N = 2) in process
TRAIN = ["--model", "gru", "--set", "train.epochs=1", "--set", "train.gru_hidden=8"]


@pytest.mark.parametrize("point,expect", [("before-publish", "old"), ("mid-publish", "new")])
def test_train_killed_at_a_named_point(fault_exported, tmp_path, point, expect):
    run = copy_run(fault_exported, tmp_path / "run")
    before = snapshot(run)
    res = cli("train", "--run", str(run), *TRAIN, fault=f"train:{point}")
    assert res.returncode == -signal.SIGKILL, res.stderr[-2000:]
    after = assert_published(run)
    assert (after == before) == (expect == "old")
    if expect == "new":  # the new gru.pt, and the cnode of the previous record carried forward
        assert after["gru.pt"] != before["gru.pt"] and after["cnode.pt"] == before["cnode.pt"]
    else:
        assert "figures/train_curves.png" not in after


def test_ctrl_c_after_the_checkpoints_are_written_keeps_the_old_training(fault_exported, tmp_path):
    """SIGINT once every training output is staged (cnode.pt, metrics.json, ...): one line, exit 130,
    and the previous checkpoints and metrics stay published together."""
    run = copy_run(fault_exported, tmp_path / "run")
    before = snapshot(run)
    res = cli("train", "--run", str(run), *TRAIN, fault="train:before-publish:INT")
    one_line_error(res)
    assert res.returncode == 130 and "interrupted" in res.stderr
    assert assert_published(run, before)


@pytest.mark.parametrize("point,expect", [("before-publish", "old"), ("mid-publish", "new")])
def test_export_killed_at_a_named_point(fault_exported, tmp_path, point, expect):
    run = copy_run(fault_exported, tmp_path / "run")
    before = snapshot(run)
    res = cli("export", "--run", str(run), "--steps", "1", "--set", "export.calib_windows=64",
              fault=f"export:{point}")
    assert res.returncode == -signal.SIGKILL, res.stderr[-2000:]
    after = assert_published(run)
    assert (after == before) == (expect == "old")
    if expect == "new":  # the files of the earlier --steps 2 are gone with their record
        assert "export/cnode_rk4_1.onnx" in after and "export/cnode_rk4_2.onnx" not in after


def test_full_disk_during_export_leaves_the_old_state(fault_exported, tmp_path):
    run = copy_run(fault_exported, tmp_path / "run")
    before = snapshot(run)
    res = cli("export", "--run", str(run), "--steps", "1", "--set", "export.calib_windows=64", fsize=20_000)
    one_line_error(res)
    assert assert_published(run, before)
