"""The one network ``quadfdi crazypad`` scores, and its alarm policy, chosen from a run's simulated
validation flights only (no CrazyPAD flight enters the choice).

- The network: of the export's networks (cnode, gru), the one with the higher window macro F1 on the
  validation flights that ``quadfdi evaluate`` measured (the manifest's ``deployment``:
  ``formats.manifest.validation_scores``, every simulator seed's validation flights pooled), as
  ``quadfdi detect`` picks it; when the export records no such scores, the one whose training kept the
  higher validation macro F1 (``RUN/history.json`` ``<net>.val_macro_f1``: one value per epoch; training
  keeps the weights of the best epoch, train/loop.py, so the figure is the list's largest). A tie keeps
  the first in ``NETWORKS`` order.
- Its policy: the one the export runs for it (``formats.export_folder.Export.policy``). When the export
  took it from ``quadfdi evaluate`` (source ``evaluation.json sha256 ...``: chosen on validation flights
  by the rule of evaluate/policy.py), ``RUN/evaluation/evaluation.json`` must be those bytes, and its
  validation row of that policy (false alarms per flight-hour, faulty flights detected) is quoted.
  A policy from the config ([alarm]) is accepted and said to be one (no validation choice).

Refused in one line: no ``RUN/export``, an export whose profile does not read any log's channels
(``core.profiles.is_masked``), no validation macro F1 for any exported network, an evaluation.json that
is not the one the export's policy came from.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import is_masked
from quadfdi.core.rundir import EVALUATION_JSON
from quadfdi.formats.manifest import validation_scores

NETWORKS = ("cnode", "gru")
HISTORY = "history.json"
EVAL_SOURCE = "evaluation.json sha256 "


def _open_export(run: Path):
    from quadfdi.formats.export_folder import MANIFEST, Export

    folder = run / "export"
    if not (folder / MANIFEST).is_file():
        raise QuadfdiError(f"--run {run}: no export ({folder / MANIFEST} does not exist; run `quadfdi export --run "
                           f"{run}` first)")
    ex = Export.open(folder)
    profile = ex.profile()
    if not is_masked(profile):
        raise QuadfdiError(f"--run {run}: its export uses profile {profile!r}, not a masked profile: the CrazyPAD "
                           "logs need one that reads whatever channels a log has (e.g. flightlog-mask)")
    return ex


def _validation_f1(run: Path, nets: list[str]) -> dict[str, float]:
    path = run / HISTORY
    try:
        hist = json.loads(path.read_text())
    except FileNotFoundError:
        raise QuadfdiError(f"--run {run}: no {HISTORY} (quadfdi train writes each network's validation macro F1 "
                           "there)") from None
    except ValueError:
        raise QuadfdiError(f"{path} is not JSON") from None
    out = {}
    for net in nets:
        f1 = (hist.get(net) or {}).get("val_macro_f1") if isinstance(hist, dict) else None
        if isinstance(f1, list) and f1 and all(isinstance(v, (int, float)) for v in f1):
            out[net] = float(max(f1))
    if not out:
        raise QuadfdiError(f"{path} holds no validation macro F1 (val_macro_f1) for the exported networks "
                           f"({', '.join(nets)})")
    return out


def _validation_row(run: Path, net: str, policy: dict, source: str) -> dict | None:
    """evaluate's validation counts of ``policy`` for ``net`` (None for a policy from the config)."""
    if not source.startswith(EVAL_SOURCE):
        return None
    path = run / EVALUATION_JSON
    if not path.is_file():
        raise QuadfdiError(f"--run {run}: the export's {net} policy came from {path}, which is not there")
    data = path.read_bytes()
    if hashlib.sha256(data).hexdigest() != source[len(EVAL_SOURCE):].strip():
        raise QuadfdiError(f"{path} is not the evaluation.json the export's {net} policy came from ({source})")
    ev = json.loads(data)
    for row in (ev.get("models", {}).get(net) or {}).get("sweep") or []:
        if all(row.get(k) == v for k, v in policy.items()):
            return {k: row.get(k) for k in ("fa_per_h", "detection_rate", "delay_onset_s", "exposure_h", "faults")}
    return None


def scored_network(run: str | Path) -> dict:
    """The export folder, its profile, the network scored and its policy, with the files and figures
    that chose them (module docstring)."""
    run = Path(run)
    if not run.is_dir():
        raise QuadfdiError(f"--run {run}: not a folder")
    ex = _open_export(run)
    nets = [n for n in NETWORKS if f"{n}_fp32" in ex.manifest.get("artifacts", {})]
    f1 = {n: v for n, v in validation_scores(ex.manifest).items() if n in nets}
    chosen_by = {"file": str(ex.root / "manifest.json"),
                 "figure": "window macro F1 on the validation flights, quadfdi evaluate", "val_macro_f1": f1}
    if len(f1) < len(nets):  # no evaluation behind the export: training's own validation score
        f1 = _validation_f1(run, nets)
        chosen_by = {"file": str(run / HISTORY), "figure": "best validation macro F1 over the epochs",
                     "val_macro_f1": f1}
    net = max(f1, key=lambda n: (f1[n], -NETWORKS.index(n)))
    policy, source = ex.policy(net)
    return {"run": str(run), "export": str(ex.root), "profile": ex.profile(), "net": net, "policy": policy,
            "policy_source": source, "policy_chosen_on_validation": source.startswith(EVAL_SOURCE),
            "policy_validation": _validation_row(run, net, policy, source),
            "chosen_by": chosen_by}


def policy_text(p: dict) -> str:
    """``p >= 0.97, 2 of 3, clear 3`` (as the real-flights tables say it)."""
    return (f"p >= {p['threshold']:g}, {p['k']} of {p['n']}, clear {p['clear_m']}"
            + (", latched" if p.get("latch") else ""))
