"""The CrazyPAD protocol's table (data/crazypad/README.md): the rules' results per condition group and
per logging session, from the folder and file names of the logs.

Groups, from the folder a log lies in: ``normal_flight`` is healthy (a flight the reference was learned
from, known by its sha256, is ``reference`` and in no test group; the others are the ``healthy test``
flights); one cut propeller on motor 3 (``cut_propeller_M3_<a>mm...``, ``cut_m3_<a>mm...``) by ``a``,
the first number after M3, the largest single-blade cut: ``a >= 3`` mm, ``2 <= a < 3`` mm, ``a < 2`` mm;
two cut propellers (``cut_M2_*``, motors 2 and 1 or 2 alone), debris (``tape_on_propeller_*``), added
mass (``add_weight_*``), swinging load (``weight_on_string_*``). The session is the file name's prefix
(``E8_``, ``E9_``). The right motors of a group's flight are the motors its folder names (M3 for the
motor-3 cuts; M1 or M2 for the two cuts; the taped or weighted ones).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

HEALTHY_FOLDER = "normal_flight"
GROUPS = ("healthy test", "M3 cut >= 3 mm", "M3 cut 2-2.5 mm", "M3 cut < 2 mm", "two cuts (M1, M2)", "debris",
          "added mass", "swinging load")
SESSIONS = ("all", "E8", "E9")
_M3_CUT = re.compile(r"^cut_(?:propeller_)?[Mm]3_([0-9]+(?:\.[0-9]+)?)mm")


def group_of(folder: str) -> str | None:
    """The protocol group of a CrazyPAD folder name (None: not a CrazyPAD condition)."""
    if folder == HEALTHY_FOLDER:
        return "healthy test"
    m = _M3_CUT.match(folder)
    if m:
        a = float(m.group(1))
        return GROUPS[1] if a >= 3.0 else GROUPS[2] if a >= 2.0 else GROUPS[3]
    for prefix, group in (("cut_M2_", GROUPS[4]), ("tape_on_propeller_", GROUPS[5]), ("add_weight_", GROUPS[6]),
                          ("weight_on_string_", GROUPS[7])):
        if folder.startswith(prefix):
            return group
    return None


def session_of(file_name: str) -> str | None:
    m = re.match(r"^(E[0-9]+)_", file_name)
    return m.group(1) if m else None


def right_motors(folder: str) -> list[str]:
    """The motors a folder's name names (``M3``; ``M2``, ``M1``; ...), as the log names them."""
    return sorted({f"M{d}" for d in re.findall(r"(?:^|_)[Mm]([1-4])(?=_|$)", folder)})


def label(rows: list[dict], paths: list[Path], reference: dict) -> None:
    """Add ``group`` (None outside the protocol), ``role`` and ``session`` to each scored flight's row."""
    ref_sha = {f["sha256"] for f in reference["flights"]}
    for row, path in zip(rows, paths):
        group = group_of(path.parent.name)
        role = "reference" if row["sha256"] in ref_sha else "healthy" if group == "healthy test" else \
            "damaged" if group else None
        row.update(group=None if role == "reference" else group, role=role, session=session_of(path.name),
                   condition=path.parent.name, right_motors=right_motors(path.parent.name) if role == "damaged" else [])


def _auroc(healthy: list[float], damaged: list[float]) -> float | None:
    if not healthy or not damaged:
        return None
    from sklearn.metrics import roc_auc_score

    return float(roc_auc_score([0] * len(healthy) + [1] * len(damaged), healthy + damaged))


def _cell(rows: list[dict], rule: str, healthy: list[float]) -> dict:
    scores = [r["rules"][rule]["score"] for r in rows]
    alarmed = [r for r in rows if r["rules"][rule]["alarm"]]
    named = {}
    for r in alarmed:  # an alarm that names no motor (a network's class without a motor) counts as "none"
        motor = r["rules"][rule]["motor"] or "none"
        named[motor] = named.get(motor, 0) + 1
    top = max(healthy) if healthy else None
    return {"flights": len(rows), "alarmed": len(alarmed),
            "right_motor": sum(r["rules"][rule]["motor"] in r["right_motors"] for r in alarmed),
            "named": dict(sorted(named.items())), "max_score": max(scores), "mean_score": float(np.mean(scores)),
            "auroc": _auroc(healthy, scores) if rows[0]["role"] == "damaged" else None,
            "above_every_healthy": sum(s > top for s in scores) if top is not None and rows[0]["role"] == "damaged"
            else None}


def table(rows: list[dict], rules: tuple[str, ...]) -> list[dict]:
    """Per rule, group and session (all, E8, E9): flights, alarmed, right motor named among the alarmed,
    motors named, max and mean score, AUROC of the session's healthy test flights against the group's
    (scikit-learn's roc_auc_score) and how many score above every such healthy flight."""
    out = []
    for rule in rules:
        for group in GROUPS:
            for session in SESSIONS:
                sel = [r for r in rows if r.get("group") == group and session in ("all", r["session"])]
                if not sel:
                    continue
                healthy = [r["rules"][rule]["score"] for r in rows if r.get("group") == "healthy test"
                           and session in ("all", r["session"])]
                out.append({"rule": rule, "group": group, "session": session, **_cell(sel, rule, healthy)})
    return out
