"""Where the solver study's outputs live in a run folder (written once, read by everyone).

    runs/<name>/solvers/solvers.json          the study (docs/solvers.md)
    runs/<name>/solvers/solvers.md            its tables and findings
    runs/<name>/solvers/solver_matrix.json    the train-by-deploy matrix
    runs/<name>/solvers/solver_matrix.md
    runs/<name>/solvers/matrix_models/*.pt    the matrix's trained CNODEs (reused with --reuse)
    runs/<name>/figures/solver_*.png          the figures, beside every other stage's
"""

from __future__ import annotations

from pathlib import Path

STUDY_FIGURES = ("solver_error_vs_nfe.png", "solver_f1_vs_latency.png")
MATRIX_FIGURES = ("solver_matrix_f1.png", "solver_controls.png")


class SolverFiles:
    """The solver study's files of the run folder ``root`` (paths as in the module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.dir = self.root / "solvers"
        self.study_json, self.study_md = self.dir / "solvers.json", self.dir / "solvers.md"
        self.matrix_json, self.matrix_md = self.dir / "solver_matrix.json", self.dir / "solver_matrix.md"
        self.matrix_models = self.dir / "matrix_models"  # the matrix's trained CNODEs (reused with --reuse)
        self.figures = self.root / "figures"  # beside every other stage's

    def rel(self, path: Path) -> str:
        """``path`` relative to the run folder, for messages and reports (``solvers/solvers.json``)."""
        return str(Path(path).relative_to(self.root))
