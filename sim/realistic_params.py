"""Ranges and constants of the realistic scenario suite (``sim.scenario = "realistic"``).

Every range below is drawn per flight by ``sim.variability``; docs/params.md ("Realistic suite")
tables each with its physical source. The controller flies every vehicle with ``NOMINAL``: the
paper's f450_3s values plus the few gains a wider envelope needs; it never sees the drawn truth.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from quadfdi.sim.params import get_vehicle

# --- the controller's (nominal) vehicle -------------------------------------------------------
# Tilt limit 40 deg: the aggressive segments fly 20-35 deg (PX4 MPC_TILTMAX_AIR defaults to 45).
# Altitude integrator clamp 8 m/s^2: it stands in for PX4's hover-thrust estimator (MPC_USE_HTE),
# which learns a 2.2 kg vehicle's hover thrust (g * (2.2/1.5 - 1) = 4.6 m/s^2 above nominal) plus sag.
# Rate P 18/s: with 20-40 ms of motor lag, 25/s left < 35 deg of phase margin (PX4 tunes P down with lag).
# Thermal fault and derating for 75 s flights (the paper's 16 s never got there): with a_Q = 30 W,
# lambda_T = 0.02 and d_min = 0.3, an overheat fault ran away to 110-136 degC and the derated motor
# (30 %) tipped 13 of 784 flights over. Here a_Q = 15 W (a seizing bearing, half the paper's) and
# the ESC's thermal foldback takes 1 % per degC above T_der down to 60 % (BLHeli_32-style
# temperature protection reduces power in steps to ~50-75 %, it does not stop the motor).
# The controller does not use these fields; the realistic physics does (sim/realistic_dynamics.py).
NOMINAL = dataclasses.replace(get_vehicle("f450_3s"), name="f450_nominal", tilt_max=0.70, iz_max=8.0,
                              k_rate_rp=18.0, irate_max_rp=80.0, a_Q=15.0, lambda_T=0.01, d_min=0.6)

# --- vehicle variability (per flight) ---------------------------------------------------------
MASS_KG = (1.0, 2.2)  # total take-off mass: bare 450-class frame with a small pack .. a 6S 8 Ah pack + camera
PAYLOAD_P = 0.3  # share of flights that drop or pick up a payload mid-flight
PAYLOAD_KG = (-0.3, 0.3)  # a parcel / sampler; the result stays inside MASS_KG
PAYLOAD_T_FRAC = (0.2, 0.8)  # when, as a fraction of the flight
CG_OFFSET_M = 0.025  # +- per horizontal axis: a pack strapped 2.5 cm off centre, a side-mounted camera
KF_SPREAD = 0.05  # +-: per-motor thrust coefficient (motor KV and prop pitch tolerances, ~ +-5 %)
COOL_SPREAD = 0.20  # +-: per-motor cooling h (bell vents, arm position in the wash)
FRAMES = ("plus", "x")  # 450 mm motor-to-motor; rotor i of "x" sits 45 deg after rotor i of "plus"
ARM_M = 0.225  # m: both in-distribution frames
OOD_ARM_M = 0.25  # m: the held-out vehicle's 500 mm X frame
CELLS = (3, 4, 5)  # in-distribution packs; the held-out vehicle flies 6S
OOD_CELLS = 6
# The build is matched to its weight, as builders do: propulsion for a thrust-to-weight ratio of
# 1.9-2.6 at the pack's nominal voltage (the usual "at least 2:1" rule), and a pack of 20-35 % of the
# take-off mass at 150 Wh/kg (LiPo pack level), so capacity = share m 150 / (3.7 cells).
# Independent draws gave 2.1 kg vehicles on 3 Ah 3S packs: 10 of 784 flights sank to the ground.
THRUST_TO_WEIGHT = (1.9, 2.6)
PACK_MASS_SHARE = (0.20, 0.35)
PACK_WH_PER_KG = 150.0
AGE = (0.0, 1.0)  # 0 = new pack, 1 = end of life (80 % capacity, 2x resistance: IEC 61960 end-of-life)
AGE_FADE = 0.20  # capacity fraction lost at age 1
AGE_R_GROWTH = 1.0  # resistance growth at age 1 (x2)
R_CELL_5AH = 0.005  # Ohm per cell of a new 5 Ah 25C pack (scales as 1 / capacity)
R_LEADS = 0.008  # Ohm: XT60, leads, PDB, shunt
# SoC at boot (= t 0; the take-off is not simulated). A healthy flight may start anywhere above PX4's
# low-battery warning (BAT_LOW_THR default 0.15; BAT_CRIT_THR 0.07, src/lib/battery/battery_params.c):
# 0.2-1.0. The earlier 0.6-1.0 put a healthy 6S pack at 3.60 V/cell (the GPS-interference flight) at
# z = -2.1 against the suite's training flights (docs/params.md "Boot SoC").
SOC_BOOT = (0.20, 1.0)
T_AMB_C = (0.0, 40.0)  # winter to desert summer
MOTOR_TAU_S = (0.020, 0.040)  # motor + ESC first-order thrust lag (2212-class motors, 10" props)
# Healthy broadband accel vibration at the IMU per axis, in hover, drawn log-uniform: 2-15 m/s^2 puts
# PX4's metric at 2.2-16 m/s^2 (sqrt(6/5) x the floor, sim/propeller.py). The real healthy-rotor quads
# in ../shared/data/flightlogs hover at 4.6 (6S, GPS interference), 5.0 (FMU-v5 hop), 9.8 (battery
# monitor disconnected) and 14.8 m/s^2 (6S UAVCAN mission) by that metric (docs/params.md "Vibration
# floor"); the earlier 1-4 m/s^2 (metric 1.1-4.4) covered none of the large 6S quads.
VIB_FLOOR = (2.0, 15.0)
IMBALANCE_G = (0.0, 0.05)  # g at 0.1 m: residual imbalance of a healthy balanced prop

# --- forward-flight rotor moment (sim/realistic_dynamics.py) -----------------------------------
# In translation each rotor's disc flaps back and the trailing rotors fly in the leading ones'
# wake: the airframe feels a moment that lifts its leading side, M = -D T (e_z x v_air) in the body
# frame, and the attitude loop answers by running the trailing rotors harder. Drawn as the trailing
# rotors' thrust-share excess per m/s of airspeed on an X frame (D = that x arm / sqrt 2). The logged
# command shares of the shared real 6S quads rise 0.024 per m/s (UAVCAN mission, 0-6 m/s, r = 0.84
# with forward speed) and 0.008 (tip-over flight, 6-20 m/s, r = 0.54); the simulator's had 0. A draw
# of 0.005-0.030 gave command shares rising a median 0.011 per m/s (thrust curve and wind: ~0.63 of
# the draw), so the range reaches 0.045 to put the mission inside it (docs/params.md "Forward-flight
# rotor moment", lab/forward_flight_shares.py). Drawn per flight from its own stream (AERO_SPAWN).
FLAP_PER_MS = (0.005, 0.045)

# --- motor mount twist (sim/realistic_dynamics.py) ---------------------------------------------
# A motor mount rotated about its arm by delta tilts the thrust sideways: F sin(delta) at the arm's
# radius, a yaw moment arm x delta per newton, the same order as the rotor's own drag torque (gamma =
# 0.016 m; 1 deg of twist at 0.225 m is 0.0039 m). The yaw integrator cancels the sum by running one
# diagonal pair harder: a steady diagonal command-share offset (s1 + s3 - s2 - s4) / 4 of about
# arm sum(delta) / (4 gamma) in the logged thrust fraction. The shared real 6S quad holds +0.036 (GPS
# interference, no yaw motion) and +0.04 (UAVCAN mission, median); the suite's healthy flights had
# -0.038..+0.027 (95 % within +-0.022: the motors' thrust spread alone). ArduCopter warns of it as
# "yaw imbalance" (twisted arms or motor mounts; ardupilot.org thrust_loss_yaw_imbalance), and a
# healthy 450 quad's forum log had motor averages 1458/1512/1595/1615 us, a diagonal offset of -0.11
# (docs/params.md "Motor mount twist", lab/yaw_trim_shares.py). Per rotor, uniform +-0.75 deg
# (drawn after FLAP in the AERO_SPAWN stream, so the flap draw did not move).
MOUNT_TWIST_DEG = 0.75

# --- wind (sim/wind.py) -----------------------------------------------------------------------
WIND_MS = (0.0, 6.0)  # mean wind, in-distribution
OOD_WIND_MS = (6.0, 8.0)  # the held-out wind range
WIND_V_FLOOR = 1.0  # m/s: Dryden airspeed floor (Taylor advection speed of a hover in calm air)
GUST_RATE_HZ = 1.0 / 20.0  # discrete (1 - cos) gusts, Poisson
GUST_MAX = 6  # gusts drawn per flight (unused ones start after the flight)
GUST_MS = (1.0, 4.0)  # peak gust speed
GUST_S = (1.0, 4.0)  # gust length in time

# --- state estimate fed to the controller (first-order Gauss-Markov errors) --------------------
# (std, correlation time [s]) per state: EKF2-class GNSS/baro/IMU fusion (PX4 EKF2 reports
# ~0.1-0.3 m horizontal, ~0.1 m vertical, 0.05 m/s, 0.5 deg tilt, 1-2 deg heading).
EST_POS_XY = (0.20, 10.0)
EST_POS_Z = (0.10, 5.0)
EST_VEL = (0.05, 1.0)
EST_TILT = (0.008, 2.0)
EST_YAW = (0.03, 20.0)
EST_RATE = (0.02, 0.005)  # gyro noise after the 30 Hz low-pass: nearly white at 200 Hz

# --- thrust curve (what the ESC does with a command) -----------------------------------------
# F / F_max = (1 - k) u + k u^2 (PX4 THR_MDL_FAC; 0.3-0.5 for hobby ESCs). The controller inverts
# it to the ESC output u; the log's thr1..4 is the thrust fraction F_cmd / F_max (docs/flight_format.md,
# PX4's actuator_motors; ingest turns PWM into it through the firmware's own curve): logging u instead
# would not match the real flights' thrust fraction (docs/ingest.md).
THR_MDL_FAC = 0.4

# --- propeller (sim/propeller.py) -------------------------------------------------------------
PROP_R_M = 0.127  # 10" prop radius
BLADE_G = 6.0  # g per blade of a 1045 prop
TIP_MASS_FACTOR = 0.6  # the tip is thinner and narrower than the mean blade: mass per length there
CUT_MAX = 0.30  # blade length cut off at severity 1 (fraction of R)
K_THRUST = 8.5 / (2 * np.pi * 8500 / 60) ** 2  # N s^2: F_max at ~8500 rpm (1045 on 2212-920KV, 3S)
MOUNT_T = 0.2  # FC vibration-mount transmissibility at 80-150 Hz (foam/gel mount, ~-14 dB)
IMU_INTEG_HZ = 200.0  # PX4 IMU_INTEG_RATE default: accel averaged over 5 ms before the metric
PX4_VIB_ALPHA = 0.01  # PX4 VehicleIMU: metric = 0.99 metric + 0.01 |a_k - a_k-1|, per IMU sample
AP_FLOOR_HZ, AP_VIBE_HZ = 5.0, 2.0  # ArduPilot AP_InertialSensor vibration floor / vibe filters
VIB_REL_NOISE = 0.05  # relative scatter of a logged metric sample (finite averaging)

# --- faults (sim/realistic_faults.py) ---------------------------------------------------------
R_SPIKE_OHM = (0.03, 0.15)  # a connector that lifts: contact resistance during a spike (1-4 V at 25 A)
CONN_SPIKE_S = (0.05, 0.5)
DESYNC_S = (0.02, 0.10)  # ESC desync: the motor stops producing thrust
EVENT_RATE_HZ = (0.2, 1.0)  # intermittent events after the onset, Poisson
N_EVENTS = 48  # events drawn per flight (those after the end do nothing)
IMBALANCE_CELL_SOC = 0.5  # weakest cell's SoC deficit at severity 1 (cell imbalance)
BATT_R_GROWTH = 1.5  # beyond end of life: R x (1 + 1.5 s) on top of the aged pack (up to 5x new)
BATT_FADE = 0.4  # capacity x (1 - 0.4 s) on top of the aged pack
INCIPIENT_SMAX = (0.25, 0.45)  # the out-of-distribution incipient set: below severity_max's range
MANOEUVRE_SNAP_P = 0.5  # share of in-flight onsets moved to the start of the next manoeuvre

# --- logging (sim/telemetry.py): each channel group at a rate drawn per flight ------------------
# The rates real logs have, per channel group (the command below, on the shared logs: the PX4 quad
# logs of ../shared/data/flightlogs, its ArduCopter log and a CrazyPAD Crazyflie log): PX4's
# logger defaults (vehicle_local_position 10 Hz, vehicle_attitude 20 Hz, vehicle_angular_velocity
# 50 Hz, battery_status 5 Hz, actuator_outputs 10 Hz, vehicle_imu_status 1 Hz) and a PX4 1.9 log's
# (8, 27.7, 27.7, 1.8, 9.2 Hz, vibration 2.7 Hz, ESC 3.2 Hz), ArduCopter's 10 Hz, the Crazyflie's
# 100 Hz. Each flight draws each group's rate uniformly from its list (RATES_SPAWN stream); a rate
# above the 50 Hz record is taken at 50 Hz: after the 25 Hz grid's anti-alias low-pass the two reach
# the models alike.
RECORD_HZ = 50.0  # the simulator records every channel at this rate, then decimates
# `quadfdi ingest rates ../shared/data/flightlogs/* ../shared/data/crazypad/motor_data/normal_flight/E9_log00`:
LOG_HZ_MEASURED = {"pos": (8.0, 9.8, 10.0, 10.1, 100.9), "att": (9.8, 20.0, 20.2, 27.7, 100.9),
                   "rate": (9.8, 27.7, 50.0, 50.1), "batt": (1.8, 5.0, 5.1, 9.9, 100.9), "esc": (3.2, 4.0),
                   "act": (8.8, 9.2, 9.8, 10.0, 100.9), "vib_px4": (1.0, 1.1, 2.7), "vib_ap": (9.8,)}
RATES_SPAWN = 8  # spawn_key (8, i): flight i's logging rates (1..7 are taken; 7: sim.variability AERO_SPAWN)
MARGIN_S = 1.0  # simulated past the last sample so every logged channel covers the grid
