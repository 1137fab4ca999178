"""The physics profile ``flightlog-phys`` (core/causal.py): flightlog-ref's channels and eight channels computed
by recursions from the flight's first sample (``r_cell``, ``r_cell_ref``, the smoothed reference deviations). The
sag recursion against float64 exponentially weighted moments and a known resistance, the time constant against
the closed form, causality and the state held over an unusable sample, the fills without current, battery or
record, the training masker's reference drop, and the C++ mirror (fwref/causal.hpp through fwref/profile.hpp,
its state carried sample by sample as the stream carries it) bit for bit on the tiny fleet's flights and on the
shared PX4 mission with its own record, with and without its current; a trained and exported flightlog-phys run
and detect on it. The stream runtime and the Cortex-M4 on that export: tests/test_vehicle_record_stream.py,
tests/test_vehicle_record_mcu.py."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core import causal, vehicle_record as vr
from quadfdi.core.channels import PROFILE_BY_NAME, REFERENCE_GROUP, groups_of_model, stream_raw
from quadfdi.core.profiles import apply_profile, channel_names, mask_layout, required_raw
from quadfdi.formats.vehicle_record_bin import record_from_vehicle_json
from tests.conftest import SHARED_DATA, quadfdi
from tests.profile_mirror import build_mirror, cpp_inputs

PHYS, REF = "flightlog-phys", "flightlog-ref"
NAMES = channel_names(PHYS, [])
PHYSICS = ["r_cell", "r_cell_ref", "m1_ref_lp", "m2_ref_lp", "m3_ref_lp", "m4_ref_lp", "vib_ref_lp", "vib_ap_ref_lp"]
COL = {n: NAMES.index(n) for n in NAMES}
PX4 = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"
STREAM_RECORD = {"profile": PHYS, "raw_channels": list(stream_raw(PROFILE_BY_NAME[PHYS])), "cells_from_stream": True,
                 "sample_dt_s": 0.04, "window": 40, "stride": 20}


def _record() -> np.ndarray:
    rec = vr.empty()
    rec[0:4] = [1.10, 0.90, 1.05, 0.95]
    rec[4:12] = 0.0
    rec[12:16] = [-0.5, 1.0, -0.25, 0.25]
    rec[16:20] = [2.0, 4.0, 1.5, 3.0]
    rec[20:24] = 1.0
    rec[24] = 0.008  # the healthy sag, ohm per cell
    return rec


def _flight(t: int = 400, seed: int = 0, n: int = 1) -> dict[str, np.ndarray]:
    """Raw channels (n, t) of a hovering quad with a current that moves."""
    rng = np.random.default_rng(seed)
    raw = {r: (rng.random((n, t)) * 0.1 + 0.5).astype(np.float32) for r in required_raw(PHYS)}
    raw["I_b"] = (20 + 3 * np.sin(np.arange(t) * 0.1) + rng.normal(0, 0.3, (n, t))).astype(np.float32)
    raw["V_b"] = (4 * (3.9 - 0.01 * raw["I_b"]) + rng.normal(0, 0.01, (n, t))).astype(np.float32)
    for name in ("vib_px4", "vib_ap"):
        raw[name] = (5 + rng.random((n, t))).astype(np.float32)
    return raw


def _apply(raw, available=None, record=None) -> np.ndarray:
    return apply_profile(PHYS, raw, 4, 0.5, 20.0, available, _record() if record is None else record)


# ------------------------------------------------------------------------------ the table


def test_profile_is_flightlog_ref_with_eight_physics_channels_before_the_availability():
    ref = channel_names(REF, [])
    assert PROFILE_BY_NAME[PHYS].id == 6 and PROFILE_BY_NAME[PHYS].raw == PROFILE_BY_NAME[REF].raw
    assert NAMES == ref[:38] + PHYSICS + ref[38:]
    r_cell = PROFILE_BY_NAME[PHYS].model[COL["r_cell"]]
    assert groups_of_model(r_cell) == ("battery", "current") and not r_cell.reference and r_cell.fill == 0.0
    cols, fill, _ = mask_layout(PHYS)
    assert COL["r_cell"] in cols["battery"] and COL["r_cell"] in cols["current"]
    assert COL["r_cell"] not in cols[REFERENCE_GROUP] and all(COL[n] in cols[REFERENCE_GROUP] for n in PHYSICS[1:])
    assert COL["vib_ref_lp"] in cols["vib_px4"] and COL["vib_ap_ref_lp"] in cols["vib_ap"]
    assert groups_of_model(PROFILE_BY_NAME[PHYS].model[COL["r_cell_ref"]]) == ("battery", "current")
    assert fill[[COL[n] for n in PHYSICS]].tolist() == [0, 0, 1, 1, 1, 1, 0, 0]


# ------------------------------------------------------------------------------ the recursions


def _ew_moments_f64(v: np.ndarray, i: np.ndarray) -> np.ndarray:
    """R = -(E[vI] - E[v] E[I]) / ((E[I^2] - E[I]^2) + I_FLOOR_A^2), float64 EW means from the first sample."""
    a = float(causal.ALPHA)
    v, i = v.astype(np.float64), i.astype(np.float64)
    m = np.array([v[0], i[0], v[0] * i[0], i[0] * i[0]])
    out = np.empty(len(v))
    for n in range(len(v)):
        if n:
            m += a * (np.array([v[n], i[n], v[n] * i[n], i[n] * i[n]]) - m)
        out[n] = -(m[2] - m[0] * m[1]) / ((m[3] - m[1] * m[1]) + causal.I_FLOOR_A ** 2)
    return out


def _ew_moments_f32(v: np.ndarray, i: np.ndarray) -> np.ndarray:
    a, m = causal.ALPHA, [v[0], i[0], v[0] * i[0], i[0] * i[0]]
    out = np.empty(len(v), np.float32)
    for n in range(len(v)):
        if n:
            m = [m[0] + a * (v[n] - m[0]), m[1] + a * (i[n] - m[1]), m[2] + a * (v[n] * i[n] - m[2]),
                 m[3] + a * (i[n] * i[n] - m[3])]
        out[n] = -(m[2] - m[0] * m[1]) / ((m[3] - m[1] * m[1]) + causal.FLOOR2)
    return out


@pytest.mark.parametrize("swing_a", [4.0, 1.0, 0.3])
def test_centred_form_is_the_ew_moments(swing_a):
    """The float32 centred recursion is the float64 EW moments within 0.1 % of the sag at a 4, 1 and 0.3 A
    swing around 20 A; float32 raw moments are 13 % off at 0.3 A (why the centred form)."""
    rng = np.random.default_rng(0)
    t = np.arange(3000) * 0.04
    i = (20 + swing_a * np.sin(2 * np.pi * t / 3.0) + rng.normal(0, 0.1, t.size)).astype(np.float32)
    v = (4.0 - 0.012 * i - 0.0005 * t + rng.normal(0, 0.003, t.size)).astype(np.float32)
    exact = _ew_moments_f64(v, i)[200:]
    scale = np.abs(exact).mean()
    centred = np.abs(causal.sag_per_ampere(v, i)[200:] - exact).max() / scale
    raw = np.abs(_ew_moments_f32(v, i)[200:] - exact).max() / scale
    print(f"swing {swing_a} A: centred {centred:.2e}, raw float32 moments {raw:.2e} of the sag")
    assert centred < 1e-3
    if swing_a == 0.3:
        assert raw > 0.05


def test_r_cell_recovers_a_known_sag_once_the_current_varies():
    """V_b = cells (V0 - R I - drift t) + noise (1 mV per cell), three packs, a 4 A swing around 18 A: after
    10 s r_cell is R within 3 % without discharge (the shrinkage var / (var + 0.25^2) is 0.8 % of it, the
    noise the rest); a discharge of 1 mV/s per cell leaks in (exponential weights are one-sided, so a trend
    and a swinging current are not orthogonal under them): within 0.6 mOhm then. At a steady current (or
    0.05 A of noise, against the 0.25 A floor) it stays near 0: nothing to measure."""
    rng = np.random.default_rng(1)
    t = np.arange(1500) * 0.04
    r_true = np.array([0.004, 0.012, 0.03])[:, None]
    i = (18 + 4 * np.sin(2 * np.pi * t / 2.5) + rng.normal(0, 0.2, (3, t.size))).astype(np.float32)
    for drift, rel, absolute in ((0.0, 0.03, 1.0), (0.001, 1.0, 6e-4)):
        v = (6 * (3.95 - r_true * i - drift * t + rng.normal(0, 0.001, (3, t.size)))).astype(np.float32)
        raw = _flight(t.size, n=3) | {"I_b": i, "V_b": v}
        late = apply_profile(PHYS, raw, 6, 0.5, 18.0, None, _record())[:, 250:, COL["r_cell"]]
        print(f"drift {drift} V/s: |r_cell / R - 1| <= {np.abs(late / r_true - 1).max():.3f}, "
              f"|r_cell - R| <= {np.abs(late - r_true).max() * 1e3:.2f} mOhm")
        assert np.abs(late / r_true - 1).max() < rel and np.abs(late - r_true).max() < absolute
    steady = causal.sag_per_ampere(v[:, :1].repeat(t.size, 1) / 6, np.full((3, t.size), 18.0, np.float32))
    assert np.abs(steady).max() == 0
    quiet = causal.sag_per_ampere((3.9 + rng.normal(0, 0.001, (3, t.size))).astype(np.float32),
                                  (18 + rng.normal(0, 0.05, (3, t.size))).astype(np.float32))
    assert np.abs(quiet[:, 250:]).max() < 0.1 * r_true.min()


def test_time_constant_is_the_closed_form():
    """A unit step through ewma after 4 s (TAU_S) of samples: 1 - (1 - ALPHA)^100 = 1 - 1/e to float32."""
    x = np.r_[np.zeros(10), np.ones(100)].astype(np.float32)
    y = causal.ewma(x)
    assert y[0] == 0 and abs(y[-1] - (1 - np.exp(-1.0))) < 1e-5
    assert abs(float(causal.ALPHA) - (1 - np.exp(-causal.SAMPLE_DT_S / causal.TAU_S))) < 1e-8


def test_recursions_are_causal_and_hold_their_state_over_an_unusable_sample():
    raw = _flight()
    x = _apply(raw)
    later = {k: v.copy() for k, v in raw.items()}
    for name in ("I_b", "V_b", "thr2", "vib_px4", "vib_ap"):
        later[name][:, 250] *= 1.5
    y = _apply(later)
    cols = [COL[n] for n in PHYSICS]
    np.testing.assert_array_equal(x[:, :250, cols].view(np.uint32), y[:, :250, cols].view(np.uint32))
    moved = [COL[n] for n in ("r_cell", "r_cell_ref", "m2_ref_lp", "vib_ref_lp", "vib_ap_ref_lp")]
    assert (x[:, 250:, moved] != y[:, 250:, moved]).all()  # and the change carries on
    gap = {k: v.copy() for k, v in raw.items()}
    gap["I_b"][:, 100] = np.nan
    g = _apply(gap)[0, :, COL["r_cell"]]
    cut = causal.sag_per_ampere(np.delete(x[:, :, COL["v_cell"]], 100, 1), np.delete(raw["I_b"], 100, 1))[0]
    assert np.isnan(g[100]) and np.isfinite(np.delete(g, 100)).all()
    np.testing.assert_array_equal(np.delete(g, 100).view(np.uint32), cut.view(np.uint32))


def test_without_current_battery_or_record_the_physics_channels_take_their_fills():
    raw = _flight(n=2)
    fills = np.array([0, 0, 1, 1, 1, 1, 0, 0], np.float32)
    cols = [COL[n] for n in PHYSICS]
    full = _apply(raw)
    assert (np.abs(full[:, 50:, cols] - fills) > 0).all()
    for lacking, name in (("current", "I_b"), ("battery", "V_b")):
        x = _apply(raw, {lacking: np.array([False, True])})  # training's masks: the values there, not read
        assert (x[0, :, COL["r_cell"]] == 0).all() and (x[0, :, COL[f"avail_{lacking}"]] == 0).all()
        assert (x[0, :, COL["r_cell_ref"]] == 0).all()
        np.testing.assert_array_equal(x[1], full[1])  # the other flight keeps everything
        y = _apply({k: v for k, v in raw.items() if k != name}, {lacking: False})  # a log without the channel
        np.testing.assert_array_equal(y[0], x[0])
    none = _apply(raw, record=vr.empty())
    assert (none[..., cols[1:]] == fills[1:]).all() and (none[..., COL["avail_reference"]] == 0).all()
    np.testing.assert_array_equal(none[..., COL["r_cell"]], full[..., COL["r_cell"]])  # the sag needs no record
    rec = _record()
    rec[[1, 16, 24]] = np.nan  # no share for motor 2, no PX4 vibration floor, no sag (a version 1 record)
    part = _apply(raw, record=rec)
    assert (part[..., [COL["m2_ref_lp"], COL["vib_ref_lp"], COL["r_cell_ref"]]] == [1, 0, 0]).all()
    np.testing.assert_array_equal(full[..., COL["r_cell_ref"]], full[..., COL["r_cell"]] - np.float32(0.008))
    np.testing.assert_array_equal(part[..., COL["m1_ref_lp"]], full[..., COL["m1_ref_lp"]])


def test_smoothed_share_is_the_smoothed_m_ref():
    """m{k}_ref_lp = ewma(thr_k / s_k) / hover_cmd: the low-passed m{k}_ref (to float32 rounding)."""
    x = _apply(_flight())[0]
    for k in range(1, 5):
        want = causal.ewma(x[:, COL[f"m{k}_ref"]])
        np.testing.assert_allclose(x[:, COL[f"m{k}_ref_lp"]], want, rtol=1e-5)
    np.testing.assert_array_equal(x[:, COL["vib_ref_lp"]], causal.ewma(x[:, COL["vib_ref"]]))


def test_training_drops_the_record_from_the_smoothed_deviations_as_no_record_does():
    from quadfdi.train.masks import Masker

    raw = _flight(n=6)
    x = _apply(raw)
    none = _apply(raw, record=vr.empty())
    dropped = Masker(PHYS, NAMES).drop_reference(x.copy(), np.arange(len(x)))
    np.testing.assert_array_equal(dropped, none)  # r_cell kept: the sag needs no record


# ------------------------------------------------------------------------------ the C++ mirror, bit for bit

@pytest.fixture(scope="module")
def mirror(tmp_path_factory) -> Path:
    """fwref/profile.hpp's flightlog-phys (tests/profile_mirror.py)."""
    return build_mirror(tmp_path_factory.mktemp("phys_mirror"), PHYS)


