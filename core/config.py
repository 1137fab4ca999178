"""One TOML config, one section per stage; defaults are the paper's Table 2.

``load_config(path, overrides)`` reads ``configs/paper.toml`` (or any file of the same shape), applies ``--set
section.key=value`` overrides, type-checks every value and validates ranges. An unknown section or key is an error
that lists the valid ones (as nanoGPT's configurator does), so a typo never silently falls back to a default. The
config used by a run is stored in the run folder (``config.toml``) and inside every artifact."""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, get_type_hints

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resources import config_file, config_names
from quadfdi.core.tomlio import dumps_toml  # noqa: F401 (re-exported: the run folder writes it)
from quadfdi.core.limits import FIRMWARE_MAX_STEPS, MAX_THREADS, check_dataset_memory, dataset_bytes
from quadfdi.core.evalconfig import AlarmConfig, EvaluateConfig  # [alarm], [evaluate], [run]: own modules (400-line cap)
from quadfdi.core.runconfig import RunConfig
from quadfdi.core.overrides import parse_override as _parse_override  # own module (400-line cap)
from quadfdi.core.coerce import coerce as _coerce  # own module (400-line cap)
from quadfdi.core.profiles import check_profile


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

    def validate(self) -> None:
        _positive(self, "n_traj", "duration_s", "sample_dt_s", "sim_dt_s", "window", "stride", "chunk")
        _not_negative(self, "seed")
        if self.window < 2:
            raise QuadfdiError(f"sim.window must be 2 samples or more (the models need a time step), found {self.window}")
        _choice(self, "scenario", ("paper", "realistic"))
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
        if self.scenario == "realistic" and self.vehicle != "f450_3s":
            raise QuadfdiError("sim.scenario='realistic' draws its vehicles around the nominal f450_3s "
                               f"(sim/realistic_params.py); sim.vehicle must be 'f450_3s', found {self.vehicle!r}")
        if self.ood_traj < 0:
            raise QuadfdiError(f"sim.ood_traj must not be negative, found {self.ood_traj}")

    @property
    def estimated_bytes(self) -> int:
        return dataset_bytes(self.n_traj, self.n_samples)

    @property
    def n_samples(self) -> int:
        return int(round(self.duration_s / self.sample_dt_s))

    @property
    def substeps(self) -> int:
        return int(round(self.sample_dt_s / self.sim_dt_s))


@dataclass(frozen=True)
class TrainConfig:
    """Model and training settings (paper Table 2 and Sections II-D to II-F)."""

    seed: int = 0
    model: str = "both"  # cnode | gru | both
    epochs: int = 14
    batch_size: int = 96
    lr: float = 2e-2  # Adam, initial learning rate of the CNODE (a sweep: docs/training.md)
    gru_lr: float = 3e-3  # Adam, initial learning rate of the GRU (at 1e-2 it lost 1 point of F1)
    lr_schedule: str = "cosine"  # constant | cosine (decays to 0 over the epochs, per batch)
    latent: int = 40  # CNODE latent dimension
    hidden: int = 64  # CNODE vector-field hidden width
    gru_hidden: int = 80
    solver: str = "rk4"  # training solver of the CNODE: dopri5 | bosh3 | rk4 | euler | midpoint
    steps: int = 8  # fixed-step solvers: N steps over [0, 1]
    rtol: float = 1e-3  # adaptive solvers
    atol: float = 1e-4
    jump_t: bool = True  # adaptive solvers: tell torchdiffeq where the path's knots are
    log_eps: float = 1e-8  # the epsilon of Eq. (12)
    # One intra-op thread: tiny matrices (batch 96 x 64); oversubscribed OpenMP made the GRU ~50x slower.
    threads: int = 1
    seeds: tuple[int, ...] = (0, 1, 2)  # the multi-seed study
    max_train_windows: int = 0  # cap: a seeded subsample of the training windows (train.data); 0 = all
    profile: str = "paper"  # the models' input channels (core.profiles, docs/profiles.md): paper | flightlog-min | flightlog-nocur | flightlog-esc
    # The motor head (models.motor, docs/training.md): "auto" = on when the data has a rotor-side class, "off" never.
    motor_head: str = "off"
    motor_loss_weight: float = 0.5  # weight of the motor cross-entropy added to the class loss
    # Training-only motor-share wander (train.augment, docs/training.md "Motor-share wander"): the largest per-window
    # amplitude of the multiplicative noise on m1_rel..m4_rel (0 = off) and its correlation time.
    share_wander: float = 0.0
    share_wander_tau_s: float = 0.3

    def validate(self) -> None:
        _positive(self, "epochs", "batch_size", "lr", "latent", "hidden", "gru_hidden", "steps", "rtol", "atol", "threads", "gru_lr")
        _not_negative(self, "seed", "max_train_windows")
        if min(self.seeds, default=0) < 0:
            raise QuadfdiError(f"train.seeds must not be negative, found {list(self.seeds)}")
        _at_most(self, MAX_THREADS, "threads")
        _choice(self, "model", ("cnode", "gru", "both"))
        _choice(self, "lr_schedule", ("constant", "cosine"))
        _choice(self, "solver", ("dopri5", "bosh3", "rk4", "euler", "midpoint"))
        check_profile(self.profile)
        _choice(self, "motor_head", ("auto", "off"))
        _not_negative(self, "motor_loss_weight", "share_wander")
        _positive(self, "share_wander_tau_s")


