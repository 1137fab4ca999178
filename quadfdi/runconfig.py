"""The [run] section: what ``quadfdi run`` does beyond one pass of the stages (quadfdi/pipeline.py).
The app layer owns it: no stage reads it.

- ``study_sim_seeds``: after training, the seed study over these simulator seeds x ``[train].seeds``
  (``quadfdi train study --sim-seeds``) adds its prediction sets for the evaluation; empty = no study
  (the paper pipeline; ``make study`` runs it apart).
- ``realism_logs``: real flight logs (paths relative to the repository root, or absolute) that
  ``quadfdi realism`` holds the run's telemetry against; empty = no realism stage. A log that is
  absent is a one-line error when the stage runs, not at load time (a config travels between machines).
"""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.errors import QuadfdiError


@dataclass(frozen=True)
class RunConfig:
    study_sim_seeds: tuple[int, ...] = ()
    realism_logs: tuple[str, ...] = ()

    def validate(self) -> None:
        if any(s < 0 for s in self.study_sim_seeds) or len(set(self.study_sim_seeds)) != len(self.study_sim_seeds):
            raise QuadfdiError(f"run.study_sim_seeds must be distinct non-negative seeds, found {list(self.study_sim_seeds)}")
        if any(not str(p).strip() for p in self.realism_logs):
            raise QuadfdiError("run.realism_logs must not hold an empty path")
