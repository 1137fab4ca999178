"""Where the solver study's outputs live in a run folder (written once, read by everyone).

    runs/<name>/solvers/solvers.json          the study (docs/solvers.md)
    runs/<name>/solvers/solvers.md            its tables and findings
    runs/<name>/solvers/solver_matrix.json    the train-by-deploy matrix
    runs/<name>/solvers/solver_matrix.md
    runs/<name>/solvers/matrix_models/*.pt    the matrix's trained CNODEs (reused with --reuse)
    runs/<name>/figures/solver_*.png          the figures, beside every other stage's
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

STUDY_FIGURES = ("solver_error_vs_nfe.png", "solver_f1_vs_latency.png")
MATRIX_FIGURES = ("solver_matrix_f1.png", "solver_controls.png")


@dataclass(frozen=True)
class SolverFiles:
    """The solver study's files of the run folder ``root``."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def dir(self) -> Path:
        return self.root / "solvers"

    @property
    def study_json(self) -> Path:
        return self.dir / "solvers.json"

    @property
    def study_md(self) -> Path:
        return self.dir / "solvers.md"

    @property
    def matrix_json(self) -> Path:
        return self.dir / "solver_matrix.json"

    @property
    def matrix_md(self) -> Path:
        return self.dir / "solver_matrix.md"

    @property
    def matrix_models(self) -> Path:
        return self.dir / "matrix_models"

    @property
    def figures(self) -> Path:
        return self.root / "figures"

    def rel(self, path: Path) -> str:
        """``path`` relative to the run folder, for messages and reports (``solvers/solvers.json``)."""
        return str(Path(path).relative_to(self.root))
