"""The study's vocabulary: one way of solving a CNODE (``Setting``), the reference, the grid.

``Setting.parse`` reads the short forms of the config's ``solvers.matrix_train`` and
``solvers.matrix_deploy`` lists (``rk4:8``, ``rk4:8:avg``, ``dopri5:1e-3``, ``bosh3:1e-4:nojump``,
``dopri5:1e-3:restart``, ``ref``); ``default_settings(cfg.solvers)`` is the study's grid. No torch
here: the report and the renderer read settings without importing it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Sequence

from quadfdi.core.config import Config, replace_section
from quadfdi.solverstudy.config import SolversConfig
from quadfdi.core.errors import QuadfdiError
from quadfdi.models.solvers import ADAPTIVE_METHODS, FIXED_METHODS, SolverSpec, fixed_method

CONTROLS = ("point", "average")  # as models.variants.CNODE_CLASSES (no torch import here)
JUMP = {"both": (True, False), "on": (True,), "off": (False,)}  # solvers.jump -> jump_t values
ATOL_RATIO = 0.1  # atol = rtol * ATOL_RATIO for the study's adaptive settings
REF_RTOL = SolversConfig.ref_rtol
F1_TOL = SolversConfig.f1_tol  # "macro F1 within 0.2 point"
LABELS = [0, 1, 2, 3]
# The tiny study of tests and `quadfdi bench --quick` (solvers.* keys).
QUICK = {"sample": 4, "steps": (1, 4, 8), "rtols": (1e-2, 1e-3), "jump": "on", "fixed_methods": ("euler", "rk4"),
         "adaptive_methods": ("dopri5",)}


@dataclass(frozen=True)
class Setting:
    """One way of solving a CNODE: a solver, its step count or tolerances, the control, the dtype.

    ``steps`` applies to fixed methods, ``rtol``/``atol``/``jump_t`` to adaptive ones (None
    otherwise). ``control`` is "point" (u at the stage times, the trained CNODE's own form) or
    "average" (each fixed step sees the mean of u over the step, ``models.variants.AverageControlCNODE``).
    ``restart`` (adaptive only): a fresh ``odeint`` on each segment between two knots instead of
    one solve told the knots through ``jump_t`` (``models.variants.KnotRestartCNODE``); exact knot handling that
    does not rely on torchdiffeq's ``jump_t`` bookkeeping (see ``KnotRestartCNODE`` for why).
    ``reference`` marks the float64 tight-tolerance solve everything is compared to.
    """

    method: str
    steps: int | None = None
    rtol: float | None = None
    atol: float | None = None
    jump_t: bool | None = None
    control: str = "point"
    dtype: str = "float32"
    restart: bool = False
    reference: bool = False

    def __post_init__(self) -> None:
        if self.method in FIXED_METHODS:
            if self.steps is None or int(self.steps) != self.steps or self.steps < 1:
                raise ValueError(f"fixed method {self.method} needs steps >= 1, found {self.steps!r}")
            if any(v is not None for v in (self.rtol, self.atol, self.jump_t)) or self.restart:
                raise ValueError(f"fixed method {self.method} takes no rtol/atol/jump_t/restart")
        elif self.method in ADAPTIVE_METHODS:
            if self.steps is not None:
                raise ValueError(f"adaptive method {self.method} takes no steps")
            for name in ("rtol", "atol"):
                v = getattr(self, name)
                if v is None or not (math.isfinite(v) and v > 0):
                    raise ValueError(f"adaptive method {self.method} needs a positive {name}, found {v!r}")
            if self.jump_t is None:
                raise ValueError(f"adaptive method {self.method} needs jump_t True or False")
            if self.control != "point":
                raise ValueError("the average control is defined for fixed steps only")
            if self.restart and not self.jump_t:
                raise ValueError("a solve restarted at every knot respects the knots: restart needs jump_t True")
        else:
            raise ValueError(f"unknown solver method {self.method!r}; valid: {', '.join((*FIXED_METHODS, *ADAPTIVE_METHODS))}")
        if self.control not in CONTROLS:
            raise ValueError(f"control must be one of {', '.join(CONTROLS)}, found {self.control!r}")
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype must be float32 or float64, found {self.dtype!r}")

    @property
    def is_fixed(self) -> bool:
        return self.method in FIXED_METHODS

    @property
    def label(self) -> str:
        """Short unique name, e.g. ``rk4 N=8``, ``rk4 N=8 avg``, ``dopri5 rtol=1e-3 jump``."""
        if self.reference:
            return f"reference ({self.method} rtol={_fmt_tol(self.rtol)} {self.dtype}{' restart' if self.restart else ''})"
        if self.is_fixed:
            return f"{self.method} N={self.steps}" + (" avg" if self.control == "average" else "")
        tail = "restart" if self.restart else ("jump" if self.jump_t else "nojump")
        atol = "" if math.isclose(self.atol, self.rtol * ATOL_RATIO) else f" atol={_fmt_tol(self.atol)}"
        return f"{self.method} rtol={_fmt_tol(self.rtol)}{atol} {tail}" + ("" if self.dtype == "float32" else f" {self.dtype}")

    def spec(self) -> SolverSpec:
        if self.is_fixed:
            return SolverSpec(self.method, steps=int(self.steps))
        return SolverSpec(self.method, rtol=float(self.rtol), atol=float(self.atol), jump_t=bool(self.jump_t))

    def evals_per_window(self) -> int | None:
        """Exact evaluation count of a fixed setting (N x stages per step); None for adaptive."""
        return int(self.steps) * fixed_method(self.method).evals_per_step if self.is_fixed else None

    def to_dict(self) -> dict:
        return {"label": self.label, **asdict(self)}

    @staticmethod
    def parse(text: str) -> "Setting":
        """``rk4:8``, ``rk4:8:avg``, ``dopri5:1e-3`` (jump_t on), ``bosh3:1e-4:nojump``,
        ``dopri5:1e-3:restart``, ``ref``.

        Adaptive tolerances: atol = rtol / 10.
        """
        parts = [p.strip() for p in text.strip().split(":")]
        if parts[0] in ("ref", "reference") and len(parts) == 1:
            return reference_setting()
        try:
            if parts[0] in FIXED_METHODS and len(parts) in (2, 3):
                control = "point"
                if len(parts) == 3:
                    control = {"avg": "average", "average": "average", "point": "point"}[parts[2]]
                return Setting(parts[0], steps=int(parts[1]), control=control)
            if parts[0] in ADAPTIVE_METHODS and len(parts) in (2, 3):
                rtol = float(parts[1])
                mode = parts[2] if len(parts) == 3 else "jump"
                jump = {"jump": True, "nojump": False, "restart": True}[mode]
                return Setting(parts[0], rtol=rtol, atol=rtol * ATOL_RATIO, jump_t=jump, restart=mode == "restart")
        except (KeyError, ValueError):
            pass
        raise ValueError(f"bad solver setting {text!r}: expected e.g. rk4:8, rk4:8:avg, dopri5:1e-3, "
                         f"bosh3:1e-4:nojump or ref")


def _fmt_tol(x: float | None) -> str:
    if x is None:
        return "-"
    e = math.log10(x)
    return f"1e{int(round(e))}" if abs(e - round(e)) < 1e-9 else f"{x:g}"


def reference_setting(rtol: float = REF_RTOL) -> Setting:
    """float64 dopri5 restarted at every knot, atol = rtol / 10: the study's ground truth.

    Restarted rather than told the knots through ``jump_t``: at such tight tolerances
    torchdiffeq 0.2.5 loses its ``jump_t`` bookkeeping (see ``KnotRestartCNODE``).
    """
    return Setting("dopri5", rtol=rtol, atol=rtol * ATOL_RATIO, jump_t=True, dtype="float64", restart=True,
                   reference=True)


def default_settings(cfg: SolversConfig | None = None) -> list[Setting]:
    """The study's grid of ``cfg`` (default: the [solvers] defaults): every fixed method x N x
    control, every adaptive method x jump_t x rtol. The reference is not in it."""
    cfg = SolversConfig() if cfg is None else cfg
    out = [Setting(m, steps=int(n), control=c) for c in cfg.controls for m in cfg.fixed_methods for n in cfg.steps]
    out += [Setting(m, rtol=float(r), atol=float(r) * ATOL_RATIO, jump_t=bool(j))
            for m in cfg.adaptive_methods for j in JUMP[cfg.jump] for r in cfg.rtols]
    return out


def parse_settings(texts: Sequence[str], where: str) -> list[Setting]:
    """``Setting.parse`` of each text, no repeats; QuadfdiError naming the config key ``where``."""
    try:
        out = [Setting.parse(t) for t in texts]
    except ValueError as exc:
        raise QuadfdiError(f"{where}: {exc}") from None
    if len({s.label for s in out}) != len(out):
        raise QuadfdiError(f"{where} must not repeat a setting")
    return out


def quick_config(cfg: Config) -> Config:
    """``cfg`` with the tiny study of ``QUICK`` (what ``quadfdi bench --quick`` used to run)."""
    return replace_section(cfg, "solvers", **QUICK)
