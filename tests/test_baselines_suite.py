"""train.features, train.baselines, train.baselines_run and `quadfdi train baselines`."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.core.config import build_config
from quadfdi.core.npzio import read_npz, write_npz
from quadfdi.formats.predictions import add_entries, check_prediction_set, read_index
from quadfdi.core.tomlio import dumps_toml
from quadfdi.formats.dataset import Dataset, dataset_arrays
from quadfdi.sim.telemetry import CHANNEL_NAMES
from tests.conftest import few_baseline_configs, quadfdi
from quadfdi.train.baselines import GRIDS, MODELS, N_CONFIGS, fit_baselines, train_subsample
from quadfdi.train.baselines_run import record_path, run_baselines
from quadfdi.train.features import (I_FLOOR_A, internal_resistance, physics_feature_names, physics_features,
                            stat_feature_names, stat_features)

W = 40
CLASSES = ("Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault")


def _window(**channels) -> tuple[np.ndarray, list[str]]:
    """One (1, W, C) window of the realistic channels (in REVERSED order: features must look channels
    up by name), healthy constants unless given."""
    base = {c: np.zeros(W) for c in CHANNEL_NAMES}
    base.update({"V_b": np.full(W, 12.0), "I_b": np.full(W, 10.0), "SoC": np.full(W, 0.8),
                 **{f"T{i}": np.full(W, 40.0) for i in range(1, 5)}, **{f"thr{i}": np.full(W, 0.5) for i in range(1, 5)}})
    base.update(channels)
    names = list(reversed(CHANNEL_NAMES))
    return np.stack([base[c] for c in names], axis=1)[None], names


def _feat(x, names, cells=None) -> dict[str, float]:
    return dict(zip(physics_feature_names(names), physics_features(x, names, cells)[0]))


def test_resistance_recovered_from_v_equals_e_minus_r_i():
    rng = np.random.default_rng(0)
    i = 15.0 + 6.0 * np.sin(np.linspace(0, 3 * np.pi, W))  # throttle changes: current std ~4 A
    v = 16.4 - 0.045 * i + rng.normal(0, 0.002, W)  # E = 16.4 V, R = 45 mOhm, ADC noise 2 mV
    f = _feat(*_window(V_b=v, I_b=i), cells=np.array([4]))
    # the shrinkage biases R by var(I) / (var(I) + I_FLOOR_A^2) = 0.4 %; the noise adds < 0.5 %
    assert f["r_int"] == pytest.approx(0.045, rel=0.01)
    assert f["v_cell_mean"] == pytest.approx(v.mean() / 4)
    assert _feat(*_window(V_b=v, I_b=i))["v_cell_mean"] == pytest.approx(v.mean())  # cells unknown: V_b


def test_resistance_guarded_at_constant_current():
    rng = np.random.default_rng(1)
    i = 10.0 + rng.normal(0, 0.01, (1, W))  # hover: the current hardly varies
    v = 12.0 + rng.normal(0, 0.005, (1, W))  # voltage noise unrelated to the current
    naive = -np.polyfit(i[0], v[0], 1)[0]
    guarded = internal_resistance(v, i)[0]
    assert abs(naive) > 0.05  # noise over noise: tens of milliohm of nonsense
    assert abs(guarded) < abs(naive) * (0.01 ** 2 / I_FLOOR_A ** 2) * 3 and np.isfinite(guarded)


def test_motor_ratio_and_temperature_features():
    t = np.linspace(0.0, 1.0, W)
    # motor 3 commands 10 % above the mean of the four: 0.55 against 0.4833 for the other three
    thr = {f"thr{i}": np.full(W, 0.55 if i == 3 else (4 * 0.5 - 0.55) / 3) for i in range(1, 5)}
    temp = {"T2": 40.0 + 8.0 * t}  # motor 2 heats by 8 K across the window
    f = _feat(*_window(**thr, **temp))
    assert f["thr_ratio3"] == pytest.approx(1.1)
    assert f["thr_ratio_max"] == pytest.approx(0.1)
    assert f["thr_ratio1"] == pytest.approx(0.9667, abs=1e-4)
    assert f["dT2_slope"] == pytest.approx(8.0 * 3 / 4)  # minus the mean of four, which holds T2 itself
    assert f["dT1_slope"] == pytest.approx(-8.0 / 4)
    assert f["dT2"] == pytest.approx(4.0 * 3 / 4) and f["dT_max"] == pytest.approx(3.0)
    assert f["soc_slope"] == pytest.approx(0.0, abs=1e-12)


def test_vibration_features_by_name_and_input_checks():
    vib = np.linspace(1.0, 5.0, W)
    x, names = _window(vib_ap=vib)
    f = _feat(x, names)
    assert f["vib_ap_mean"] == pytest.approx(3.0) and f["vib_ap_max"] == pytest.approx(5.0)
    paper = [c for c in names if not c.startswith("vib")]  # the paper dataset: no vibration channels
    xp = x[:, :, [names.index(c) for c in paper]]
    assert not any(n.startswith("vib") for n in physics_feature_names(paper))
    assert physics_features(xp, paper).shape == (1, len(physics_feature_names(paper)))
    assert stat_features(xp, paper).shape == (1, len(stat_feature_names(paper)))
    with pytest.raises(ValueError, match=r"\(1, 40, 25\)\) but 23"):
        physics_features(x, paper)
    with pytest.raises(ValueError, match="need channels I_b"):
        physics_features(np.delete(xp, paper.index("I_b"), axis=2), [c for c in paper if c != "I_b"])
    with pytest.raises(ValueError, match=r"shape \(n, W, C\)"):
        stat_features(x[0], names)
    with pytest.raises(ValueError, match="cells"):
        physics_features(x, names, cells=np.array([0]))


# ---------------------------------------------------------------- a small synthetic five-class suite

N_T, WIN, STRIDE = 160, 20, 10


def _arrays(seed: int, n_flights: int = 50) -> dict[str, np.ndarray]:
    """Flights of the 25 realistic channels; each fault moves its physical channel from mid-flight,
    with flight-to-flight spread so that the task is not separable (configurations score differently)."""
    rng = np.random.default_rng(seed)
    n, c = n_flights, len(CHANNEL_NAMES)
    tel = rng.normal(0.0, 1.0, (n, N_T, c))
    idx = {name: k for k, name in enumerate(CHANNEL_NAMES)}
    tel[:, :, idx["V_b"]] += 15.0
    tel[:, :, idx["I_b"]] = 10 + 3 * rng.normal(0, 1, (n, N_T))
    for i in range(1, 5):
        tel[:, :, idx[f"thr{i}"]] = 0.5 + 0.02 * rng.normal(0, 1, (n, N_T))
    cls = np.arange(n) % 5
    split = np.repeat([0, 1, 2, 3], [n // 2, n // 5, n // 5, n - n // 2 - 2 * (n // 5)])  # train, val, test, OOD
    sev = np.zeros((n, N_T))
    sev[:, N_T // 2:] = np.where(cls[:, None] > 0, 1.0, 0.0)
    amp = rng.uniform(0.0, 1.5, n)  # some faults too weak to see
    late = np.arange(N_T) >= N_T // 2
    for k, ch in ((1, "V_b"), (2, "thr2"), (3, "T3"), (4, "vib_px4")):
        scale = 0.05 if ch == "thr2" else 1.0
        tel[np.ix_(cls == k, late, [idx[ch]])] += (amp[cls == k, None, None] * scale)
    rows = {"telemetry": tel.astype(np.float32), "time": np.arange(N_T) * 0.04,
            "channel_names": np.array(CHANNEL_NAMES), "channel_units": np.array(["-"] * c),
            "states": np.zeros((n, N_T, 1)), "state_names": np.array(["x"]), "state_units": np.array(["m"]),
            "severity": sev, "fault_class": cls.astype(np.int64), "onset_s": np.zeros(n), "ramp_s": np.zeros(n),
            "severity_max": np.ones(n), "fault_motor": np.zeros(n, np.int64), "detectable_s": np.zeros(n),
            "split": split.astype(np.int8), "traj_index": np.arange(n), "severity_threshold": np.array(0.5),
            "class_names": np.array(CLASSES),
            "split_names": np.array(["train", "validation", "test", "test_ood_mission"]),
            "pack_cells": np.full(n, 4, np.int8)}
    return rows


def _config(seed: int):
    return build_config({"sim": {"seed": seed, "window": WIN, "stride": STRIDE, "scenario": "realistic",
                                 "classes": list(CLASSES), "n_traj": 50}})


def _dataset(arrays, seed: int = 0) -> Dataset:
    return Dataset(path=None, arrays=arrays, config=_config(seed))


FULL_GRIDS = {m: list(g) for m, g in GRIDS.items()}  # before the fixture below cuts them
_few_configs = pytest.fixture(scope="module", autouse=True)(few_baseline_configs)


def test_every_baseline_gets_the_networks_tuning_budget():
    assert N_CONFIGS == 24 and all(len(g) == N_CONFIGS for g in FULL_GRIDS.values())
    assert FULL_GRIDS["logreg_stats"] == FULL_GRIDS["logreg_physics"]


@pytest.fixture(scope="module")
def fitted():
    ds = _dataset(_arrays(0))
    return ds, fit_baselines(ds, seed=3)


def test_tuning_reads_validation_only(fitted):
    ds, (evals, res) = fitted
    arrays = dict(ds.arrays)
    tel = arrays["telemetry"].copy()
    rng = np.random.default_rng(9)
    tel[arrays["split"] >= 2] = rng.normal(0, 5, tel[arrays["split"] >= 2].shape)  # scramble test + OOD
    _, res2 = fit_baselines(_dataset({**arrays, "telemetry": tel}), seed=3)
    for m in MODELS:
        assert len(res[m].record["validation_macro_f1"]) == len(GRIDS[m]) == 3
        assert res2[m].record["chosen"] == res[m].record["chosen"]
        assert res2[m].record["validation_macro_f1"] == res[m].record["validation_macro_f1"]
        assert res2[m].record["macro_f1_by_split"]["test"] != res[m].record["macro_f1_by_split"]["test"]
    # the scores do come from the validation windows: scrambling those changes them
    val = arrays["telemetry"].copy()
    val[arrays["split"] == 1] = rng.normal(0, 5, val[arrays["split"] == 1].shape)
    _, res3 = fit_baselines(_dataset({**arrays, "telemetry": val}), seed=3, models=("logreg_physics",))
    assert res3["logreg_physics"].record["validation_macro_f1"] != res["logreg_physics"].record["validation_macro_f1"]


def test_baselines_learn_and_cover_every_evaluation_window(fitted):
    ds, (evals, res) = fitted
    assert set(np.unique(evals.split)) == {1, 2, 3}  # validation, test and the OOD set; never train
    assert len(evals.y) == 25 * (1 + (N_T - WIN) // STRIDE)
    for m in MODELS:
        assert res[m].proba.shape == (len(evals.y), 5)
        np.testing.assert_allclose(res[m].proba.sum(axis=1), 1.0, atol=1e-9)
        assert max(res[m].record["validation_macro_f1"]) > 0.4, m  # chance is 0.2
    assert res["logreg_physics"].record["features"] == physics_feature_names(CHANNEL_NAMES)
    per_class = res["gbt"].record["f1_per_class_by_split"]
    assert set(per_class) == {"validation", "test", "test_ood_mission"} and list(per_class["test"]) == list(CLASSES)
    assert res["gbt"].record["macro_f1_by_split"]["test"] == pytest.approx(np.mean(list(per_class["test"].values())))


def test_deterministic_per_seed(fitted):
    ds, (_, res) = fitted
    _, again = fit_baselines(ds, seed=3, models=("gbt",))
    np.testing.assert_array_equal(again["gbt"].proba, res["gbt"].proba)
    a, b = train_subsample(1000, 3, 100), train_subsample(1000, 3, 100)
    np.testing.assert_array_equal(a, b)
    assert len(a) == 100 and np.all(np.diff(a) > 0)
    assert not np.array_equal(a, train_subsample(1000, 4, 100))
    np.testing.assert_array_equal(train_subsample(50, 3, 100), np.arange(50))  # under the cap: every window
    np.testing.assert_array_equal(train_subsample(500, 3, 0), np.arange(500))  # cap 0: every window


def _run(tmp_path, arrays, seed=0):
    run = tmp_path / "run"
    run.mkdir()
    cfg = _config(seed)
    (run / "config.toml").write_text(dumps_toml(cfg))
    write_npz(run / "dataset.npz", dataset_arrays(arrays, cfg.sim))
    return run


def test_run_writes_prediction_sets_and_index(tmp_path):
    run = _run(tmp_path, _arrays(0, 30))
    seed1 = run / "sims" / "seed1"
    seed1.mkdir(parents=True)
    write_npz(seed1 / "dataset.npz", dataset_arrays(_arrays(1, 30), _config(1).sim))
    add_entries(run, [{"model": "cnode", "sim_seed": 1, "train_seed": 0, "dataset": "sims/seed1/dataset.npz",
                       "predictions": "predictions/cnode_sim1_train0.npz"}])
    written, lines = run_baselines(run, seed=2, models=("logreg_stats", "logreg_physics"))
    assert len(lines) == 4
    entries = [e for e in read_index(run) if e["model"] != "cnode"]
    assert {(e["model"], e["sim_seed"], e["train_seed"], e["dataset"]) for e in entries} == {
        (m, s, 2, d) for m in ("logreg_stats", "logreg_physics")
        for s, d in ((0, "dataset.npz"), (1, "sims/seed1/dataset.npz"))}
    for e in entries:
        arrays = read_npz(run / e["predictions"])
        check_prediction_set(arrays, e["predictions"])
        assert arrays["proba"].dtype == np.float32 and list(arrays["class_names"]) == list(CLASSES)
        assert set(np.unique(arrays["split"])) == {1, 2, 3}
        _check_suspected_motor(run, e, arrays)
    from quadfdi.core.jsonio import read_json
    rec = read_json(record_path(run, 1, 2))
    # the configurations actually fitted (this module cuts every grid to 3), not the run-scale budget
    assert rec["n_configs"] == len(GRIDS["logreg_physics"]) == 3 and rec["dataset"] == "sims/seed1/dataset.npz"
    assert all(len(m["validation_macro_f1"]) == 3 for m in rec["models"].values())
    assert rec["models"]["logreg_physics"]["chosen"] == int(np.argmax(rec["models"]["logreg_physics"]["validation_macro_f1"]))


def _two_seed_run(root):
    run = _run(root, _arrays(0, 30))
    (run / "sims" / "seed1").mkdir(parents=True)
    write_npz(run / "sims" / "seed1" / "dataset.npz", dataset_arrays(_arrays(1, 30), _config(1).sim))
    add_entries(run, [{"model": "cnode", "sim_seed": 1, "train_seed": 0, "dataset": "sims/seed1/dataset.npz",
                       "predictions": "predictions/cnode_sim1_train0.npz"}])
    return run


def test_two_workers_write_the_serial_bytes_and_a_rerun_reads_the_cache(tmp_path, monkeypatch):
    """One job per dataset: on a local cluster of two workers the prediction sets are the serial bytes and the
    records the serial ones but for the fit times; a second run reads each dataset's fits from the cache (the
    fit times it reports are the first run's to the digit)."""
    import json

    from quadfdi.core.executor import ExecSettings

    (tmp_path / "s").mkdir()
    (tmp_path / "p").mkdir()
    serial, parallel = _two_seed_run(tmp_path / "s"), _two_seed_run(tmp_path / "p")
    monkeypatch.setitem(GRIDS, "logreg_stats", FULL_GRIDS["logreg_stats"])  # the grid the Dask workers import
    run_baselines(serial, seed=2, models=("logreg_stats",), cap=200)
    two = ExecSettings(workers=2)
    run_baselines(parallel, seed=2, models=("logreg_stats",), cap=200, settings=two)
    for name in ("logreg_stats_sim0_train2.npz", "logreg_stats_sim1_train2.npz"):
        assert (serial / "predictions" / name).read_bytes() == (parallel / "predictions" / name).read_bytes()
    timing = ("fit_seconds", "fit_cpu_seconds", "tuning_seconds", "tuning_cpu_seconds")

    def record(run):
        rec = json.loads(record_path(run, 1, 2).read_text())["models"]["logreg_stats"]
        return {k: v for k, v in rec.items() if k not in timing}, {k: rec[k] for k in timing}

    assert record(serial)[0] == record(parallel)[0]
    assert len(list((parallel / "cache" / "baselines").glob("*.npz"))) == 2
    first = record(parallel)[1]
    run_baselines(parallel, seed=2, models=("logreg_stats",), cap=200, settings=two)
    assert record(parallel)[1] == first


