"""Shared fixtures: a small simulated run folder, made once per test session."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Small but complete: every class in every split (n_traj 24 -> 6 per class).
SMALL_SIM = ["--set", "sim.n_traj=24", "--set", "sim.duration_s=8.0", "--set", "sim.onset_frac=[0.1, 0.3]",
             "--set", "sim.ramp_frac=[0.2, 0.4]"]


def quadfdi(*args: str, check: bool = False, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """Run the real console entry point in a subprocess (what a user types)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "quadfdi.cli", *args], capture_output=True, text=True,
                          cwd=cwd, env=env, check=check, timeout=900)


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run") / "small"
    res = quadfdi("sim", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out), *SMALL_SIM)
    assert res.returncode == 0, res.stderr
    return out
