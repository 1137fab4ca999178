"""Wind of the realistic suite: mean wind + Dryden turbulence + discrete (1 - cos) gusts.

Dryden turbulence, MIL-F-8785C low-altitude model (h < 1000 ft, lengths in feet inside):

    L_w = h,  L_u = L_v = h / (0.177 + 0.000823 h)^1.2,  sigma_w = 0.1 W_20,
    sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4,
    Phi_u(w) = sigma_u^2 (2 L_u / (pi V)) / (1 + (L_u w / V)^2)
    Phi_v(w) = sigma_v^2 (L_v / (pi V)) (1 + 3 (L_v w / V)^2) / (1 + (L_v w / V)^2)^2   (w: the same form)

one-sided PSDs over the temporal frequency w [rad/s], integrating to sigma^2. They are the outputs
of white noise n (one-sided PSD 1/pi) through H_u = sigma_u sqrt(2 tau_u) / (1 + tau_u s) and
H_v = sigma_v sqrt(tau_v) (1 + sqrt(3) tau_v s) / (1 + tau_v s)^2, tau = L / V. The second-order
filter is split as sqrt(3) lag(n) + (1 - sqrt(3)) lag(lag(n)), each lag discretised
z' = phi z + (1 - phi) n_k with phi = exp(-dt / tau) and n_k ~ N(0, 1/dt) (white noise held over a
step): exact variance 1 / (2 tau) at dt << tau, and the Dryden shape below the 100 Hz step
Nyquist. tests/test_realistic_physics.py compares the Welch PSD of this very code with Phi.

V is the airspeed the eddies pass the vehicle at. At hover it is the mean wind (Taylor's frozen
turbulence), and Dryden's tau = L / V diverges as V -> 0, so V = max(W_mean, WIND_V_FLOOR): the
"airspeed floor at hover" (MATLAB's Dryden block and JSBSim floor it the same way). W_20, the wind
at 20 ft, is the drawn mean wind; h is the mission altitude band's middle.

Gusts: 1 - cos shape (MIL-F-8785C discrete gust), w(t) = A/2 (1 - cos(2 pi (t - t_g) / T_g)) inside
[t_g, t_g + T_g], along the mean wind's direction +-30 deg.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from quadfdi.sim.realistic_params import WIND_V_FLOOR

FT = 0.3048
H_REF_M = 19.0  # m: middle of the mission altitude band (sim.mission.ALT_M)


class Dryden(NamedTuple):
    """Per-flight Dryden filter coefficients, all (B,) or (B, 3) float64."""

    phi: np.ndarray  # (B, 3) lag pole of the u, v, w filters
    gain: np.ndarray  # (B, 3) sigma sqrt(2 tau) (u) or sigma sqrt(tau) (v, w)
    sigma: np.ndarray  # (B, 3) m/s, sigma_u, sigma_v, sigma_w
    tau: np.ndarray  # (B, 3) s, L / V


def dryden(w_mean: np.ndarray, dt: float, h_m: float = H_REF_M) -> Dryden:
    """Coefficients for mean winds ``w_mean`` (B,) [m/s] at altitude h_m [m] and step dt [s]."""
    h = h_m / FT
    L_uv = h / (0.177 + 0.000823 * h) ** 1.2 * FT
    L_w = h * FT
    sigma_w = 0.1 * w_mean
    sigma_uv = sigma_w / (0.177 + 0.000823 * h) ** 0.4
    V = np.maximum(w_mean, WIND_V_FLOOR)
    tau = np.stack([L_uv / V, L_uv / V, L_w / V], axis=-1)
    sigma = np.stack([sigma_uv, sigma_uv, sigma_w], axis=-1)
    gain = sigma * np.sqrt(tau * np.array([2.0, 1.0, 1.0]))
    return Dryden(np.exp(-dt / tau), gain, sigma, tau)


def turbulence_step(z: np.ndarray, n: np.ndarray, dr: Dryden, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One step. z (B, 5) filter states [u lag, v lag1, v lag2, w lag1, w lag2]; n (B, 3) standard
    normals. Returns the new z and the turbulence (B, 3) [m/s] in the mean-wind frame (u along it)."""
    w = n * (1.0 / np.sqrt(dt))
    phi, c = dr.phi, 1.0 - dr.phi
    out = np.empty_like(z)
    out[:, 0] = phi[:, 0] * z[:, 0] + c[:, 0] * w[:, 0]
    out[:, 1] = phi[:, 1] * z[:, 1] + c[:, 1] * w[:, 1]
    out[:, 2] = phi[:, 1] * z[:, 2] + c[:, 1] * z[:, 1]
    out[:, 3] = phi[:, 2] * z[:, 3] + c[:, 2] * w[:, 2]
    out[:, 4] = phi[:, 2] * z[:, 4] + c[:, 2] * z[:, 3]
    s3 = np.sqrt(3.0)
    turb = np.stack([out[:, 0], s3 * out[:, 1] + (1 - s3) * out[:, 2], s3 * out[:, 3] + (1 - s3) * out[:, 4]],
                    axis=-1) * dr.gain
    return out, turb


def psd(dr: Dryden, omega: np.ndarray) -> np.ndarray:
    """Dryden one-sided PSDs Phi_u, Phi_v, Phi_w at omega (n,) [rad/s], (B, n, 3) [(m/s)^2 / (rad/s)]."""
    x = dr.tau[:, None, :] * omega[None, :, None]
    s2, tau = dr.sigma[:, None, :] ** 2, dr.tau[:, None, :]
    long = s2 * 2 * tau / np.pi / (1 + x * x)
    lat = s2 * tau / np.pi * (1 + 3 * x * x) / (1 + x * x) ** 2
    return np.concatenate([long[..., :1], lat[..., 1:]], axis=-1)


def to_inertial(turb: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Mean-wind-frame turbulence (..., B, 3) to the inertial frame (u along ``direction`` (B,) rad)."""
    c, s = np.cos(direction), np.sin(direction)
    return np.stack([c * turb[..., 0] - s * turb[..., 1], s * turb[..., 0] + c * turb[..., 1], turb[..., 2]], -1)


def gusts(t: np.ndarray, t_g: np.ndarray, T_g: np.ndarray, A: np.ndarray, dir_g: np.ndarray) -> np.ndarray:
    """Sum of 1 - cos gusts at times t (n,): t_g, T_g, A, dir_g (B, G). Returns (n, B, 3) [m/s]."""
    ph = (t[:, None, None] - t_g[None]) / T_g[None]  # (n, B, G)
    inside = (ph >= 0.0) & (ph <= 1.0)
    mag = np.where(inside, 0.5 * A[None] * (1.0 - np.cos(2 * np.pi * ph)), 0.0)
    return np.stack([(mag * np.cos(dir_g)[None]).sum(-1), (mag * np.sin(dir_g)[None]).sum(-1),
                     np.zeros(mag.shape[:2])], axis=-1)


def markov_step(e: np.ndarray, n: np.ndarray, phi: np.ndarray, q: np.ndarray) -> np.ndarray:
    """First-order Gauss-Markov step e' = phi e + q n (stationary std q / sqrt(1 - phi^2)); the
    state-estimate errors of sim/realistic_dynamics.py."""
    return phi * e + q * n
