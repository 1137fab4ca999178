"""Airframe classes of the fleet suite: the 450 mm class it trains on and two held-out sizes.

A class is the realistic suite's vehicle draw (sim.variability) scaled by ``size`` = prop radius /
the 450 class's 10-inch prop = arm / 0.225 m (props fill the same share of the frame in every
class: 5" on a 250, 10" on a 450, 14-15" on a 650). docs/params.md ("Airframe classes") gives the
laws and their sources; in short:

- mass x size^2: the same disc loading (take-off weight per rotor disc area) in every class;
- pack: same cell count rule per class (4S on a 250, 6S on a 650), capacity from the same pack mass
  share and 150 Wh/kg, so the C-rate and the flight time stay those of the 450 class;
- propulsion: F_max from the same thrust-to-weight draw; induced power P = F^1.5 / sqrt(2 rho A)
  gives c_P x 1/size, the rotor drag torque per newton gamma x size (C_Q/C_T R of similar props);
- inertia: point masses on the arms (sim.realistic_dynamics.vehicle), so J x mass arm^2 = size^4;
- CG offset x size; motor + ESC lag x sqrt(size) (Froude similarity: times ~ sqrt(length / g));
- motor thermal node (sim.thermal): heat capacity, cooling h and the fault heat x size^2 (motor mass
  and surface ~ its power at equal specific power), the loss terms scaled so that copper and
  mechanical losses stay the same share of the rotor power: c_F x size^-2 (F^2 ~ size^4),
  R_w x size^-2 (cells / 4)^2 (I ~ size^2 / cells); so a healthy motor runs as warm as a 450's;
- rate loop: PX4's rate gains act on normalised torque; a tuned vehicle of the class holds its
  rate-loop crossover at the Froude-scaled frequency (x size^-1/2, the same phase margin against its
  own motor lag). With the plant gain torque / J ~ size^-2 (roll, pitch) and size^-1 (yaw: gamma ~
  size), the controller's output is scaled by size^1.5 (roll, pitch) and size^0.5 (yaw).
"""

from __future__ import annotations

import math

from quadfdi.sim import realistic_params as P

# (name, arm [m], pack cells, frame (1 = X)); class 0 is the realistic suite's draw unchanged
AIRFRAME_CLASSES = (("450", P.ARM_M, None, None), ("250", 0.125, 4, 1), ("650", 0.325, 6, 1))
CLASS_OF_GROUP = {5: 1, 6: 2}  # test groups of the held-out sizes -> airframe class
MOTOR_CELLS_450 = 4  # the pack the 450 class's motor model (R_w) stands for: the middle of its 3S-5S


def scale_vehicle(v: dict, cls: int) -> dict:
    """The realistic vehicle draw ``v`` (sim.variability._vehicle) rebuilt as airframe class ``cls``."""
    if cls == 0:
        return dict(v, size=1.0, airframe_class=0, motor_heat=1.0, motor_c_F=1.0, motor_R_w=1.0)
    _, arm, cells, frame = AIRFRAME_CLASSES[cls]
    size = arm / P.ARM_M
    mass = v["mass"] * size * size
    return dict(v, size=size, airframe_class=cls, arm=arm, frame=frame, cells=cells, mass=mass,
                capacity=v["capacity"] * (mass / v["mass"]) * (v["cells"] / cells), cg=v["cg"] * size,
                motor_tau=v["motor_tau"] * math.sqrt(size), motor_heat=size * size, motor_c_F=size ** -2,
                motor_R_w=size ** -2 * (cells / MOTOR_CELLS_450) ** 2)


def payload_range(size: float) -> tuple[float, float]:
    """Take-off mass range of a class (the payload stays inside it)."""
    return P.MASS_KG[0] * size * size, P.MASS_KG[1] * size * size
