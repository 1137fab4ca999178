"""The fleet suite's airframe classes flown by the controller: hover collective and tracking per class.

    python lab/fleet_classes.py [--untuned] [SECTION.KEY=VALUE ...]

Simulates, with configs/fleet.toml (and the overrides), the first ``ood_traj`` in-distribution
flights (450 class) and the two held-out size sets (250, 650 class), and prints per class over the
healthy flights: take-off mass, hover collective (mean of the four thrust fractions over the first
2 s, trimmed hover at the mission start), position error against the mission reference after 2 s
(RMS and max), largest tilt and the RMS of the roll/pitch rate error's 2-4 Hz-and-above part (body
rate minus its 0.25 s moving mean: a ringing rate loop shows here). ``--untuned`` flies the held-out
classes with the 450 class's rate-loop output (no per-class scaling) to show what the scaling does.
"""

from __future__ import annotations

import sys

import numpy as np

from quadfdi.core.config import load_config
from quadfdi.sim import fleet, mission
from quadfdi.sim import realistic_dynamics as rd


def _untuned() -> None:
    real = rd.vehicle

    def vehicle(draws):
        return real(draws)._replace(ctrl=np.ones((len(draws), 3)))

    rd.vehicle = vehicle
    import quadfdi.sim.realistic_loop as rl

    rl.rd.vehicle = vehicle


def main(argv: list[str]) -> None:
    if "--untuned" in argv:
        argv = [a for a in argv if a != "--untuned"]
        _untuned()
    cfg = load_config("fleet", argv).sim
    n = cfg.ood_traj
    base = cfg.n_traj + 4 * n
    rows = list(range(n)) + list(range(base, base + 2 * n))
    out = fleet.generate(cfg, rows)
    _, _, group, _ = fleet.labels(cfg)
    names = list(out["channel_names"])
    thr = out["telemetry"][..., names.index("thr1"):names.index("thr1") + 4].astype(np.float64).mean(-1)
    st = out["states"].astype(np.float64)
    t = out["time"]
    ref = np.stack([mission.evaluate(mission.prepare([fleet.draw_fleet_flight(cfg, i, int(group[i]))["mission"]]), t)[0][:, 0]
                    for i in rows])
    err = np.linalg.norm(st[..., 0:3] - ref, axis=-1)[:, t >= 2.0]
    tilt = np.degrees(np.arccos(np.cos(st[..., 6]) * np.cos(st[..., 7])))
    k = 6  # 0.24 s moving mean at 25 Hz
    rate = st[..., 9:11]
    kern = np.ones(k) / k
    smooth = np.apply_along_axis(lambda a: np.convolve(a, kern, "same"), 1, rate)
    ring = np.sqrt(((rate - smooth)[:, k:-k] ** 2).mean(axis=(1, 2)))
    healthy = out["fault_class"] == 0
    print("| class | healthy flights | mass [kg] | hover collective | position error RMS / max [m] | max tilt [deg] | rate ringing RMS [deg/s] |")
    print("|---|---|---|---|---|---|---|")
    for c, cname in enumerate(out["airframe_class_names"]):
        m = healthy & (out["airframe_class"] == c) & (out["test_group"] != 2)
        if not m.any():
            continue
        print(f"| {cname} | {m.sum()} | {out['mass_kg'][m].min():.2f}-{out['mass_kg'][m].max():.2f} | "
              f"{thr[m, :50].mean(axis=1).min():.2f}-{thr[m, :50].mean(axis=1).max():.2f} | "
              f"{np.sqrt((err[m] ** 2).mean()):.2f} / {err[m].max():.2f} | {tilt[m].max():.1f} | "
              f"{np.degrees(ring[m]).mean():.1f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