@dataclass(frozen=True)
class ExportConfig:
    """Deployment graph settings (SPEC section 4)."""

    steps: int = 8  # N of the unrolled classic RK4 graph
    opset: int = 18
    calib_windows: int = 512  # training windows used to calibrate int8 activation scales
    reference_windows: int = 4  # test windows written to reference.bin

    def validate(self) -> None:
        _positive(self, "steps", "opset", "calib_windows", "reference_windows")
        _at_most(self, FIRMWARE_MAX_STEPS, "steps")
        if self.opset < 17:
            raise QuadfdiError(f"export.opset must be 17 or newer, found {self.opset}")


@dataclass(frozen=True)
class SolversConfig:
    """The ODE-solver study of a trained CNODE and the train-by-deploy matrix (docs/solvers.md)."""

    sample: int = 64  # test windows solved one by one (seeded sample); 0 = the whole test split
    sample_seed: int = 0
    fixed_methods: tuple[str, ...] = ("euler", "midpoint", "rk4")
    steps: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 79)  # N of the fixed-step settings
    adaptive_methods: tuple[str, ...] = ("dopri5", "bosh3")
    rtols: tuple[float, ...] = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)  # adaptive settings, atol = rtol / 10
    jump: str = "both"  # adaptive settings told the knots as jump_t: both | on | off
    controls: tuple[str, ...] = ("point", "average")  # control representations of the fixed steps
    ref_rtol: float = 1e-9  # the float64 dopri5 reference, restarted at every knot
    f1_tol: float = 0.002  # "matches": macro F1 at most this far below the adaptive setting's
    f1_two_sided: bool = False  # ... or within f1_tol on either side
    threads: int = 1  # torch intra-op threads of the study (its latencies depend on it)
    matrix_train: tuple[str, ...] = ("dopri5", "rk4:1", "rk4:2", "rk4:8", "rk4:32", "rk4:1:avg", "rk4:2:avg", "rk4:8:avg")
    matrix_deploy: tuple[str, ...] = ("dopri5:1e-3", "rk4:1", "rk4:2", "rk4:8", "rk4:32", "rk4:1:avg", "rk4:2:avg",
                                      "rk4:8:avg", "ref")
    matrix_epochs: int = 0  # training epochs of every matrix model; 0 = train.epochs
    matrix_max_train_windows: int = 0  # seeded subset of the training windows; 0 = all
    matrix_batch: int = 96  # windows per deploy solve
    matrix_threads: int = 0  # 0 = train.threads
    break_tol: float = 0.02  # a model "breaks" when the reference's macro F1 is this far below its own solver's

    def validate(self) -> None:
        for name, valid in (("fixed_methods", ("euler", "midpoint", "rk4")), ("adaptive_methods", ("dopri5", "bosh3")),
                            ("controls", ("point", "average"))):
            bad = [v for v in getattr(self, name) if v not in valid]
            if bad or len(set(getattr(self, name))) != len(getattr(self, name)):
                raise QuadfdiError(f"solvers.{name}: unknown or repeated value {(bad or [''])[0]!r}; valid: {', '.join(valid)}")
        if not self.controls or not (self.fixed_methods or self.adaptive_methods):
            raise QuadfdiError("solvers: the study needs at least one control and one method")
        if any(n < 1 for n in self.steps) or any(not r > 0 for r in self.rtols):
            raise QuadfdiError("solvers.steps must be positive integers and solvers.rtols positive numbers")
        _choice(self, "jump", ("both", "on", "off"))
        _positive(self, "ref_rtol", "threads", "matrix_batch")
        _at_most(self, MAX_THREADS, "threads", "matrix_threads")
        for name in ("sample", "sample_seed", "f1_tol", "break_tol", "matrix_epochs", "matrix_max_train_windows",
                     "matrix_threads"):
            if getattr(self, name) < 0:
                raise QuadfdiError(f"solvers.{name} must not be negative, found {getattr(self, name)}")
        if not self.matrix_train or not self.matrix_deploy:
            raise QuadfdiError("solvers.matrix_train and solvers.matrix_deploy need at least one setting each")


