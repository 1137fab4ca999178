"""The vehicle record on board: its file (formats/vehicle_record_bin.py, fwref/vehicle_record.hpp) and its
refusals in both readers; flightlog-ref's model channels from fwref/profile.hpp bit for bit as
core.profiles.apply_profile computes them, with a record, without one and with fields that hold nothing, on
simulated fleet flights (the record learned from the vehicle's own reference flights), a CrazyPAD log (the
record from normal_flight E8_log00, E8_log01, E9_log00, E9_log01) and a shared PX4 log (a record from
itself); stream files carrying the record (version 3). The stream runtime with a record:
tests/test_vehicle_record_stream.py; the Cortex-M stream image: tests/test_vehicle_record_mcu.py."""

from __future__ import annotations

import dataclasses
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core import vehicle_record as vr
from quadfdi.core.channels import PROFILE_BY_NAME, stream_raw
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.vehicle_record_bin import (parse_record, read_record, record_bytes, record_from_vehicle_json,
                                                write_record)
from tests.conftest import ROOT, SHARED_DATA, quadfdi
from tests.profile_mirror import build_mirror, cpp_inputs

REF = "flightlog-ref"
PAD = SHARED_DATA / "crazypad" / "motor_data"
PAD_REFERENCE = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]
PAD_TESTED = [PAD / "normal_flight" / "E9_log03", PAD / "cut_propeller_M3_3mm" / "E8_log01"]
PX4 = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"
# the onboard record's keys the stream helpers read, for the flightlog-ref stream order
STREAM_RECORD = {"profile": REF, "raw_channels": list(stream_raw(PROFILE_BY_NAME[REF])), "cells_from_stream": True,
                 "sample_dt_s": 0.04, "window": 40, "stride": 20}
FLEET_TINY = ["sim.n_traj=64", "sim.ood_traj=8", "sim.duration_s=24.0", "sim.chunk=80", "sim.window=40",
              "sim.stride=20"]


