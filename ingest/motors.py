"""Motor geometry, the map to the project's motor order, and command normalisation.

Project order (docs/params.md, sim/rigid_body.py Eq. 3, z up): rotor 1 on +x, 2 on +y, 3 on -x,
4 on -y, i.e. counter-clockwise seen from above; Eq. 3's yaw row gamma(F1 - F2 + F3 - F4) makes
rotors 1 and 3 the clockwise ones (their drag torque yaws the body +z). A real quad's motors are
put in that order by walking counter-clockwise (in FLU) from the first clockwise motor at or after
+x. For an X frame this is a 45 deg turn of the numbering, not of the body: rates and attitude stay
in the real body frame.

Motor commands become the simulator's ``thr`` = thrust command / full thrust, in [0, 1]:
PX4 actuator_motors already is that. PWM (actuator_outputs, RCOU) first becomes the actuator
fraction a = (pwm - min) / (max - min), then thrust through the autopilot's own thrust curve
thr = (1 - k) a + k a^2 (PX4 THR_MDL_FAC, ArduCopter MOT_THST_EXPO: the curve each firmware inverts).
"""

from __future__ import annotations

import numpy as np

from quadfdi.core.errors import QuadfdiError

# (x forward, y right) in FRD, spin seen from above (+1 CCW, -1 CW), for motor 1..4.
QUAD_X = ((1.0, 1.0, +1), (-1.0, -1.0, +1), (1.0, -1.0, -1), (-1.0, 1.0, -1))  # PX4 4001, ArduCopter X
QUAD_PLUS_PX4 = ((0.0, 1.0, +1), (0.0, -1.0, +1), (1.0, 0.0, -1), (-1.0, 0.0, -1))  # PX4 5001
QUAD_PLUS_AP = QUAD_PLUS_PX4  # ArduCopter FRAME_TYPE 0: motor 1 right, 2 left (CCW), 3 front, 4 back (CW)


def px4_geometry(params: dict) -> tuple[tuple, str]:
    """Rotor (x, y, spin) list from CA_ROTORn_* (PX4 >= 1.13), else from the airframe number."""
    n = int(params.get("CA_ROTOR_COUNT", 0) or 0)
    if n > 0 and "CA_ROTOR0_PX" in params:
        rotors = tuple((float(params[f"CA_ROTOR{i}_PX"]), float(params[f"CA_ROTOR{i}_PY"]),
                        1 if float(params.get(f"CA_ROTOR{i}_KM", 0.05)) > 0 else -1) for i in range(n))
        return rotors, f"CA_ROTOR0..{n - 1}_PX/PY/KM"
    sa = int(params.get("SYS_AUTOSTART", 0) or 0)
    if 4000 <= sa < 5000:
        return QUAD_X, f"airframe SYS_AUTOSTART={sa} (quad X family, PX4 motor numbering)"
    if 5000 <= sa < 6000:
        return QUAD_PLUS_PX4, f"airframe SYS_AUTOSTART={sa} (quad + family)"
    raise QuadfdiError(f"motor geometry unknown: no CA_ROTOR parameters and airframe SYS_AUTOSTART={sa} is not a quad")


def ardupilot_geometry(params: dict) -> tuple[tuple, str]:
    """Rotor list of ArduCopter FRAME_CLASS 1 (quad) with FRAME_TYPE 0 (+) or 1 (X)."""
    fc, ft = int(params.get("FRAME_CLASS", -1)), int(params.get("FRAME_TYPE", -1))
    if fc != 1:
        raise QuadfdiError(f"not a quadrotor: FRAME_CLASS={fc} (1 = quad)")
    if ft == 1:
        return QUAD_X, "FRAME_CLASS=1 FRAME_TYPE=1 (quad X)"
    if ft == 0:
        return QUAD_PLUS_AP, "FRAME_CLASS=1 FRAME_TYPE=0 (quad +)"
    raise QuadfdiError(f"quad FRAME_TYPE={ft} is not supported (only 0 = +, 1 = X)")


def motor_map(rotors: tuple) -> list[int]:
    """Log motor index (0-based) for project rotor 1..4; one-line error if not a 4-rotor alternating quad."""
    if len(rotors) != 4:
        raise QuadfdiError(f"not a quadrotor: the log's geometry has {len(rotors)} rotors")
    ang = [float(np.degrees(np.arctan2(-y, x))) % 360.0 for x, y, _ in rotors]  # FRD -> FLU angle
    order = sorted(range(4), key=lambda i: ang[i])
    spins = [rotors[i][2] for i in order]
    if any(spins[k] == spins[(k + 1) % 4] for k in range(4)):
        raise QuadfdiError("motor geometry is not an alternating-spin quad: cannot map to the project's order")
    first = next(k for k in range(4) if spins[k] < 0)  # smallest angle among clockwise motors
    return [order[(first + k) % 4] for k in range(4)]


def pwm_to_thrust(pwm: np.ndarray, pwm_min: float, pwm_max: float, expo: float) -> tuple[np.ndarray, int]:
    """Thrust fraction of PWM commands and how many samples were below pwm_min (clipped to 0)."""
    a = (np.asarray(pwm, dtype=np.float64) - pwm_min) / (pwm_max - pwm_min)
    below = int(np.sum(a < 0))
    a = np.clip(a, 0.0, 1.0)
    return (1.0 - expo) * a + expo * a * a, below
