"""Markdown tables of the solver study and the train-by-deploy matrix, with findings in words.

Every sentence here is computed from the numbers it describes (nothing hand-written about the
results), so a rerun at another scale rewrites its own conclusions. Inputs are the dicts of
``solverstudy.study.run_study`` and ``solverstudy.matrix.run_matrix`` (or their JSON files).

What other stages read (from the run folder's files alone, no torch imported):
``report_section(run_root)`` (the run report's solver section), ``headline(run_root)``
and ``load_records(run_root)`` (the study's records, bench.json's ``solvers`` list).
"""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import not_run
from quadfdi.core.tables import md_table
from quadfdi.formats.solver_files import SolverFiles, read_outputs
from quadfdi.solverstudy.settings import F1_TOL


def _e(x: float | None) -> str:
    return "—" if x is None else ("0" if x == 0 else f"{x:.1e}")


def _f(x: float | None, nd: int = 4) -> str:
    return "—" if x is None else f"{x:.{nd}f}"


def _n(x: float | None) -> str:
    if x is None:
        return "—"
    return f"{x:.0f}" if abs(x - round(x)) < 1e-9 or x >= 100 else f"{x:.1f}"


def _table(head: list[str], rows: list[list[str]]) -> list[str]:
    return md_table(head, rows)[:-1]  # the callers place their own blank lines


def _rule(meta: dict) -> str:
    tol = meta.get("f1_tol", F1_TOL) * 100
    if meta.get("f1_two_sided"):
        return f"within {tol:.1f} point of it"
    return f"at most {tol:.1f} point below it (a higher F1 is at least as accurate)"


def study_headline(study: dict, adaptive: str = "dopri5 rtol=1e-3 jump") -> str:
    """One sentence on the cheapest fixed setting that matches ``adaptive``."""
    row = next((m for m in study["matched"] if m["adaptive"] == adaptive), None)
    if row is None:
        return f"The study has no {adaptive} setting."
    if row["fixed"] is None:
        return (f"No fixed-step setting matches {adaptive} ({_n(row['adaptive_nfe'])} evaluations per window, "
                f"max logit error {_e(row['adaptive_max_logit_err'])}, macro F1 {_f(row['adaptive_macro_f1'])}).")
    return (f"The cheapest fixed-step setting that matches {adaptive} ({_n(row['adaptive_nfe'])} evaluations per "
            f"window, max logit error {_e(row['adaptive_max_logit_err'])}) is {row['fixed']} "
            f"({_n(row['fixed_nfe'])} evaluations, error {_e(row['fixed_max_logit_err'])}): "
            f"{row['ratio']:.2f} times fewer evaluations.")


def control_sentence(study: dict) -> str:
    """Point against step-average control for the same weights, at equal N (same evaluations)."""
    by = {(r["method"], r["steps"], r["control"]): r for r in study["solvers"] if r["steps"] is not None}
    pairs = sorted((k[0], k[1]) for k in by if k[2] == "average" and (k[0], k[1], "point") in by)
    if not pairs:
        return ""
    method = "rk4" if any(m == "rk4" for m, _ in pairs) else pairs[0][0]
    parts = []
    for m, n in pairs:
        if m != method:
            continue
        p, a = by[(m, n, "point")], by[(m, n, "average")]
        parts.append(f"N = {n}: {_e(p['max_logit_err'])} point, {_e(a['max_logit_err'])} average")
    return (f"Max logit error of {method} against the reference with the same weights, by control at equal N: "
            + "; ".join(parts) + ".")


