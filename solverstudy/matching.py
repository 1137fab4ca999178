""""Matches": for each adaptive setting, the cheapest fixed setting at least as accurate.

Pure functions of the study's records (dicts, or the JSON's), so ``render`` recomputes the table
with another rule without solving anything.
"""

from __future__ import annotations

from typing import Iterable, Sequence

from quadfdi.solverstudy.settings import ADAPTIVE_METHODS, CONTROLS, F1_TOL, FIXED_METHODS


def matches(fixed: dict, adaptive: dict, f1_tol: float = F1_TOL, two_sided: bool = False) -> bool:
    """Matches: max logit error no larger than the adaptive setting's, and macro F1 not more than
    ``f1_tol`` below it (``two_sided``: not more than ``f1_tol`` away on either side).

    One-sided by default: the issue asks for "the cheapest fixed setting at least as accurate",
    and a fixed setting closer to the reference that also scores higher is that; the literal
    "within 0.2 point" would reject it.
    """
    if fixed["max_logit_err"] > adaptive["max_logit_err"]:
        return False
    diff = fixed["macro_f1"] - adaptive["macro_f1"]
    return (abs(diff) if two_sided else -diff) <= f1_tol + 1e-12


def matched_table(records: Iterable[dict], f1_tol: float = F1_TOL, two_sided: bool = False,
                  controls: Sequence[str] | None = None) -> list[dict]:
    """For each adaptive record (not the reference): the cheapest matching fixed record, or None.

    Cheapest = fewest ``nfe_per_window``; a tie goes to the smaller max error. ``ratio`` is the
    adaptive setting's evaluations over the fixed one's (how many times fewer the fixed needs).
    Candidates: fixed records whose control is in ``controls``; by default only the adaptive
    setting's own control (point), i.e. another solver of the very same model. The step-average
    control solves the same ODE only in the limit N -> infinity (and exactly the same model only
    for weights that behave as an ODE), so it is matched separately (``controls=CONTROLS``).
    """
    records = list(records)
    fixed = [r for r in records if r["method"] in FIXED_METHODS]
    out = []
    for a in records:
        if a["method"] not in ADAPTIVE_METHODS or a.get("reference"):
            continue
        allowed = (a.get("control", "point"),) if controls is None else tuple(controls)
        ok = [f for f in fixed if f.get("control", "point") in allowed and matches(f, a, f1_tol, two_sided)]
        best = min(ok, key=lambda f: (f["nfe_per_window"], f["max_logit_err"])) if ok else None
        out.append({
            "adaptive": a["label"],
            "adaptive_nfe": a["nfe_per_window"],
            "adaptive_max_logit_err": a["max_logit_err"],
            "adaptive_macro_f1": a["macro_f1"],
            "fixed": best["label"] if best else None,
            "fixed_nfe": best["nfe_per_window"] if best else None,
            "fixed_max_logit_err": best["max_logit_err"] if best else None,
            "fixed_macro_f1": best["macro_f1"] if best else None,
            "ratio": (a["nfe_per_window"] / best["nfe_per_window"]) if best else None,
        })
    return out


def matched_tables(records: list[dict], f1_tol: float = F1_TOL, two_sided: bool = False) -> dict:
    """The study's ``matched`` (same control only) and ``matched_any_control`` (None when every
    record has the point control) tables."""
    return {"matched": matched_table(records, f1_tol, two_sided),
            "matched_any_control": (matched_table(records, f1_tol, two_sided, CONTROLS)
                                    if any(r.get("control", "point") != "point" for r in records) else None)}