def _same_bits(mirror: Path, tmp: Path, rs, record: np.ndarray | None) -> np.ndarray:
    """The C++ inputs of stream ``rs`` with ``record`` are the Python stream path's (detect.streamref.windows_of:
    apply_profile over the whole stream) bit for bit, NaN where Python has NaN; returns them."""
    from quadfdi.detect.streamref import windows_of

    rs = dataclasses.replace(rs, vehicle=record)
    sw = windows_of(rs, STREAM_RECORD)
    got = cpp_inputs(mirror, tmp, rs, sw.hover, record, PHYS)
    fin = np.isfinite(sw.x)
    assert (np.isfinite(got) == fin).all()
    np.testing.assert_array_equal(got.view(np.uint32)[fin], sw.x.view(np.uint32)[fin])
    return sw.x


def test_cpp_profile_is_python_bit_for_bit_on_fleet_flights(mirror, tiny_fleet, tmp_path):
    """Every flight of the tiny fleet (each under its mask pattern) with its vehicle's record, without one, and
    with one whose motor 2 share and PX4 vibration floor hold nothing."""
    from quadfdi.formats.dataset import load_dataset, vehicle_columns
    from quadfdi.formats.stream import from_dataset
    from quadfdi.train.vehicle_ref import learn_references

    ds = load_dataset(tiny_fleet / "dataset.npz")
    refs, vid = learn_references(ds.arrays, "fleet"), vehicle_columns(ds.arrays)["vehicle_id"]
    moving = 0
    for row in range(len(vid)):
        rs = from_dataset(tiny_fleet / "dataset.npz", row, STREAM_RECORD, ds)
        record = None if row % 3 == 1 else vr.from_reference(refs[int(vid[row])])
        if row % 3 == 2:
            record[[1, 16]] = np.nan
        x = _same_bits(mirror, tmp_path, rs, record)
        if rs.carries("I_b") and rs.carries("V_b"):
            moving += int(np.abs(x[50:, COL["r_cell"]]).max() > 1e-4)
        else:
            assert (x[:, COL["r_cell"]] == 0).all()
    assert moving >= 5


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    """The shared PX4 UAVCAN mission as a flightlog-phys stream, and the vehicle record learned from itself."""
    if not PX4.is_file():
        pytest.skip(f"the shared logs are not at {PX4.parent}")
    from quadfdi.detect.stream_cli import from_flight

    out = tmp_path_factory.mktemp("mission_phys")
    res = quadfdi("vehicle", "learn", str(PX4), "--out", str(out / "v.json"))
    assert res.returncode == 0, res.stderr
    return from_flight(PX4, STREAM_RECORD), record_from_vehicle_json(out / "v.json"), out / "v.json"