def study_markdown(study: dict, command: str | None = None, figures: str = "../figures") -> str:
    meta, ref = study["meta"], study["reference"]
    lines = ["## Solvers: fixed against adaptive steps", ""]
    if command:
        lines += [f"Made by `{command}`.", ""]
    lines += [
        f"Model: `{meta.get('checkpoint', '?')}` ({meta.get('trained_with', '?')}, {meta['control']} control). "
        f"Windows: {meta['sample']}. Reference: {ref['method']} in {ref['dtype']} at rtol {_e(ref['rtol'])}, "
        f"atol {_e(ref['atol'])}, restarted at every knot (torchdiffeq's `jump_t` loses track of the knots at such "
        f"tolerances, see docs/solvers.md): macro F1 {_f(ref['macro_f1'])} on these windows"
        + (f", {_f(ref['split_macro_f1'])} on the whole test split" if ref.get("split_macro_f1") is not None else "")
        + f", {_n(ref['nfe_per_window'])} evaluations per window. Adaptive settings use {meta['atol_rule']}. "
        f"Latency: {meta['latency_note']}."
        + (f" Reference check: it differs from {meta['reference_check']['against']} by at most "
           f"{_e(meta['reference_check']['max_abs_logit_diff'])} in a logit on {meta['reference_check']['n_windows']} "
           "windows." if meta.get("reference_check") else ""),
        "",
        f"**{study_headline(study)}**",
        "",
        "### Matched accuracy",
        "",
        "A fixed setting matches an adaptive one when its max abs logit error against the reference is no "
        f"larger and its macro F1 is {_rule(meta)}, both on the same windows. Cheapest = fewest evaluations per window; "
        "the last column is the adaptive setting's evaluations over the fixed one's.",
        "",
    ]
    rows = []
    for m in study["matched"]:
        rows.append([m["adaptive"], _n(m["adaptive_nfe"]), _e(m["adaptive_max_logit_err"]), _f(m["adaptive_macro_f1"]),
                     m["fixed"] or "none matches", _n(m["fixed_nfe"]), _e(m["fixed_max_logit_err"]),
                     _f(m["fixed_macro_f1"]), "—" if m["ratio"] is None else f"{m['ratio']:.2f}x"])
    lines += _table(["adaptive", "NFE", "max err", "F1", "cheapest matching fixed", "NFE", "max err", "F1",
                     "fewer evaluations"], rows)
    if study.get("matched_any_control"):
        lines += ["", "With the step-average control also as a candidate (the same weights driven by each step's "
                  "mean control: another discretisation of the same ODE, which tends to it as N grows):", ""]
        rows = [[m["adaptive"], _n(m["adaptive_nfe"]), _e(m["adaptive_max_logit_err"]), m["fixed"] or "none matches",
                 _n(m["fixed_nfe"]), _e(m["fixed_max_logit_err"]), "—" if m["ratio"] is None else f"{m['ratio']:.2f}x"]
                for m in study["matched_any_control"]]
        lines += _table(["adaptive", "NFE", "max err", "cheapest matching fixed, any control", "NFE", "max err",
                         "fewer evaluations"], rows)
        sentence = control_sentence(study)
        if sentence:
            lines += ["", sentence]
    lines += ["", "### Every setting", "",
              "`F1` and the errors are on the study's windows; `split F1` is on the whole test split (fixed steps "
              "only: their result does not depend on the batch). NFE: mean evaluations per window (min–max).", ""]
    rows = []
    for r in study["solvers"]:
        spread = "" if r["nfe_min"] == r["nfe_max"] else f" ({r['nfe_min']}–{r['nfe_max']})"
        rows.append([r["label"], _f(r["macro_f1"]), _f(r.get("split_macro_f1")), _f(r["argmax_agreement"], 3),
                     _e(r["max_logit_err"]), _e(r["mean_logit_err"]), _n(r["nfe_per_window"]) + spread,
                     f"{r['latency_us'] / 1e3:.2f}"])
    lines += _table(["setting", "F1", "split F1", "agreement", "max err", "mean err", "NFE / window", "latency ms"], rows)
    lines += ["", f"![logit error vs evaluations]({figures}/solver_error_vs_nfe.png)",
              f"![macro F1 vs latency]({figures}/solver_f1_vs_latency.png)", ""]
    return "\n".join(lines)


def ott_sentence(matrix: dict) -> str:
    """Whether fixed-step-trained models break under other solvers, and where the critical step lies."""
    ott = matrix.get("ott", [])
    tol = matrix["meta"].get("break_tol", 0.02)
    point = [o for o in ott if o["control"] == "point" and o["step"] is not None]
    if not point:
        return "No fixed-step point-control model was trained, so the matrix cannot show a critical step."
    broke = sorted((o for o in point if o["breaks"]), key=lambda o: o["step"])
    held = sorted((o for o in point if not o["breaks"]), key=lambda o: o["step"])

    def names(os):
        return ", ".join(f"{o['train']} ({_f(o['macro_f1_own'], 3)} -> {_f(o['macro_f1_ref'], 3)})" for o in os)

    parts = []
    if broke:
        parts.append(f"Trained with a fixed step and solved with the reference, {names(broke)} lose more than "
                     f"{tol * 100:.0f} points of macro F1")
    if held:
        parts.append(("while " if broke else "") + f"{names(held)} keep their macro F1 within {tol * 100:.0f} points")
    text = "; ".join(parts) + "."
    if broke and held:
        if max(o["step"] for o in held) < min(o["step"] for o in broke):
            text += (f" The critical step lies between h = 1/{round(1 / max(o['step'] for o in held))} and "
                     f"h = 1/{round(1 / min(o['step'] for o in broke))}, as Ott et al. (2021) describe.")
        else:
            text += " Breaking does not follow the step size monotonically here, so no single critical step shows."
    elif held:
        text += (" No trained step size reached the critical one: even the largest, "
                 f"h = 1/{round(1 / max(o['step'] for o in held))}, gives a model whose macro F1 holds under the other "
                 "solvers (its logits still move: see the error table).")
    else:
        text += " Every trained step size is above the critical one."
    avg_broke = [o for o in ott if o["control"] == "average" and o["breaks"]]
    if avg_broke:
        one = len(avg_broke) == 1
        text += (f" Of the step-average models, {names(avg_broke)} depend{'s' if one else ''} on "
                 f"{'its' if one else 'their'} discretisation: solved as the ODE {'it tends' if one else 'they tend'} "
                 f"to, {'it loses' if one else 'they lose'} more than "
                 f"{tol * 100:.0f} points (expected at coarse N, where the mean control is the model, not an "
                 "approximation of the path).")
    adaptive = [o for o in ott if o["step"] is None]
    for o in adaptive:
        text += (f" The {o['train']}-trained model scores {_f(o['macro_f1_own'], 3)} with its own solver and "
                 f"{_f(o['worst_macro_f1'], 3)} at worst (under {o['worst_deploy']}).")
    return text