@dataclass(frozen=True)
class BenchConfig:
    """Latency measurement settings of ``quadfdi bench`` (docs/bench.md); ``--quick`` replaces the
    counts with tiny ones and the thread counts with (1,)."""

    cpus: str = "0,1"  # CPUs every benchmark process is pinned to (taskset); --cpus overrides
    threads: tuple[int, ...] = (1, 2)  # intra-op thread counts timed (torch, ort)
    windows: int = 300  # batch-1 windows per setting, each timed once
    warmup: int = 30  # warm-up calls before each timed loop ...
    warmup_s: float = 1.0  # ... or this many seconds, whichever ends first
    batch: int = 96  # the batched setting's batch size
    batches: int = 10  # batched calls timed per setting
    budget_s: float = 8.0  # time budget of each timed loop (dopri5 is the one that hits it)
    min_samples: int = 5  # the budget never cuts a loop below this many calls
    profile_windows: int = 100  # windows run under the ORT per-node profiler
    callgrind_windows: int = 5  # windows run under valgrind callgrind (C++)
    worker_timeout_s: float = 900.0  # one worker process may take this long
    stream_flights: int = 10  # test flights replayed through fwref_stream (bench/stream.py); 0 skips; --quick: 1
    # A runtime below its floor after re-measuring: the floors are not lower bounds here, so the bench
    # exits non-zero (after writing bench.json); false only reports it (plumbing checks, not timings).
    fail_below_floor: bool = True

    def validate(self) -> None:
        _positive(self, "windows", "warmup_s", "batch", "batches", "budget_s", "min_samples", "profile_windows",
                  "callgrind_windows", "worker_timeout_s")
        if self.warmup < 0:
            raise QuadfdiError(f"bench.warmup must be 0 or more, found {self.warmup}")
        if self.stream_flights < 0:
            raise QuadfdiError(f"bench.stream_flights must be 0 or more, found {self.stream_flights}")
        if not self.threads or min(self.threads) < 1 or max(self.threads) > MAX_THREADS:
            raise QuadfdiError(f"bench.threads must be a non-empty list of counts in 1..{MAX_THREADS}, found {list(self.threads)}")
        parts = [c.strip() for c in self.cpus.split(",")]
        if not all(c.isdigit() for c in parts):
            raise QuadfdiError(f"bench.cpus must be a comma-separated list of CPU numbers, found {self.cpus!r}")


