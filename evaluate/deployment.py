"""Windowed or streaming: which member of each network family is deployed, chosen on validation.

Each family has a windowed member (a full window per decision) and a streaming one (one step per
sample, its state carried over the flight): CNODE = ``cnode`` / ``scnode``, GRU = ``gru`` / ``sgru``.
The deployed member is the one with the higher window macro F1 on the VALIDATION flights, the very
figure of evaluation.json's ``results`` (set ``validation``: the same prediction sets, pooling and
bootstrap as every other cell; nothing is recomputed here). Ties go to the windowed member, the
one every runtime of the chain (ONNX, C++ window, Cortex-M image) has run longest. A member without
a prediction set, or without a validation score, is no candidate; a family without a candidate has
no deployed member (``chosen`` null) and says why.

evaluation.json ``deployment`` (docs/formats.md): ``{"set", "metric", "rule", "families": {family:
{"chosen", "members", "candidates": {model: {"macro_f1": {value, lo, hi}, "flights",
"prediction_sets": [{path, sha256}]}}, "not_candidates": {model: why},
"streaming_minus_windowed_common_flights": {flights, diff, lo, hi} or null}}}``. The last is the paired
difference on the validation flights both members were scored on, read from ``paired``: members
trained on fewer simulator seeds are scored on fewer flights, and this says whether the choice
holds on the flights they share.
"""

from __future__ import annotations

from quadfdi.core.tables import md_table

FAMILIES = {"cnode": ("cnode", "scnode"), "gru": ("gru", "sgru")}  # family -> (windowed, streaming)
TITLES = {"cnode": "windowed CNODE", "scnode": "streaming CNODE", "gru": "windowed GRU", "sgru": "streaming GRU"}
SET = "validation"
RULE = ("higher window macro F1 on the validation flights (evaluation.json results, set validation); "
        "ties: the windowed member; a member without a prediction set or validation score is no candidate")


def _sets_of(model: str, entries: list[dict], inputs: list[dict]) -> list[dict]:
    """The model's indexed prediction sets with the sha256 evaluation.json's ``inputs`` records."""
    sha = {i["path"]: i["sha256"] for i in inputs}
    return [{"path": e["predictions"], "sha256": sha.get(e["predictions"])}
            for e in sorted(entries, key=lambda e: e["predictions"]) if e["model"] == model]


def choose_family(members: tuple[str, str], results: list[dict], entries: list[dict], inputs: list[dict]) -> dict:
    """The choice within one family (module docstring)."""
    val = {r["model"]: r for r in results if r["set"] == SET}
    candidates, absent, chosen = {}, {}, None
    for model in members:  # windowed first: a later member must be strictly better
        sets = _sets_of(model, entries, inputs)
        r = val.get(model)
        if not sets:
            absent[model] = "no prediction set in predictions/index.json"
        elif r is None or r["metrics"]["macro_f1"]["value"] is None:
            absent[model] = "no validation flights scored"
        else:
            candidates[model] = {"macro_f1": r["metrics"]["macro_f1"], "flights": r["flights"], "prediction_sets": sets}
            score = r["metrics"]["macro_f1"]["value"]
            if chosen is None or score > candidates[chosen]["macro_f1"]["value"]:
                chosen = model
    return {"chosen": chosen, "members": list(members), "candidates": candidates, "not_candidates": absent}


def _paired(fam: dict, pairs: list[dict]) -> dict | None:
    """streaming minus windowed macro F1 on the validation flights both were scored on (evaluation.json
    ``paired``): context for a choice between members scored on different flights, not the rule."""
    win, stream = fam["members"]
    for p in pairs:
        if p["set"] == SET and {p["a"], p["b"]} == {win, stream}:
            d, s = p["diff"]["macro_f1"], (1.0 if p["a"] == stream else -1.0)
            lo, hi = (None, None) if d["lo"] is None else sorted((s * d["lo"], s * d["hi"]))
            return {"flights": p["flights"], "diff": None if d["diff"] is None else s * d["diff"], "lo": lo, "hi": hi}
    return None


def deployment(results: list[dict], pairs: list[dict], entries: list[dict], inputs: list[dict]) -> dict:
    """evaluation.json ``deployment``: ``results`` and ``pairs`` (evaluate.protocol), the prediction
    index's ``entries`` and evaluation.json's ``inputs`` (paths with their sha256)."""
    fams = {fam: choose_family(members, results, entries, inputs) for fam, members in FAMILIES.items()}
    for f in fams.values():
        f["streaming_minus_windowed_common_flights"] = _paired(f, pairs)
    return {"set": SET, "metric": "macro_f1", "rule": RULE, "families": fams}


def deployed_models(ev: dict) -> set[str] | None:
    """The chosen member of every family, or None for an evaluation.json written before the choice."""
    dep = ev.get("deployment")
    if not isinstance(dep, dict):
        return None
    return {f["chosen"] for f in dep["families"].values() if f.get("chosen")}


def _ci(m: dict) -> str:
    return "—" if m.get("value") is None else (
        f"{m['value']:.3f}" + ("" if m.get("lo") is None else f" [{m['lo']:.3f}, {m['hi']:.3f}]"))


def markdown(ev: dict) -> list[str]:
    """evaluation.md's section on the choice (empty for an evaluation.json without it)."""
    dep = ev.get("deployment")
    if not isinstance(dep, dict):
        return []
    rows = []
    for fam, f in dep["families"].items():
        for model in f["members"]:
            c = f["candidates"].get(model)
            rows.append([fam, f"{TITLES.get(model, model)} ({model})",
                         _ci(c["macro_f1"]) if c else f"— ({f['not_candidates'].get(model, '?')})",
                         c["flights"] if c else "—", "**deployed**" if f["chosen"] == model else ""])
    common = []
    for fam, f in dep["families"].items():
        c = f.get("streaming_minus_windowed_common_flights")
        if c and c["diff"] is not None:
            common.append(f"{fam} {c['diff']:+.3f}" + ("" if c["lo"] is None else f" [{c['lo']:+.3f}, {c['hi']:+.3f}]")
                          + f" on {c['flights']} flights")
    return ["## Windowed or streaming (chosen on validation flights)", "", f"Rule: {dep['rule']}.", "",
            *md_table(["family", "member", "validation macro F1 [95 %]", "flights", ""], rows),
            *([f"Streaming minus windowed on the validation flights both were scored on (paired): "
               f"{'; '.join(common)}.", ""] if common else [])]
