"""PX4's vibration metric in m/s^2 (ingest/px4_vibration.py): the three PX4 definitions on the
shared logs that hold them (1.9 ECL vibe[2], 1.12 accel_vibration_metric in m/s; 1.13+ in m/s^2 on
synthetic topics), and the refusals to guess (no firmware version, no interval). Cheap: two small
logs, read once."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.ingest import px4_vibration
from quadfdi.ingest.model import LogRead
from tests.conftest import SHARED_DATA

REAL = SHARED_DATA / "flightlogs"
pytestmark = pytest.mark.skipif(not (REAL / "px4_quad_6s_uavcan_mission.ulg").is_file(), reason="no shared logs")


@pytest.fixture(scope="module")
def reads():
    from quadfdi.ingest.px4 import read_px4

    return {k: read_px4(str(REAL / f)) for k, f in (("v19", "px4_quad_6s_uavcan_mission.ulg"),
                                                    ("v112", "px4_fmuv5_quad_real_short.ulg"))}


def _topic(name: str, fields: list[str]) -> dict:
    from pyulog import ULog

    d = ULog(str(REAL / name), message_name_filter_list=[fields[0].split(".")[0]]).data_list[0].data
    return {f: d[f.split(".", 1)[1]].astype(float) for f in fields}


def test_firmware_version_from_ver_sw_release():
    assert px4_vibration.firmware_version({"ver_sw_release": 0x01090080}) == (1, 9, 0)
    assert px4_vibration.firmware_version({"ver_sw_release": 0x010C0300}) == (1, 12, 3)
    assert px4_vibration.firmware_version({}) is None and px4_vibration.firmware_version({"ver_sw_release": 0}) is None


def test_px4_19_vibe2_divided_by_the_logged_integration_interval(reads):
    lr = reads["v19"]
    ch, meta = lr.channels["vib_px4"], lr.vehicle["vibration"]
    assert "vib_px4" not in lr.status and meta["source"] == "estimator_status.vibe[2]" and meta["firmware"] == "1.9.0"
    raw = _topic("px4_quad_6s_uavcan_mission.ulg", ["estimator_status.vibe[2]", "estimator_status.timestamp"])
    dt = np.median(_topic("px4_quad_6s_uavcan_mission.ulg",
                          ["sensor_combined.accelerometer_integral_dt"])["sensor_combined.accelerometer_integral_dt"]) * 1e-6
    assert dt == pytest.approx(0.004) == meta["integration_interval_s"]  # FMU-v3 on PX4 1.9: 4 ms
    np.testing.assert_allclose(ch.v, raw["estimator_status.vibe[2]"] / dt, rtol=1e-6)
    assert 10 < np.median(ch.v) < 20  # m/s^2: no longer the 0.06 "m/s" read as m/s^2
    assert "accelerometer_integral_dt" in ch.source and meta["jitter_term_bound_m_s2"] < 0.05 * np.median(ch.v)


def test_px4_112_metric_is_a_delta_velocity_and_agrees_with_ecl(reads):
    """1.11-1.12 logged accel_vibration_metric on delta velocity; dividing by vehicle_imu's interval
    gives m/s^2, and ECL's vibe[2] over the same interval (another filter instance on the same IMU
    data) lands within 35 % of it: the two definitions are the same quantity."""
    lr = reads["v112"]
    meta = lr.vehicle["vibration"]
    assert meta["logged_unit"] == "m/s (delta velocity)" and meta["firmware"] == "1.12.3"
    assert meta["integration_interval_s"] == pytest.approx(0.005, abs=1e-4)
    ecl = _topic("px4_fmuv5_quad_real_short.ulg", ["estimator_status.vibe[2]"])["estimator_status.vibe[2]"]
    ratio = np.median(lr.channels["vib_px4"].v) / (np.median(ecl) / meta["integration_interval_s"])
    assert 0.65 < ratio < 1.35, ratio


class _Topics:
    def __init__(self, **topics):
        self.topics = topics

    def get(self, name, instance=0):
        return self.topics.get(name)


def _lr() -> LogRead:
    return LogRead("px4", {}, {}, {}, [], [], "none", (0.0, 1.0))


def test_px4_113_and_later_metric_is_used_as_logged():
    """Since 1.13 the field is in m/s^2 (the simulator's vib_px4): no conversion, the interval only
    recorded (the 1.15/1.16 shared logs: tests/test_ingest.py reads them whole)."""
    t = np.arange(4.0)
    lr = _lr()
    topics = _Topics(vehicle_imu_status={"t": t, "accel_vibration_metric": np.array([4.0, 4.5, 5.0, 4.0])},
                     vehicle_imu={"t": t, "delta_velocity_dt": np.array([5000.0, 5000, 5010, 4990])})
    px4_vibration.vibration_channel(topics, {"ver_sw_release": 0x01100000}, lambda n: None, lr)
    np.testing.assert_array_equal(lr.channels["vib_px4"].v, [4.0, 4.5, 5.0, 4.0])
    meta = lr.vehicle["vibration"]
    assert meta["conversion"] == "none" and meta["firmware"] == "1.16.0" and meta["integration_interval_s"] == 0.005


def test_no_version_or_no_interval_is_unusable_never_guessed():
    t, m = np.arange(3.0), np.full(3, 0.02)
    imu = {"t": t, "accel_vibration_metric": m}
    lr = _lr()
    px4_vibration.vibration_channel(_Topics(vehicle_imu_status=imu), {}, lambda n: None, lr)
    assert "vib_px4" not in lr.channels and "no firmware version" in lr.status["vib_px4"]
    lr = _lr()
    px4_vibration.vibration_channel(_Topics(vehicle_imu_status=imu), {"ver_sw_release": 0x010B0200}, lambda n: None, lr)
    assert "vib_px4" not in lr.channels and "vehicle_imu.delta_velocity_dt" in lr.status["vib_px4"]
    lr = _lr()
    px4_vibration.vibration_channel(_Topics(estimator_status={"t": t, "vibe[2]": m}), {"ver_sw_release": 0x01080000},
                                    lambda n: None, lr)
    assert "vib_px4" not in lr.channels and "accelerometer_integral_dt" in lr.status["vib_px4"]