def a_record(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rec = rng.normal(0.0, 0.1, vr.SIZE).astype(np.float32)
    rec[:4] += 1.0
    rec[20:24] += 1.0
    rec[[12, 14]], rec[[13, 15]] = -1.0, 1.0
    return rec


# ------------------------------------------------------------------------------ the record file


def test_record_file_round_trips_and_refuses_in_one_line(tmp_path):
    rec = a_record()
    rec[[16, 17, 22]] = np.nan  # no PX4 vibration floor, no rpm share of ESC 3: NaN survives the round trip
    write_record(tmp_path / "r.bin", rec, REF)
    data = (tmp_path / "r.bin").read_bytes()
    assert len(data) == vr.FILE_BYTES == 116 and data[:8] == b"QFDIVEH\0"
    np.testing.assert_array_equal(read_record(tmp_path / "r.bin", REF).view(np.uint32), rec.view(np.uint32))
    v1 = data[:8] + (1).to_bytes(4, "little") + data[12:16 + 4 * vr.SIZE_V1]  # before the sag field: still read
    np.testing.assert_array_equal(parse_record(v1, REF, "v1").view(np.uint32), vr.from_v1(rec[:24]).view(np.uint32))
    assert np.isnan(parse_record(v1, REF, "v1")[24]) and vr.FILE_BYTES_V1 == len(v1) == 112
    mask_id = (PROFILE_BY_NAME["flightlog-mask"].id).to_bytes(4, "little")
    bad = {"truncated": (data[:100], "holds 100 bytes, a vehicle record 116"),
           "longer": (data + b"\0", "holds 117 bytes"),
           "v1 longer": (v1 + b"\0", "holds 113 bytes, a vehicle record 112"),
           "magic": (b"QFDISTR\0" + data[8:], "is not a quadfdi vehicle record"),
           "version": (data[:8] + (3).to_bytes(4, "little") + data[12:], "version 3, this reader reads 1 and 2"),
           "profile": (data[:12] + mask_id + data[16:], "is for profile 'flightlog-mask', the model's is 'flightlog-ref'"),
           "infinite": (data[:16] + np.float32(np.inf).tobytes() + data[20:], "field 0 is infinite")}
    for name, (blob, why) in bad.items():
        with pytest.raises(QuadfdiError, match=why) as err:
            parse_record(blob, REF, f"vehicle record {name}.bin")
        assert "\n" not in str(err.value)
    with pytest.raises(QuadfdiError, match="profile 'flightlog-mask' reads no vehicle record"):
        record_bytes(rec, "flightlog-mask")
    with pytest.raises(QuadfdiError, match="profile 'flightlog-mask' reads no vehicle record"):
        read_record(tmp_path / "r.bin", "flightlog-mask")
    with pytest.raises(QuadfdiError, match="is not a regular file"):
        read_record(tmp_path, REF)


def test_vehicle_record_cli_writes_the_record_of_a_reference(tmp_path, fleet_refs):
    """`quadfdi vehicle record`: a learned vehicle.json's record as 112 bytes; a profile without references, a
    file that is not a vehicle reference, a missing one: one line, exit 2, nothing written."""
    from quadfdi.formats.vehicle import write_vehicle

    refs, _ = fleet_refs
    write_vehicle(tmp_path / "v.json", refs[min(refs)])
    res = quadfdi("vehicle", "record", str(tmp_path / "v.json"), "--out", str(tmp_path / "r.bin"))
    assert res.returncode == 0, res.stderr
    np.testing.assert_array_equal(read_record(tmp_path / "r.bin", REF).view(np.uint32),
                                  vr.from_reference(refs[min(refs)]).view(np.uint32))
    (tmp_path / "other.json").write_text(json.dumps({"format_version": 1}))
    for args, why in (((str(tmp_path / "nowhere.json"),), "does not exist"),
                      ((str(tmp_path / "other.json"),), "vehicle reference"),
                      ((str(tmp_path / "v.json"), "--profile", "flightlog-mask"), "reads no vehicle record")):
        res = quadfdi("vehicle", "record", *args, "--out", str(tmp_path / "new.bin"))
        assert res.returncode == 2 and why in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
        assert not (tmp_path / "new.bin").exists()


@pytest.fixture(scope="module")
def mirror(tmp_path_factory) -> Path:
    """fwref/profile.hpp's flightlog-ref and the record loader (tests/profile_mirror.py)."""
    return build_mirror(tmp_path_factory.mktemp("ref_mirror"), REF)


def test_cpp_loader_reads_the_same_bits_and_refuses_the_same_files(mirror, tmp_path):
    rec = a_record(1)
    rec[[18, 19, 23]] = np.nan
    write_record(tmp_path / "r.bin", rec, REF)
    res = subprocess.run([str(mirror), "load", str(tmp_path / "r.bin")], capture_output=True, text=True, check=True)
    assert [int(v) for v in res.stdout.split()] == rec.view(np.uint32).tolist()
    data = (tmp_path / "r.bin").read_bytes()
    mask_id = (PROFILE_BY_NAME["flightlog-mask"].id).to_bytes(4, "little")
    v1 = data[:8] + (1).to_bytes(4, "little") + data[12:16 + 4 * vr.SIZE_V1]
    (tmp_path / "v1.bin").write_bytes(v1)
    res = subprocess.run([str(mirror), "load", str(tmp_path / "v1.bin")], capture_output=True, text=True, check=True)
    assert [int(v) for v in res.stdout.split()] == vr.from_v1(rec[:24]).view(np.uint32).tolist()  # sag NaN
    for name, blob, why in (("trunc", data[:100], "holds 100 bytes, a vehicle record 116"),
                            ("magic", b"QFDISTR\0" + data[8:], "is not a quadfdi vehicle record"),
                            ("version", data[:8] + (3).to_bytes(4, "little") + data[12:], "format version"),
                            ("v1 longer", v1 + b"\0\0\0\0", "a version 1 record"),
                            ("profile", data[:12] + mask_id + data[16:], "is for profile 'flightlog-mask', the model's "
                                                                         "is 'flightlog-ref'"),
                            ("inf", data[:20] + np.float32(-np.inf).tobytes() + data[24:], "infinite field")):
        (tmp_path / f"{name}.bin").write_bytes(blob)
        res = subprocess.run([str(mirror), "load", str(tmp_path / f"{name}.bin")], capture_output=True, text=True)
        assert res.returncode == 2 and why in res.stderr and len(res.stderr.strip().splitlines()) == 1, (name, res.stderr)
    res = subprocess.run([str(mirror), "load", str(tmp_path)], capture_output=True, text=True)
    assert res.returncode == 2 and "is a folder, not a regular file" in res.stderr


# ------------------------------------------------------------------------------ the profile, bit for bit


def _same_bits(mirror: Path, tmp: Path, rs, record: np.ndarray | None) -> np.ndarray:
    """The C++ inputs of stream ``rs`` with ``record`` are apply_profile's (through streamref.windows_of, the
    Python stream path) bit for bit, NaN where Python has NaN; returns them."""
    from quadfdi.detect.streamref import windows_of

    rs = dataclasses.replace(rs, vehicle=record)
    sw = windows_of(rs, STREAM_RECORD)
    got = cpp_inputs(mirror, tmp, rs, sw.hover, record, REF)
    fin = np.isfinite(sw.x)
    assert (np.isfinite(got) == fin).all()
    np.testing.assert_array_equal(got.view(np.uint32)[fin], sw.x.view(np.uint32)[fin])
    return sw.x


def _ref_columns() -> tuple[list[int], int, np.ndarray]:
    names = [c.name for c in PROFILE_BY_NAME[REF].model]
    cols = list(range(names.index("m1_ref"), names.index("m1_ref") + 10))
    return cols, names.index("avail_reference"), np.array([PROFILE_BY_NAME[REF].model[j].fill for j in cols], np.float32)


@pytest.fixture(scope="module")
def fleet_run(tmp_path_factory) -> Path:
    """A tiny fleet-suite dataset (vehicles flying several flights, the first ones their reference flights)."""
    out = tmp_path_factory.mktemp("fleet") / "tiny"
    res = quadfdi("sim", "--config", str(ROOT / "configs/fleet.toml"), "--out", str(out), "--workers", "1",
                  *[a for v in FLEET_TINY for a in ("--set", v)])
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def fleet_refs(fleet_run) -> tuple[dict, np.ndarray]:
    """Each vehicle's reference, `vehicle learn`'s estimate (vehicle.learn.learn) on its own reference flights;
    the vehicle id of each dataset row."""
    from quadfdi.formats.dataset import load_dataset, vehicle_columns
    from quadfdi.train.vehicle_ref import learn_references

    ds = load_dataset(fleet_run / "dataset.npz")
    arrays = {k: ds[k] for k in ds.arrays}
    return learn_references(arrays, "fleet"), vehicle_columns(arrays)["vehicle_id"]


@pytest.fixture(scope="module")
def fleet_records(fleet_refs) -> tuple[dict, np.ndarray]:
    refs, vid = fleet_refs
    return {v: vr.from_reference(r) for v, r in refs.items()}, vid


def test_cpp_profile_is_python_bit_for_bit_on_simulated_flights(mirror, fleet_run, fleet_records, tmp_path):
    """Every flight of the tiny fleet (each under its mask pattern) with its vehicle's record, without a
    record and with a record whose PX4 vibration floor, motor 2 share and ESC 4 rpm share hold nothing."""
    from quadfdi.core.profiles import flight_pattern
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.formats.stream import from_dataset

    records, vid = fleet_records
    ds = load_dataset(fleet_run / "dataset.npz")
    cols, avail_ref, fills = _ref_columns()
    patterns = set()
    for row in range(len(vid)):
        rs = from_dataset(fleet_run / "dataset.npz", row, STREAM_RECORD, ds)
        patterns.add(flight_pattern(int(ds["traj_index"][row])).name)
        rec = records[int(vid[row])]
        mode = row % 3
        record = None if mode == 1 else rec.copy()
        if mode == 2:
            record[[1, 16, 17, 23]] = np.nan
        x = _same_bits(mirror, tmp_path, rs, record)
        if record is None:
            np.testing.assert_array_equal(x[:, cols], np.broadcast_to(fills, (len(x), 10)))
        assert (x[:, avail_ref] == float(record is not None)).all()
        if mode == 0 and rs.carried_flags.all():  # every channel and every field: no reference channel at its fill
            assert (np.abs(x[:, cols] - fills) > 0).mean(axis=0).min() > 0.5
        if mode == 2:
            np.testing.assert_array_equal(x[:, [cols[1], cols[4], cols[9]]], np.broadcast_to(fills[[1, 4, 9]], (len(x), 3)))
    assert len(patterns) >= 4, patterns


@pytest.fixture(scope="module")
def pad_record(tmp_path_factory) -> np.ndarray:
    if not PAD.is_dir():
        pytest.skip(f"the CrazyPAD logs are not at {PAD}")
    out = tmp_path_factory.mktemp("pad") / "crazyflie.json"
    res = quadfdi("vehicle", "learn", *map(str, PAD_REFERENCE), "--out", str(out))
    assert res.returncode == 0, res.stderr
    res = quadfdi("vehicle", "record", str(out), "--out", str(out.with_suffix(".bin")))
    assert res.returncode == 0, res.stderr
    rec = read_record(out.with_suffix(".bin"), REF)
    np.testing.assert_array_equal(rec.view(np.uint32), record_from_vehicle_json(out).view(np.uint32))
    return rec


def test_cpp_profile_is_python_bit_for_bit_on_crazypad_logs(mirror, pad_record, tmp_path):
    """A held-out healthy CrazyPAD flight and a 3 mm cut on motor 3, with the record of the four reference
    flights (a Crazyflie logs no vibration and no ESC: those fields NaN) and without one."""
    from quadfdi.detect.stream_cli import from_flight

    assert np.isfinite(pad_record[:4]).all() and np.isnan(pad_record[16:24]).all()
    cols, avail_ref, fills = _ref_columns()
    for path in PAD_TESTED:
        rs = from_flight(path, STREAM_RECORD)
        x = _same_bits(mirror, tmp_path, rs, pad_record)
        assert (x[:, avail_ref] == 1).all() and (x[:, cols[4:]] == fills[4:]).all()  # nothing held, or lacking
        m_ref = x[:, cols[:4]][np.isfinite(x[:, cols[:4]]).all(axis=1)]
        assert len(m_ref) > 100 and np.abs(np.median(m_ref, axis=0) - 1.0).max() < 0.3
        _same_bits(mirror, tmp_path, rs, None)


def test_cpp_profile_is_python_bit_for_bit_on_a_px4_log_with_its_own_record(mirror, tmp_path):
    """The shared PX4 UAVCAN mission (PX4 vibration, ESC rpm, current and temperature) with a record learned
    from itself: every reference channel but vib_ap_ref (no ArduPilot vibration) is computed."""
    if not PX4.is_file():
        pytest.skip(f"the shared logs are not at {PX4.parent}")
    from quadfdi.detect.stream_cli import from_flight

    res = quadfdi("vehicle", "learn", str(PX4), "--out", str(tmp_path / "v.json"))
    assert res.returncode == 0, res.stderr
    record = record_from_vehicle_json(tmp_path / "v.json")
    assert np.isfinite(record[:18]).all() and np.isnan(record[18:20]).all() and np.isfinite(record[20:]).all()
    rs = from_flight(PX4, STREAM_RECORD)
    x = _same_bits(mirror, tmp_path, rs, record)
    cols, _, fills = _ref_columns()
    live = np.isfinite(x).all(axis=1)
    assert live.sum() > 500 and (x[live][:, cols[5]] == fills[5]).all()
    assert all((x[live][:, cols[j]] != fills[j]).mean() > 0.9 for j in (0, 1, 2, 3, 4, 6, 7, 8, 9))
    half = record.copy()
    half[[0, 20]] = np.nan, np.nan  # no share for motor 1: no reference at all (has_record reads share_a[0])
    x = _same_bits(mirror, tmp_path, rs, half)
    assert (x[:, -1] == 0).all()


# ------------------------------------------------------------------------------ stream files


def test_stream_files_carry_the_record_and_old_versions_still_read(tmp_path, fleet_run, fleet_records):
    from quadfdi.formats.stream import from_dataset, read_stream, stream_bytes, write_stream

    records, vid = fleet_records
    rs = from_dataset(fleet_run / "dataset.npz", 5, STREAM_RECORD, vehicle=records[int(vid[5])])
    write_stream(tmp_path / "v3.bin", rs)
    back = read_stream(tmp_path / "v3.bin")
    assert int.from_bytes((tmp_path / "v3.bin").read_bytes()[8:12], "little") == 4  # the record's 25 floats
    np.testing.assert_array_equal(back.vehicle.view(np.uint32), rs.vehicle.view(np.uint32))
    np.testing.assert_array_equal(back.values.view(np.uint32), rs.values.view(np.uint32))
    without = stream_bytes(dataclasses.replace(rs, vehicle=None))
    assert int.from_bytes(without[8:12], "little") == 2  # no record: the version 2 bytes, as before
    (tmp_path / "v2.bin").write_bytes(without)
    assert read_stream(tmp_path / "v2.bin").vehicle is None
    data = bytearray((tmp_path / "v3.bin").read_bytes())
    at = 128 + sum(len(n) + 1 for n in rs.names) + len(rs.names)  # the record after the names and carried flags
    data[at:at + 4] = np.float32(np.inf).tobytes()
    (tmp_path / "inf.bin").write_bytes(bytes(data))
    with pytest.raises(QuadfdiError, match="vehicle record field 0 is infinite"):
        read_stream(tmp_path / "inf.bin")
    old = bytearray((tmp_path / "v3.bin").read_bytes())  # version 3: a version 1 record (24 floats), still read
    old[8:12] = (3).to_bytes(4, "little")
    old[at + 4 * vr.SIZE_V1:at + 4 * vr.SIZE] = bytes(4)
    (tmp_path / "old.bin").write_bytes(bytes(old))
    np.testing.assert_array_equal(read_stream(tmp_path / "old.bin").vehicle.view(np.uint32),
                                  vr.from_v1(rs.vehicle[:24]).view(np.uint32))
    with pytest.raises(QuadfdiError, match="profile 'flightlog-mask' reads no vehicle record"):
        stream_bytes(dataclasses.replace(rs, profile="flightlog-mask"))
