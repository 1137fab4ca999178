"""The alarm policy of each exported network (manifest ``alarm_per_model``, weights.bin's
``alarm.models``): from the config ([alarm] and its optional [alarm.<net>] tables) or, with
``quadfdi export --alarm-from evaluation``, the policy ``quadfdi evaluate`` chose for that network
on validation flights (RUN/evaluation/evaluation.json ``models.<net>.policy``).

The networks listed: the export's own (cnode, gru), and the streaming GRU (sgru, whose
sgru_weights.bin copies weights.bin's on-board record) when its policy is given: an [alarm.sgru]
table, or (--alarm-from evaluation) an ``sgru`` entry in evaluation.json. A network not listed
runs the default policy (manifest ``alarm``, the record's ``alarm.policy``).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from quadfdi.core.alarm import POLICY_KEYS, AlarmConfig, check_policy
from quadfdi.core.errors import QuadfdiError

SOURCES = ("config", "evaluation")
EXPORTED = ("cnode", "gru")  # the networks weights.bin holds
EVALUATION = Path("evaluation") / "evaluation.json"


def _from_config(alarm: AlarmConfig) -> dict[str, dict]:
    nets = list(EXPORTED) + (["sgru"] if alarm.sgru else [])
    return {net: {"policy": alarm.policy_for(net), "source": "config"} for net in nets}


def _from_evaluation(root: Path) -> dict[str, dict]:
    path = root / EVALUATION
    if not path.is_file():
        raise QuadfdiError(f"--alarm-from evaluation: {path} does not exist (run `quadfdi evaluate --run {root}` first)")
    data = path.read_bytes()
    try:
        models = json.loads(data)["models"]
    except (ValueError, KeyError, TypeError):
        raise QuadfdiError(f"--alarm-from evaluation: {path} is not an evaluation.json (no 'models')") from None
    source = f"evaluation.json sha256 {hashlib.sha256(data).hexdigest()}"
    out = {}
    for net in list(EXPORTED) + (["sgru"] if "sgru" in models else []):
        pol = (models.get(net) or {}).get("policy") if isinstance(models, dict) else None
        if not isinstance(pol, dict) or any(k not in pol for k in POLICY_KEYS):
            raise QuadfdiError(f"--alarm-from evaluation: {path} has no chosen policy for network {net!r} "
                               f"(evaluated: {', '.join(sorted(models)) if isinstance(models, dict) else 'none'})")
        p = {"threshold": float(pol["threshold"]), "k": int(pol["k"]), "n": int(pol["n"]),
             "clear_m": int(pol["clear_m"]), "latch": bool(pol["latch"])}
        check_policy(p["threshold"], p["k"], p["n"], p["clear_m"], f"{path} models.{net}.policy.")
        out[net] = {"policy": p, "source": source}
    return out


def policies_per_model(root: str | Path, alarm: AlarmConfig, source: str = "config") -> dict[str, dict]:
    """network -> {"policy": {threshold, k, n, clear_m, latch}, "source": "config" or "evaluation.json
    sha256 <hex>"}; a one-line QuadfdiError when evaluation.json is absent or lacks a network."""
    if source not in SOURCES:
        raise QuadfdiError(f"--alarm-from must be one of {', '.join(SOURCES)}, found {source!r}")
    return _from_config(alarm) if source == "config" else _from_evaluation(Path(root))
