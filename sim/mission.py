"""Mission references of the realistic suite: hover, waypoint legs, aggressive segments, yaw turns.

A mission is a chain of ``N_SEG`` segments; segment k moves the position setpoint by dP_k and the
heading by dpsi_k over D_k seconds along a minimum-jerk profile s(tau) = 10 tau^3 - 15 tau^4 +
6 tau^5 (zero velocity and acceleration at both ends; Flash & Hogan 1985, the usual smooth
waypoint profile), so p, v and a are analytic (the controller's feed-forward). Peak values of
min-jerk: v = 1.875 dP / D, a = 5.774 dP / D^2, which is how the segment sizes are chosen:

- hover (type 0):      hovers of 5-15 s and 0.5-2 m repositionings;
- survey (type 1):     10-30 m waypoint legs at 2-5 m/s peak, 2-5 s hovers between, heading along the leg;
- aggressive (type 2): dashes at 20-35 deg of tilt (a = g tan(tilt)), 2-3 m/s climbs and
                       descents, 90-180 deg yaw turns at 1-1.5 rad/s peak, short hovers;
- inspection (type 3, held out): slow 1-2 m/s vertical scans of 5-10 m, 2-4 m side steps,
                       +-45 deg heading sweeps, long hovers (a structure inspection).

``draw(rng, kind)`` draws one flight's segments; ``prepare`` stacks a batch; ``evaluate(m, t)``
evaluates it at a block of times with elementwise numpy (same outputs as ``sim.reference.evaluate``).
"""

from __future__ import annotations

import numpy as np

N_SEG = 40  # segments drawn per flight (enough for the longest flight of the suite)
MISSION_TYPES = ("hover", "survey", "aggressive", "inspection")
TRAIN_TYPES = (0, 1, 2)  # the held-out type is inspection
G = 9.81
ALT_M = (8.0, 30.0)  # m: mission altitude band (z up); a step that would leave it flips sign


def _segment(rng: np.random.Generator, kind: int) -> tuple[np.ndarray, float, float]:
    """One segment (dP (3,), dpsi, D); always 8 draws, so every segment uses the same amount of rng."""
    u = rng.uniform(size=8)
    heading = 2 * np.pi * u[0]
    hor = np.array([np.cos(heading), np.sin(heading), 0.0])
    sgn = 1.0 if u[7] < 0.5 else -1.0
    if kind == 0:
        if u[1] < 0.5:
            return np.zeros(3), 0.0, 5.0 + 10.0 * u[2]
        D = 3.0 + 3.0 * u[3]
        return hor * (0.5 + 1.5 * u[4]) + np.array([0, 0, sgn * 0.5 * u[5]]), sgn * 0.3 * u[6], D
    if kind == 1:
        if u[1] < 0.35:
            return np.zeros(3), 0.0, 2.0 + 3.0 * u[2]
        dist, v = 10.0 + 20.0 * u[3], 2.0 + 3.0 * u[4]
        return hor * dist, sgn * np.pi * u[6] / 2, 1.875 * dist / v
    if kind == 2:
        pick = u[1]
        if pick < 0.15:
            return np.zeros(3), 0.0, 1.0 + 2.0 * u[2]
        if pick < 0.55:  # dash: peak tilt 20-35 deg
            D = 2.0 + 2.0 * u[3]
            acc = G * np.tan(np.radians(20.0 + 15.0 * u[4]))
            return hor * acc * D * D / 5.774, 0.0, D
        if pick < 0.8:  # climb / descent at 2-3 m/s peak
            D, v = 3.0 + 2.0 * u[3], 2.0 + 1.0 * u[4]
            return np.array([0.0, 0.0, sgn * v * D / 1.875]), 0.0, D
        dpsi = sgn * np.radians(90.0 + 90.0 * u[5])  # yaw turn, peak rate 1.875 dpsi / D
        return np.zeros(3), dpsi, 1.875 * abs(dpsi) / (1.0 + 0.5 * u[6])
    # inspection
    pick = u[1]
    if pick < 0.3:
        return np.zeros(3), 0.0, 5.0 + 10.0 * u[2]
    if pick < 0.65:
        dz, v = 5.0 + 5.0 * u[3], 1.0 + u[4]
        return np.array([0.0, 0.0, sgn * dz]), 0.0, 1.875 * dz / v
    if pick < 0.85:
        return hor * (2.0 + 2.0 * u[3]), 0.0, 4.0 + 2.0 * u[4]
    return np.zeros(3), sgn * np.radians(45.0), 4.0 + 2.0 * u[5]


