"""generate(): contract, determinism, shard regeneration, class assignment, closed-loop flight and
the telemetry signature of every fault class."""

from __future__ import annotations

import dataclasses
import io

import numpy as np
import pytest

from quadfdi.sim.config import SimConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.sim import sensors
from quadfdi.sim.assign import assign, class_counts
from quadfdi.sim.params import get_vehicle
from quadfdi.sim.simulate import generate

VP = get_vehicle("f450_3s")
# Small and fast: 30 trajectories of 4 s, faults early enough to show.
SMALL = dataclasses.replace(SimConfig(), n_traj=30, duration_s=4.0, window=40, stride=5,
                            onset_frac=(0.1, 0.3), ramp_frac=(0.2, 0.4))
# Faults that have time to develop: 8 s, every class equally.
FAULTY = dataclasses.replace(SimConfig(), n_traj=16, duration_s=8.0, window=40, stride=5, fault_ratio=0.75,
                             onset_frac=(0.1, 0.2), ramp_frac=(0.3, 0.4), severity_max=(0.8, 1.0))

TIME_KEYS = ("telemetry", "states", "severity", "effectiveness", "thrust_act", "cooling", "fault_heat", "r_int",
             "c_eff", "kappa_v", "reference")


@pytest.fixture(scope="module")
def small():
    return generate(SMALL)


@pytest.fixture(scope="module")
def faulty():
    return generate(FAULTY)


def _col(ds, name):
    return ds["states"][..., list(ds["state_names"]).index(name)]


def _chan(ds, name):
    return ds["telemetry"][..., list(ds["channel_names"]).index(name)]


# ----------------------------------------------------------------------------- contract


def test_keys_dtypes_and_shapes(small):
    n, T, C, S = 30, SMALL.n_samples, 23, 19
    expect = {
        "telemetry": (np.float32, (n, T, C)), "time": (np.float64, (T,)), "states": (np.float32, (n, T, S)),
        "severity": (np.float32, (n, T)), "fault_class": (np.int8, (n,)), "onset_s": (np.float64, (n,)),
        "ramp_s": (np.float64, (n,)), "severity_max": (np.float64, (n,)), "fault_motor": (np.int8, (n,)),
        "detectable_s": (np.float64, (n,)), "split": (np.int8, (n,)), "traj_index": (np.int64, (n,)),
        "severity_threshold": (np.float64, ()), "effectiveness": (np.float32, (n, T, 4)),
    }
    for key, (dtype, shape) in expect.items():
        assert small[key].dtype == dtype and small[key].shape == shape, key
    for key in ("channel_names", "channel_units", "state_names", "state_units"):
        assert small[key].dtype.kind == "U"
    assert list(small["channel_names"]) == list(sensors.CHANNEL_NAMES)
    assert list(small["state_names"]) == list(sensors.STATE_NAMES)
    np.testing.assert_array_equal(small["time"], np.arange(T) * SMALL.sample_dt_s)
    np.testing.assert_array_equal(small["traj_index"], np.arange(n))
    assert float(small["severity_threshold"]) == SMALL.severity_threshold
    # no pickle anywhere: the whole dict round-trips with allow_pickle=False
    buf = io.BytesIO()
    np.savez(buf, **small)
    buf.seek(0)
    with np.load(buf, allow_pickle=False) as z:
        for key in small:
            np.testing.assert_array_equal(z[key], small[key])