def test_cpp_profile_is_python_bit_for_bit_on_a_px4_log_with_and_without_its_current(mirror, mission, tmp_path):
    """The mission (current, PX4 vibration, ESC telemetry) with its own record: r_cell a per-cell sag of a few
    milliohm, r_cell_ref near 0 (the flight is its own reference), every smoothed deviation but vib_ap_ref_lp (no
    ArduPilot metric) live; without its current both sags at their fill and avail_current 0, the rest unchanged."""
    rs, record, _ = mission
    x = _same_bits(mirror, tmp_path, rs, record)
    live = np.isfinite(x).all(axis=1)
    r = x[live][:, COL["r_cell"]]
    print(f"mission r_cell: median {np.median(r) * 1e3:.2f} mohm per cell, 5-95 % "
          f"{np.percentile(r, 5) * 1e3:.2f}-{np.percentile(r, 95) * 1e3:.2f}")
    assert live.sum() > 500 and 0 < np.median(r) < 0.05
    assert (x[live][:, COL["vib_ap_ref_lp"]] == 0).all()
    assert all((x[live][:, COL[n]] != 1).mean() > 0.9 for n in PHYSICS[2:6])
    beyond = x[live][:, COL["r_cell_ref"]]
    print(f"mission r_cell_ref: median {np.median(beyond) * 1e3:.2f} mohm per cell (its own reference's sag "
          f"{record[24] * 1e3:.2f})")
    assert np.isfinite(record[24]) and abs(np.median(beyond)) < 0.5 * record[24]
    i_b = rs.names.index("I_b")
    values = rs.values.copy()
    values[:, i_b] = np.nan
    flags = rs.carried_flags.copy()
    flags[i_b] = False
    y = _same_bits(mirror, tmp_path, dataclasses.replace(rs, values=values, carried=flags), record)
    assert (y[:, [COL["r_cell"], COL["r_cell_ref"]]] == 0).all() and (y[:, COL["avail_current"]] == 0).all()
    keep = [COL[n] for n in PHYSICS[2:]]
    np.testing.assert_array_equal(y[live][:, keep], x[live][:, keep])


