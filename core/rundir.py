"""The run folder: every stage reads its inputs from and writes its outputs to ``runs/<name>/``.

File names live here once, so the stages and the docs agree on them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from quadfdi.core.atomic import ensure_dir
from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.stage import recover_run

# evaluate's result, which export reads (--alarm-from evaluation): relative to the run folder, as stage
# records name it
EVALUATION_JSON = "evaluation/evaluation.json"


@dataclass(frozen=True)
class RunDir:
    """The file names of one run folder (``root``): each stage's outputs, named once here."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    config = property(lambda self: self.root / "config.toml")
    dataset = property(lambda self: self.root / "dataset.npz")
    figures = property(lambda self: self.root / "figures")
    metrics = property(lambda self: self.root / "metrics.json")
    export = property(lambda self: self.root / "export")
    evaluation = property(lambda self: self.root / EVALUATION_JSON)

    def checkpoint(self, kind: str) -> Path:
        return self.root / f"{kind}.pt"

    def predictions(self, kind: str) -> Path:
        return self.root / f"predictions_{kind}.npz"


def create_run(out: str | Path, cfg: Config) -> RunDir:
    """Make the run folder (and recover it). config.toml is not written here: the sim stage
    publishes it with the dataset, after the simulation succeeded, so a failed or killed
    re-simulation never leaves a new config beside the old dataset."""
    run = RunDir(ensure_dir(out))
    recover_run(run.root)
    return run


def open_run(path: str | Path, overrides: list[str] | tuple[str, ...] = (), need: tuple[str, ...] = ()) -> tuple[RunDir, Config]:
    """An existing run folder and its stored config (with ``--set`` overrides applied)."""
    run = RunDir(Path(path))
    if not run.root.is_dir():
        raise QuadfdiError(f"run folder {run.root} does not exist (run `quadfdi sim --out {run.root}` first)")
    recover_run(run.root)
    if not run.config.is_file() or run.config.is_symlink():
        raise QuadfdiError(f"{run.config} is missing or not a regular file: {run.root} is not a quadfdi run folder")
    if not run.config.read_bytes().strip():
        raise QuadfdiError(f"{run.config} is empty (expected the [sim] ... sections `quadfdi sim` writes): "
                           f"re-run quadfdi sim --out {run.root}")
    for attr in need:
        p = getattr(run, attr)
        if not p.exists():
            raise QuadfdiError(f"{p} is missing: run the stage that writes it first")
    return run, load_config(run.config, overrides)