def test_fault_metadata_conventions(small):
    cls = small["fault_class"]
    healthy = cls == 0
    assert np.isnan(small["onset_s"][healthy]).all() and np.isnan(small["ramp_s"][healthy]).all()
    assert (small["severity_max"][healthy] == 0).all() and (small["severity"][healthy] == 0).all()
    assert np.isnan(small["detectable_s"][healthy]).all()
    assert (small["fault_motor"][np.isin(cls, [0, 1])] == -1).all()
    assert np.isin(small["fault_motor"][np.isin(cls, [2, 3])], [0, 1, 2, 3]).all()
    f = ~healthy
    lo, hi = SMALL.onset_frac
    assert ((small["onset_s"][f] >= lo * SMALL.duration_s) & (small["onset_s"][f] <= hi * SMALL.duration_s)).all()
    # severity is Eq. (6) at the sample times; t_det is its first crossing of the threshold
    t = small["time"]
    for i in np.flatnonzero(f):
        s = small["severity_max"][i] * np.clip((t - small["onset_s"][i]) / small["ramp_s"][i], 0, 1)
        np.testing.assert_allclose(small["severity"][i], s, rtol=1e-6, atol=1e-7)
        first = t[np.argmax(s >= SMALL.severity_threshold)]
        assert small["detectable_s"][i] == pytest.approx(first)


def test_progress_and_bad_indices():
    cfg = dataclasses.replace(SMALL, duration_s=3.2, window=20, chunk=4)
    seen = []
    out = generate(cfg, indices=[3, 9, 1, 4, 5, 6], progress=seen.append)
    assert seen == [4, 2]
    np.testing.assert_array_equal(out["traj_index"], [3, 9, 1, 4, 5, 6])
    with pytest.raises(QuadfdiError, match="outside 0..29"):
        generate(cfg, indices=[30])
    with pytest.raises(QuadfdiError, match="no trajectory"):
        generate(cfg, indices=[])


# ----------------------------------------------------------------------------- determinism


def test_same_seed_same_bytes_other_seed_differs(small):
    again = generate(SMALL)
    for key in small:
        assert small[key].tobytes() == again[key].tobytes(), key
    other = generate(dataclasses.replace(SMALL, seed=1), indices=range(5))
    assert not np.array_equal(other["telemetry"], small["telemetry"][:5])


def test_shard_regeneration_is_bitwise(small):
    shard = generate(dataclasses.replace(SMALL, chunk=3), indices=range(10, 20))
    for key, value in small.items():
        if value.ndim and value.shape[0] == 30:
            assert shard[key].tobytes() == value[10:20].tobytes(), key
        else:
            assert shard[key].tobytes() == value.tobytes(), key


def test_two_chunks_equal_one_batch(small):
    # SMALL is one batch of 30 (chunk 240); the same dataset integrated as two batches of 15
    assert SMALL.chunk >= SMALL.n_traj
    seen = []
    halves = generate(dataclasses.replace(SMALL, chunk=15), progress=seen.append)
    assert seen == [15, 15]
    assert halves.keys() == small.keys()
    for key, value in small.items():
        assert halves[key].dtype == value.dtype and halves[key].shape == value.shape, key
        assert halves[key].tobytes() == value.tobytes(), key


# ----------------------------------------------------------------------------- assign


@pytest.mark.parametrize("n, ratio", [(240, 0.75), (31, 0.5), (7, 1.0), (10, 0.0), (100, 0.7)])
def test_assign_exact_counts_and_stratified_splits(n, ratio):
    cls, split = assign(0, n, ratio, (0.7, 0.15, 0.15))
    assert cls.dtype == np.int8 and split.dtype == np.int8 and cls.shape == split.shape == (n,)
    n_fault = int(np.floor(ratio * n + 0.5))
    counts = np.bincount(cls, minlength=4)
    assert counts[0] == n - n_fault and counts[1:].sum() == n_fault
    assert counts[1:].max() - counts[1:].min() <= 1 and (np.diff(counts[1:]) <= 0).all()  # remainder to low ids
    np.testing.assert_array_equal(counts, class_counts(n, ratio))
    for k in range(4):
        m = cls == k
        c = int(m.sum())
        share = int(np.floor(0.15 * c + 0.5 + 1e-9))  # round half up, for validation and for test
        assert np.bincount(split[m], minlength=3).tolist() == [c - 2 * share, share, share]


