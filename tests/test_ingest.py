"""quadfdi ingest on every shared real log: each ingests with its documented channels and rates, or
is refused with one line, exit 2 and no output (docs/ingest.md)."""

from __future__ import annotations

import os
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, quadfdi

# CI places shared/ beside the clone; a git worktree elsewhere points QUADFDI_FLIGHTLOGS at it.
LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
pytestmark = pytest.mark.skipif(not LOGS.is_dir(), reason=f"shared flight logs not found at {LOGS} "
                                "(CI places shared/ beside the clone)")

CORE = ["z", "vz", "roll", "pitch", "yaw", "p", "q", "r", "thr1", "thr2", "thr3", "thr4", "vib_px4"]
# log -> (channels that must be "ok", channels that must not be, {channel: documented rate in Hz})
INGESTS = {
    "px4_sitl_quad_esc.ulg": (CORE + ["x", "V_b", "rpm1", "esc_temp4", "esc_cur1"], ["I_b"],
                              {"roll": 20, "p": 50, "thr1": 10, "V_b": 5, "rpm1": 4, "vib_px4": 1}),
    "px4_quad_6s_vibration_tipover.ulg": (CORE + ["x", "y", "V_b", "I_b", "rpm1", "rpm4", "esc_cur4"], ["T1"],
                                          {"roll": 20, "p": 50, "thr1": 10, "V_b": 5, "rpm1": 4, "vib_px4": 1}),
    "px4_quad_6s_gps_interference.ulg": (CORE + ["x", "V_b"], ["I_b", "rpm1", "esc_cur1"],
                                         {"roll": 20, "p": 50, "thr1": 10, "V_b": 5, "vib_px4": 1}),
    "px4_quad_6s_uavcan_mission.ulg": (CORE + ["x", "V_b", "I_b", "rpm1", "esc_temp1", "esc_cur1"],
                                       ["T1"], {"roll": 28, "V_b": 1.8, "thr1": 9, "rpm1": 3, "esc_cur1": 3}),
    "px4_quad_battery_monitor_disconnected.ulg": (CORE + ["x"], ["V_b", "I_b", "SoC"],
                                                  {"roll": 20, "p": 50, "thr1": 10, "vib_px4": 1}),
}
REFUSALS = {
    # 2.7 s airborne by the land detector, 0.4 s once the landing is cut back to its touchdown
    "px4_fmuv5_quad_real_short.ulg": "too short: 0.4 s airborne",
    "px4_cubeorange_vtol_real.ulg": "not a multirotor",
    "ardupilot_plane_1s.BIN": "not a multirotor: ArduPlane",
    "ardupilot_copter_quadx_ground.BIN": "never airborne",
}


@pytest.fixture(scope="module")
def ingested(tmp_path_factory) -> dict[str, Path]:
    """Every ingestible log through the real CLI, once."""
    out = {}
    for name in INGESTS:
        d = tmp_path_factory.mktemp("ing") / name
        res = quadfdi("ingest", str(LOGS / name), "--out", str(d))
        assert res.returncode == 0, res.stderr
        out[name] = d
    return out


def _load(d: Path) -> dict:
    from quadfdi.formats.flight import load_flight

    return load_flight(d / "flight.npz")


def test_every_shared_log_is_covered():
    assert {p.name for p in LOGS.iterdir() if p.suffix in (".ulg", ".BIN")} == set(INGESTS) | set(REFUSALS)


@pytest.mark.parametrize("name", sorted(REFUSALS))
def test_refusals_are_one_line_exit_2_no_output(name, tmp_path):
    out = tmp_path / "out"
    res = quadfdi("ingest", str(LOGS / name), "--out", str(out))
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and REFUSALS[name] in lines[0] and name in lines[0], res.stderr
    assert not out.exists()


@pytest.mark.parametrize("name", sorted(INGESTS))
def test_channels_and_rates(name, ingested):
    a = _load(ingested[name])
    must, must_not, rates = INGESTS[name]
    status = dict(zip(map(str, a["channel_names"]), map(str, a["channel_status"])))
    rate = dict(zip(map(str, a["channel_names"]), a["channel_rates_hz"]))
    for ch in must:
        assert status[ch] == "ok", (ch, status[ch])
    for ch in must_not:
        assert status[ch] != "ok", ch
        j = list(a["channel_names"]).index(ch)
        assert not a["mask"][:, j].any() and np.isnan(a["telemetry"][:, j]).all()
    for ch, hz in rates.items():
        assert abs(rate[ch] - hz) < 0.15 * hz, (ch, rate[ch], hz)
    # the grid is the simulator's 25 Hz and masked values are NaN, unmasked finite
    assert np.allclose(np.diff(a["time"]), 0.04)
    assert np.isfinite(a["telemetry"][a["mask"]]).all() and np.isnan(a["telemetry"][~a["mask"]]).all()
    assert len(str(a["log_sha256"])) == 64 and a["airborne"].any()
    summary = json.loads((ingested[name] / "ingest.json").read_text())
    assert summary["vehicle"]["motor_map"] and summary["vehicle"]["battery"]["cells"] in (4, 6)


