"""Shared fixtures: a small simulated run folder, made once per test session."""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Callable

import pytest

ROOT = Path(__file__).resolve().parents[1]
# The shared real data (flight logs, CrazyPAD) beside the checkout, or where this workplace keeps it.
SHARED_DATA = next((p for p in (ROOT.parent / "shared" / "data", Path("/work/shared/data")) if p.is_dir()),
                   ROOT.parent / "shared" / "data")

# Small but complete: every class in every split (n_traj 24 -> 6 per class).
SMALL_SIM = ["--set", "sim.n_traj=24", "--set", "sim.duration_s=8.0", "--set", "sim.onset_frac=[0.1, 0.3]",
             "--set", "sim.ramp_frac=[0.2, 0.4]"]


def quadfdi(*args: str, check: bool = False, cwd: Path = ROOT, timeout: float = 900) -> subprocess.CompletedProcess:
    """Run the real console entry point in a subprocess (what a user types)."""
    return subprocess.run([sys.executable, "-m", "quadfdi.cli", *args], capture_output=True, text=True,
                          cwd=cwd, check=check, timeout=timeout)


def copy_run(src: Path, dst: Path,
             names: tuple[str, ...] = ("config.toml", "dataset.npz", ".stages/sim.json")) -> Path:
    """A new run folder ``dst`` holding copies of ``names`` from the run folder ``src`` (by default
    its published sim stage: the dataset, the config and the stage record that vouches for them)."""
    dst.mkdir(parents=True, exist_ok=True)
    for name in names:
        (dst / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src / name, dst / name)
    return dst


def publish_checkpoints(run: Path, models: dict, channel_names: list[str], config: dict | None = None) -> None:
    """Publish ``models`` ({kind: model}) as the run's train stage (core.stage), as ``quadfdi train``
    would: the export and parity stages read only published checkpoints."""
    from quadfdi.core.config import load_config
    from quadfdi.core.stage import stage
    from quadfdi.models.checkpoint import save_checkpoint

    sim = load_config(run / "config.toml").to_dict()["sim"]
    with stage(run, "train", {"sim": sim}) as st:
        st.consume("dataset.npz", ("sim",))
        for kind, model in models.items():
            save_checkpoint(st.path(f"{kind}.pt"), model, config or {}, channel_names)


def random_weight_run(src: Path, out: Path, kinds: tuple[str, ...] = ("cnode", "gru"), config: dict | None = None) -> Path:
    """A copy of the run ``src`` with random-weight (untrained, seed 0) checkpoints, normalised on its
    training split and published as its train stage: what export, bench and the solver study need,
    without the cost of training."""
    import torch

    from quadfdi.formats.dataset import load_dataset
    from quadfdi.train.data import fit_normalisation
    from quadfdi.models.networks import CNODE, GRUClassifier

    copy_run(src, out)
    ds = load_dataset(out / "dataset.npz")
    mean, std = fit_normalisation(ds)
    torch.manual_seed(0)
    models = {}
    for kind in kinds:
        models[kind] = CNODE(ds.n_channels) if kind == "cnode" else GRUClassifier(ds.n_channels)
        models[kind].set_normalisation(mean, std)
    publish_checkpoints(out, models, ds.channel_names, config)
    return out


def trained_export_run(src: Path, out: Path, *train_sets: str, export_sets: tuple[str, ...] = ()) -> Path:
    """A copy of the run ``src`` trained through the real CLI (``--set`` values ``train_sets``) and
    exported (``--set`` values ``export_sets``): the files that parity, the firmware and export checks
    on a trained model need."""
    copy_run(src, out)
    res = quadfdi("train", "--run", str(out), *[a for v in train_sets for a in ("--set", v)])
    assert res.returncode == 0, res.stderr
    res = quadfdi("export", "--run", str(out), *[a for v in export_sets for a in ("--set", v)])
    assert res.returncode == 0, res.stderr
    return out


def built_once(tmp_path_factory, name: str, make: Callable[[Path], Path]) -> Path:
    """What ``make(folder)`` builds in ``folder`` (it returns a path inside it), built once per test session:
    under pytest-xdist the first worker to ask builds it in the session's shared temporary folder under a file
    lock (the other waits instead of building it again) and each worker gets its own copy, so that a test
    writing beside a fixture's files touches only its worker's; without xdist, built in place."""
    mine = tmp_path_factory.mktemp(name)
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return make(mine)
    shared = tmp_path_factory.getbasetemp().parent / "built-once"
    shared.mkdir(exist_ok=True)
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = shared / f"{name}.path"
        if not done.is_file():
            shutil.rmtree(shared / name, ignore_errors=True)
            (shared / name).mkdir()
            done.write_text(str(make(shared / name).relative_to(shared / name)))
        shutil.copytree(shared / name, mine, symlinks=True, dirs_exist_ok=True)
        return mine / done.read_text()


