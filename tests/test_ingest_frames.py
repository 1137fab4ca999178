"""Frames and resampling checked against the logs themselves and a synthetic chirp."""

from __future__ import annotations

import os
from pathlib import Path
import numpy as np
import pytest

from conftest import ROOT

# CI places shared/ beside the clone; a git worktree elsewhere points QUADFDI_FLIGHTLOGS at it.
LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
needs_logs = pytest.mark.skipif(not LOGS.is_dir(), reason=f"shared flight logs not found at {LOGS}")


def _euler_rate_agreement(lr, flip: bool = False, window_s: float = 0.5) -> list[float]:
    """Correlation, per Euler angle, of the logged attitude change over window_s with the integral
    of E(eta) omega (the converted body rates, at their own rate) over the same window, airborne."""
    from scipy.integrate import cumulative_trapezoid

    from quadfdi.sim.rigid_body import euler_rate_matrix

    ch = lr.channels
    ta, tw = ch["roll"].t, ch["p"].t
    eta = np.stack([ch["roll"].v, ch["pitch"].v, np.unwrap(ch["yaw"].v)], 1)
    w = np.stack([ch[k].v for k in "pqr"], 1)
    if flip:
        w[:, 1:] *= -1  # the log's FRD rates against our z-up attitude: must disagree
    eta_w = np.stack([np.interp(tw, ta, eta[:, i]) for i in range(3)], 1)
    integral = cumulative_trapezoid(np.einsum("nij,nj->ni", euler_rate_matrix(eta_w), w), tw, axis=0, initial=0)
    t = np.arange(max(ta[0], tw[0]), min(ta[-1], tw[-1]), window_s)
    air = np.zeros(len(t) - 1, bool)
    for a, b in lr.airborne:
        air |= (t[:-1] >= a) & (t[1:] <= b)
    logged = np.diff(np.stack([np.interp(t, ta, eta[:, i]) for i in range(3)], 1), axis=0)[air]
    integ = np.diff(np.stack([np.interp(t, tw, integral[:, i]) for i in range(3)], 1), axis=0)[air]
    return [float(np.corrcoef(logged[:, i], integ[:, i])[0, 1]) for i in range(3)]


@needs_logs
@pytest.mark.parametrize("name", ["px4_quad_6s_gps_interference.ulg", "px4_quad_battery_monitor_disconnected.ulg",
                                  "px4_quad_6s_vibration_tipover.ulg", "px4_quad_6s_uavcan_mission.ulg"])
def test_body_rates_integrate_to_logged_attitude(name):
    from quadfdi.ingest.flight import read_log

    lr = read_log(LOGS / name)
    assert min(_euler_rate_agreement(lr)) > 0.93
    flipped = _euler_rate_agreement(lr, flip=True)
    assert flipped[1] < -0.9 and flipped[2] < -0.9


@needs_logs
@pytest.mark.parametrize("name", ["px4_quad_6s_gps_interference.ulg", "px4_quad_battery_monitor_disconnected.ulg"])
def test_velocity_matches_position_differences(name):
    from quadfdi.ingest.flight import read_log

    ch = read_log(LOGS / name).channels
    t = ch["x"].t
    pos = np.stack([ch[k].v for k in ("x", "y", "z")], 1)
    vel = np.stack([ch[k].v for k in ("vx", "vy", "vz")], 1)
    dp, vm = np.diff(pos, axis=0) / np.diff(t)[:, None], 0.5 * (vel[1:] + vel[:-1])
    ok = np.isfinite(dp).all(1) & np.isfinite(vm).all(1)
    assert min(np.corrcoef(vm[ok, i], dp[ok, i])[0, 1] for i in range(3)) > 0.95
    # z up: climbing after take-off means z grows
    assert np.nanmax(ch["z"].v) - ch["z"].v[0] > 0.5


