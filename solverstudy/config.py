"""The [solvers] section: the ODE-solver study of a trained CNODE and the train-by-deploy matrix
(docs/solvers.md)."""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.limits import MAX_THREADS
from quadfdi.core.sections import at_most, choice, positive


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
        choice(self, "jump", ("both", "on", "off"))
        positive(self, "ref_rtol", "threads", "matrix_batch")
        at_most(self, MAX_THREADS, "threads", "matrix_threads")
        for name in ("sample", "sample_seed", "f1_tol", "break_tol", "matrix_epochs", "matrix_max_train_windows",
                     "matrix_threads"):
            if getattr(self, name) < 0:
                raise QuadfdiError(f"solvers.{name} must not be negative, found {getattr(self, name)}")
        if not self.matrix_train or not self.matrix_deploy:
            raise QuadfdiError("solvers.matrix_train and solvers.matrix_deploy need at least one setting each")
