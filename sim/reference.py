"""Smooth random flight references: per trajectory, sums of sinusoids per axis and a slow yaw.

    p_ref,j(t) = c_j + sum_k A_jk sin(w_jk t + phi_jk),   j in {x, y, z},  k = 1..N_SINES
    psi_ref(t) = psi_0 + A_psi sin(w_psi t + phi_psi)

with analytic velocity and acceleration (the controller's feed-forward). Frequencies are
0.03-0.2 Hz; the amplitudes of an axis sum to a random total (<= 2 m horizontal, <= 0.5 m
vertical) and are scaled down if the reference's peak acceleration bound sum A w^2 would exceed
REF_ACC_MAX (that keeps the commanded tilt near 10 deg, well inside the 23 deg limit). The yaw
stays within (-pi, pi) (|psi_0| <= pi/2, A_psi <= 0.5 rad), so the yaw channel never wraps.

``draw(rng)`` draws one trajectory's reference parameters (its part of the fixed draw order);
``prepare(refs)`` stacks a batch of them; ``evaluate(ref, t)`` evaluates the batch at time t
with elementwise numpy only.
"""

from __future__ import annotations

import numpy as np

N_SINES = 3
REF_FREQ_HZ = (0.03, 0.2)  # Hz: slow survey-like manoeuvres
REF_AMP_XY_M = (0.5, 2.0)  # m: total horizontal amplitude per axis
REF_AMP_Z_M = (0.1, 0.5)  # m: total altitude amplitude around the hover altitude
REF_CENTRE_XY_M = (-3.0, 3.0)  # m: where the pattern is centred in the local frame
REF_ALT_M = (5.0, 15.0)  # m: hover altitude (z up), out of ground effect
REF_ACC_MAX = (1.5, 1.5, 0.6)  # m/s^2: bound on sum A w^2 per axis (x, y, z)
REF_YAW0_RAD = (-np.pi / 2, np.pi / 2)  # rad: mean heading
REF_YAW_AMP_RAD = (0.0, 0.5)  # rad: heading swing
REF_YAW_FREQ_HZ = (0.02, 0.06)  # Hz: slow heading changes (<= 0.19 rad/s)


def draw(rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One trajectory's reference parameters, drawn in a fixed order from ``rng``.

    Returns amp, omega, phase (3, N_SINES) [m, rad/s, rad]; centre (3,) [m];
    yaw (4,) = (psi_0 [rad], A_psi [rad], w_psi [rad/s], phi_psi [rad]).
    """
    freq = rng.uniform(*REF_FREQ_HZ, size=(3, N_SINES))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, N_SINES))
    weight = rng.uniform(0.2, 1.0, size=(3, N_SINES))
    total_xy = rng.uniform(*REF_AMP_XY_M, size=2)
    total_z = rng.uniform(*REF_AMP_Z_M)
    centre_xy = rng.uniform(*REF_CENTRE_XY_M, size=2)
    alt = rng.uniform(*REF_ALT_M)
    yaw0 = rng.uniform(*REF_YAW0_RAD)
    yaw_amp = rng.uniform(*REF_YAW_AMP_RAD)
    yaw_freq = rng.uniform(*REF_YAW_FREQ_HZ)
    yaw_phase = rng.uniform(0.0, 2.0 * np.pi)

    omega = 2.0 * np.pi * freq
    amp = weight / weight.sum(axis=1, keepdims=True) * np.array([total_xy[0], total_xy[1], total_z])[:, None]
    acc_bound = (amp * omega**2).sum(axis=1)  # (3,) peak |a_ref| bound per axis
    amp = amp * np.minimum(1.0, np.array(REF_ACC_MAX) / acc_bound)[:, None]
    return {
        "amp": amp,
        "omega": omega,
        "phase": phase,
        "centre": np.array([centre_xy[0], centre_xy[1], alt]),
        "yaw": np.array([yaw0, yaw_amp, 2.0 * np.pi * yaw_freq, yaw_phase]),
    }


def prepare(refs: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Stack per-trajectory ``draw`` outputs into a batch (leading axis) and precompute the
    velocity and acceleration amplitudes A w and -A w^2 used by ``evaluate``."""
    ref = {k: np.stack([r[k] for r in refs]) for k in refs[0]}
    ref["amp_w"] = ref["amp"] * ref["omega"]  # (batch, 3, K) m/s
    ref["amp_w2"] = -(ref["amp_w"] * ref["omega"])  # (batch, 3, K) m/s^2
    return ref


def evaluate(ref: dict[str, np.ndarray], t: float | np.ndarray) -> tuple[np.ndarray, ...]:
    """Reference at time t for a batch.

    ref: ``prepare`` output (amp, omega, phase, amp_w, amp_w2 (batch, 3, N_SINES);
    centre (batch, 3); yaw (batch, 4)). t: a time [s], or a 1-D array of n times (then every
    output gets a leading (n,) axis: one call for a block of steps).
    Returns p (batch, 3) [m], v (batch, 3) [m/s], a (batch, 3) [m/s^2], psi (batch,) [rad],
    psi_dot (batch,) [rad/s].
    """
    tt = np.asarray(t, dtype=np.float64)
    ph = ref["omega"] * tt[..., None, None, None] + ref["phase"]  # ([n,] batch, 3, K)
    s, c = np.sin(ph), np.cos(ph)
    p = ref["centre"] + _sum_k(ref["amp"] * s)
    v = _sum_k(ref["amp_w"] * c)
    a = _sum_k(ref["amp_w2"] * s)
    yaw = ref["yaw"]
    yph = yaw[:, 2] * tt[..., None] + yaw[:, 3]  # ([n,] batch)
    psi = yaw[:, 0] + yaw[:, 1] * np.sin(yph)
    psi_dot = (yaw[:, 1] * yaw[:, 2]) * np.cos(yph)
    return p, v, a, psi, psi_dot


def _sum_k(x: np.ndarray) -> np.ndarray:
    """Sum over the sine axis written out: a fixed addition order per trajectory."""
    out = x[..., 0]
    for k in range(1, x.shape[-1]):
        out = out + x[..., k]
    return out