def test_resampler_removes_what_would_alias():
    from quadfdi.core.resample import make_grid, resample

    fs, dur = 250.0, 40.0
    t = np.arange(0, dur, 1 / fs)
    f_inst = 0.2 + (60.0 - 0.2) * t / dur  # linear chirp 0.2 -> 60 Hz
    x = np.sin(2 * np.pi * np.cumsum(f_inst) / fs)
    grid = make_grid(0.0, dur - 1 / fs)
    y, m = resample(t, x, grid)
    assert m.all()
    f_at = np.interp(grid, t, f_inst)
    hi = f_at > 15.0  # anything above 15 Hz lands on 0..10 Hz after 25 Hz sampling
    assert np.sqrt(np.mean(y[hi & (f_at < 55)] ** 2)) < 0.03
    naive = np.interp(grid, t, x)  # decimation without the filter: the alias survives at full power
    assert np.sqrt(np.mean(naive[hi & (f_at < 55)] ** 2)) > 0.5
    lo = f_at < 5.0  # the passband is kept
    assert np.max(np.abs(y[lo][5:] - naive[lo][5:])) < 0.03


def test_resampler_masks_gaps_instead_of_interpolating():
    from quadfdi.core.resample import make_grid, resample

    t = np.concatenate([np.arange(0, 5, 0.1), np.arange(7, 10, 0.1)])
    v = np.sin(t)
    grid = make_grid(0.0, 9.9)
    y, m = resample(t, v, grid)
    inside = (grid > 4.95) & (grid < 7.0)
    assert not m[inside].any() and np.isnan(y[inside]).all()
    assert m[(grid < 4.9) | (grid >= 7.0) & (grid <= 9.9)].all()
    assert np.allclose(y[m], np.sin(grid[m]), atol=2e-3)


def test_angles_wrap_through_the_resampler():
    from quadfdi.core.resample import make_grid, resample

    t = np.arange(0, 10, 0.01)
    yaw = (np.pi - 0.05 + 0.1 * t + np.pi) % (2 * np.pi) - np.pi  # crosses +-pi at t = 0.5
    y, m = resample(t, yaw, make_grid(0, 9.99), angle=True)
    assert m.all() and np.max(np.abs(y)) <= np.pi and np.max(np.abs(np.diff(np.unwrap(y)))) < 0.01


def test_motor_map_quad_x_and_plus():
    from quadfdi.ingest.motors import QUAD_PLUS_PX4, QUAD_X, motor_map, pwm_to_thrust

    assert motor_map(QUAD_X) == [2, 1, 3, 0]
    assert motor_map(QUAD_PLUS_PX4) == [2, 1, 3, 0]  # front (CW), left, back (CW), right
    thr, below = pwm_to_thrust(np.array([900.0, 1000.0, 1500.0, 2000.0]), 1000, 2000, 0.6)
    assert below == 1 and np.allclose(thr, [0, 0, 0.4 * 0.5 + 0.6 * 0.25, 1.0])


def test_labels_json_is_checked(tmp_path):
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.ingest.labels import load_labels

    time = np.arange(0, 60, 0.04)
    p = tmp_path / "labels.json"
    p.write_text('{"faults": [{"class": "MotorFault", "motor": 2, "start_s": 31.0, "end_s": 44.5}]}')
    assert load_labels(p, time)[0]["motor"] == 2
    p.write_text('{"faults": [{"class": "MotorFault", "start_s": 31.0, "end_s": 44.5}]}')
    with pytest.raises(QuadfdiError, match="needs 'motor'"):
        load_labels(p, time)
    p.write_text('{"faults": [{"class": "Healthy", "start_s": 1.0, "end_s": 2.0}]}')
    with pytest.raises(QuadfdiError, match="is not one of"):
        load_labels(p, time)
    p.write_text('{"faults": [{"class": "BatteryFault", "start_s": 50.0, "end_s": 70.0}]}')
    with pytest.raises(QuadfdiError, match="end_s"):
        load_labels(p, time)


