"""The [sim] section: simulator and dataset settings (paper Table 2, docs/realistic.md for the realistic
suite's keys). Its JSON, and nothing else of the config, is embedded in dataset.npz."""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.limits import MAX_WINDOW, check_dataset_memory, dataset_bytes
from quadfdi.core.sections import at_most, choice, not_negative, positive


@dataclass(frozen=True)
class SimConfig:
    """Simulator and dataset settings (paper Table 2)."""

    seed: int = 0
    vehicle: str = "f450_3s"  # named vehicle class, see sim/params.py
    n_traj: int = 240
    duration_s: float = 16.0
    sample_dt_s: float = 0.04  # 25 Hz telemetry
    sim_dt_s: float = 0.005  # internal integration step (200 Hz), 8 per telemetry sample
    fault_ratio: float = 0.75
    onset_frac: tuple[float, float] = (0.14, 0.43)  # of the flight duration
    ramp_frac: tuple[float, float] = (0.30, 0.62)  # of the flight duration
    severity_max: tuple[float, float] = (0.5, 1.0)  # final severity s_max,k, uniform
    severity_threshold: float = 0.2  # s_thr: labels windows, defines the detectable time
    split: tuple[float, float, float] = (0.70, 0.15, 0.15)  # train / validation / test
    window: int = 80
    stride: int = 10
    chunk: int = 240  # trajectories integrated together (vectorised batch)
    # --- realistic suite (docs/realistic.md); the defaults are the paper's and leave its dataset byte for byte ---
    scenario: str = "paper"  # paper: Eqs. 1-9 as published | realistic: sim/realistic*.py
    classes: tuple[str, ...] = ("Healthy", "BatteryFault", "MotorFault", "OverheatFault")  # label order
    ood_traj: int = 0  # realistic: flights per out-of-distribution test set (4 sets), on top of n_traj
    # --- fleet suite (docs/fleet.md): each vehicle flies several flights, its first ones healthy ---
    flights_per_vehicle: int = 0  # fleet: flights of every vehicle (n_traj and ood_traj are multiples of it)
    reference_flights: int = 0  # fleet: the first flights of each vehicle, healthy (the reference flights)

    def validate(self) -> None:
        positive(self, "n_traj", "duration_s", "sample_dt_s", "sim_dt_s", "window", "stride", "chunk")
        not_negative(self, "seed")
        at_most(self, MAX_WINDOW, "window")
        if self.window < 2:
            raise QuadfdiError(f"sim.window must be 2 samples or more (the models need a time step), found {self.window}")
        choice(self, "scenario", ("paper", "realistic", "fleet"))
        self._validate_classes()
        if not 0.0 <= self.fault_ratio <= 1.0:
            raise QuadfdiError(f"sim.fault_ratio must be in [0, 1], found {self.fault_ratio}")
        for name in ("onset_frac", "ramp_frac", "severity_max"):
            lo, hi = getattr(self, name)
            if not 0.0 <= lo <= hi <= 1.0 or (name != "onset_frac" and lo <= 0.0):
                raise QuadfdiError(f"sim.{name} must be [lo, hi] with 0 < lo <= hi <= 1, found {[lo, hi]}")
        if not 0.0 < self.severity_threshold < self.severity_max[0]:
            raise QuadfdiError(
                f"sim.severity_threshold must be in (0, severity_max[0]={self.severity_max[0]}), "
                f"found {self.severity_threshold}"
            )
        if abs(sum(self.split) - 1.0) > 1e-9 or min(self.split) < 0:
            raise QuadfdiError(f"sim.split must be three non-negative shares summing to 1, found {list(self.split)}")
        check_dataset_memory(self.n_traj, self.n_samples)
        ratio = self.sample_dt_s / self.sim_dt_s
        if abs(ratio - round(ratio)) > 1e-9:
            raise QuadfdiError(
                f"sim.sample_dt_s ({self.sample_dt_s}) must be a whole multiple of sim.sim_dt_s ({self.sim_dt_s})"
            )
        if self.n_samples < self.window:
            raise QuadfdiError(
                f"sim.duration_s={self.duration_s} gives {self.n_samples} samples, fewer than sim.window={self.window}"
            )
        # Every fault trajectory must become detectable at least one stride before the end:
        # worst case is the latest onset, the longest ramp and the smallest final severity.
        t_det_worst = self.duration_s * (self.onset_frac[1] + self.ramp_frac[1] * self.severity_threshold / self.severity_max[0])
        last_end = (self.n_samples - 1) * self.sample_dt_s
        if t_det_worst > last_end - self.stride * self.sample_dt_s + 1e-9:
            raise QuadfdiError(
                f"sim: a fault may become detectable at {t_det_worst:.2f} s, later than one stride before the "
                f"last sample ({last_end:.2f} s); lower sim.severity_threshold or raise sim.severity_max"
            )

    def _validate_classes(self) -> None:
        paper = SimConfig.classes
        known = (*paper, "PropellerFault")  # sim/realistic_faults.py simulates these
        if self.scenario == "paper" and (self.classes != paper or self.ood_traj):
            raise QuadfdiError(f"sim.scenario='paper' simulates exactly the classes {list(paper)} and no "
                               f"out-of-distribution sets (sim.ood_traj = 0); use sim.scenario='realistic'")
        bad = [c for c in self.classes if c not in known]
        if bad or len(set(self.classes)) != len(self.classes) or self.classes[:1] != ("Healthy",) or len(self.classes) < 2:
            raise QuadfdiError(f"sim.classes must start with Healthy and list distinct classes of {list(known)}, "
                               f"found {list(self.classes)}")
        if self.scenario != "paper" and self.vehicle != "f450_3s":
            raise QuadfdiError(f"sim.scenario={self.scenario!r} draws its vehicles around the nominal f450_3s "
                               f"(sim/realistic_params.py); sim.vehicle must be 'f450_3s', found {self.vehicle!r}")
        if self.ood_traj < 0:
            raise QuadfdiError(f"sim.ood_traj must not be negative, found {self.ood_traj}")
        self._validate_fleet()

    def _validate_fleet(self) -> None:
        f, r = self.flights_per_vehicle, self.reference_flights
        if self.scenario != "fleet":
            if f or r:
                raise QuadfdiError("sim.flights_per_vehicle and sim.reference_flights belong to sim.scenario='fleet' "
                                   f"(found {f} and {r} with scenario {self.scenario!r})")
            return
        if not 1 <= r < f:
            raise QuadfdiError(f"sim.scenario='fleet' needs 1 <= sim.reference_flights < sim.flights_per_vehicle, "
                               f"found {r} and {f}")
        if self.n_traj % f or self.ood_traj % f:
            raise QuadfdiError(f"sim.n_traj ({self.n_traj}) and sim.ood_traj ({self.ood_traj}) must be whole "
                               f"multiples of sim.flights_per_vehicle ({f}): every vehicle flies all its flights")

    @property
    def estimated_bytes(self) -> int:
        return dataset_bytes(self.n_traj, self.n_samples)

    @property
    def n_samples(self) -> int:
        return int(round(self.duration_s / self.sample_dt_s))

    @property
    def substeps(self) -> int:
        return int(round(self.sample_dt_s / self.sim_dt_s))
