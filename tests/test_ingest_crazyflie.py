"""The Crazyflie uSD event-log reader on the shared CrazyPAD logs: one test per trap of the logs'
README (no extension, a declared event type without records, logs without yaw, degrees and g,
no land detector), the CRC and bounded reading, and the motor numbering back to the log's M1-M4."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.ingest.crazyflie import parse, read_crazyflie
from quadfdi.ingest.flight import ingest, read_log
from tests.conftest import SHARED_DATA, quadfdi

PAD = SHARED_DATA / "crazypad" / "motor_data"
HEALTHY = PAD / "normal_flight" / "E9_log00"
NO_YAW = sorted((PAD / "cut_propeller_M3_2mm").glob("E8_*")) + sorted((PAD / "cut_propeller_M3_3mm").glob("E8_*"))

pytestmark = pytest.mark.skipif(not PAD.is_dir(), reason=f"the CrazyPAD logs are not at {PAD}")


def _rewrite(data: bytes) -> bytes:
    """``data`` with its CRC-32 recomputed: a file whose damage the CRC no longer catches."""
    return data[:-4] + struct.pack("<I", zlib.crc32(data[:-4]))


def test_a_log_without_extension_is_read_by_its_first_byte():
    assert HEALTHY.suffix == "" and HEALTHY.read_bytes()[0] == 0xBC
    lr = read_log(HEALTHY)
    assert lr.autopilot == "crazyflie"
    assert {"x", "y", "z", "vx", "vy", "vz", "roll", "yaw", "V_b", "thr1", "thr2", "thr3", "thr4"} <= set(lr.channels)
    assert all(lr.status[c].startswith("absent") for c in ("pitch", "p", "q", "r", "I_b", "vib_px4", "vib_ap"))


def test_the_declared_event_type_without_records_is_ignored_and_noted():
    events, silent = parse(HEALTHY.read_bytes(), HEALTHY.name)
    assert list(events) == ["fixedFrequency"] and silent == ["activeMarkerModeChanged"]
    assert any("activeMarkerModeChanged" in n for n in read_crazyflie(str(HEALTHY)).notes)


def test_the_six_logs_without_yaw_are_ingested_with_yaw_absent():
    assert len(NO_YAW) == 6
    for path in NO_YAW:
        lr, arrays = ingest(path)
        names = list(arrays["channel_names"])
        assert "yaw" not in lr.channels and lr.status["yaw"] == "absent: stateEstimate.yaw not logged"
        assert not arrays["mask"][:, names.index("yaw")].any()
        assert arrays["mask"][:, names.index("roll")].any()


def test_units_are_converted_degrees_to_radians_and_millivolts_to_volts():
    events, _ = parse(HEALTHY.read_bytes(), HEALTHY.name)
    raw = events["fixedFrequency"]
    lr = read_crazyflie(str(HEALTHY))
    np.testing.assert_allclose(lr.channels["roll"].v, np.radians(raw["stateEstimate.roll"]))
    assert np.all(np.abs(lr.channels["yaw"].v) <= np.pi)
    np.testing.assert_allclose(lr.channels["V_b"].v, raw["pm.vbatMV"] / 1000.0)
    assert 3.0 < float(np.median(lr.channels["V_b"].v)) < 4.35  # one LiPo cell
    assert lr.vehicle["battery"]["cells"] == 1


def test_airborne_is_inferred_and_checked_against_every_log():
    """No land detector: the height-and-command rule finds about 16 s airborne in every CrazyPAD log (the
    README's figure), two flights in E9_log00 (motors off at 11.9 s, on again at 16.9 s)."""
    lr = read_crazyflie(str(HEALTHY))
    assert len(lr.airborne) == 2 and not lr.landing_lag
    assert lr.airborne[0][1] < 12.0 < 16.9 < lr.airborne[1][0]
    totals = [sum(b - a for a, b in read_crazyflie(str(p)).airborne) for p in sorted(PAD.glob("*/*"))]
    assert len(totals) == 222
    assert 14.5 < min(totals) and max(totals) < 17.0


def test_motors_trace_back_to_the_logs_m1_to_m4():
    """The healthy vehicle runs M3 about 13 % above the four's mean (README): in the project's order that
    is the rotor whose vehicle.motor_map entry names the log's M3."""
    lr, arrays = ingest(HEALTHY)
    mmap = json.loads(str(arrays["vehicle"]))["motor_map"]
    names, air = list(arrays["channel_names"]), arrays["airborne"].astype(bool)
    thr = np.array([arrays["telemetry"][air, names.index(f"thr{k}")] for k in range(1, 5)])
    share = thr.mean(axis=1) / thr.mean() - 1
    assert mmap[int(np.argmax(share))] + 1 == 3 and share.max() > 0.08
    assert sorted(mmap) == [0, 1, 2, 3]


def test_crc_mismatch_truncation_and_foreign_files_are_one_line(tmp_path):
    data = HEALTHY.read_bytes()
    cases = {
        "flipped": (data[:500] + bytes([data[500] ^ 0xFF]) + data[501:], "CRC-32 mismatch"),
        "truncated": (data[:-1000], "CRC-32 mismatch"),
        "cut record": (_rewrite(data[:-1000] + data[-4:]), "cut off"),
        "version 3": (_rewrite(data[:1] + struct.pack("<H", 3) + data[3:]), "version 3"),
        "foreign": (_rewrite(b"\xbc" + b"\x02\x00\x01\x00" + b"\xff" * 40 + b"\0\0\0\0"), "Crazyflie"),
    }
    for label, (blob, words) in cases.items():
        path = tmp_path / label.replace(" ", "_")
        path.write_bytes(blob)
        with pytest.raises(QuadfdiError, match=words) as exc:
            read_log(path)
        assert "\n" not in str(exc.value), label


def test_a_fifo_is_refused_before_reading(tmp_path):
    import os

    fifo = tmp_path / "log"
    os.mkfifo(fifo)
    with pytest.raises(QuadfdiError, match="not a regular file"):
        read_crazyflie(str(fifo))


def test_ingest_cli_writes_a_flight(tmp_path):
    res = quadfdi("ingest", str(HEALTHY), "--out", str(tmp_path / "f"))
    assert res.returncode == 0, res.stderr
    assert Path(tmp_path / "f" / "flight.npz").is_file()