def test_assign_paper_scale_and_seeded():
    cls, split = assign(0, 240, 0.75, (0.7, 0.15, 0.15))
    assert np.bincount(cls).tolist() == [60, 60, 60, 60]
    for k in range(4):
        assert np.bincount(split[cls == k]).tolist() == [42, 9, 9]
    cls2, split2 = assign(0, 240, 0.75, (0.7, 0.15, 0.15))
    assert cls.tobytes() == cls2.tobytes() and split.tobytes() == split2.tobytes()
    cls3, _ = assign(1, 240, 0.75, (0.7, 0.15, 0.15))
    assert not np.array_equal(cls, cls3) and np.bincount(cls3).tolist() == [60, 60, 60, 60]
    with pytest.raises(QuadfdiError):
        assign(0, 10, 1.5, (0.7, 0.15, 0.15))


# ----------------------------------------------------------------------------- closed-loop flight


def test_closed_loop_is_stable_and_tracks_the_reference(small, faulty):
    for ds in (small, faulty):
        assert np.isfinite(ds["telemetry"]).all() and np.isfinite(ds["states"]).all()
        tilt = np.degrees(np.arccos(np.cos(_col(ds, "roll")) * np.cos(_col(ds, "pitch"))))
        assert tilt.max() < 25
        assert (ds["battery_limited"] == 0).all()
        thr = ds["telemetry"][..., -4:]
        assert thr.min() > -0.01 and thr.max() < 1.01
    err = np.linalg.norm(faulty["states"][..., 0:3] - faulty["reference"][..., 0:3], axis=-1)
    settled = err[:, 75:]  # after 3 s the initial offsets (<= 0.5 m, 0.3 m/s) are gone
    h = faulty["fault_class"] == 0
    assert np.sqrt((settled[h] ** 2).mean()) < 0.1 and settled[h].max() < 0.3
    assert settled.max() < 0.8  # faulty vehicles too: the integrators compensate
    yaw_err = np.abs(_col(faulty, "yaw") - faulty["reference"][..., 3])[:, 75:]
    assert yaw_err.max() < 0.1


def test_healthy_hover_numbers(small):
    h = small["fault_class"] == 0
    I, V = _col(small, "I_b")[h], _col(small, "V_b")[h]
    P = (I * V).mean()
    assert 140 < P < 200 and 11.5 < I.mean() < 17
    T = small["states"][h][..., -4:]
    t_amb = small["t_amb"][h][:, None, None]
    assert (T > t_amb).all() and (T < t_amb + 25).all()


def test_soc_drop_matches_integrated_current(small):
    t = small["time"]
    soc = _col(small, "SoC").astype(np.float64)
    I = _col(small, "I_b").astype(np.float64)
    C = small["c_eff"].astype(np.float64)
    drop = soc[:, 0] - soc[:, -1]
    integral = np.trapezoid(I / C, t, axis=1) / 3600
    np.testing.assert_allclose(drop, integral, rtol=3e-3)


# ----------------------------------------------------------------------------- fault signatures


def _early_late(a):
    return a[:, :25].mean(axis=1), a[:, -25:].mean(axis=1)  # first and last second


def test_battery_fault_sags_voltage_and_raises_current(faulty):
    cls = faulty["fault_class"]
    b, h = cls == 1, cls == 0
    e, l = _early_late(_chan(faulty, "V_b"))
    assert ((l - e)[b] < (l - e)[h].min() - 0.3).all()  # sags beyond any healthy drift
    e, l = _early_late(_chan(faulty, "I_b"))
    assert ((l - e)[b] > (l - e)[h].max() + 1.0).all()  # draws more current
    e, l = _early_late(faulty["telemetry"][..., -4:].mean(axis=-1))
    assert ((l - e)[b] > 0.03).all()  # every motor's throttle rises to hold altitude


