"""quadfdi realism: steady segments, the noise/spectrum statistics, and the command on the shared logs."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from conftest import ROOT, quadfdi

# CI places shared/ beside the clone; a git worktree elsewhere points QUADFDI_FLIGHTLOGS at it.
LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
needs_logs = pytest.mark.skipif(not LOGS.is_dir(), reason=f"shared flight logs not found at {LOGS}")


def test_hp_noise_recovers_white_noise_under_slow_motion():
    from quadfdi.realism.stats import hp_noise

    rng = np.random.default_rng(0)
    t = np.arange(0, 60, 0.02)
    v = 2.0 * np.sin(2 * np.pi * 0.05 * t) + 0.03 * rng.standard_normal(len(t))
    noise, n = hp_noise(t, v, [(0, 60)])
    assert abs(noise - 0.03) < 0.002 and n == len(t) - 1


def test_log_like_holds_the_latest_sample_and_caps_at_the_sim_rate():
    from quadfdi.realism.stats import log_like

    t = np.arange(0, 4, 0.04)
    tl, vl = log_like(t, t.copy(), 5.0)
    assert np.allclose(np.diff(tl), 0.2) and np.all(vl <= tl + 1e-9) and np.all(tl - vl < 0.04)
    tl, _ = log_like(t, t.copy(), 50.0)
    assert np.allclose(np.diff(tl), 0.04)


def test_steady_segments_hover_and_manoeuvre():
    from quadfdi.realism.steady import segments

    t = np.arange(0, 60, 0.04)
    vx = np.where(t < 30, 0.0, 3.0 * np.sin(2 * np.pi * 0.3 * (t - 30)))  # hover, then aggressive swings
    ch = {"vx": vx, "vy": 0 * t, "vz": 0 * t, "roll": 0 * t, "pitch": 0.1 + 0 * t, "r": 0 * t}
    segs = segments(t, ch, np.ones(len(t), bool), 20.0)
    assert len(segs) == 1 and segs[0]["kind"] == "hover" and segs[0]["start_s"] == 0.0
    assert 28.0 < segs[0]["end_s"] < 31.0
    assert segments(t, ch, np.ones(len(t), bool), 40.0) == []


@needs_logs
def test_realism_command_writes_table_and_figures(small_run):
    logs = ["px4_quad_6s_gps_interference.ulg", "px4_quad_battery_monitor_disconnected.ulg",
            "px4_quad_6s_uavcan_mission.ulg", "ardupilot_plane_1s.BIN"]
    res = quadfdi("realism", "--run", str(small_run), "--logs", *(str(LOGS / n) for n in logs),
                  "--mass", "px4_quad_6s_gps_interference.ulg=2.5")
    assert res.returncode == 0, res.stderr
    out = small_run / "realism"
    for group in ("position", "velocity", "attitude", "rates", "battery", "motors"):
        assert (out / f"realism_{group}.png").stat().st_size > 1000
    md = (out / "realism.md").read_text()
    assert "px4_quad_6s_uavcan_mission.ulg | no qualifying segment" in md
    assert "refused: " in md and "not a multirotor" in md
    assert "no qualifying steady segment: px4_quad_6s_uavcan_mission.ulg, ardupilot_plane_1s.BIN" in res.stdout
    data = json.loads((out / "realism.json").read_text())
    rows = {r["channel"]: r for r in data["table"]}
    for c in ("p", "q", "r", "roll", "thr1", "thr4", "z", "vz"):
        assert rows[c]["logs"] == 2 and rows[c]["noise_ratio"] is not None and rows[c]["noise_ratio"] > 0
    assert rows["p"]["real_rate_hz"] > 45 and rows["p"]["sim_rate_hz"] == 25.0  # the simulator is capped at 25 Hz
    assert rows["thr1"]["sim_rate_hz"] == pytest.approx(rows["thr1"]["real_rate_hz"])  # logged at the real rate
    assert "2.5 kg (--mass)" in md and "unknown (no log records it" in md
    segs = [s for r in data["real"] for s in r["segments"]]
    assert len(segs) == 2 and all(s["end_s"] - s["start_s"] >= 20 for s in segs)


def test_realism_needs_a_run(tmp_path):
    res = quadfdi("realism", "--run", str(tmp_path / "nope"), "--logs", "x.ulg")
    assert res.returncode == 2 and "does not exist" in res.stderr


def test_simulated_yaw_noise_ignores_the_wrap():
    """A simulated yaw turning steadily through +-pi has the noise of its ripple, not of the 2 pi
    jumps (the real side unwraps too): the sim / real yaw ratio read 57x before this."""
    from quadfdi.realism.compare import _sim_channel

    t = np.arange(0, 40, 0.04)
    rng = np.random.default_rng(0)
    yaw = np.angle(np.exp(1j * (3.0 + 0.3 * t))) + 1e-3 * rng.standard_normal(t.size)  # wraps 2 times
    tel = yaw[None, :, None]
    segs = [{"start_s": 2.0, "end_s": 38.0, "i0": 50, "i1": 950}]
    got = _sim_channel(t, tel, 0, [(0, segs)], 20.0, angle=True)
    assert got["noise"] < 0.01