def test_the_record_of_a_reference_holds_its_sag_and_the_cli_writes_it_for_the_physics_profile(mission, tmp_path):
    """`quadfdi vehicle record --profile flightlog-phys`: field 24 the reference's sag per ampere per cell
    (vehicle.json battery.sag_v_per_a, with its sign turned: ohm), the file for profile 6 and refused for 5."""
    import json

    from quadfdi.core.errors import QuadfdiError
    from quadfdi.formats.vehicle_record_bin import read_record

    _, record, vehicle_json = mission
    res = quadfdi("vehicle", "record", str(vehicle_json), "--profile", PHYS, "--out", str(tmp_path / "r.bin"))
    assert res.returncode == 0, res.stderr
    sag = json.loads(vehicle_json.read_text())["battery"]["sag_v_per_a"]["mean"]
    assert record[24] == np.float32(-sag) and 0 < record[24] < 0.05
    np.testing.assert_array_equal(read_record(tmp_path / "r.bin", PHYS).view(np.uint32), record.view(np.uint32))
    with pytest.raises(QuadfdiError, match="is for profile 'flightlog-phys', the model's is 'flightlog-ref'"):
        read_record(tmp_path / "r.bin", REF)


# ------------------------------------------------------------------------------ train, export, detect


def test_a_physics_run_trains_exports_and_records_its_profile(physics_export):
    """`quadfdi train --set train.profile=flightlog-phys` then export (tests/conftest.py): the manifest's 57
    channels with r_cell's formula, weights.bin's on-board record profile id 6, both networks with and without
    the record in the prediction index."""
    import json

    from tests.test_stream import _record

    manifest = json.loads((physics_export / "manifest.json").read_text())
    assert manifest["profile"]["name"] == PHYS and len(NAMES) == 57
    assert "r_cell" in json.dumps(manifest["profile"]) and "tau 4 s" in json.dumps(manifest["profile"])
    assert _record(physics_export)["profile"] == PHYS
    index = json.loads((physics_export.parent / "predictions" / "index.json").read_text())["entries"]
    assert {"cnode", "cnode_noref", "gru", "gru_noref"} <= {e["model"] for e in index}