def draw(rng: np.random.Generator, kind: int) -> dict[str, np.ndarray]:
    """One flight's mission of type ``kind``: start (3,), psi0, and per segment t0, D, P0, dP, psi0, dpsi."""
    start = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(*ALT_M)])
    psi = rng.uniform(-np.pi, np.pi)
    t0, D, S0, dS = np.empty(N_SEG), np.empty(N_SEG), np.empty(N_SEG), np.empty(N_SEG)
    P0, dP = np.empty((N_SEG, 3)), np.empty((N_SEG, 3))
    p, t = start.copy(), 0.0
    for k in range(N_SEG):
        d, dpsi, dur = _segment(rng, kind)
        if kind == 1 and np.any(d[:2]):  # survey: fly heading along the leg (a turn on the spot first)
            dpsi = np.arctan2(d[1], d[0]) - psi
            dpsi = dpsi - 2 * np.pi * np.round(dpsi / (2 * np.pi))
        if not ALT_M[0] <= p[2] + d[2] <= ALT_M[1]:
            d[2] = -d[2]
        t0[k], D[k], P0[k], dP[k], S0[k], dS[k] = t, dur, p, d, psi, dpsi
        p, psi, t = p + d, psi + dpsi, t + dur
    return {"t0": t0, "D": D, "P0": P0, "dP": dP, "S0": S0, "dS": dS, "kind": np.array(kind)}


def prepare(ms: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Stack per-flight missions on a leading batch axis."""
    return {k: np.stack([m[k] for m in ms]) for k in ms[0]}


def _minjerk(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t2 = tau * tau
    s = t2 * tau * (10.0 + tau * (-15.0 + 6.0 * tau))
    ds = t2 * (30.0 + tau * (-60.0 + 30.0 * tau))
    dds = tau * (60.0 + tau * (-180.0 + 120.0 * tau))
    return s, ds, dds


def evaluate(m: dict[str, np.ndarray], t: np.ndarray) -> tuple[np.ndarray, ...]:
    """References at times t (n,) for the batch: p, v, a (n, B, 3), psi, psi_dot (n, B).

    Past the last segment the vehicle holds its last setpoint."""
    t = np.asarray(t, dtype=np.float64)
    B = m["t0"].shape[0]
    k = np.maximum((t[:, None, None] >= m["t0"][None]).sum(axis=-1) - 1, 0)  # (n, B) active segment
    b = np.arange(B)[None, :]
    t0, D = m["t0"][b, k], m["D"][b, k]
    tau = np.clip((t[:, None] - t0) / D, 0.0, 1.0)
    s, ds, dds = _minjerk(tau)
    dP = m["dP"][b, k]  # (n, B, 3)
    p = m["P0"][b, k] + dP * s[..., None]
    v = dP * (ds / D)[..., None]
    a = dP * (dds / (D * D))[..., None]
    dS = m["dS"][b, k]
    psi = m["S0"][b, k] + dS * s
    psi_dot = dS * ds / D
    return p, v, a, psi, psi_dot


def manoeuvre_starts(m: dict[str, np.ndarray]) -> np.ndarray:
    """Start times of the segments that move (position or heading), (B, N_SEG); NaN for hovers."""
    moving = (np.abs(m["dP"]).sum(axis=-1) > 0) | (m["dS"] != 0)
    return np.where(moving, m["t0"], np.nan)
