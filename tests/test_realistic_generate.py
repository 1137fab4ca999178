"""Realistic suite, end to end on a small config: contract, classes, splits, determinism per seed,
shard regeneration, fault signatures; and the suite's counts in configs/realistic.toml."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.formats.dataset import class_names, dataset_arrays, load_dataset, make_windows, split_names, write_npz
from quadfdi.sim.realistic import SPLIT_NAMES, labels, n_flights
from quadfdi.sim.simulate import generate
from tests.conftest import ROOT

CONFIG = ROOT / "configs/realistic.toml"
SMALL = ["sim.n_traj=20", "sim.ood_traj=2", "sim.duration_s=12.0", "sim.chunk=14", "sim.window=40"]


@pytest.fixture(scope="module")
def cfg():
    return load_config(CONFIG, SMALL)


@pytest.fixture(scope="module")
def ds(cfg):
    return generate(cfg.sim)


def test_suite_counts_meet_the_issue():
    sim = load_config(CONFIG).sim
    cls, split, group = labels(sim)
    test = split >= 2
    assert test.sum() >= 300
    healthy_test = (cls == 0) & test
    assert healthy_test.sum() >= 100 and healthy_test.sum() * sim.duration_s >= 2 * 3600
    in_dist_healthy_test = (cls == 0) & (split == 2)
    assert in_dist_healthy_test.sum() >= 100
    assert set(np.unique(split)) == set(range(len(SPLIT_NAMES)))
    assert sim.classes == ("Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault")
    for g in range(1, 5):  # every out-of-distribution set is test only and holds every class
        assert np.all(split[group == g] == 2 + g) and set(cls[group == g]) == set(range(5))
    assert np.all(group[split <= 2] == 0)


def test_contract_classes_and_splits(ds, cfg, tmp_path):
    n = n_flights(cfg.sim)
    assert ds["telemetry"].shape == (n, cfg.sim.n_samples, 25) and np.isfinite(ds["telemetry"]).all()
    assert list(ds["channel_names"][-2:]) == ["vib_px4", "vib_ap"]
    path = tmp_path / "dataset.npz"
    write_npz(path, dataset_arrays(ds, cfg.sim))
    loaded = load_dataset(path)
    assert class_names(loaded.arrays) == cfg.sim.classes and split_names(loaded.arrays) == SPLIT_NAMES
    assert loaded.config.sim == cfg.sim  # the embedded [sim] section rebuilds it, new keys included
    assert json.loads(str(loaded["config"]))["sim"]["scenario"] == "realistic"
    w = make_windows(loaded, "test_ood_wind")
    assert len(w) > 0 and set(loaded["split"][w.traj]) == {5}
    assert set(make_windows(loaded, "train").y) <= set(range(5))
    rotor = np.isin(ds["fault_class"], (2, 3, 4))
    assert np.all(ds["fault_motor"][rotor] >= 0) and np.all(ds["fault_motor"][~rotor] == -1)


def test_per_flight_parameters_recorded(ds):
    n = ds["telemetry"].shape[0]
    for key in ("mass_kg", "payload_kg", "pack_capacity_ah", "pack_age", "t_amb", "wind_ms", "soc0"):
        assert ds[key].shape == (n,) and np.isfinite(ds[key]).all()
    assert ds["cg_offset_m"].shape == (n, 2) and ds["thrust_coef_factor"].shape == (n, 4)
    vehicle_ood = ds["test_group"] == 2
    assert np.all(ds["pack_cells"][vehicle_ood] == 6) and np.all(ds["pack_cells"][~vehicle_ood] <= 5)
    assert np.all(ds["wind_ms"][ds["test_group"] == 3] >= 6.0)
    assert np.all(ds["mission_type"][ds["test_group"] == 1] == 3)


def test_deterministic_per_seed_and_shard_regeneration(ds, cfg):
    rows = [1, 5, 21]  # two in distribution, one out-of-distribution flight
    again = generate(cfg.sim, indices=rows)
    for key in ("telemetry", "states", "severity", "mass_kg", "fault_class", "split"):
        assert np.array_equal(again[key], ds[key][rows]), key
    other = generate(load_config(CONFIG, SMALL + ["sim.seed=1"]).sim, indices=[1])
    assert not np.array_equal(other["telemetry"][0], ds["telemetry"][1])


def test_flights_are_sane_and_faults_show(ds):
    names = list(ds["channel_names"])
    tel, cls = ds["telemetry"], ds["fault_class"]
    z_ref_dev = np.abs(ds["states"][..., 2] - ds["states"][:, :1, 2]).max()
    assert z_ref_dev < 40.0  # nobody fell out of the sky
    assert np.abs(ds["states"][..., 6:8]).max() < np.radians(60)
    vib = tel[..., names.index("vib_ap")]
    prop = cls == 4
    late = vib[:, -50:].mean(axis=1)
    assert late[prop].mean() > 1.3 * late[cls == 0].mean()  # a cut prop shakes the vehicle
    soc = tel[..., names.index("SoC")]
    assert np.all(soc[:, -1] < soc[:, 0])  # the coulomb counter counts down


def test_sharded_generation_keeps_every_flight(cfg, ds, tmp_path):
    """The shard path (quadfdi sim with workers or a cache) gives generate()'s arrays: the
    out-of-distribution flights included, the name tables once (not one copy per shard)."""
    from quadfdi.core.rundir import RunDir
    from quadfdi.sim.shards import n_rows, simulate_sharded

    full = load_config(CONFIG, SMALL)
    assert n_rows(full.sim) == n_flights(full.sim) == len(ds["fault_class"])
    got = simulate_sharded(RunDir(tmp_path), full, progress=False)
    assert set(got) == set(ds)
    for k in ds:
        np.testing.assert_array_equal(got[k], ds[k], err_msg=k)


# Regression pins of this module's dataset, so that any change to the simulator's output shows as a
# reviewable diff. Split in two: what the vehicle did (every array but the logged telemetry) and what
# its logger wrote (telemetry, esc_telemetry: the logging rates drawn per flight, sensor noise, the
# resampler). The logging-rate draw has its own stream (sim.realistic_params.RATES_SPAWN), so it moves
# only the second; the ESC streams draw after everything else, so they move only esc_telemetry.
STATE_SHA256 = "d8d093d54f2e81edbef7b99cef73521647e5cf28d4ee7ddedcfce6024b6ce044"
LOGGED_SHA256 = "68e1e921f01b70abbcd8f2e83619c79c5a4610f781ca1c18b2d6e4cc8665c85d"
LOGGED = ("telemetry", "esc_telemetry")


def _digest(ds, keys) -> str:
    import hashlib

    h = hashlib.sha256()
    for k in keys:
        a = np.ascontiguousarray(ds[k])
        h.update(k.encode()), h.update(str(a.dtype).encode()), h.update(a.tobytes())
    return h.hexdigest()


def test_simulated_state_and_logged_telemetry_are_pinned(ds):
    assert _digest(ds, [k for k in sorted(ds) if k not in LOGGED]) == STATE_SHA256
    assert _digest(ds, LOGGED) == LOGGED_SHA256
    assert list(ds["esc_channel_names"]) == [f"rpm{k}" for k in range(1, 5)] + [f"esc_cur{k}" for k in range(1, 5)] \
        + [f"esc_temp{k}" for k in range(1, 5)]
    assert ds["esc_telemetry"].shape == ds["telemetry"].shape[:2] + (12,) and np.isfinite(ds["esc_telemetry"]).all()


def test_logging_rates_are_drawn_per_flight_from_the_measured_table(cfg):
    """Each group's rate is one of the rates real logs have (capped at the 50 Hz record), drawn from the
    flight's own stream: the same flight gets the same rates in any batch."""
    from quadfdi.sim import realistic_params as P
    from quadfdi.sim.telemetry import log_rates

    idx = np.arange(cfg.sim.n_traj)
    rates = log_rates(cfg.sim.seed, idx)
    alone = log_rates(cfg.sim.seed, idx[5:6])
    for g, table in P.LOG_HZ_MEASURED.items():
        allowed = {min(r, P.RECORD_HZ) for r in table}
        assert set(rates[g]) <= allowed and rates[g][5] == alone[g][0]
    assert len(set(rates["att"])) > 1 and len(set(rates["batt"])) > 1  # flights differ


