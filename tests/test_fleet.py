"""The fleet suite on tiny settings: splits by vehicle, reference flights first and healthy, the held-out
airframe classes outside the training arm, a vehicle kept across its flights, the dataset's fleet keys."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import dataset_arrays, load_dataset, split_rows, vehicle_columns, write_npz
from quadfdi.sim.fleet import SPLIT_NAMES, labels, n_flights
from quadfdi.sim.simulate import generate

TINY = ["sim.n_traj=12", "sim.ood_traj=3", "sim.flights_per_vehicle=3", "sim.reference_flights=1",
        "sim.duration_s=8.0", "sim.chunk=40", "sim.window=40", "sim.stride=20", "sim.onset_frac=[0.05, 0.2]",
        "sim.ramp_frac=[0.05, 0.1]"]


@pytest.fixture(scope="module")
def cfg():
    return load_config("fleet", TINY)


@pytest.fixture(scope="module")
def ds(cfg, tmp_path_factory):
    path = tmp_path_factory.mktemp("fleet") / "dataset.npz"
    write_npz(path, dataset_arrays(generate(cfg.sim), cfg.sim))
    return load_dataset(path)


def test_shipped_config_splits_by_vehicle_with_reference_flights_first():
    sim = load_config("fleet").sim
    cls, split, group, ref = labels(sim)
    F, R = sim.flights_per_vehicle, sim.reference_flights
    vehicle, flight = np.arange(split.size) // F, np.arange(split.size) % F
    for v in np.unique(vehicle):  # every vehicle's flights sit in one split
        assert len(set(split[vehicle == v])) == 1
    assert np.array_equal(ref, flight < R) and np.all(cls[ref] == 0)
    assert set(cls[~ref]) == set(range(len(sim.classes)))
    assert set(np.unique(split)) == set(range(len(SPLIT_NAMES)))
    healthy_test_h = ((split == 2) & ~ref & (cls == 0)).sum() * sim.duration_s / 3600
    assert healthy_test_h * len(load_config("fleet").run.study_sim_seeds) >= 10.0  # the false-alarm goal's exposure
    assert np.all(group[split >= 3] == split[split >= 3] - 2)


def test_tiny_dataset_keys_splits_and_classes(ds, cfg):
    a = ds.arrays
    v = vehicle_columns(a)
    assert a["telemetry"].shape[0] == n_flights(cfg.sim) == 12 + 6 * 3
    assert v["vehicle_id"].dtype == np.int32 and v["reference_flight"].dtype == bool
    train, val, test = (set(v["vehicle_id"][split_rows(ds, s)]) for s in ("train", "validation", "test"))
    assert train and val and test and not (train & val or train & test or val & test)
    first = v["vehicle_flight"] == 0
    assert np.array_equal(v["reference_flight"], first) and np.all(a["fault_class"][first] == 0)
    assert [str(n) for n in a["airframe_class_names"]] == ["450", "250", "650"]
    assert ds.config.sim == cfg.sim  # the new keys are embedded and read back


def test_held_out_airframes_lie_outside_the_training_arms(ds):
    a, v = ds.arrays, vehicle_columns(ds.arrays)
    train_arm = a["arm_m"][split_rows(ds, "train")]
    for name, cls in (("test_ood_size_250", 1), ("test_ood_size_650", 2)):
        rows = split_rows(ds, name)
        assert np.all(v["airframe_class"][rows] == cls) and np.all(v["airframe_class"][a["split"] <= 2] == 0)
        arm = a["arm_m"][rows]
        assert np.all((arm < train_arm.min()) | (arm > train_arm.max()))
    small, large = split_rows(ds, "test_ood_size_250"), split_rows(ds, "test_ood_size_650")
    assert a["mass_kg"][small].max() < a["mass_kg"][a["split"] <= 2].min() < a["mass_kg"][a["split"] <= 2].max() \
        < a["mass_kg"][large].min()  # mass x size^2 (sim.fleet_params)
    healthy = (a["fault_class"] == 0)
    names = list(a["channel_names"])
    thr = a["telemetry"][..., names.index("thr1"):names.index("thr1") + 4].mean(axis=(1, 2))
    for rows in (small, large):  # flown: hover collective of a 1.9-2.6 thrust-to-weight build, level
        h = rows[healthy[rows]]
        assert np.all((thr[h] > 0.25) & (thr[h] < 0.65)), thr[h]
        assert np.abs(a["states"][h][..., 6:8]).max() < np.radians(45)


def test_a_vehicle_keeps_its_build_while_pack_wind_and_mission_change(ds):
    a, v = ds.arrays, vehicle_columns(ds.arrays)
    same = ("mass_kg", "arm_m", "frame", "pack_cells", "pack_capacity_ah", "cg_offset_m", "thrust_coef_factor",
            "cooling_factor", "motor_tau_s", "vib_floor_ms2", "prop_imbalance_g")
    differ = ("pack_age", "pack_r_ohm", "soc0", "wind_ms", "wind_dir_rad", "t_amb")
    for vid in np.unique(v["vehicle_id"]):
        rows = np.flatnonzero(v["vehicle_id"] == vid)
        for k in same:
            assert np.all(a[k][rows] == a[k][rows[0]]), (vid, k)
        for k in differ:
            assert len(np.unique(a[k][rows])) == len(rows), (vid, k)
    assert len(np.unique(a["mass_kg"])) == len(np.unique(v["vehicle_id"]))  # vehicles differ from each other


def test_rows_regenerate_alone_and_older_datasets_read_as_one_vehicle_per_flight(ds, cfg):
    again = generate(cfg.sim, indices=[4, 25])
    for k in ("telemetry", "vehicle_id", "reference_flight", "mass_kg"):
        assert np.array_equal(again[k], ds[k][[4, 25]]), k
    old = {k: x for k, x in ds.arrays.items() if k not in ("vehicle_id", "vehicle_flight", "reference_flight",
                                                         "airframe_class")}
    cols = vehicle_columns(old)
    assert np.array_equal(cols["vehicle_id"], np.arange(len(old["split"]))) and not cols["reference_flight"].any()


@pytest.mark.parametrize("override, message", [
    (["sim.reference_flights=3"], "reference_flights < sim.flights_per_vehicle"),
    (["sim.n_traj=13"], "whole multiples of sim.flights_per_vehicle"),
    (["sim.scenario=realistic"], "belong to sim.scenario='fleet'"),
])
def test_bad_fleet_settings_are_one_line_errors(override, message):
    with pytest.raises(QuadfdiError, match=message):
        load_config("fleet", TINY + override).sim.validate()


def test_the_report_counts_vehicles_reference_flights_and_the_healthy_hours_after_them(ds, cfg):
    """report.md's simulation section of a fleet: per split, vehicles, reference flights and the healthy
    flights after them with their hours (what false alarms are scored on), beside the classes."""
    from quadfdi.sim.report import report_section

    lines = report_section(ds.path.parent)
    assert "vehicles drawn once, each flying 3 flights, the first 1 healthy reference flights" in lines[2]
    head = next(line for line in lines if line.startswith("| split"))
    assert head.startswith("| split | trajectories | vehicles | reference flights | healthy after them | Healthy |")
    v = vehicle_columns(ds.arrays)
    for code, name in enumerate(SPLIT_NAMES):
        m = ds["split"] == code
        healthy = int((m & ~v["reference_flight"] & (ds["fault_class"] == 0)).sum())
        hours = healthy * cfg.sim.duration_s / 3600
        row = next(line for line in lines if line.startswith(f"| {name} |"))
        assert row.startswith(f"| {name} | {int(m.sum())} | {len(np.unique(v['vehicle_id'][m]))} | "
                              f"{int((m & v['reference_flight']).sum())} | {healthy} ({hours:.2f} h) |"), row
