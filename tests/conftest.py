"""Shared fixtures: a small simulated run folder, made once per test session."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Small but complete: every class in every split (n_traj 24 -> 6 per class).
SMALL_SIM = ["--set", "sim.n_traj=24", "--set", "sim.duration_s=8.0", "--set", "sim.onset_frac=[0.1, 0.3]",
             "--set", "sim.ramp_frac=[0.2, 0.4]"]


def quadfdi(*args: str, check: bool = False, cwd: Path = ROOT, timeout: float = 900) -> subprocess.CompletedProcess:
    """Run the real console entry point in a subprocess (what a user types)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "quadfdi.cli", *args], capture_output=True, text=True,
                          cwd=cwd, env=env, check=check, timeout=timeout)


def copy_run(src: Path, dst: Path, names: tuple[str, ...] = ("config.toml", "dataset.npz")) -> Path:
    """A new run folder ``dst`` holding copies of ``names`` from the run folder ``src``."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in names:
        shutil.copy(src / name, dst / name)
    return dst


def random_weight_run(src: Path, out: Path, kinds: tuple[str, ...] = ("cnode", "gru"), config: dict | None = None) -> Path:
    """A copy of the run ``src`` with random-weight (untrained, seed 0) checkpoints, normalised on its
    training split: what export, bench and the solver study need, without the cost of training."""
    import torch

    from sim.dataset import load_dataset
    from train.checkpoint import save_checkpoint
    from train.data import fit_normalisation
    from train.models import CNODE, GRUClassifier

    copy_run(src, out)
    ds = load_dataset(out / "dataset.npz")
    mean, std = fit_normalisation(ds)
    torch.manual_seed(0)
    for kind in kinds:
        model = CNODE(ds.n_channels) if kind == "cnode" else GRUClassifier(ds.n_channels)
        model.set_normalisation(mean, std)
        save_checkpoint(out / f"{kind}.pt", model, config or {}, ds.channel_names)
    return out


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run") / "small"
    res = quadfdi("sim", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out), *SMALL_SIM)
    assert res.returncode == 0, res.stderr
    return out