def few_baseline_configs():
    """Every baseline's grid cut to its 1st, 9th and 17th configuration (cheap trees: 7 leaves) while the
    fixture lives: the tuning logic under test is the same for 3 configurations as for the 24 of a run
    (train.baselines.N_CONFIGS, checked in tests/test_baselines_suite.py), at an eighth of the fits."""
    from quadfdi.train.baselines import GRIDS

    with pytest.MonkeyPatch.context() as mp:
        for model, grid in list(GRIDS.items()):
            mp.setitem(GRIDS, model, grid[::8])
        yield


@pytest.fixture(scope="session")
def small_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run") / "small"
    res = quadfdi("sim", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out), *SMALL_SIM)
    assert res.returncode == 0, res.stderr
    return out


# ---- a flightlog-min model (tiny realistic run): quadfdi detect (tests/test_detect.py) and the
# streaming runtime (tests/test_stream.py) share it

FLIGHTLOG_TINY = ["sim.n_traj=20", "sim.ood_traj=2", "sim.duration_s=12.0", "sim.chunk=14", "sim.window=40"]
FLIGHTLOG_TRAIN = ["train.epochs=1", "train.latent=8", "train.hidden=16", "train.gru_hidden=16",
                   "train.max_train_windows=60", "train.profile=flightlog-min", "train.motor_head=auto"]
# The GRU's own alarm policy ([alarm.gru]), unlike the CNODE's (the [alarm] default): the stream's and
# detect's parity tests then hold each network to its own policy (weights.bin's alarm.models).
FLIGHTLOG_ALARM = ["alarm.gru.threshold=0.4", "alarm.gru.k=1", "alarm.gru.n=2", "alarm.gru.clear_m=2"]


@pytest.fixture(scope="session")
def flightlog_export(tmp_path_factory) -> Path:
    """RUN/export of a tiny realistic run trained with the flightlog-min profile through the CLI."""
    def make(folder: Path) -> Path:
        sim = folder / "tiny"
        res = quadfdi("sim", "--config", str(ROOT / "configs/realistic.toml"), "--out", str(sim), "--workers", "1",
                      *[a for v in FLIGHTLOG_TINY for a in ("--set", v)])
        assert res.returncode == 0, res.stderr
        return trained_export_run(sim, folder / "run", *FLIGHTLOG_TRAIN, export_sets=tuple(FLIGHTLOG_ALARM)) / "export"

    return built_once(tmp_path_factory, "flightlog", make)


@pytest.fixture(scope="session")
def mission_npz(tmp_path_factory) -> Path:
    """The shared UAVCAN mission log ingested once (skips where the shared logs are not here)."""
    log = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"
    if not log.is_file():
        pytest.skip(f"the shared real flight logs are not at {log.parent}")

    def make(folder: Path) -> Path:
        res = quadfdi("ingest", str(log), "--out", str(folder / "mission"))
        assert res.returncode == 0, res.stderr
        return folder / "mission" / "flight.npz"

    return built_once(tmp_path_factory, "mission", make)


# ---- a flightlog-ref model (the masked profile plus deviations from the vehicle's own reference flights) on a
# tiny fleet (vehicles flying several flights, the first two healthy reference flights): tests of the
# reference profile (tests/test_reference_profile.py) and of its C++ mirror share it

FLEET_TINY = ["sim.n_traj=16", "sim.ood_traj=4", "sim.flights_per_vehicle=4", "sim.reference_flights=2",
              "sim.duration_s=14.0", "sim.chunk=48", "sim.window=40", "sim.stride=20", "sim.onset_frac=[0.05, 0.2]",
              "sim.ramp_frac=[0.05, 0.1]", 'sim.classes=["Healthy", "PropellerFault"]', "sim.fault_ratio=0.5"]
REFERENCE_TRAIN = [v if not v.startswith("train.profile=") else "train.profile=flightlog-ref" for v in FLIGHTLOG_TRAIN]


@pytest.fixture(scope="session")
def tiny_fleet(tmp_path_factory) -> Path:
    """A simulated tiny fleet run folder (FLEET_TINY), made once."""
    def make(folder: Path) -> Path:
        res = quadfdi("sim", "--config", str(ROOT / "configs/fleet.toml"), "--out", str(folder / "tiny"), "--workers",
                      "1", *[a for v in FLEET_TINY for a in ("--set", v)])
        assert res.returncode == 0, res.stderr
        return folder / "tiny"

    return built_once(tmp_path_factory, "fleet_ref", make)


