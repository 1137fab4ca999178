"""Simulator physics against independent references (SPEC section 7).

References: scipy's solve_ivp on an independently written Eq. (2) (scipy's Rotation for R, the
paper's E(eta) matrix, a full cross product), closed forms (hover equilibrium, battery quadratic,
thermal steady state and exponential, Eq. (6) ramp, Simpson's rule for classic RK4) and sample
statistics with stated tolerances.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rk4 import rk4_step
from quadfdi.sim import battery, controller, dynamics, faults, rigid_body, sensors, thermal
from quadfdi.sim.params import VEHICLES, get_vehicle

VP = get_vehicle("f450_3s")
RNG = np.random.default_rng(1234)


# ----------------------------------------------------------------------------- parameters


def test_get_vehicle_unknown_lists_valid_names():
    with pytest.raises(QuadfdiError, match="f450_3s"):
        get_vehicle("x500")
    assert set(VEHICLES) == {"f450_3s"}


def test_vehicle_is_plausible_f450():
    hover = VP.m * VP.g / 4
    assert 0.3 < hover / VP.F_max < 0.55  # hover throttle 30-55 % at V_nom
    P = battery.prop_power(np.full((1, 4), hover), VP)[0] + VP.P_av
    assert 140 < P < 190  # healthy hover power
    V, I, _ = battery.terminal(np.array([0.8]), np.array([P]), VP.R_0, 0.0, 1.0, VP)
    assert 12 < I[0] < 17 and 11 < V[0] < 12.6
    assert battery.ocv(np.array(0.0), VP) == pytest.approx(9.0)
    assert battery.ocv(np.array(1.0), VP) == pytest.approx(12.6)
    plateau = battery.ocv(np.linspace(0.2, 0.7, 11), VP)
    assert plateau.min() >= 11.0 and plateau.max() <= 11.75
    assert 25 < VP.C_th / VP.h_nom < 45  # thermal time constant [s]


# ----------------------------------------------------------------------------- integrator


def test_simulator_integrates_with_the_shared_rk4():
    # one RK4 program for the simulator, training, ONNX and C++ (core/rk4.py)
    assert dynamics.rk4_step is rk4_step


def test_rk4_is_classic_not_three_eighths():
    # x' = t^4 over one step of h = 1: classic RK4 is Simpson's rule (5/24); the 3/8 rule gives 11/54.
    calls = []

    def f(t, x):
        calls.append(t)
        return np.full_like(x, t**4)

    x1 = rk4_step(f, 0.0, np.zeros((1, 1)), 1.0)
    assert x1[0, 0] == pytest.approx(5.0 / 24.0, abs=1e-15)
    assert abs(x1[0, 0] - 11.0 / 54.0) > 1e-3
    assert calls == [0.0, 0.5, 0.5, 1.0]  # 4 evaluations, stages at 0, h/2, h/2, h
    calls.clear()
    rk4_step(f, 0.0, np.zeros((1, 1)), 1.0, k1=f(0.0, np.zeros((1, 1))))
    assert len(calls) == 4  # k1 supplied by the caller: 3 more evaluations


def _rigid_body_reference(t, y, F, vp):
    """Eq. (2) written independently: scipy Rotation (intrinsic ZYX = Rz Ry Rx), the paper's
    E(eta) matrix, a full inertia matrix and np.cross."""
    p, v, eta, w = y[0:3], y[3:6], y[6:9], y[9:12]
    phi, th, psi = eta
    R = Rotation.from_euler("ZYX", [psi, th, phi]).as_matrix()
    T = F.sum()
    M = np.array([vp.L * (F[1] - F[3]), vp.L * (F[2] - F[0]), vp.gamma * (F[0] - F[1] + F[2] - F[3])])
    J = np.diag([vp.Jxx, vp.Jyy, vp.Jzz])
    E = np.array([[1, np.sin(phi) * np.tan(th), np.cos(phi) * np.tan(th)],
                  [0, np.cos(phi), -np.sin(phi)],
                  [0, np.sin(phi) / np.cos(th), np.cos(phi) / np.cos(th)]])
    vdot = (R @ np.array([0, 0, T]) - vp.m * vp.g * np.array([0, 0, 1]) - vp.k_L * v) / vp.m
    wdot = np.linalg.solve(J, M - np.cross(w, J @ w) - vp.k_Omega * w)
    return np.concatenate([v, vdot, E @ w, wdot])


def test_rigid_body_rk4_matches_solve_ivp():
    # Asymmetric fixed thrusts, tilted and spinning start: all terms of Eq. (2) are exercised.
    x0 = np.array([[0.3, -0.2, 10.0, 1.0, -0.5, 0.2, 0.2, -0.15, 0.7, 0.8, -0.6, 0.4]])
    F = np.array([[3.9, 3.5, 3.6, 3.8]])
    t_end = 1.5
    ref = solve_ivp(_rigid_body_reference, (0.0, t_end), x0[0], args=(F[0], VP), method="DOP853",
                    rtol=1e-13, atol=1e-13)
    assert ref.success
    errs = []
    for dt in (0.005, 0.0025):
        x = x0.copy()
        n = int(round(t_end / dt))
        for k in range(n):
            x = rk4_step(lambda ts, xs: rigid_body.deriv(xs, F, VP), k * dt, x, dt)
        errs.append(np.abs(x[0] - ref.y[:, -1]).max())
    assert errs[0] < 2e-6, errs  # the simulator's 5 ms step
    assert 12 < errs[0] / errs[1] < 20, errs  # fourth order: halving h divides the error by ~16


def test_derivative_matches_reference_pointwise():
    for _ in range(20):
        x = np.concatenate([RNG.normal(0, 2, 6), RNG.uniform(-0.6, 0.6, 3), RNG.normal(0, 1, 3)])[None, :]
        F = RNG.uniform(0, VP.F_max, (1, 4))
        np.testing.assert_allclose(rigid_body.deriv(x, F, VP)[0], _rigid_body_reference(0, x[0], F[0], VP),
                                   rtol=1e-12, atol=1e-12)


def test_rotation_is_zyx_and_euler_rates_match_angular_velocity():
    eta = RNG.uniform(-0.8, 0.8, (5, 3))
    R = rigid_body.rotation(eta)
    for k in range(5):
        ref = Rotation.from_euler("ZYX", eta[k, ::-1]).as_matrix()
        np.testing.assert_allclose(R[k], ref, atol=1e-14)
    # R^T dR/dt = [omega]x when eta_dot = E(eta) omega (central differences)
    w = RNG.normal(0, 1, (5, 3))
    eta_dot = np.einsum("bij,bj->bi", rigid_body.euler_rate_matrix(eta), w)
    h = 1e-6
    dR = (rigid_body.rotation(eta + h * eta_dot) - rigid_body.rotation(eta - h * eta_dot)) / (2 * h)
    S = np.einsum("bji,bjk->bik", R, dR)
    np.testing.assert_allclose(np.stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]], -1), w, atol=1e-8)


def test_hover_equilibrium():
    T = np.array([VP.m * VP.g])
    F = rigid_body.mixer(T, np.zeros((1, 3)), VP)
    np.testing.assert_allclose(F, VP.m * VP.g / 4)
    x = np.zeros((1, 12))
    x[0, 2], x[0, 8] = 7.0, 0.9  # any position and heading
    np.testing.assert_allclose(rigid_body.deriv(x, F, VP), 0.0, atol=1e-14)
    # a 1 % thrust excess accelerates up at 1 % of g
    assert rigid_body.deriv(x, 1.01 * F, VP)[0, 5] == pytest.approx(0.01 * VP.g, rel=1e-9)


def test_mixer_and_moments_are_inverse():
    T = RNG.uniform(5, 25, 10)
    tau = RNG.normal(0, 0.2, (10, 3))
    T2, M = rigid_body.moments(rigid_body.mixer(T, tau, VP), VP)
    np.testing.assert_allclose(T2, T, rtol=1e-12)
    np.testing.assert_allclose(M, tau, atol=1e-12)
    # the paper's first rotor: F1 = T/4 - tau_pitch/(2L) + tau_yaw/(4 gamma)
    F = rigid_body.mixer(T, tau, VP)
    np.testing.assert_allclose(F[:, 0], T / 4 - tau[:, 1] / (2 * VP.L) + tau[:, 2] / (4 * VP.gamma))


def test_mixer_desaturation_keeps_range_and_roll_pitch():
    T = np.array([4 * VP.F_max, 30.0, 2.0, 15.0])
    tau = np.array([[0.0, 0.0, 0.1], [0.5, 0.0, 0.1], [0.0, 0.2, -0.1], [0.1, -0.1, 0.02]])
    F = controller.mix_desaturate(T, tau, VP)
    assert (F >= 0).all() and (F <= VP.F_max).all()
    _, M = rigid_body.moments(F, VP)
    np.testing.assert_allclose(M[1:, :2], tau[1:, :2], atol=1e-12)  # roll/pitch kept when feasible
    np.testing.assert_allclose(M[3], tau[3], atol=1e-12)  # unsaturated: exact


# ----------------------------------------------------------------------------- battery


def test_battery_closed_form_satisfies_both_equations():
    n = 200
    soc = RNG.uniform(0.5, 1, n)
    s_b = RNG.uniform(0, 1, n)
    R, C, dV, k = faults.battery(s_b, VP)
    P = RNG.uniform(10, 250, n)
    V, I, limited = battery.terminal(soc, P, R, dV, k, VP)
    E = battery.ocv(soc, VP) - dV
    ok = ~limited
    assert ok.all()  # 250 W is below the maximum power of every pack state here
    np.testing.assert_allclose(V, E - I * R, rtol=1e-12)  # V_b = V_ocv - DeltaV - I R_int
    np.testing.assert_allclose(I, k * P / V, rtol=1e-10)  # I_b = k P / V_b
    assert (V > E / 2).all()  # the physical (larger) root


def test_battery_clamps_at_maximum_power_point():
    soc, R = np.array([0.3]), 0.05
    E = battery.ocv(soc, VP)
    P_max = E**2 / (4 * R)
    V, I, limited = battery.terminal(soc, 1.5 * P_max, R, 0.0, 1.0, VP)
    assert limited[0]
    assert V[0] == pytest.approx(E[0] / 2) and I[0] == pytest.approx(E[0] / (2 * R))
    V2, I2, lim2 = battery.terminal(soc, 0.999 * P_max, R, 0.0, 1.0, VP)
    assert not lim2[0] and V2[0] > E[0] / 2


def test_soc_drop_equals_integrated_current_over_capacity():
    # Time-varying power through the closed form, SoC integrated with RK4 vs quadrature of I_b.
    def power(t):
        return 160 + 60 * np.sin(0.7 * t)

    def f(t, x):
        _, I, _ = battery.terminal(x[:, 0], np.full(1, power(t)), VP.R_0, 0.0, 1.0, VP)
        return battery.deriv(I, VP.C_nom)[:, None]

    x, dt = np.array([[0.9]]), 0.01
    for k in range(1000):
        x = rk4_step(f, k * dt, x, dt)
    soc_t = solve_ivp(lambda t, y: f(t, y[None, :])[0], (0, 10), [0.9], rtol=1e-12, atol=1e-14, dense_output=True)
    ts = np.linspace(0, 10, 20001)
    I = np.array([battery.terminal(np.array([soc_t.sol(t)[0]]), np.array([power(t)]), VP.R_0, 0.0, 1.0, VP)[1][0]
                  for t in ts])
    charge_ah = np.trapezoid(I, ts) / 3600
    assert 0.9 - x[0, 0] == pytest.approx(charge_ah / VP.C_nom, rel=1e-6)


# ----------------------------------------------------------------------------- thermal


def test_thermal_steady_state_and_time_constant():
    I_m = np.array([[3.5, 3.0, 4.0, 0.0]])
    F = np.array([[3.7, 3.2, 4.1, 0.0]])
    h = np.array([[0.35, 0.35, 0.2, 0.35]])
    Q = np.array([[0.0, 0.0, 10.0, 0.0]])
    T_amb = 21.0
    T_ss = T_amb + (VP.R_w * I_m**2 + VP.c_F * F**2 + Q) / h  # written out by hand
    np.testing.assert_allclose(thermal.steady_state(I_m, F, h, Q, T_amb, VP), T_ss, rtol=1e-14)
    np.testing.assert_allclose(thermal.deriv(T_ss, I_m, F, h, Q, T_amb, VP), 0.0, atol=1e-12)
    # from ambient: T(t) = T_ss + (T0 - T_ss) exp(-h t / C_th)
    T, dt = np.full((1, 4), T_amb), 0.05
    for k in range(800):  # 40 s
        T = rk4_step(lambda ts, Ts: thermal.deriv(Ts, I_m, F, h, Q, T_amb, VP), k * dt, T, dt)
    exact = T_ss + (T_amb - T_ss) * np.exp(-h * 40.0 / VP.C_th)
    np.testing.assert_allclose(T, exact, rtol=1e-9)


def test_motor_currents_share_bus_current_by_thrust():
    F = np.array([[1.0, 2.0, 3.0, 4.0]])
    I = thermal.motor_currents(F, np.array([20.0]))
    np.testing.assert_allclose(I, [[2.0, 4.0, 6.0, 8.0]])
    assert np.isfinite(thermal.motor_currents(np.zeros((1, 4)), np.array([1.0]))).all()


# ----------------------------------------------------------------------------- faults


def test_severity_ramp_closed_form():
    t = np.linspace(0, 16, 1601)
    on, ramp, smax = 3.0, 5.0, 0.7
    s = faults.severity(t, on, ramp, smax)
    expect = np.where(t < on, 0.0, np.where(t > on + ramp, smax, smax * (t - on) / ramp))
    np.testing.assert_allclose(s, expect, atol=1e-15)
    assert faults.severity(5.5, on, ramp, smax) == pytest.approx(0.35)
    assert (np.diff(s) >= 0).all() and s.max() == pytest.approx(smax)


def test_battery_fault_sags_voltage_and_raises_current():
    s = np.array([0.0, 0.5, 1.0])
    R, C, dV, k = faults.battery(s, VP)
    np.testing.assert_allclose(R, VP.R_0 * (1 + VP.a_R * s))
    np.testing.assert_allclose(C, VP.C_nom * (1 - VP.a_C * s))
    np.testing.assert_allclose(dV, VP.Delta_V * s)
    V, I, _ = battery.terminal(np.full(3, 0.7), np.full(3, 170.0), R, dV, k, VP)
    assert (np.diff(V) < 0).all() and (np.diff(I) > 0).all()
    assert (np.diff(battery.deriv(I, C)) < 0).all()  # SoC falls faster


def test_motor_fault_reduces_only_the_faulty_rotor():
    onehot = np.array([[0.0, 0.0, 1.0, 0.0]])
    c = faults.motor_effectiveness(np.array([0.8]), onehot, VP)
    np.testing.assert_allclose(c, [[1, 1, 1 - VP.a_M * 0.8, 1]])
    # through the simulator's thrust path (Eq. 8): F_act = c_i d_m kappa_V F_cmd, d_m = 1 below T_der;
    # power and heat follow the drive (kappa_V F_cmd d_m), so the bus current does not change
    x = np.zeros((1, dynamics.N_X))
    x[0, 12], x[0, 13:17] = 0.8, VP.T_der - 20.0

    def held(c_i):
        return dynamics.StepInputs(np.full((1, 4), 4.0), c_i, np.ones((1, 4)), np.full((1, 4), VP.h_nom),
                                   np.zeros((1, 4)), np.array([VP.R_0]), np.array([VP.C_nom]), np.zeros(1),
                                   np.ones(1), np.full((1, 1), 20.0))

    _, aux = dynamics.augmented_deriv(x, held(c), VP)
    _, aux_ok = dynamics.augmented_deriv(x, held(np.ones((1, 4))), VP)
    np.testing.assert_allclose(aux.F_act, 4.0 * c, rtol=1e-15)
    assert aux.F_act[0, 2] < aux.F_act[0, 0] == 4.0
    assert aux.I_b[0] == aux_ok.I_b[0]


def test_overheat_fault_cools_less_heats_more_and_derates():
    onehot = np.array([[1.0, 0.0, 0.0, 0.0]])
    s = np.array([1.0])
    h = faults.cooling(s, onehot, VP)
    assert h[0, 0] == pytest.approx(max(VP.h_nom * (1 - VP.a_h), VP.h_min)) and (h[0, 1:] == VP.h_nom).all()
    assert faults.cooling(np.array([5.0]), onehot, VP)[0, 0] == VP.h_min  # lower bound
    Q = faults.fault_heat(s, onehot, VP)
    np.testing.assert_allclose(Q, [[VP.a_Q, 0, 0, 0]])
    fac = faults.overheat_factor(s, onehot, VP)
    T_m = np.array([[VP.T_der + 10, VP.T_der + 10, VP.T_der - 10, VP.T_der + 500]])
    d = faults.derating(T_m, fac, VP)
    np.testing.assert_allclose(d[0, 0], (1 - VP.lambda_T * 10) * (1 - VP.a_d))
    np.testing.assert_allclose(d[0, 1], 1 - VP.lambda_T * 10)
    assert d[0, 2] == 1.0 and d[0, 3] == VP.d_min
    # the overheated motor's node heats faster at the same current and thrust
    dT = thermal.deriv(np.full((1, 4), 25.0), np.full((1, 4), 3.5), np.full((1, 4), 3.7), h, Q, 20.0, VP)
    assert dT[0, 0] > dT[0, 1] > 0


def test_kappa_v_falls_with_bus_voltage():
    V = np.array([12.6, VP.V_nom, 10.0])
    k = faults.kappa_v(V, VP)
    assert k[1] == 1.0 and k[0] > 1 > k[2]
    assert k[2] == pytest.approx(1 - VP.k_V * (VP.V_nom - 10.0) / VP.V_nom)


# ----------------------------------------------------------------------------- sensors (Eq. 9)


def test_noise_and_bias_statistics():
    n_traj, n_t, dt = 60, 400, 0.04
    rng = np.random.default_rng(7)
    draws = [sensors.draw_unit(rng, n_t) for _ in range(n_traj)]
    noise = np.stack([d[0] for d in draws])
    incr = np.stack([d[1] for d in draws])
    y, b = sensors.measure(np.zeros((n_traj, n_t, sensors.N_CHANNELS)), noise, incr, VP, dt)
    sigma_n, sigma_b = sensors.sigmas(VP)
    assert (b[:, 0] == 0).all()
    n_hat = (y - b).reshape(-1, sensors.N_CHANNELS)
    db = np.diff(b, axis=1).reshape(-1, sensors.N_CHANNELS)
    # sample std of N normals: relative standard error 1/sqrt(2N); allow 5 standard errors
    tol_n = 5 / np.sqrt(2 * n_hat.shape[0])
    tol_b = 5 / np.sqrt(2 * db.shape[0])
    np.testing.assert_allclose(n_hat.std(axis=0), sigma_n, rtol=tol_n)
    assert (np.abs(n_hat.mean(axis=0)) <= 5 * sigma_n / np.sqrt(n_hat.shape[0])).all()
    np.testing.assert_allclose(db.std(axis=0), np.sqrt(dt) * sigma_b, rtol=tol_b)
    # the walk's variance grows linearly: Var b(t) = sigma_b^2 t
    live = sigma_b > 0
    var_end = b[:, -1, live].var(axis=0)
    np.testing.assert_allclose(var_end, sigma_b[live] ** 2 * (n_t - 1) * dt, rtol=5 * np.sqrt(2 / n_traj))


def test_channels_and_states_contract():
    assert len(sensors.CHANNEL_NAMES) == len(sensors.CHANNEL_UNITS) == 23
    assert len(sensors.STATE_NAMES) == len(sensors.STATE_UNITS) == 19
    states = RNG.normal(size=(2, 3, 19))
    thr = RNG.uniform(size=(2, 3, 4))
    C = sensors.truth_channels(states, thr)
    for j, name in enumerate(sensors.CHANNEL_NAMES):
        if name.startswith("thr"):
            np.testing.assert_array_equal(C[..., j], thr[..., int(name[3]) - 1])
        else:
            np.testing.assert_array_equal(C[..., j], states[..., sensors.STATE_NAMES.index(name)])
