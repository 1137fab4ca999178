"""Rigid-body dynamics (paper Eq. 2) and the static mixer / body moments (Eq. 3).

Frames: inertial I with z up (gravity is -g e3), body B with z along the thrust. Attitude by
ZYX Euler angles eta = (phi, theta, psi): R_B^I = Rz(psi) Ry(theta) Rx(phi); E(eta) maps the
body rates omega_B to eta-dot (singular at theta = +-90 deg, far outside the flown envelope).

Rigid-body state layout, (batch, 12): p (0:3) [m], v (3:6) [m/s], eta (6:9) [rad],
omega_B (9:12) [rad/s]. Every function is vectorised over the leading batch axis and uses
only elementwise numpy (no matmul/BLAS), so a trajectory's numbers do not depend on which other
trajectories share its batch (shard regeneration is bitwise).
"""

from __future__ import annotations

import numpy as np

from quadfdi.sim.params import VehicleParams

N_RB = 12  # rigid-body state size


def rot_x(phi: np.ndarray) -> np.ndarray:
    """Elementary rotation about x, (batch,) -> (batch, 3, 3)."""
    c, s = np.cos(phi), np.sin(phi)
    o, z = np.ones_like(phi), np.zeros_like(phi)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(theta: np.ndarray) -> np.ndarray:
    """Elementary rotation about y, (batch,) -> (batch, 3, 3)."""
    c, s = np.cos(theta), np.sin(theta)
    o, z = np.ones_like(theta), np.zeros_like(theta)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(psi: np.ndarray) -> np.ndarray:
    """Elementary rotation about z, (batch,) -> (batch, 3, 3)."""
    c, s = np.cos(psi), np.sin(psi)
    o, z = np.ones_like(psi), np.zeros_like(psi)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def rotation(eta: np.ndarray) -> np.ndarray:
    """R_B^I(eta) = Rz(psi) Ry(theta) Rx(phi), eta (batch, 3) -> (batch, 3, 3). Reference form
    (the physics tests check ``deriv`` against it); ``deriv`` uses only its third column, written out."""
    return rot_z(eta[:, 2]) @ rot_y(eta[:, 1]) @ rot_x(eta[:, 0])


def euler_rate_matrix(eta: np.ndarray) -> np.ndarray:
    """E(eta) of Eq. (2): eta_dot = E(eta) omega_B. eta (batch, 3) -> (batch, 3, 3)."""
    sp, cp = np.sin(eta[:, 0]), np.cos(eta[:, 0])
    tt, ct = np.tan(eta[:, 1]), np.cos(eta[:, 1])
    o, z = np.ones_like(sp), np.zeros_like(sp)
    return np.stack(
        [np.stack([o, sp * tt, cp * tt], -1), np.stack([z, cp, -sp], -1), np.stack([z, sp / ct, cp / ct], -1)], -2
    )


def mixer(T: np.ndarray, tau: np.ndarray, vp: VehicleParams) -> np.ndarray:
    """Eq. (3): rotor thrusts from collective T (batch,) [N] and torques tau (batch, 3) [N m]
    (roll, pitch, yaw). Returns (batch, 4) [N], unclipped."""
    base = 0.25 * T  # (batch,)
    r = tau[:, 0] / (2.0 * vp.L)
    p = tau[:, 1] / (2.0 * vp.L)
    y = tau[:, 2] / (4.0 * vp.gamma)
    return np.stack([base - p + y, base + r - y, base + p + y, base - r - y], axis=-1)


def moments(F: np.ndarray, vp: VehicleParams) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (3): total thrust (batch,) [N] and body moments M_B (batch, 3) [N m] of thrusts F (batch, 4)."""
    T, Mx, My, Mz = _moments(F, vp)
    return T, np.stack([Mx, My, Mz], axis=-1)


def _moments(F: np.ndarray, vp: VehicleParams) -> tuple[np.ndarray, ...]:
    F1, F2, F3, F4 = F[:, 0], F[:, 1], F[:, 2], F[:, 3]
    return (F1 + F2) + (F3 + F4), vp.L * (F2 - F4), vp.L * (F3 - F1), vp.gamma * ((F1 - F2) + (F3 - F4))


def deriv(x: np.ndarray, F: np.ndarray, vp: VehicleParams, out: np.ndarray | None = None) -> np.ndarray:
    """Eq. (2): time derivative of the rigid-body state.

    x: (batch, 12) state [p, v, eta, omega_B] (extra trailing columns are ignored);
    F: (batch, 4) actuated rotor thrusts [N]; out: optional (batch, 12) array to write into.
    Returns (batch, 12).
    """
    return _deriv(x, *_moments(F, vp), vp, out)


def _deriv(x: np.ndarray, T: np.ndarray, Mx: np.ndarray, My: np.ndarray, Mz: np.ndarray, vp: VehicleParams,
           out: np.ndarray | None) -> np.ndarray:
    if out is None:
        out = np.empty((x.shape[0], N_RB))
    sn = np.sin(x[:, 6:9])  # (batch, 3) sin(phi, theta, psi)
    cn = np.cos(x[:, 6:9])
    sp, st, ss = sn[:, 0], sn[:, 1], sn[:, 2]
    cp, ct, cs = cn[:, 0], cn[:, 1], cn[:, 2]
    p, q, r = x[:, 9], x[:, 10], x[:, 11]

    out[:, 0:3] = x[:, 3:6]  # p_dot = v
    # m v_dot = R e3 T - m g e3 - k_L v; R e3 = third column of Rz Ry Rx
    a_t = T * (1.0 / vp.m)  # (batch,)
    kl = vp.k_L / vp.m
    cp_st = cp * st
    out[:, 3] = a_t * (cs * cp_st + ss * sp) - kl * x[:, 3]
    out[:, 4] = a_t * (ss * cp_st - cs * sp) - kl * x[:, 4]
    out[:, 5] = a_t * (ct * cp) - (vp.g + kl * x[:, 5])

    # eta_dot = E(eta) omega_B
    qs_rc = q * sp + r * cp
    inv_ct = 1.0 / ct
    out[:, 6] = p + qs_rc * (st * inv_ct)
    out[:, 7] = q * cp - r * sp
    out[:, 8] = qs_rc * inv_ct

    # J omega_dot = M - omega x (J omega) - k_Omega omega, J diagonal
    ko = vp.k_Omega
    out[:, 9] = (Mx - (vp.Jzz - vp.Jyy) * (q * r) - ko * p) * (1.0 / vp.Jxx)
    out[:, 10] = (My - (vp.Jxx - vp.Jzz) * (r * p) - ko * q) * (1.0 / vp.Jyy)
    out[:, 11] = (Mz - (vp.Jyy - vp.Jxx) * (p * q) - ko * r) * (1.0 / vp.Jzz)
    return out