@pytest.fixture(scope="session")
def reference_export(tiny_fleet, tmp_path_factory) -> Path:
    """RUN/export of a tiny fleet run trained with the flightlog-ref profile through the CLI."""
    return built_once(tmp_path_factory, "fleet_ref_run", lambda folder: trained_export_run(
        tiny_fleet, folder / "run", *REFERENCE_TRAIN, export_sets=tuple(FLIGHTLOG_ALARM)) / "export")


# ---- a flightlog-phys model (flightlog-ref's channels and the causal physics channels, core/causal.py) on the
# same tiny fleet: tests/test_phys_profile.py and the reference profiles' stream tests

PHYSICS_TRAIN = [v if not v.startswith("train.profile=") else "train.profile=flightlog-phys" for v in FLIGHTLOG_TRAIN]


@pytest.fixture(scope="session")
def physics_export(tiny_fleet, tmp_path_factory) -> Path:
    """RUN/export of the tiny fleet trained with the flightlog-phys profile through the CLI."""
    return built_once(tmp_path_factory, "fleet_phys_run", lambda folder: trained_export_run(
        tiny_fleet, folder / "run", *PHYSICS_TRAIN, export_sets=tuple(FLIGHTLOG_ALARM)) / "export")


# ---- a flightlog-mask model (the masked profile: whatever channels a log has) on the same tiny dataset:
# tests/test_masks.py and tests/test_masks_mcu.py share it

MASKED_TRAIN = [v if not v.startswith("train.profile=") else "train.profile=flightlog-mask" for v in FLIGHTLOG_TRAIN]


@pytest.fixture(scope="session")
def masked_export(flightlog_export, tmp_path_factory) -> Path:
    """RUN/export of the flightlog-min fixture's dataset trained with the masked profile through the CLI."""
    return built_once(tmp_path_factory, "masked_run", lambda folder: trained_export_run(
        flightlog_export.parent, folder / "run", *MASKED_TRAIN, export_sets=tuple(FLIGHTLOG_ALARM)) / "export")


# ---- the fault-injection suite's runs (tests/test_faults*.py)


@pytest.fixture(scope="session")
def fault_sims(tmp_path_factory) -> dict[str, Path]:
    """A tiny simulated run (seed 0) and the same simulated with seed 1: the old and the new state."""
    from tests import faultkit

    base = tmp_path_factory.mktemp("faults")
    runs = {"old": base / "old", "new": base / "new"}
    for seed, (name, out) in enumerate(runs.items()):
        res = faultkit.cli(*faultkit.sim_cmd(out, seed))
        assert res.returncode == 0, res.stderr[-2000:]
    return runs


@pytest.fixture(scope="session")
def fault_exported(small_run, tmp_path_factory) -> Path:
    """The session's small run, trained (1 epoch, small models) and exported (N = 2) in process."""
    from quadfdi.train import figures as train_figures
    from quadfdi.core.rundir import open_run
    from tests import faultkit
    from quadfdi.export.run import export_run
    from quadfdi.train.run import train_run

    def make(folder: Path) -> Path:
        run_dir = faultkit.copy_run(small_run, folder / "run")
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(train_figures, "draw_all", lambda run, ds, result: [])
            run, cfg = open_run(run_dir, ["train.epochs=1", "train.latent=8", "train.hidden=16", "train.gru_hidden=8",
                                          "export.steps=2", "export.calib_windows=64"])
            train_run(run, cfg, "both", log=lambda s: None)
            export_run(run, cfg, log=lambda s: None)
        return run_dir

    return built_once(tmp_path_factory, "faults_train", make)


# The longest files first, longest first: `make test` hands whole files to two workers (pytest-xdist
# --dist loadfile) in collection order, and a long file picked up last leaves the other worker idle at
# the end. The files of 20 worker-seconds or more in a fresh-clone `make test` (junit times, setup
# included), by time: the pipeline run, the host and sanitizer builds, the fleet detect, the real
# flights, the Dask sweeps, ...; the other 77 files (about 330 s) fill in after them.
LONG_FILES = ("test_pipeline.py", "test_stream.py", "test_detect_vehicle.py", "test_real_flights.py",
              "test_distributed.py", "test_solverstudy.py", "test_faults.py", "test_stream_cnode_onboard.py",
              "test_firmware.py", "test_fuzz.py", "test_vehicle_record_mcu.py", "test_wheel.py",
              "test_bench_report.py", "test_train_realistic.py", "test_masks_mcu.py", "test_sweep_reuse.py",
              "test_parity.py", "test_phys_profile.py", "test_models.py", "test_firmware_tanhq.py",
              "test_reference_profile.py", "test_export_trained.py", "test_detect.py", "test_baselines_suite.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONG_FILES)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FILES)))  # stable: file order kept otherwise
