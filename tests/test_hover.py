"""core/hover.py (the collective hover estimate) and its C++ mirror fwref/hover.hpp: the filter's
specification on constructed flights, and bit-identical estimates on simulated and real flights."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core import hover
from tests.conftest import SHARED_DATA
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

REAL = SHARED_DATA / "flightlogs"


def _flight(t=200, cmd=0.45, cur=9.0, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = np.zeros((t, len(hover.INPUTS)), np.float32)
    x[:, 0] = rng.normal(0, 0.05, t)  # vz
    x[:, 1:3] = rng.normal(0, 0.02, (t, 2))  # roll, pitch
    x[:, 3:7] = cmd + rng.normal(0, 0.01, (t, 4))
    x[:, 7] = cur + rng.normal(0, 0.3, t)
    return x


def test_freezes_after_n_steady_samples_with_the_float32_mean():
    x = _flight()
    x[:10, 0] = 1.0  # climbing: not steady
    est = hover.estimate(x)
    assert est.freeze == 10 + hover.STEADY_SAMPLES - 1
    run = x[10:10 + hover.STEADY_SAMPLES]
    c = (((run[:, 3] + run[:, 4]) + run[:, 5]) + run[:, 6]) * np.float32(0.25)
    s = np.float32(0)
    for v in c:
        s = np.float32(s + v)
    assert est.cmd.tobytes() == np.float32(s / np.float32(hover.STEADY_SAMPLES)).tobytes()
    assert abs(float(est.cur) - float(run[:, 7].mean())) < 1e-4
    # frozen: what follows changes nothing
    y = x.copy()
    y[est.freeze + 1:, 3:7] *= 2
    assert hover.estimate(y) == est


@pytest.mark.parametrize("col,value", [(0, 0.6), (1, 0.3), (2, -0.3), (3, np.nan)])
def test_an_unsteady_or_missing_sample_restarts_the_run(col, value):
    x = _flight()
    x[30, col] = value
    assert hover.estimate(x).freeze == 30 + hover.STEADY_SAMPLES


def test_not_airborne_motors_idle_and_never_steady():
    x = _flight()
    air = np.ones(len(x), bool)
    air[:40] = False
    # a take-off at sample 40: 2 s of settling (spool-up, climb-out), then 2 s of steady samples
    assert hover.estimate(x, air).freeze == 40 + hover.SETTLE_SAMPLES + hover.STEADY_SAMPLES - 1
    assert hover.estimate(x, np.ones(len(x), bool)).freeze == hover.STEADY_SAMPLES - 1  # starts airborne: settled
    y, air2 = _flight(t=300), np.ones(300, bool)
    air2[:40] = False
    air2[100:103] = False  # a touch-down before the freeze restarts the settling
    assert hover.estimate(y, air2).freeze == 103 + hover.SETTLE_SAMPLES + hover.STEADY_SAMPLES - 1
    x[:, 3:7] = 0.01  # motors at idle: collective below CMD_MIN
    assert hover.estimate(x).freeze == -1 and np.isnan(hover.estimate(x).cmd)
    assert hover.estimate(_flight(t=hover.STEADY_SAMPLES - 1)).freeze == -1


def test_a_missing_current_gives_the_command_only():
    x = _flight()
    x[:, 7] = np.nan
    est = hover.estimate(x)
    assert est.freeze == hover.STEADY_SAMPLES - 1 and np.isfinite(est.cmd) and np.isnan(est.cur)


def _real_columns() -> list[tuple[np.ndarray, np.ndarray]]:
    from quadfdi.ingest.flight import ingest

    out = []
    for name in ("px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_gps_interference.ulg", "px4_sitl_quad_esc.ulg"):
        if (REAL / name).is_file():
            a = ingest(REAL / name)[1]
            names = [str(n) for n in a["channel_names"]]
            cols = np.stack([a["telemetry"][:, names.index(c)] if str(a["channel_status"][names.index(c)]) == "ok"
                             else np.full(len(a["time"]), np.nan) for c in hover.INPUTS], axis=1)
            out.append((cols.astype(np.float32), np.asarray(a["airborne"], bool)))
    return out


def _cpp(build: Path, flights: list[tuple[np.ndarray, np.ndarray]], tmp: Path) -> np.ndarray:
    t = max(len(c) for c, _ in flights)
    data = np.full((len(flights), t, 9), np.nan, np.float32)
    for i, (c, air) in enumerate(flights):
        data[i, :len(c), :8] = c
        data[i, :, 8] = 0.0
        data[i, :len(c), 8] = air
    data.astype("<f4").tofile(tmp / "in.f32")
    subprocess.run([str(build / "fwref_hover"), "--in", str(tmp / "in.f32"), "--samples", str(t),
                    "--out", str(tmp / "out.bin")], check=True, timeout=60)
    return np.fromfile(tmp / "out.bin", dtype=np.dtype([("cmd", "<f4"), ("cur", "<f4"), ("freeze", "<i4")]))


def test_cpp_estimate_is_bit_identical_on_simulated_and_real_flights(host_build, flightlog_export,  # noqa: F811
                                                                    tmp_path):
    flights = [(_flight(seed=s), np.ones(200, bool)) for s in range(3)]
    with np.load(flightlog_export.parent / "dataset.npz") as d:  # a tiny realistic-suite run's flights
        names = [str(n) for n in d["channel_names"]]
        tel = d["telemetry"][:12]
    flights += [(f[:, [names.index(c) for c in hover.INPUTS]], np.ones(len(f), bool)) for f in tel]
    real = _real_columns()
    flights += real
    got = _cpp(host_build, flights, tmp_path)
    assert len(got) == len(flights)
    frozen = 0
    for (cols, air), g in zip(flights, got):
        py = hover.estimate(cols, air)
        assert g["freeze"] == py.freeze
        assert np.float32(g["cmd"]).tobytes() == py.cmd.tobytes()
        assert np.float32(g["cur"]).tobytes() == py.cur.tobytes() or (np.isnan(g["cur"]) and np.isnan(py.cur))
        frozen += py.freeze >= 0
    # the comparison is on real estimates, not on NaN = NaN: all but two flights freeze (one real log and one
    # aggressive 12 s simulated flight never hold the steady test's 50 samples)
    assert frozen >= len(flights) - 2
    if real:
        assert any(hover.estimate(c, a).freeze >= 0 for c, a in real)