def test_six_s_quads_fly_long_enough(ingested):
    # the tip-over: 74.1 s by its land detector, 68.1 s once each of its two landings is cut back to the
    # touchdown (segments.end_at_touchdown: neither ends in a descent at 0.3 m/s, so each loses 3 s)
    for name, lo in (("px4_quad_6s_vibration_tipover.ulg", 65), ("px4_quad_6s_gps_interference.ulg", 50),
                     ("px4_quad_6s_uavcan_mission.ulg", 35)):
        a = _load(ingested[name])
        air = a["airborne_segments"]
        assert lo < float(np.sum(air[:, 1] - air[:, 0])) < 80
        assert json.loads(str(a["vehicle"]))["battery"]["cells"] == 6


def test_airborne_ends_at_touchdown_not_at_the_land_detectors_landed(ingested):
    """The mission descends at 0.6 m/s until 41.47 s and is on the ground from the next sample (its
    vertical speed jumps to +0.15 m/s); PX4's land detector says ground_contact at 42.23 s and
    landed at 42.85 s. flight.npz's airborne ends at the touchdown; the land detector's interval
    is kept in the vehicle JSON's source note."""
    a = _load(ingested["px4_quad_6s_uavcan_mission.ulg"])
    end = float(a["airborne_segments"][-1, 1])
    assert 41.4 < end < 41.5, end
    t = a["time"]
    assert a["airborne"][(t > 40.0) & (t <= 41.4)].all() and not a["airborne"][t > 41.5].any()
    assert "touchdown" in json.loads(str(a["vehicle"]))["airborne_source"]


def test_deterministic_bytes(ingested, tmp_path):
    name = "px4_sitl_quad_esc.ulg"
    res = quadfdi("ingest", str(LOGS / name), "--out", str(tmp_path))
    assert res.returncode == 0
    assert (tmp_path / "flight.npz").read_bytes() == (ingested[name] / "flight.npz").read_bytes()


def test_bench_prints_seconds_per_flight_hour():
    res = quadfdi("ingest", "bench", str(LOGS / "px4_sitl_quad_esc.ulg"), "--repeat", "1")
    assert res.returncode == 0, res.stderr
    data = json.loads(res.stdout)
    assert data["s_per_flight_hour"] > 0 and data["logs"][0]["log_span_s"] > 30 and "extrapolated" in data["method"]


def test_usage_errors_are_one_line(tmp_path):
    res = quadfdi("ingest", str(LOGS / "px4_sitl_quad_esc.ulg"))
    assert res.returncode == 2 and "needs --out" in res.stderr
    foreign = tmp_path / "x.ulg"
    foreign.write_bytes(b"not a log at all")
    res = quadfdi("ingest", str(foreign), "--out", str(tmp_path / "o"))
    assert res.returncode == 2 and "neither a PX4 ULog, an ArduPilot DataFlash nor a Crazyflie" in res.stderr
    assert not (tmp_path / "o").exists()


def test_gap_factor_bridges_the_missions_vibration_gaps(ingested, tmp_path):
    """--gap-factor 7 spans the mission's estimator_status gaps (longest 1.41 s, median interval 0.21 s):
    vib_px4's airborne coverage grows, nothing else of the log changes, the factor is recorded."""
    name = "px4_quad_6s_uavcan_mission.ulg"
    res = quadfdi("ingest", str(LOGS / name), "--out", str(tmp_path / "g7"), "--gap-factor", "7")
    assert res.returncode == 0, res.stderr
    a, b = _load(ingested[name]), _load(tmp_path / "g7")
    names = [str(n) for n in a["channel_names"]]
    j = names.index("vib_px4")
    air = a["airborne"]
    assert a["mask"][air, j].mean() < 0.75 and b["mask"][air, j].mean() > 0.95
    assert json.loads(str(a["resampling"]))["gap_factor"] == 3.0 and json.loads(str(b["resampling"]))["gap_factor"] == 7.0
    same = [k for k in range(len(names)) if np.array_equal(a["mask"][:, k], b["mask"][:, k])]
    assert j not in same and len(same) >= 12  # the mission has gaps in 17 channels: positions, attitude, rates, motors, vib
    assert np.array_equal(a["telemetry"][:, same], b["telemetry"][:, same], equal_nan=True)
    both = a["mask"][:, j] & b["mask"][:, j]  # linear interpolation within a run: bridging adds, moves nothing
    assert np.array_equal(a["telemetry"][both, j], b["telemetry"][both, j])
    res = quadfdi("ingest", str(LOGS / name), "--out", str(tmp_path / "bad"), "--gap-factor", "1")
    assert res.returncode == 2 and "--gap-factor must be at least 1.5" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def test_ingest_rates_tabulates_each_groups_rate_on_the_shared_logs():
    """What sim.realistic_params.LOG_HZ_MEASURED is made from: PX4's logger defaults on the v1.15/1.16
    logs (attitude 20 Hz, rates 50 Hz, battery 5 Hz, vibration 1 Hz) and the v1.9 log's slower battery."""
    import json

    from quadfdi.sim import realistic_params as P

    logs = [str(LOGS / n) for n in ("px4_quad_6s_gps_interference.ulg", "px4_quad_6s_uavcan_mission.ulg",
                                    "ardupilot_plane_1s.BIN")]
    res = quadfdi("ingest", "rates", *logs)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    gps, mission, plane = out["logs"]
    assert gps["rates"]["att"] == 20.0 and gps["rates"]["rate"] == 50.0 and gps["rates"]["vib_px4"] == 1.0
    assert mission["rates"]["batt"] == 1.8 and "not a multirotor" in plane["refused"]
    for g, rates in out["groups"].items():
        assert set(rates) <= set(P.LOG_HZ_MEASURED[g]), g