def test_esc_temperatures_sit_near_the_flights_ambient(ds):
    """Every simulated ESC reads within its sensor offset (+-1 degC) and one telemetry unit below the
    flight's ambient at worst, and a few kelvin above it (12 s flights, hover-class currents)."""
    temp = ds["esc_telemetry"][..., 8:].astype(np.float64) - ds["t_amb"][:, None, None]
    assert temp.min() >= -1.5 and temp.max() < 15.0, (temp.min(), temp.max())
    assert np.median(temp) > 0.0  # they run above ambient


def test_esc_telemetry_physics(ds):
    """The four ESC currents sum to the bus current less the avionics (gain errors +-5 %); a cut
    blade's rotor spins fastest (it needs more rpm for its thrust)."""
    from quadfdi.sim.realistic_params import NOMINAL

    names = list(ds["channel_names"])
    esc, tel = ds["esc_telemetry"].astype(np.float64), ds["telemetry"].astype(np.float64)
    want = (tel[..., names.index("I_b")] - NOMINAL.P_av / tel[..., names.index("V_b")]).mean(axis=1)
    got = esc[..., 4:8].sum(axis=2).mean(axis=1)
    assert np.all(np.abs(got / want - 1.0) < 0.08), np.abs(got / want - 1.0).max()
    rpm = esc[..., :4]
    assert 2000 < np.median(rpm) < 12000
    cut = (ds["fault_class"] == 4) & (ds["prop_cut_frac"] > 0.1) & (ds["severity"][:, -1] >= ds["severity_max"])
    assert cut.sum() >= 1
    share = rpm[cut, -25:].mean(axis=1) / rpm[cut, -25:].mean(axis=(1, 2))[:, None]
    assert np.all(share.argmax(axis=1) == ds["fault_motor"][cut]), (share, ds["fault_motor"][cut])