def controls_sentence(matrix: dict) -> str:
    rows = [r for r in matrix.get("controls", []) if r["average_macro_f1"] is not None and r["point_macro_f1"] is not None]
    if not rows:
        return "No pair of point and average-control models trained at the same N."
    parts = []
    for r in sorted(rows, key=lambda r: r["steps"]):
        d = r["average_macro_f1"] - r["point_macro_f1"]
        parts.append(f"at N = {r['steps']} ({_n(r['nfe_per_window'])} evaluations) the step-average model scores "
                     f"{_f(r['average_macro_f1'], 3)} against {_f(r['point_macro_f1'], 3)} point-sampled "
                     f"({'+' if d >= 0 else ''}{d * 100:.1f} points)")
    text = "Trained and deployed at the same N, " + "; ".join(parts) + "."
    text += " " + f1_match_sentence(matrix)
    return text


def f1_match_sentence(matrix: dict, f1_tol: float = F1_TOL) -> str:
    """The cheapest fixed-step model (trained and deployed at its N) whose macro F1 reaches the
    dopri5-trained model's under dopri5: an F1-only comparison between different trained models."""
    base = None
    for o in matrix.get("ott", []):
        if o["step"] is None and o["own_deploy"]:
            cell = next(c for c in matrix["cells"] if c["train"] == o["train"] and c["deploy"] == o["own_deploy"])
            base = (o, cell)
    if base is None:
        return ""
    o, cell = base
    fixed = [(x, next(c for c in matrix["cells"] if c["train"] == x["train"] and c["deploy"] == x["own_deploy"]))
             for x in matrix["ott"] if x["step"] is not None]
    ok = [(x, c) for x, c in fixed if c["macro_f1"] >= cell["macro_f1"] - f1_tol - 1e-12]
    if not ok:
        best = max(fixed, key=lambda xc: xc[1]["macro_f1"], default=None)
        tail = f" (best: {best[0]['train']}, {_f(best[1]['macro_f1'], 3)})" if best else ""
        return (f"No fixed-step model reaches the macro F1 of the {o['train']} model under {o['own_deploy']} "
                f"({_f(cell['macro_f1'], 3)}, {_n(cell['nfe_per_window'])} evaluations per window){tail}.")
    x, c = min(ok, key=lambda xc: (xc[1]["nfe_per_window"], -xc[1]["macro_f1"]))
    return (f"The cheapest fixed-step model whose macro F1 reaches (within {f1_tol * 100:.1f} point) that of the "
            f"{o['train']} model under {o['own_deploy']} ({_f(cell['macro_f1'], 3)} at {_n(cell['nfe_per_window'])} "
            f"evaluations per window) is {x['train']} ({_f(c['macro_f1'], 3)} at {_n(c['nfe_per_window'])}): "
            f"{cell['nfe_per_window'] / c['nfe_per_window']:.1f} times fewer evaluations. This compares different "
            "trained models by F1 only, not one model's solver error.")