def test_motor_fault_raises_the_faulty_motors_throttle(faulty):
    rows = np.flatnonzero(faulty["fault_class"] == 2)
    assert rows.size
    for i in rows:
        m = faulty["fault_motor"][i]
        thr = faulty["telemetry"][i, :, -4:]
        e, l = thr[:25].mean(axis=0), thr[-25:].mean(axis=0)
        rise = l - e
        assert rise[m] > 0.08 and rise[m] > np.delete(rise, m).max() + 0.05
        assert faulty["effectiveness"][i, -1, m] < 1 - 0.5 * VP.a_M * faulty["severity_max"][i]


def test_overheat_fault_heats_that_motor(faulty):
    rows = np.flatnonzero(faulty["fault_class"] == 3)
    assert rows.size
    healthy_rise = []
    for i in np.flatnonzero(faulty["fault_class"] == 0):
        T = _chan(faulty, "T1")[i : i + 1]
        healthy_rise.append(float(np.diff(_early_late(T), axis=0)[0, 0]))
    for i in rows:
        m = faulty["fault_motor"][i]
        T = faulty["telemetry"][i, :, 15:19]
        rise = T[-25:].mean(axis=0) - T[:25].mean(axis=0)
        assert rise[m] > 4.0 and rise[m] > np.delete(rise, m).max() + 3.0
        assert faulty["cooling"][i, -1, m] < VP.h_nom and faulty["fault_heat"][i, -1, m] > 0


def test_every_fault_is_detectable_before_the_end():
    # Paper defaults: worst case onset 0.43, ramp 0.62, s_max 0.5, threshold 0.2 -> 10.85 s of 16 s.
    cfg = SimConfig()
    from quadfdi.sim.draws import draw_trajectory

    t = np.arange(cfg.n_samples) * cfg.sample_dt_s
    for i in range(cfg.n_traj):  # the draws only: cheap
        d = draw_trajectory(cfg, VP, i)
        s = d["s_max"] * np.clip((t - d["onset"]) / d["ramp"], 0, 1)
        assert (s >= cfg.severity_threshold).any()
        assert t[np.argmax(s >= cfg.severity_threshold)] <= t[-1] - 0.4


@pytest.mark.slow
def test_paper_scale_flights_are_sane():
    out = generate(SimConfig())
    assert out["telemetry"].shape == (240, 400, 23)
    assert np.isfinite(out["telemetry"]).all()
    tilt = np.degrees(np.arccos(np.cos(_col(out, "roll")) * np.cos(_col(out, "pitch"))))
    assert tilt.max() < 25
    f = out["fault_class"] > 0
    assert np.isfinite(out["detectable_s"][f]).all()
    assert (out["detectable_s"][f] <= out["time"][-1] - 0.4).all()
    assert (out["battery_limited"] == 0).all()
    assert np.bincount(out["fault_class"]).tolist() == [60, 60, 60, 60]


def test_voltage_compensation_option_flies():
    # PX4-style thrust scaling (v_comp): the command carries 1/kappa_V, the altitude integrator idles.
    from quadfdi.sim.draws import draw_trajectory
    from quadfdi.sim.simulate import simulate_batch

    vp = dataclasses.replace(VP, v_comp=True)
    cfg = dataclasses.replace(SMALL, duration_s=3.2, window=20)
    draws = [draw_trajectory(cfg, vp, i) for i in range(4)]
    out = simulate_batch(draws, np.zeros(4, dtype=np.int8), cfg, vp)
    assert np.isfinite(out["states"]).all()
    err = np.linalg.norm(out["states"][:, -25:, 0:3] - out["reference"][:, -25:, 0:3], axis=-1)
    assert err.max() < 0.3
    thr = out["throttle"][:, -25:].mean(axis=(1, 2))
    expect = VP.hover_thrust / (out["kappa_v"][:, -25:].mean(axis=1) * VP.F_max)
    np.testing.assert_allclose(thr, expect, rtol=0.05)
