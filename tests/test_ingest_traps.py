"""The traps of real logs, one test each, on the shared logs (README of shared/data/flightlogs)."""

from __future__ import annotations

import os
from pathlib import Path
import json

import numpy as np
import pytest

from conftest import ROOT

# CI places shared/ beside the clone; a git worktree elsewhere points QUADFDI_FLIGHTLOGS at it.
LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
pytestmark = pytest.mark.skipif(not LOGS.is_dir(), reason=f"shared flight logs not found at {LOGS}")


def read(name):
    from quadfdi.ingest.flight import read_log

    return read_log(LOGS / name)


def test_fmuv5_second_publisher_and_armed_outputs_below_pwm_min():
    lr = read("px4_fmuv5_quad_real_short.ulg")
    assert any("noutputs=4" in n and "second publisher" in n for n in lr.notes)
    assert "noutputs=0" in lr.vehicle["motor_command"]
    assert lr.vehicle["pwm_samples_below_min"] > 0  # armed at 1000 us under PWM_MAIN_MIN = 1230
    assert lr.vehicle["pwm_range"]["motor1"][:2] == [1230.0, 1950.0]
    for k in range(1, 5):
        v = lr.channels[f"thr{k}"].v
        assert v.min() == 0.0 and v.max() <= 1.0 and not np.any(v == 1500)  # no 1500 us publisher leaks in


def test_pack_at_3v5_per_cell_is_4s_not_3s():
    from quadfdi.ingest.battery import cells_from_voltage

    lr = read("px4_fmuv5_quad_real_short.ulg")
    v = lr.channels["V_b"].v
    rest = float(np.median(v[lr.channels["V_b"].t < lr.airborne[0][0]]))  # before take-off
    assert 3.4 < rest / 4 < 3.65
    assert round(rest / 4.2) == 3  # the rounding rule's wrong answer
    assert cells_from_voltage(float(np.nanmax(v))) == 4 and cells_from_voltage(14.0) == 4
    assert lr.vehicle["battery"]["cells"] == 4


def test_sitl_bat1_vs_bat_n_cells_current_minus_one_six_escs():
    lr = read("px4_sitl_quad_esc.ulg")
    bat = lr.vehicle["battery"]
    assert bat["sources"]["BAT1_N_CELLS"] == 4 and bat["sources"]["BAT_N_CELLS"] == 3
    assert bat["cells"] == 4 and bat["disagreement"] and bat["from_voltage"] == 4
    assert "I_b" not in lr.channels and "-1" in lr.status["I_b"]
    assert any("6 ESCs on a quad" in n for n in lr.notes)
    assert {f"rpm{k}" for k in range(1, 5)} <= set(lr.channels)


def test_vtol_header_span_is_not_the_data_span():
    from pyulog import ULog

    from quadfdi.ingest.px4 import Topics, open_ulog

    full = ULog(str(LOGS / "px4_cubeorange_vtol_real.ulg"))  # every message: one stamped ~1194 s
    assert (full.last_timestamp - full.start_timestamp) / 1e6 > 1170
    t0, t1 = Topics(open_ulog(str(LOGS / "px4_cubeorange_vtol_real.ulg")), []).span()
    assert 6.0 < t1 - t0 < 7.0


def test_samples_before_log_start_are_dropped():
    lr = read("px4_quad_6s_vibration_tipover.ulg")
    assert any(n.startswith("actuator_outputs[1]: dropped 1 of 1") and "before its start" in n for n in lr.notes)
    for ch in lr.channels.values():
        assert ch.t.min() >= 0.0


def test_unused_actuator_outputs_beside_uavcan_escs():
    lr = read("px4_quad_6s_uavcan_mission.ulg")
    assert any(n.startswith("actuator_outputs[0]: unused (always 0)") for n in lr.notes)
    assert lr.vehicle["motor_command"].startswith("actuator_outputs[1]")
    air = (lr.channels["thr1"].t > lr.airborne[0][0] + 5) & (lr.channels["thr1"].t < lr.airborne[0][1] - 5)
    hover = np.mean([lr.channels[f"thr{k}"].v[air] for k in range(1, 5)])
    assert 0.3 < hover < 0.9
    assert 15 < np.nanmedian(lr.channels["esc_temp1"].v) < 40  # UAVCAN kelvin -> degC


def test_disconnected_battery_monitor_is_unusable():
    lr = read("px4_quad_battery_monitor_disconnected.ulg")
    for ch in ("V_b", "I_b", "SoC"):
        assert ch not in lr.channels and "disconnected" in lr.status[ch]


def test_uncalibrated_current_sensor_is_unusable():
    lr = read("px4_quad_6s_gps_interference.ulg")
    assert "I_b" not in lr.channels and "not calibrated" in lr.status["I_b"]


def test_arduplane_nkf1_no_rate_is_refused_as_not_multirotor():
    from quadfdi.ingest.ardupilot import load

    cols, params, texts = load(str(LOGS / "ardupilot_plane_1s.BIN"))
    assert "NKF1" in cols and "XKF1" not in cols and "RATE" not in cols
    with pytest.raises(Exception, match="not a multirotor: ArduPlane"):
        read("ardupilot_plane_1s.BIN")


def test_arducopter_ground_log_parameters_and_channels():
    from quadfdi.ingest.ardupilot import read_ardupilot

    lr = read_ardupilot(str(LOGS / "ardupilot_copter_quadx_ground.BIN"))
    v = lr.vehicle
    assert v["geometry_source"].startswith("FRAME_CLASS=1 FRAME_TYPE=1")
    assert v["pwm_range"][:2] == [1120.0, 1920.0] and abs(v["thrust_expo"] - 0.6) < 1e-6
    assert v["motor_map"] == [2, 1, 3, 0]  # front-left, rear-left, rear-right, front-right
    assert v["battery"]["cells"] == 4  # 16.4 V, from the voltage (no BATT_CELLS)
    assert {"x", "roll", "p", "V_b", "thr1", "vib_ap"} <= set(lr.channels) and "vib_px4" not in lr.channels
    vibe = lr.channels["vib_ap"]  # VIBE's in-plane mean, the simulator's definition (not the 3-axis norm)
    assert vibe.source == "VIBE: (VibeX + VibeY) / 2"
    assert lr.airborne == []
    assert json.dumps(v, default=float)


def test_end_at_touchdown_rules():
    """segments.end_at_touchdown on synthetic vertical speeds (up-positive, 10 Hz)."""
    from quadfdi.ingest.segments import LANDING_LOOKBACK_S, end_at_touchdown

    t = np.arange(0.0, 20.0, 0.1)
    descent = np.where(t < 14.0, -0.6, 0.0)  # descends at 0.6 m/s, touches down at 14 s, landed at 15.5 s
    assert end_at_touchdown([(2.0, 15.5)], t, descent, 20.0) == [(2.0, float(t[t < 14.0][-1]))]
    # a landing too gentle to see loses the whole lookback; an interval that ends with the data is kept
    gentle = np.full_like(t, -0.2)
    assert end_at_touchdown([(2.0, 15.5)], t, gentle, 20.0) == [(2.0, 15.5 - LANDING_LOOKBACK_S)]
    assert end_at_touchdown([(2.0, 20.0)], t, gentle, 20.0) == [(2.0, 20.0)]
    # never lengthens; a hop shorter than its cut is dropped; no vertical speed: the lookback
    assert end_at_touchdown([(14.5, 15.5)], t, descent, 20.0) == []
    assert end_at_touchdown([(2.0, 15.5)], np.zeros(0), np.zeros(0), 20.0) == [(2.0, 12.5)]