def matrix_markdown(matrix: dict, command: str | None = None, figures: str = "../figures") -> str:
    meta = matrix["meta"]
    cols = [d["label"] for d in matrix["deploy"]]
    short = ["reference" if d.get("reference") else d["label"] for d in matrix["deploy"]]
    lines = ["## Solvers: training solver by deployment solver", ""]
    if command:
        lines += [f"Made by `{command}`.", ""]
    lines += [f"{len(matrix['train'])} CNODEs trained {meta['epochs']} epochs each on {meta['n_train_windows']} "
              f"training windows (same initial weights, same batches), deployed on all {meta['n_test_windows']} test "
              f"windows in batches of {meta['batch']}. Training took {meta['train_seconds']:.0f} s, the whole matrix "
              f"{meta['seconds']:.0f} s ({meta['threads']} thread(s)). Logit errors are against each model's own "
              "float64 dopri5 reference (rtol 1e-9, restarted at every knot): the ODE the weights stand for.", ""]
    rows = [[i["label"], f"{i['train_seconds']:.0f}", _n(i["nfe_per_forward_train"]), _f(i["best_val_macro_f1"]),
             str(i["best_epoch"] + 1)] for i in matrix["train"]]
    lines += _table(["trained with", "seconds", "NFE / forward", "best val F1", "best epoch"], rows)
    for key, title, fmt in (("macro_f1", "Macro F1 (test split)", _f), ("max_logit_err", "Max abs logit error vs own reference", _e)):
        lines += ["", f"### {title}", ""]
        rows = []
        for i in matrix["train"]:
            cells = {c["deploy"]: c for c in matrix["cells"] if c["train"] == i["label"]}
            rows.append([i["label"], *(fmt(cells[c][key]) if c in cells else "—" for c in cols)])
        lines += _table(["trained \\ deployed", *short], rows)
    nfe = {c["deploy"]: c["nfe_per_window"] for c in matrix["cells"]}
    lines += ["", "Evaluations per window of each deploy solver: "
              + ", ".join(f"{s} {_n(nfe.get(c))}" for s, c in zip(short, cols)) + " (adaptive: per batched solve).", ""]
    lines += ["### Do fixed-step-trained models break? (Ott et al., ICLR 2021)", "", ott_sentence(matrix), ""]
    rows = [[o["train"], o["own_deploy"], _f(o["macro_f1_own"]), _f(o["macro_f1_ref"]),
             f"{o['f1_drop_to_ref'] * 100:+.1f}", _e(o["max_logit_err_own"]), f"{o['worst_deploy']} ({_f(o['worst_macro_f1'], 3)})",
             "yes" if o["breaks"] else "no"] for o in matrix.get("ott", [])]
    lines += _table(["trained with", "own solver", "F1 own", "F1 reference", "drop (points)", "own vs ODE max err",
                     "worst deploy", "breaks"], rows)
    if matrix.get("controls"):
        lines += ["", "### Control representation at equal evaluations", "",
                  "Point: u sampled at the RK4 stage times (the CNODE as trained by `quadfdi train`). Average: each "
                  "step sees the mean of u over the step, a constant (N, W) matrix of the window, so a coarse grid "
                  "still sees every sample; trained that way, since it is another model.", "",
                  controls_sentence(matrix), ""]
        rows = [[f"{r['method']} N={r['steps']}", _n(r["nfe_per_window"]), _f(r["point_macro_f1"]), _f(r["average_macro_f1"]),
                 _e(r["point_max_logit_err"]), _e(r["average_max_logit_err"])] for r in matrix["controls"]]
        lines += _table(["trained and deployed", "NFE", "F1 point", "F1 average", "max err point", "max err average"], rows)
    lines += ["", "One training seed: differences of a point or less in macro F1 are within what another seed "
              "or another batch order moves (the test windows of one trajectory are strongly correlated).", "",
              f"![macro F1 matrix]({figures}/solver_matrix_f1.png)"]
    if matrix.get("controls"):
        lines += [f"![control representations]({figures}/solver_controls.png)"]
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------- what other stages read


def report_section(run_root: str | Path) -> list[str]:
    """Markdown lines of the run report's solver section (figure links relative to the run
    folder); a "Not run" section when neither the study nor the matrix has run."""
    study, matrix = read_outputs(run_root)
    if not study and not matrix:
        return not_run("## Solvers", f"no solvers/solvers.json in this run (`quadfdi solvers study --run {run_root}` "
                                     "writes it)")
    parts = []
    if study:
        parts.append(study_markdown(study, study["meta"].get("command"), figures="figures"))
    if matrix:
        parts.append(matrix_markdown(matrix, matrix["meta"].get("command"), figures="figures"))
    text = "\n".join(parts)
    return text.splitlines() + [""] if text.strip() else []


def headline(run_root: str | Path) -> list[str]:
    """The run report's headline bullet of the study (the cheapest fixed setting that matches dopri5), or []."""
    study, _ = read_outputs(run_root)
    if not study or not study.get("matched"):
        return []
    return [f"- Solvers (solvers/solvers.json): {study_headline(study)}"]