def test_ardupilot_conversions_and_airborne_fallback_on_synthetic_messages():
    """The DataFlash path of a flying copter (no shared log has one): units, frames, PWM, airborne."""
    from quadfdi.ingest.ardupilot import flight_state, motor_channels, state_channels
    from quadfdi.ingest.model import LogRead

    t = np.arange(0, 30, 0.1)
    n = len(t)
    up = (t > 5) & (t < 25)
    cols = {
        "XKF1": {"t": t, "PN": t * 0 + 1.0, "PE": t * 0 + 2.0, "PD": np.where(up, -3.0, 0.0),
                 "VN": t * 0, "VE": t * 0 + 0.5, "VD": t * 0},
        "ATT": {"t": t, "Roll": t * 0 + 10.0, "Pitch": t * 0 + 5.0, "Yaw": t * 0 + 90.0},
        "RATE": {"t": t, "R": t * 0 + 30.0, "P": t * 0 + 30.0, "Y": t * 0 + 30.0},
        "RCOU": {"t": t, **{f"C{k}": np.where(up, 1520.0, 1000.0) for k in range(1, 15)}},
        "CTUN": {"t": t, "ThO": np.where(up, 0.4, 0.0), "Alt": np.where(up, 3.0, 0.0)},
        "ARM": {"t": np.array([1.0, 28.0]), "ArmState": np.array([1, 0])},
    }
    params = {"MOT_PWM_MIN": 0.0, "MOT_PWM_MAX": 0.0, "RC3_MIN": 1000.0, "RC3_MAX": 2000.0, "MOT_THST_EXPO": 0.5}
    lr = LogRead("ardupilot", {}, {}, {}, [], [], "none", (0.0, float(t[-1])), [])
    state_channels(cols, lr)
    motor_channels(cols, params, [2, 1, 3, 0], lr)
    flight_state(cols, lr)
    c = lr.channels
    assert c["x"].v[0] == 1.0 and c["y"].v[0] == -2.0 and c["vy"].v[0] == -0.5 and c["z"].v[100] == 3.0
    assert np.isclose(c["roll"].v[0], np.radians(10)) and np.isclose(c["pitch"].v[0], -np.radians(5))
    assert np.isclose(c["yaw"].v[0], -np.pi / 2)
    assert np.isclose(c["p"].v[0], np.radians(30)) and np.isclose(c["q"].v[0], -np.radians(30))
    assert lr.vehicle["pwm_range"][2].startswith("RC3_MIN/MAX")  # MOT_PWM_* unset: ArduCopter's fallback
    assert np.isclose(c["thr1"].v[100], 0.5 * 0.52 + 0.5 * 0.52 ** 2) and c["thr1"].source.startswith("RCOU.C3")
    assert lr.armed == [(1.0, 28.0)] and len(lr.airborne) == 1
    assert abs(lr.airborne[0][0] - 5.1) < 0.11 and abs(lr.airborne[0][1] - 25.0) < 0.11


def test_ardupilot_pos_fallback_without_ekf_messages():
    from quadfdi.ingest.ardupilot import state_channels
    from quadfdi.ingest.model import LogRead

    t = np.arange(0, 10, 0.1)
    pos = {"t": t, "Lat": 52.0 + 1e-5 * t, "Lng": 10.0 - 1e-5 * t, "RelHomeAlt": 0.5 * t}
    lr = LogRead("ardupilot", {}, {}, {}, [], [], "none", (0.0, 9.9), [])
    state_channels({"POS": pos}, lr)
    c = lr.channels
    assert np.isclose(c["x"].v[-1], 9.9e-5 * 111319.49, rtol=1e-6)  # north
    assert c["y"].v[-1] > 0.6  # moving west: +y in NWU
    assert np.isclose(c["z"].v[-1], 4.95) and "vx" in lr.status
