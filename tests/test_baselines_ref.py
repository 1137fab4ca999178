"""The baselines against each fleet vehicle's own reference (train/vehicle_ref.py, train/features_ref.py):
the reference rests on the vehicle's own reference flights only, the relative share is near zero on its
healthy flights and names the faulty rotor on a propeller fault, the reference models fit and predict
beside their twins, evaluation leaves reference flights out, and datasets without vehicles are unchanged."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.evaluate.load import load_run
from quadfdi.formats.dataset import dataset_arrays, load_dataset, make_windows, write_npz
from quadfdi.sim.simulate import generate
from quadfdi.train.baselines import GRIDS, MODELS, REF_MODELS, fit_baselines
from quadfdi.train.baselines_run import run_baselines
from quadfdi.train.features import physics_feature_names, physics_features
from quadfdi.train.features_ref import ref_feature_names, ref_features
from quadfdi.train.vehicle_ref import learn_references, vehicle_refs
from tests.conftest import few_baseline_configs

# Flights long enough for a reference (vehicle.learn: 10 s airborne), two reference flights per vehicle,
# half of the later flights with a propeller fault.
TINY = ["sim.n_traj=16", "sim.ood_traj=4", "sim.flights_per_vehicle=4", "sim.reference_flights=2",
        "sim.duration_s=14.0", "sim.chunk=48", "sim.window=40", "sim.stride=20", "sim.onset_frac=[0.05, 0.2]",
        "sim.ramp_frac=[0.05, 0.1]", 'sim.classes=["Healthy", "PropellerFault"]', "sim.fault_ratio=0.5"]


_few_configs = pytest.fixture(scope="module", autouse=True)(few_baseline_configs)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    cfg = load_config("fleet", TINY)
    root = tmp_path_factory.mktemp("fleetref")
    write_npz(root / "dataset.npz", dataset_arrays(generate(cfg.sim), cfg.sim))
    return root, load_dataset(root / "dataset.npz")


def _dumps(ref: dict) -> str:
    return json.dumps(ref, sort_keys=True)


def test_reference_rests_on_the_vehicles_own_reference_flights_only(run):
    _, ds = run
    a = ds.arrays
    base = learn_references(a, "d")
    vid, ref = a["vehicle_id"], a["reference_flight"]
    changed = dict(a, telemetry=a["telemetry"].copy())
    others = (vid != 0) | ~ref  # every other vehicle's flights and vehicle 0's later flights
    changed["telemetry"][others] *= np.float32(1.05)
    again = learn_references(changed, "d")
    assert _dumps(again[0]) == _dumps(base[0])
    assert all(_dumps(again[v]) != _dumps(base[v]) for v in base if v != 0)  # the change could be seen
    for v, r in base.items():  # learned from exactly the vehicle's reference rows
        assert [f["file"] for f in r["flights"]] == [f"d#{i}" for i in np.flatnonzero((vid == v) & ref)]
    assert len(base[0]["flights"]) == 2
    assert base[0]["motor_temp"] is not None and base[0]["battery"]["mode"] == "sag"


def _features(ds):
    w = make_windows(ds)
    refs = vehicle_refs(ds.arrays, "d")
    names = ds.channel_names
    cells = ds["pack_cells"][w.traj]
    rel = ref_features(w.x, names, cells, *refs.windows(w.traj, w.start, w.x.shape[1]))
    phys = physics_features(w.x, names, cells)
    return w, dict(zip(ref_feature_names(names), rel.T)), dict(zip(physics_feature_names(names), phys.T))


def test_relative_share_is_near_zero_when_healthy_and_names_the_faulty_rotor(run):
    _, ds = run
    a = ds.arrays
    w, rel, phys = _features(ds)
    dev = np.stack([rel[f"share_dev{i}"] for i in range(1, 5)], axis=1)
    ratio = np.stack([phys[f"thr_ratio{i}"] for i in range(1, 5)], axis=1)
    healthy = (a["fault_class"][w.traj] == 0) & ~a["reference_flight"][w.traj]
    # the vehicles' asymmetry (twist, CG, per-motor thrust) is what the reference takes out: 0.66 of the
    # reference-free deviation here (14 s flights, two 14 s reference flights), 0.50 of it on the fleet suite
    assert np.abs(dev[healthy]).mean() < 0.75 * np.abs(ratio[healthy] - 1.0).mean()
    faulty = np.flatnonzero(a["fault_class"] == 1)
    assert len(faulty) >= 5
    for row in faulty:
        m = (w.traj == row) & (w.y == 1)
        mean = dev[m].mean(axis=0)
        assert int(np.argmax(mean)) == int(a["fault_motor"][row]), (row, mean)
        assert mean.max() > 0.05


def test_reference_models_fit_beside_their_twins_without_reference_flights(run):
    _, ds = run
    evals, out = fit_baselines(ds, seed=0, models=MODELS + REF_MODELS, cap=0)
    assert set(out) == set(MODELS + REF_MODELS)
    for m in REF_MODELS:
        assert GRIDS[m] == GRIDS[m[:-len("_ref")]]  # the same tuning budget
        rec = out[m].record
        assert rec["n_train_windows"] < out[m[:-len("_ref")]].record["n_train_windows"]  # no reference flight
        assert out[m].proba.shape == (len(evals.y), 2) and np.isfinite(out[m].proba).all()
        assert "share_dev1" in rec["features"] and "thr_ratio1" not in rec["features"]
    assert evals.ref_flight.any()  # predicted, never scored (evaluate leaves them out)
    plain_evals, plain = fit_baselines(ds, seed=0, models=MODELS, cap=0)
    assert np.array_equal(plain_evals.ref_flight, evals.ref_flight)  # the twins do not depend on the flag
    for m in MODELS:
        assert np.array_equal(plain[m].proba, out[m].proba) and plain[m].record["chosen"] == out[m].record["chosen"]


def test_run_writes_the_reference_sets_and_evaluation_leaves_reference_flights_out(run):
    root, ds = run
    _, lines = run_baselines(root, seed=0, which="run", cap=200, reference=True)
    assert not any("skipped" in line for line in lines)
    sets, _ = load_run(root)
    assert {s.model for s in sets} == set(MODELS + REF_MODELS)
    ref_rows = set(np.flatnonzero(ds["reference_flight"]).tolist())
    for s in sets:
        assert s.rows.size and not ref_rows & set(s.rows.tolist())
        assert s.motor is not None


def test_the_record_says_which_temperatures_the_baselines_read(run, tmp_path):
    root, _ = run
    (tmp_path / "dataset.npz").symlink_to(root / "dataset.npz")
    written, lines = run_baselines(tmp_path, seed=0, which="run", cap=200, models=("logreg_physics",), logged=True)
    record = json.loads(next(p for p in written if p.suffix == ".json" and "baselines" in p.name).read_text())
    assert record["models"]["logreg_physics"]["temperatures"] == "esc_temp1..4 (ESC boards)"
    assert "temperatures esc_temp1..4 (ESC boards)" in lines[0]
    assert "esc_temp1_mean" not in record["models"]["logreg_physics"]["features"]  # physics only: dT from ESCs
    assert "dT1" in record["models"]["logreg_physics"]["features"]


def test_configs_and_datasets_without_vehicles_are_unchanged(tmp_path):
    assert not load_config("paper").train.baselines_reference
    assert not load_config("realistic").train.baselines_reference
    assert load_config("fleet").train.baselines_reference
    from tests.test_baselines_suite import _arrays, _config  # the synthetic suite: no vehicle columns

    outs = []
    for reference in (False, True):
        root = tmp_path / str(reference)
        root.mkdir()
        write_npz(root / "dataset.npz", dataset_arrays(_arrays(0), _config(0).sim))
        written, lines = run_baselines(root, seed=0, which="run", cap=200, reference=reference)
        lines = [line.split("; tuning")[0] for line in lines]  # the CPU seconds are not under test
        outs.append(({p.name: p.read_bytes() for p in written if p.suffix == ".npz"}, lines))
    (plain, plain_lines), (ref, ref_lines) = outs
    assert plain == ref and set(plain) == {f"{m}_sim0_train0.npz" for m in MODELS}
    assert ref_lines == [f"sim 0: {', '.join(REF_MODELS)} skipped: dataset.npz has no vehicles with reference "
                         "flights"] + plain_lines


def test_a_run_for_real_logs_reads_esc_temperatures_not_the_windings(run):
    """logged_view: T1..T4 (the simulator's windings) replaced column for column by esc_temp1..4; the
    physics and reference features then read the ESCs' offsets; a dataset without ESC telemetry unchanged."""
    from quadfdi.train.baselines_channels import logged_view

    _, ds = run
    view, temps = logged_view(ds)
    assert temps == "esc_temp" and "T1" not in view.channel_names and "T1" in ds.channel_names
    names, esc = view.channel_names, [str(n) for n in ds["esc_channel_names"]]
    for k in range(1, 5):
        col = names.index(f"esc_temp{k}")
        assert col == ds.channel_names.index(f"T{k}")
        assert np.array_equal(view["telemetry"][:, :, col], ds["esc_telemetry"][:, :, esc.index(f"esc_temp{k}")])
    w = make_windows(view, "train")
    phys = physics_features(w.x[:50], names)
    esc_t = w.x[:50][:, :, [names.index(f"esc_temp{k}") for k in range(1, 5)]].astype(np.float64)
    dt = (esc_t - esc_t.mean(axis=2, keepdims=True)).mean(axis=1)
    pn = physics_feature_names(names)
    assert np.allclose(phys[:, [pn.index(f"dT{k}") for k in range(1, 5)]], dt)
    refs = vehicle_refs(view.arrays, "view")  # the references' temperature offsets: the ESCs'
    base = learn_references(view.arrays, "view")
    vid = int(view["vehicle_id"][0])
    assert base[vid]["motor_temp"] is None
    assert np.allclose(refs.const[0, :4], [m["mean"] for m in base[vid]["esc"]["temp_offset"]["motors"]])
    assert not np.allclose(refs.const[0, :4], 0.0)
    from tests.test_baselines_suite import _arrays, _config  # no ESC telemetry: nothing to read instead

    plain = load_dataset_from(_arrays(0), _config(0))
    same, temps = logged_view(plain)
    assert same is plain and temps == "T"


def load_dataset_from(arrays, cfg):
    from quadfdi.formats.dataset import Dataset

    return Dataset(path=None, arrays=dataset_arrays(arrays, cfg.sim), config=cfg)
