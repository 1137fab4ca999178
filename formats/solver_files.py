"""Where the solver study's outputs live in a run folder, and their reader (written once, read by everyone).

    runs/<name>/solvers/solvers.json          the study (docs/solvers.md)
    runs/<name>/solvers/solvers.md            its tables and findings
    runs/<name>/solvers/solver_matrix.json    the train-by-deploy matrix
    runs/<name>/solvers/solver_matrix.md
    runs/<name>/solvers/matrix_models/*.pt    the matrix's trained CNODEs (reused with --reuse)
    runs/<name>/figures/solver_*.png          the figures, beside every other stage's
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json

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


def read_outputs(run_root: str | Path) -> tuple[dict | None, dict | None]:
    """The study's and the matrix's JSON of ``run_root`` (None for a file that is not there)."""
    files = SolverFiles(Path(run_root))
    return tuple(read_json(p, "solver file") if p.is_file() else None  # type: ignore[return-value]
                 for p in (files.study_json, files.matrix_json))


def load_records(run_root: str | Path) -> list[dict]:
    """The study's records (``solvers/solvers.json``'s ``solvers`` list; [] when it has not run)."""
    study, _ = read_outputs(run_root)
    if study is None:
        return []
    if not isinstance(study.get("solvers"), list):
        raise QuadfdiError(f"{SolverFiles(Path(run_root)).study_json} holds no list of solver records")
    return study["solvers"]
