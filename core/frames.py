"""Frames: PX4 and ArduPilot log NED (inertial) and FRD (body); the simulator uses z up.

The simulator (sim/rigid_body.py) has an inertial frame with z up and a body frame with z along the
thrust, ZYX Euler angles. Its x axis has no geographic meaning, so we take the one rotation that
maps both log frames at once: 180 deg about x, i.e. NED -> NWU (x north, y west, z up) and
FRD -> FLU. With the same rotation on both sides, R_nwu_flu = Rx(pi) R_ned_frd Rx(pi), whose ZYX
angles are (roll, -pitch, -yaw): no re-derivation of the attitude is needed.
"""

from __future__ import annotations

import numpy as np


def ned_to_sim(n: np.ndarray, e: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A NED vector (position, velocity) in the simulator's z-up frame (NWU)."""
    return n, -e, -d


def frd_to_sim(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A body FRD vector (body rates) in the simulator's body frame (FLU)."""
    return x, -y, -z


def euler_ned_to_sim(roll, pitch, yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX Euler angles of R_ned_frd -> those of R_nwu_flu (see the module docstring)."""
    return roll, -np.asarray(pitch), wrap(-np.asarray(yaw))


def quat_to_euler(q0, q1, q2, q3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ZYX (roll, pitch, yaw) in rad of a unit quaternion (w, x, y, z), as PX4's Eulerf does."""
    roll = np.arctan2(2.0 * (q0 * q1 + q2 * q3), 1.0 - 2.0 * (q1 * q1 + q2 * q2))
    pitch = np.arcsin(np.clip(2.0 * (q0 * q2 - q3 * q1), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (q0 * q3 + q1 * q2), 1.0 - 2.0 * (q2 * q2 + q3 * q3))
    return roll, pitch, yaw


def wrap(a: np.ndarray) -> np.ndarray:
    """Angle to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi
