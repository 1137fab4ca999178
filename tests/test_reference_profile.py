"""The reference profile ``flightlog-ref`` (core/vehicle_record.py): the vehicle record from a vehicle
reference, the ten reference channels against hand arithmetic, their fills without a record or without
what the record holds, each fleet flight read against its own vehicle's reference flights only, the
training masker dropping the record exactly as no record does, a train run indexing ``<kind>_noref``
beside ``<kind>``, and detect reading the reference only for this profile and saying so."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.core import vehicle_record as vr
from quadfdi.core.channels import PROFILE_BY_NAME, REFERENCE_GROUP
from quadfdi.core.config import load_config
from quadfdi.core.profiles import apply_profile, channel_names, mask_layout, required_raw
from quadfdi.formats.dataset import dataset_arrays, load_dataset, write_npz
from quadfdi.sim.simulate import generate
from quadfdi.train.masks import Masker
from quadfdi.train.vehicle_ref import dataset_flight, learn_references, profiled, vehicle_records
from tests.conftest import FLEET_TINY, SHARED_DATA, quadfdi

REF, MASK = "flightlog-ref", "flightlog-mask"
NAMES = channel_names(REF, [])
PAD = SHARED_DATA / "crazypad" / "motor_data"
REFERENCE_FLIGHTS = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]


def _raw(n_flights: int = 2, t: int = 30, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    raw = {r: (rng.random((n_flights, t)) + 0.5).astype(np.float32) for r in required_raw(REF)}
    raw["r"] = (rng.random((n_flights, t)) * 4 - 2).astype(np.float32)  # beyond the record's yaw-rate range
    return raw


def _record() -> np.ndarray:
    rec = vr.empty()
    rec[0:4] = [1.10, 0.90, 1.05, 0.95]
    rec[4:8] = [0.02, -0.01, 0.0, 0.03]
    rec[8:12] = [0.05, -0.05, 0.01, 0.0]
    rec[12:16] = [-0.5, 1.0, -0.25, 0.25]
    rec[16:18] = [2.0, 3.0]  # PX4 floor; no ArduPilot floor (NaN)
    rec[20:24] = [1.01, 0.99, 1.02, 0.98]
    return rec


def test_profile_is_the_masked_profile_then_ten_reference_channels_and_avail_reference():
    mask = channel_names(MASK, [])
    assert PROFILE_BY_NAME[REF].raw == PROFILE_BY_NAME[MASK].raw and PROFILE_BY_NAME[REF].id == 5
    refs = ["m1_ref", "m2_ref", "m3_ref", "m4_ref", "vib_ref", "vib_ap_ref", "rpm1_ref", "rpm2_ref", "rpm3_ref",
            "rpm4_ref"]
    assert NAMES == mask[:28] + refs + mask[28:] + ["avail_reference"]
    cols, fill, avail = mask_layout(REF)
    assert [NAMES[j] for j in cols[REFERENCE_GROUP]] == refs and avail[REFERENCE_GROUP] == len(NAMES) - 1
    assert REFERENCE_GROUP not in mask_layout(MASK)[0]
    assert [fill[NAMES.index(n)] for n in ("m1_ref", "vib_ref", "rpm4_ref")] == [1.0, 0.0, 1.0]


def test_reference_channels_are_the_documented_arithmetic_and_the_rest_is_the_masked_profile():
    raw, rec = _raw(), _record()
    x = apply_profile(REF, raw, 4, np.float32(0.5), np.float32(10.0), record=rec)
    plain = apply_profile(MASK, raw, 4, np.float32(0.5), np.float32(10.0))
    assert np.array_equal(x[..., :28], plain[..., :28]) and np.array_equal(x[..., 38:48], plain[..., 28:])
    col = {n: x[..., j] for j, n in enumerate(NAMES)}
    f = np.float32
    vh = np.float32(np.cos(raw["yaw"].astype(np.float64))) * raw["vx"] + \
        np.float32(np.sin(raw["yaw"].astype(np.float64))) * raw["vy"]
    vf, yr = np.clip(vh, f(-0.5), f(1.0)), np.clip(raw["r"], f(-0.25), f(0.25))
    for k in range(4):
        s = (rec[k] + rec[4 + k] * vf) + rec[8 + k] * yr
        assert np.array_equal(col[f"m{k + 1}_ref"], (raw[f"thr{k + 1}"] / f(0.5)) / s)
        a = [raw[f"rpm{i}"] for i in range(1, 5)]
        share = a[k] / ((((a[0] + a[1]) + a[2]) + a[3]) * f(0.25))
        assert np.array_equal(col[f"rpm{k + 1}_ref"], share / rec[20 + k])
    c = (((raw["thr1"] + raw["thr2"]) + raw["thr3"]) + raw["thr4"]) * f(0.25)
    assert np.array_equal(col["vib_ref"], raw["vib_px4"] - (rec[16] + rec[17] * c))
    assert (col["vib_ap_ref"] == 0.0).all() and (col["avail_reference"] == 1.0).all()  # NaN field: its fill


def test_without_a_record_or_without_the_groups_the_reference_channels_take_their_fills():
    raw = _raw()
    fills = np.array([PROFILE_BY_NAME[REF].model[j].fill for j in range(len(NAMES))], np.float32)
    none = apply_profile(REF, raw, 4, np.float32(0.5), np.float32(10.0))
    assert np.array_equal(none[..., 28:38], np.broadcast_to(fills[28:38], none[..., 28:38].shape))
    assert (none[..., -1] == 0.0).all()
    per_flight = np.stack([_record(), vr.empty()])  # flight 0 has a record, flight 1 none
    x = apply_profile(REF, raw, 4, np.float32(0.5), np.float32(10.0), {"vib_px4": np.array([False, True])},
                      per_flight)
    assert (x[0, :, -1] == 1.0).all() and (x[1, :, -1] == 0.0).all()
    assert (x[0, :, NAMES.index("vib_ref")] == 0.0).all()  # the flight lacks the PX4 metric
    assert not (x[0, :, NAMES.index("m1_ref")] == 1.0).all()
    no_rates = apply_profile(REF, raw, 4, np.float32(0.5), np.float32(10.0), {"rates": False}, _record())
    rec = _record()
    assert not np.array_equal(no_rates[..., NAMES.index("m1_ref")], x[0:1, :, NAMES.index("m1_ref")][0])
    vf = np.clip(no_rates[..., NAMES.index("vx_h")], np.float32(-0.5), np.float32(1.0))
    s = (rec[0] + rec[4] * vf) + rec[8] * np.float32(0.0)  # yaw rate 0 without body rates
    assert np.array_equal(no_rates[..., NAMES.index("m1_ref")], (raw["thr1"] / np.float32(0.5)) / s)


def test_record_from_a_reference_takes_its_share_model_floors_and_esc_shares():
    ref = {"motor_share": [{"mean": m} for m in (1.1, 0.9, 1.05, 0.95)],
           "share_model": {"regressors": ["v_forward"], "range_5_95": {"v_forward": [-1.0, 2.0]},
                           "motors": [{"intercept": 1.0 + k / 10, "per_v_forward": k / 100, "per_yaw_rate": 9.0}
                                      for k in range(4)]},
           "vibration": {"vib_ap": {"floor": {"mean": 1.5}, "per_collective": {"mean": 2.5}}}, "esc": {}}
    rec = vr.from_reference(ref)
    assert np.allclose(rec[0:4], [1.0, 1.1, 1.2, 1.3]) and np.allclose(rec[4:8], [0, 0.01, 0.02, 0.03])
    assert (rec[8:12] == 0).all() and list(rec[12:16]) == [-1.0, 2.0, 0.0, 0.0]  # yaw rate not a regressor
    assert np.isnan(rec[16:18]).all() and list(rec[18:20]) == [1.5, 2.5] and np.isnan(rec[20:24]).all()
    ref["share_model"] = {"motors": None}  # too few steady samples: the airborne mean share, no slopes
    rec = vr.from_reference(ref)
    assert np.allclose(rec[0:4], [1.1, 0.9, 1.05, 0.95]) and (rec[4:16] == 0).all()
    with pytest.raises(ValueError, match="four motor shares"):
        vr.from_reference({"motor_share": []})


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    cfg = load_config("fleet", FLEET_TINY)
    root = tmp_path_factory.mktemp("fleetrefprofile")
    write_npz(root / "dataset.npz", dataset_arrays(generate(cfg.sim), cfg.sim))
    return load_dataset(root / "dataset.npz")


def test_each_fleet_flight_reads_its_own_vehicles_reference(fleet):
    records = vehicle_records(fleet)
    refs = learn_references(fleet.arrays, str(fleet.path))
    for row, v in enumerate(fleet["vehicle_id"]):
        assert np.array_equal(records[row], vr.from_reference(refs[int(v)]), equal_nan=True)
    assert np.isfinite(records[:, :16]).all() and np.isfinite(records[:, 16:18]).all()
    pd = profiled(fleet, REF, patterns=False)
    x, healthy = pd["telemetry"], fleet["fault_class"] == 0
    ref_rows = fleet["reference_flight"] & healthy
    m = x[ref_rows][..., [NAMES.index(f"m{k}_ref") for k in range(1, 5)]]
    rel = x[ref_rows][..., [NAMES.index(f"m{k}_rel") for k in range(1, 5)]]
    # on its own reference flights the vehicle's asymmetry is taken out: the four closer to 1 than the raw shares
    assert np.abs(np.median(m, axis=1) - 1).mean() < np.abs(np.median(rel, axis=1) - 1).mean()
    assert (x[..., -1] == 1.0).all()
    noref = profiled(fleet, REF, patterns=False, reference=False)["telemetry"]
    dropped = Masker(REF, pd.channel_names).drop_reference(x.copy(), np.arange(len(x)))
    assert np.array_equal(dropped, noref)  # the masker's drop is exactly "no record"


def test_a_dataset_without_vehicles_has_no_records(fleet):
    arrays = {k: v for k, v in fleet.arrays.items() if k not in ("vehicle_id", "reference_flight")}
    from quadfdi.formats.dataset import Dataset

    ds = Dataset(fleet.path, arrays, fleet.config)
    assert np.isnan(vehicle_records(ds)).all()
    assert (profiled(ds, REF, patterns=False)["telemetry"][..., -1] == 0.0).all()


def test_a_train_run_indexes_each_network_with_and_without_the_record(reference_export):
    import json

    run = reference_export.parent
    models = {e["model"] for e in json.loads((run / "predictions" / "index.json").read_text())["entries"]}
    assert {"cnode", "cnode_noref", "gru", "gru_noref"} <= models
    manifest = json.loads((reference_export / "manifest.json").read_text())
    assert "avail_reference" in json.dumps(manifest)


def test_detect_reads_the_reference_only_for_a_reference_profile_and_says_so(reference_export, masked_export):
    from quadfdi.detect.run import detect

    ds = load_dataset(reference_export.parent / "dataset.npz")
    refs = learn_references(ds.arrays, "d")
    row = int(np.flatnonzero(~ds["reference_flight"])[0])
    flight, ref = dataset_flight(ds.arrays, row, "d").arrays, refs[int(ds["vehicle_id"][row])]
    with_ref = detect(reference_export, flight, "cnode", "fp32", "ort", ref)
    without = detect(reference_export, flight, "cnode", "fp32", "ort", None)
    assert with_ref["record"]["model_reference"] == "reads the vehicle record"
    assert without["record"]["model_reference"].startswith("no vehicle reference")
    assert (with_ref["inputs"].x[:, -1] == 1).all() and (without["inputs"].x[:, -1] == 0).all()
    assert not np.array_equal(with_ref["arrays"]["proba"], without["arrays"]["proba"], equal_nan=True)
    masked = detect(masked_export, flight, "cnode", "fp32", "ort", ref)
    assert masked["record"]["model_reference"] == "the model's profile reads no vehicle reference"


@pytest.mark.skipif(not all(p.exists() for p in REFERENCE_FLIGHTS), reason="the CrazyPAD logs are not here")
def test_detect_cli_reads_a_crazyflie_reference_on_a_held_out_flight(reference_export, tmp_path):
    import json

    ref = tmp_path / "cf.json"
    res = quadfdi("vehicle", "learn", *map(str, REFERENCE_FLIGHTS), "--out", str(ref))
    assert res.returncode == 0, res.stderr
    data = json.loads(ref.read_text())
    rec = vr.from_reference(data)
    m3 = next(m["rotor"] for m in data["motor_share"] if m["log_motor"] == "M3")  # the record is in project order
    assert rec[m3 - 1] > 1.05 and np.isfinite(rec[:16]).all()  # the healthy Crazyflie runs its M3 above the mean
    assert np.isnan(rec[16:24]).all()  # no vibration metric, no ESC telemetry in these logs
    out = tmp_path / "d"
    res = quadfdi("detect", "--model", str(reference_export), str(PAD / "normal_flight" / "E9_log04"),
                  "--vehicle", str(ref), "--out", str(out))
    assert res.returncode in (0, 1), res.stderr
    record = json.loads((out / "alarms.json").read_text())
    assert record["model_reference"] == "reads the vehicle record" and record["vehicle_reference"] is not None


def test_solver_study_and_bench_time_the_models_own_inputs(reference_export):
    from quadfdi.bench.run import test_windows
    from quadfdi.core.rundir import RunDir
    from quadfdi.formats.export_folder import Export
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.solverstudy.run import _test_windows

    run = RunDir(reference_export.parent)
    cfg = load_config(run.root / "config.toml")
    _, blob = load_checkpoint(run.checkpoint("cnode"), "cnode")
    _, test = _test_windows(run, cfg, blob)
    assert test.x.shape[2] == len(NAMES) and (test.x[..., -1] == 1).all()  # each flight with its vehicle's record
    assert test_windows(run, Export.open(reference_export)).x.shape[2] == len(NAMES)
