"""The alarm policies an export writes, decided once (``Policies``): the default policy (manifest
``alarm``, weights.bin's ``alarm.policy``) and each exported network's (manifest ``alarm_per_model``,
weights.bin's ``alarm.models``), from the config ([alarm] and its optional [alarm.<net>] tables) or,
with ``quadfdi export --alarm-from evaluation``, the policy ``quadfdi evaluate`` chose for that
network on validation flights (``models.<net>.policy`` of core.rundir.EVALUATION_JSON).

evaluation.json is read once (``policies_of``, which ``quadfdi export`` calls before it imports torch,
so that a refusal is quick) and is an input of the export stage: ``Policies.consume`` records it in the
stage record after checking it against the evaluate stage's record and against the bytes the policies
came from. So a republished evaluation.json makes the export stale (core.records.check_upstream), and
a hand-edited one is refused.

The networks listed: the export's own (cnode, gru), and the streaming GRU (sgru, whose
sgru_weights.bin copies weights.bin's on-board record) when its policy is given: an [alarm.sgru]
table, or (--alarm-from evaluation) an ``sgru`` entry in evaluation.json. A network not listed
runs the default policy (core.alarm.resolve_policy).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from quadfdi.core.alarm import AlarmConfig, check_policy
from quadfdi.core.contracts import POLICY_KEYS, POLICY_TYPES
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import EVALUATION_JSON, RunDir

SOURCES = ("config", "evaluation")
EXPORTED = ("cnode", "gru")  # the networks weights.bin holds


@dataclass(frozen=True)
class Policies:
    """``default``: {threshold, k, n, clear_m, latch}; ``per_model``: network -> {"policy": ..., "source":
    "config" or "evaluation.json sha256 <hex>"}; ``evaluation_sha256``: the evaluation.json they were
    read from (None: from the config)."""

    default: dict
    per_model: dict[str, dict]
    evaluation_sha256: str | None = None

    def per_network(self) -> dict[str, dict]:
        """network -> policy (weights.bin's alarm.models)."""
        return {net: e["policy"] for net, e in self.per_model.items()}

    def consume(self, st) -> None:
        """Record evaluation.json as an input of the stage ``st`` (core.stage.StageWriter) when the
        policies came from it: checked against its producer's record and the bytes read."""
        if self.evaluation_sha256 is None:
            return
        st.consume(EVALUATION_JSON)
        if st.inputs[EVALUATION_JSON]["sha256"] != self.evaluation_sha256:
            raise QuadfdiError(f"--alarm-from evaluation: {st.root / EVALUATION_JSON} changed while the export read it: "
                               f"run the export again")


def _from_config(alarm: AlarmConfig) -> Policies:
    nets = list(EXPORTED) + (["sgru"] if alarm.sgru else [])
    return Policies(alarm.policy(), {net: {"policy": alarm.policy_for(net), "source": "config"} for net in nets})


def _from_evaluation(run: RunDir, alarm: AlarmConfig) -> Policies:
    path = run.evaluation
    if not path.is_file():
        raise QuadfdiError(f"--alarm-from evaluation: {path} does not exist (run `quadfdi evaluate --run {run.root}` first)")
    data = path.read_bytes()
    try:
        models = json.loads(data)["models"]
    except (ValueError, KeyError, TypeError):
        raise QuadfdiError(f"--alarm-from evaluation: {path} is not an evaluation.json (no 'models')") from None
    sha = hashlib.sha256(data).hexdigest()
    out = {}
    for net in list(EXPORTED) + (["sgru"] if "sgru" in models else []):
        pol = (models.get(net) or {}).get("policy") if isinstance(models, dict) else None
        if not isinstance(pol, dict) or any(k not in pol for k in POLICY_KEYS):
            raise QuadfdiError(f"--alarm-from evaluation: {path} has no chosen policy for network {net!r} "
                               f"(evaluated: {', '.join(sorted(models)) if isinstance(models, dict) else 'none'})")
        p = {key: POLICY_TYPES[key](pol[key]) for key in POLICY_KEYS}
        check_policy(p["threshold"], p["k"], p["n"], p["clear_m"], f"{path} models.{net}.policy.")
        out[net] = {"policy": p, "source": f"evaluation.json sha256 {sha}"}
    return Policies(alarm.policy(), out, sha)


def policies_of(run: RunDir, alarm: AlarmConfig, source: str = "config") -> Policies:
    """The policies of an export of ``run`` (module docstring); a one-line QuadfdiError for another
    ``source``, or when evaluation.json is absent or lacks a network."""
    if source not in SOURCES:
        raise QuadfdiError(f"--alarm-from must be one of {', '.join(SOURCES)}, found {source!r}")
    return _from_config(alarm) if source == "config" else _from_evaluation(run, alarm)
