"""manifest.json ``deployment``: which member of each network family (windowed or streaming) is
deployed, as ``quadfdi evaluate`` chose it on validation flights (evaluate/deployment.py), with the
sha256 of the evaluation.json it was read from.

Read once, before the export builds anything (``deployment_of``; ``quadfdi export`` calls it before
it imports torch, so that a refusal is quick):

- no evaluation.json, one that no evaluate stage published, one made from prediction sets that were
  republished since (stale), or one written before the choice existed: ``deployment`` is null and
  ``deployment_note`` says why; the export never guesses a member;
- an evaluation.json whose bytes no longer match the sha256 its evaluate stage recorded (edited after
  it was published): refused in one line, nothing written;
- otherwise the choice, each candidate's validation macro F1 with its flight-bootstrap interval, and
  evaluation.json's sha256; evaluation.json is then an input of the export stage (``consume``), so a
  republished evaluation makes the export stale.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from quadfdi.core import records
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import EVALUATION_JSON, RunDir


@dataclass(frozen=True)
class Deployment:
    """``entry``: manifest ``deployment`` (None: none recorded); ``note``: why it is None."""

    entry: dict | None
    note: str | None = None

    def consume(self, st) -> None:
        """Record evaluation.json as an input of the export stage ``st`` when the entry came from it."""
        if self.entry is None:
            return
        st.consume(EVALUATION_JSON)
        if st.inputs[EVALUATION_JSON]["sha256"] != self.entry["evaluation_sha256"]:
            raise QuadfdiError(f"{st.root / EVALUATION_JSON} changed while the export read it: run the export again")


def _null(note: str) -> Deployment:
    return Deployment(None, note)


def _families(dep, path) -> dict:
    """The families of evaluation.json's ``deployment``, checked (one-line error otherwise)."""
    fams = dep.get("families") if isinstance(dep, dict) else None
    if not isinstance(fams, dict) or not fams:
        raise QuadfdiError(f"{path}: 'deployment' has no families: not an evaluation.json of quadfdi evaluate")
    out = {}
    for fam, f in fams.items():
        cands = f.get("candidates") if isinstance(f, dict) else None
        if not isinstance(cands, dict) or (f.get("chosen") is not None and f["chosen"] not in cands):
            raise QuadfdiError(f"{path}: deployment.families.{fam} chooses a member that is not one of its candidates")
        out[fam] = {"chosen": f["chosen"], "members": list(f.get("members", [])),
                    "candidates": {m: {"macro_f1": c["macro_f1"], "flights": c["flights"]} for m, c in cands.items()},
                    "not_candidates": dict(f.get("not_candidates", {}))}
    return out


def deployment_of(run: RunDir) -> Deployment:
    """The deployment an export of ``run`` records (module docstring)."""
    path = run.evaluation
    if not path.is_file():
        return _null(f"no {EVALUATION_JSON} when exported: run `quadfdi evaluate --run {run.root}`, then the export")
    data = path.read_bytes()
    sha = hashlib.sha256(data).hexdigest()
    found = records.producer_of(run.root, EVALUATION_JSON)
    if found is None:
        return _null(f"{EVALUATION_JSON} (sha256 {sha}) was not published by quadfdi evaluate: not trusted")
    stage, rec, entry = found
    if entry["sha256"] != sha:
        raise QuadfdiError(f"{path}: sha256 {sha[:16]}... differs from {entry['sha256'][:16]}... recorded in "
                           f".stages/{stage}.json (changed after it was published): re-run quadfdi {stage}")
    try:
        records.check_upstream(run.root, stage, rec)
    except QuadfdiError as exc:
        return _null(f"{EVALUATION_JSON} (sha256 {sha}) is stale: {exc}")
    try:
        dep = json.loads(data).get("deployment")
    except (ValueError, AttributeError):
        raise QuadfdiError(f"{path} is not an evaluation.json (not a JSON object)") from None
    if dep is None:
        return _null(f"{EVALUATION_JSON} (sha256 {sha}) predates the windowed-or-streaming choice: "
                     f"re-run `quadfdi evaluate --run {run.root}`, then the export")
    return Deployment({"evaluation": EVALUATION_JSON, "evaluation_sha256": sha, "set": dep.get("set"),
                       "metric": dep.get("metric"), "rule": dep.get("rule"), "families": _families(dep, path)})
