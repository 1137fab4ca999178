"""The ESC thermal model (sim/esc_thermal.py) on constructed inputs: its steady state and time
constant, a busier ESC and less airflow run warmer, the per-flight draws from their own stream."""

from __future__ import annotations

import numpy as np

from quadfdi.sim import esc_thermal as E


def _draws(B: int = 2) -> dict[str, np.ndarray]:
    d = E.draw(0, np.arange(B))
    d["offset"] = np.zeros((B, 4))
    return d


def test_draws_are_per_flight_and_inside_their_ranges():
    a, b = E.draw(3, np.array([4, 9])), E.draw(3, np.array([9]))
    for k in a:
        np.testing.assert_array_equal(a[k][1], b[k][0], err_msg=k)  # a flight's draws do not depend on its batch
    assert np.all((a["C"] >= E.C_J_PER_K[0]) & (a["C"] <= E.C_J_PER_K[1]))
    assert np.all(np.abs(a["offset"]) <= E.OFFSET_C) and a["R"].shape == (2, 4) and a["G_flow"].shape == (2, 4)
    assert not np.array_equal(E.draw(4, np.array([4]))["R"], a["R"][:1])


def test_steady_state_and_time_constant():
    """Constant inputs: T -> T_amb + P / G, reached with tau = C / G (63 % after tau)."""
    d = _draws(1)
    dt, n = 0.02, 40000
    P, G = np.full((n, 1, 4), 1.5), np.full((n, 1, 4), 0.1)
    d["t_pre"][:] = 0.0  # start at ambient
    T = E.temperatures(P, G, np.array([20.0]), d, dt)
    np.testing.assert_allclose(T[0], 20.0)
    np.testing.assert_allclose(T[-1], 20.0 + 15.0, atol=1e-3)
    tau = d["C"][0] / 0.1
    k = int(round(tau / dt))
    np.testing.assert_allclose(T[k] - 20.0, 15.0 * (1.0 - np.exp(-1.0)), rtol=2e-3)  # backward Euler, dt/tau < 1e-3


def test_more_current_heats_more_and_airflow_cools():
    d = _draws(1)
    d["R"][:] = 0.02
    d["G_flow"][:] = 0.05
    V = np.array([[15.0]])
    P = E.losses(np.array([[[2.0, 2.0, 2.5, 3.0]]]), V, d)[0, 0]
    assert P[0] == P[1] < P[2] < P[3]
    G = E.conductance(np.array([[[0.0, 2.0, 4.0, 4.0]]]), np.array([[0.0]]), d)[0, 0]
    assert G[0] == d["G_still"][0] and G[0] < G[1] < G[2]
    G_fast = E.conductance(np.array([[[4.0] * 4]]), np.array([[10.0]]), d)[0, 0]
    assert np.all(G_fast > G[3])  # forward flight over the wash cools more


def test_reported_is_whole_degrees_with_the_offset():
    d = _draws(1)
    d["offset"][:] = [[0.4, -0.4, 0.0, 0.9]]
    got = E.reported(np.array([[[20.2, 20.2, 20.49, 20.2]]]), d)
    np.testing.assert_array_equal(got, [[[21.0, 20.0, 20.0, 21.0]]])


def test_warm_start_and_a_busier_esc_in_flight():
    """Through esc_temperatures: the ESC with 1.5x the current ends hottest; t = 0 is warmed by t_pre."""
    B, n = 1, 3000
    d = _draws(B)
    F = np.full((n, B, 4), 4.0)
    I = np.full((n, B, 4), 3.0)
    I[..., 2] = 4.5
    out = E.esc_temperatures(F, I, np.full((n, B), 15.0), np.zeros((n, B, 3)),
                             {"t_amb": np.array([10.0]), "wind_ms": np.array([0.0]), "wind_dir": np.array([0.0])}, d, 0.02)
    end = np.array([out[f"esc_temp{k}"][-1, 0] for k in range(1, 5)])
    assert end.argmax() == 2 and end[2] > end[0] and out["esc_temp1"][0, 0] >= 10.0


def test_a_cut_blade_heats_its_esc_more():
    """A cut blade's rotor draws more current for the same thrust (sim.esc_telemetry.esc_current), so its
    ESC loses more and settles warmer; the same conductance (same thrust, same wash)."""
    from quadfdi.sim.esc_telemetry import esc_current

    d = _draws(1)
    d["R"][:], d["G_flow"][:] = 0.02, 0.05
    F, V = np.full((1, 1, 4), 4.0), np.full((1, 1), 15.0)
    cut = np.array([[[0.0, 0.0, 0.3, 0.0]]])
    I = esc_current(F, cut, V)
    assert I[0, 0, 2] > 1.1 * I[0, 0, 0]
    rise = E.losses(I, V, d) / E.conductance(F, np.zeros((1, 1)), d)  # steady state above ambient
    assert rise[0, 0, 2] > rise[0, 0, 0]