def test_cli_errors_write_nothing(tmp_path):
    bad = _arrays(0, 30)
    bad["split"] = np.where(bad["split"] == 1, 2, bad["split"]).astype(np.int8)  # no validation flights
    run = _run(tmp_path, bad)
    r = quadfdi("train", "baselines", "--run", str(run))
    assert r.returncode == 2 and "validation" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (run / "predictions").exists()
    # the run's dataset is fine, but the index lists a dataset that is missing: nothing written either
    write_npz(run / "dataset.npz", dataset_arrays(_arrays(0, 30), _config(0).sim))
    add_entries(run, [{"model": "cnode", "sim_seed": 1, "train_seed": 0, "dataset": "sims/seed1/dataset.npz",
                       "predictions": "predictions/cnode_sim1_train0.npz"}])
    before = sorted(p.name for p in (run / "predictions").iterdir())
    r = quadfdi("train", "baselines", "--run", str(run))
    assert r.returncode == 2 and "seed1/dataset.npz" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert sorted(p.name for p in (run / "predictions").iterdir()) == before
    r = quadfdi("train", "baselines", "--run", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and "does not exist" in r.stderr
    r = quadfdi("train", "baselines", "--run", str(run), "--max-train-windows", "-1")
    assert r.returncode == 2 and "must not be negative" in r.stderr
    assert sorted(p.name for p in (run / "predictions").iterdir()) == before


def _check_suspected_motor(run, entry, arrays):
    """motor_proba is one-hot on the rotor with the highest window-mean command (the physics rule)."""
    from quadfdi.formats.dataset import load_dataset, make_windows

    mp = arrays["motor_proba"]
    assert mp.shape == (len(arrays["proba"]), 4) and np.all(mp.sum(axis=1) == 1.0)
    ds = load_dataset(run / entry["dataset"])
    cols = [ds.channel_names.index(f"thr{i}") for i in range(1, 5)]
    for code in np.unique(arrays["split"]):
        w = make_windows(ds, int(code))
        want = {(int(t), round(float(e), 6)): int(np.argmax(x[:, cols].mean(axis=0))) for t, e, x in zip(w.traj, w.t_end, w.x)}
        rows = np.flatnonzero(arrays["split"] == code)
        got = {(int(arrays["traj"][r]), round(float(arrays["t_end"][r]), 6)): int(np.argmax(mp[r])) for r in rows}
        assert got == want