def test_a_dataset_on_another_grid_is_refused(tiny_fleet):
    """The recursions' coefficient belongs to the 25 Hz grid: a dataset sampled otherwise, one line."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.models.inputs import profiled_dataset

    ds = load_dataset(tiny_fleet / "dataset.npz")
    cfg = ds.config
    other = dataclasses.replace(ds, config=dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, sample_dt_s=0.02)))
    with pytest.raises(QuadfdiError, match="its recursions step every 0.04 s"):
        profiled_dataset(other, PHYS)
    assert profiled_dataset(ds, PHYS, records=None)["telemetry"].shape[-1] == 57


def test_detect_runs_a_physics_model_on_a_fleet_flight_with_its_reference(physics_export):
    """quadfdi.detect on a held-out fleet flight: the inputs are the dataset path's (the recursions over the
    whole flight), the record read, r_cell moving."""
    from quadfdi.detect.run import detect
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.train.vehicle_ref import dataset_flight, learn_references

    ds = load_dataset(physics_export.parent / "dataset.npz")
    refs = learn_references(ds.arrays, "d")
    row = int(np.flatnonzero(~ds["reference_flight"])[0])
    flight, ref = dataset_flight(ds.arrays, row, "d").arrays, refs[int(ds["vehicle_id"][row])]
    out = detect(physics_export, flight, "cnode", "int8", "cpp", ref)
    assert out["record"]["model_reference"] == "reads the vehicle record"
    x = out["inputs"].x
    assert (x[:, COL["avail_reference"]] == 1).all() and np.ptp(x[:, COL["r_cell"]]) > 0
    from quadfdi.models.inputs import profiled_dataset
    from quadfdi.core import vehicle_record as record

    records = np.stack([record.from_reference(refs[int(v)]) for v in ds["vehicle_id"]])
    want = profiled_dataset(ds, PHYS, patterns=False, records=records)["telemetry"][row]
    cols = [COL[n] for n in PHYSICS]
    np.testing.assert_array_equal(x[:, cols].view(np.uint32), want[:, cols].view(np.uint32))