@dataclass(frozen=True)
class Config:
    sim: SimConfig = field(default_factory=SimConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    solvers: SolversConfig = field(default_factory=SolversConfig)
    bench: BenchConfig = field(default_factory=BenchConfig)
    alarm: AlarmConfig = field(default_factory=AlarmConfig)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def validate(self) -> None:
        [getattr(self, f.name).validate() for f in fields(self)]

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {f.name: _section_dict(getattr(self, f.name)) for f in fields(self)}


def _section_dict(section: Any) -> dict[str, Any]:
    """The section's keys (tuples as lists); an empty table ([alarm.<net>] not given) is left out."""
    return {f.name: (list(v) if isinstance(v := getattr(section, f.name), tuple) else v) for f in fields(section)
            if getattr(section, f.name) != {}}


def _positive(section: Any, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if not value > 0:
            raise QuadfdiError(f"{_section_name(section)}.{name} must be positive, found {value}")


def _not_negative(section: Any, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if value < 0:
            raise QuadfdiError(f"{_section_name(section)}.{name} must not be negative, found {value}")


def _at_most(section: Any, limit: int, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if value > limit:
            raise QuadfdiError(f"{_section_name(section)}.{name} must be at most {limit}, found {value}")


def _choice(section: Any, name: str, allowed: tuple[str, ...]) -> None:
    value = getattr(section, name)
    if value not in allowed:
        raise QuadfdiError(f"{_section_name(section)}.{name} must be one of {', '.join(allowed)}; found {value!r}")


def _section_name(section: Any) -> str:
    for f in fields(Config):
        if f.default_factory is type(section):  # type: ignore[misc]
            return f.name
    return type(section).__name__


def build_config(data: dict[str, Any], overrides: list[str] | tuple[str, ...] = (), source: str = "config") -> Config:
    """Config from a parsed TOML mapping plus ``section.key=value`` overrides, checked."""
    merged: dict[str, dict[str, Any]] = {}
    sections = {f.name: f.default_factory for f in fields(Config)}  # type: ignore[misc]
    for name, body in data.items():
        if name not in sections:
            raise QuadfdiError(f"{source}: unknown section [{name}]; valid sections: {', '.join(sections)}")
        if not isinstance(body, dict):
            raise QuadfdiError(f"{source}: [{name}] must be a table")
        merged[name] = dict(body)
    for text in overrides:
        section, key, value = _parse_override(text)
        if section not in sections:
            raise QuadfdiError(f"--set {text}: unknown section {section!r}; valid sections: {', '.join(sections)}")
        merged.setdefault(section, {})[key] = value
    built = {}
    for name, cls in sections.items():
        hints = get_type_hints(cls)
        valid = [f.name for f in fields(cls)]
        kwargs = {}
        body = merged.get(name, {})
        if hasattr(cls, "fold_tables"):  # [alarm]: per-network tables ([alarm.cnode], --set alarm.cnode.k=3)
            body = cls.fold_tables(body, source)
        for key, value in body.items():
            if key not in hints:
                raise QuadfdiError(f"{source}: unknown key {name}.{key}; valid keys of [{name}]: {', '.join(valid)}")
            kwargs[key] = getattr(cls, "coerce_key", _coerce)(value, hints[key], f"{name}.{key}")
        built[name] = cls(**kwargs)
    cfg = Config(**built)
    cfg.validate()
    return cfg


def load_config(path: str | Path | None, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """Read a TOML config (a shipped config's name such as ``paper``, a file, or the defaults when ``path``
    is None: core.resources.config_file) and apply overrides."""
    data: dict[str, Any] = {}
    source = "defaults"
    if path is not None:
        p = config_file(path)
        source = str(p)
        try:
            data = tomllib.loads(p.read_text())
        except FileNotFoundError:
            raise QuadfdiError(f"config file {p} does not exist (shipped configs, by name: "
                               f"{', '.join(config_names())})") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise QuadfdiError(f"cannot read config file {p}: {exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise QuadfdiError(f"config file {p} is not valid TOML: {exc}") from None
    return build_config(data, overrides, source)


def replace_section(cfg: Config, section: str, **changes: Any) -> Config:
    """A copy of ``cfg`` with some keys of one section changed (validated)."""
    new = dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **changes)})
    new.validate()
    return new
