"""PX4's accelerometer vibration metric -> ``vib_px4`` in m/s^2 (the quantity the realistic suite
simulates under the same name), from whichever of PX4's three definitions the log holds.

All three are the same filter, PX4's EMA m <- 0.99 m + 0.01 |x_k - x_(k-1)| run once per
integrated IMU sample, on different x (sources and line citations: docs/ingest.md, "Vibration"):

- PX4 >= 1.13: ``vehicle_imu_status.accel_vibration_metric`` with x = acceleration (delta velocity /
  its interval; PX4 PR #17965), m/s^2: used as logged.
- PX4 1.11-1.12: the same field with x = delta velocity, m/s: divided by the interval
  (``vehicle_imu.delta_velocity_dt`` of the same instance, median).
- PX4 < 1.11 (no vehicle_imu_status): ECL's ``estimator_status.vibe[2]``, x = delta velocity =
  ``sensor_combined.accelerometer_m_s2 * accelerometer_integral_dt`` (ekf2_main), m/s: divided by
  the median ``sensor_combined.accelerometer_integral_dt``.

Dividing by the median interval is exact for a constant interval. Two documented differences stay:
the interval's jitter (|a| |dt_k - dt_(k-1)| enters a delta-velocity metric; reported in
``vehicle["vibration"]``) and the interval itself (PX4 1.9 integrates 4 ms, the simulator models
IMU_INTEG_RATE 200 Hz = 5 ms). No factor is fitted. Without a firmware version or an interval the
channel is marked unusable, never guessed.
"""

from __future__ import annotations

import numpy as np

from quadfdi.ingest.model import Channel, LogRead

ACCEL_UNITS_SINCE = (1, 13)  # PR #17965 (merged 2021-07): accel_vibration_metric on acceleration


def firmware_version(info: dict) -> tuple[int, int, int] | None:
    """(major, minor, patch) from the ULog info ``ver_sw_release`` (0xAABBCCTT), None if absent."""
    v = info.get("ver_sw_release")
    if v is None or int(v) == 0:
        return None
    v = int(v)
    return (v >> 24) & 0xFF, (v >> 16) & 0xFF, (v >> 8) & 0xFF


def _jitter(dt_s: np.ndarray, accel_norm: float) -> dict:
    """The interval's spread and what it can add to a delta-velocity metric, in m/s^2 after the
    division: |a| E|dt_i - dt_j| / dt over the logged intervals (taken as independent)."""
    dt = dt_s[np.isfinite(dt_s) & (dt_s > 0)]
    med = float(np.median(dt))
    sub = dt[:: max(1, len(dt) // 2000)]  # E|dt_i - dt_j| on at most 2000 samples
    spread = float(np.abs(sub[:, None] - sub[None, :]).mean())
    return {"integration_interval_s": med, "interval_samples": int(len(dt)),
            "interval_p5_p95_s": [float(np.percentile(dt, 5)), float(np.percentile(dt, 95))],
            "jitter_term_bound_m_s2": accel_norm * spread / med}


def _from_delta_velocity(t: np.ndarray, metric: np.ndarray, dt_s: np.ndarray, accel_norm: float,
                         src: str, dt_src: str, lr: LogRead) -> None:
    info = _jitter(dt_s, accel_norm)
    dt = info["integration_interval_s"]
    lr.channels["vib_px4"] = Channel("vib_px4", t, metric.astype(float) / dt,
                                     f"{src} / median {dt_src} ({dt * 1e3:.2f} ms)")
    lr.vehicle["vibration"] = dict(info, source=src, logged_unit="m/s (delta velocity)",
                                   conversion=f"divided by the median {dt_src}", interval_source=dt_src)


def vibration_channel(tp, info: dict, read_topic, lr: LogRead) -> None:
    """Set ``lr.channels['vib_px4']`` (m/s^2) and ``lr.vehicle['vibration']``, or ``lr.status``.

    ``tp``: ingest.px4.Topics; ``info``: the ULog's msg_info_dict; ``read_topic(name)``: that topic's
    instance 0 read from the log on demand (sensor_combined runs at 200 Hz in newer logs: not
    parsed unless needed)."""
    ver = firmware_version(info)
    imu = tp.get("vehicle_imu_status")
    g = 9.80665  # |a| in the jitter bound: hover specific force
    if imu is not None and "accel_vibration_metric" in imu:
        src = "vehicle_imu_status[0].accel_vibration_metric"
        if ver is None:
            lr.status["vib_px4"] = ("unusable: the log has no firmware version (ver_sw_release) to tell PX4's "
                                    "two accel_vibration_metric definitions (m/s before 1.13, m/s^2 since) apart")
            return
        if ver[:2] >= ACCEL_UNITS_SINCE:
            lr.channels["vib_px4"] = Channel("vib_px4", imu["t"], imu["accel_vibration_metric"].astype(float), src)
            vi = tp.get("vehicle_imu")
            extra = _jitter(vi["delta_velocity_dt"].astype(float) * 1e-6, 0.0) if vi is not None else {}
            extra.pop("jitter_term_bound_m_s2", None)
            lr.vehicle["vibration"] = dict(extra, source=src, logged_unit="m/s^2", conversion="none",
                                           firmware=".".join(map(str, ver)))
            return
        vi = tp.get("vehicle_imu")
        if vi is None or "delta_velocity_dt" not in vi:
            lr.status["vib_px4"] = (f"unusable: PX4 {'.'.join(map(str, ver))} logs accel_vibration_metric as a "
                                    "delta velocity (m/s) and the log has no vehicle_imu.delta_velocity_dt to convert it")
            return
        _from_delta_velocity(imu["t"], imu["accel_vibration_metric"], vi["delta_velocity_dt"].astype(float) * 1e-6,
                             g, src, "vehicle_imu[0].delta_velocity_dt", lr)
        lr.vehicle["vibration"]["firmware"] = ".".join(map(str, ver))
        return
    est = tp.get("estimator_status")
    if est is None or "vibe[2]" not in est:
        return  # absent: no vibration metric in this log
    sc = read_topic("sensor_combined")
    if sc is None or "accelerometer_integral_dt" not in sc:
        lr.status["vib_px4"] = ("unusable: estimator_status.vibe[2] is a delta-velocity metric (m/s) and the log "
                                "has no sensor_combined.accelerometer_integral_dt to convert it")
        return
    acc = np.sqrt(sum(sc[f"accelerometer_m_s2[{i}]"].astype(float) ** 2 for i in range(3)))
    _from_delta_velocity(est["t"], est["vibe[2]"], sc["accelerometer_integral_dt"].astype(float) * 1e-6,
                         float(np.median(acc)), "estimator_status.vibe[2]", "sensor_combined.accelerometer_integral_dt", lr)
    if ver is not None:
        lr.vehicle["vibration"]["firmware"] = ".".join(map(str, ver))
