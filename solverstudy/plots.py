"""Figures of the solver study and of the train-by-deploy matrix (PNG, written atomically).

- ``solver_error_vs_nfe.png``: max abs logit error against the reference vs evaluations per
  window, log-log, one marker family per method (hollow markers: adaptive without ``jump_t``;
  dashed with plus markers: fixed steps with the step-average control).
- ``solver_f1_vs_latency.png``: macro F1 vs batch-1 latency (PyTorch eager, this process).
- ``solver_matrix_f1.png``: macro F1 of each trained model (rows) under each deploy solver.
- ``solver_controls.png``: point-sampled vs step-average control, trained and deployed at N:
  macro F1 and logit error vs evaluations.

Each takes the dict that ``solverstudy.study.run_study`` / ``solverstudy.matrix.run_matrix``
returns (or its JSON), so a figure is redrawn from the JSON alone.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from quadfdi.core.plotting import pyplot as _plt
from quadfdi.core.plotting import save_png as _save
from quadfdi.formats.solver_files import MATRIX_FIGURES, STUDY_FIGURES

MARKERS = {"euler": "o", "midpoint": "s", "rk4": "^", "dopri5": "D", "bosh3": "v"}
COLORS = {"euler": "tab:blue", "midpoint": "tab:orange", "rk4": "tab:green", "dopri5": "tab:red", "bosh3": "tab:purple"}
ERR_FLOOR = 1e-12  # a zero error cannot sit on a log axis


def _families(records: list[dict]) -> dict[tuple, list[dict]]:
    """Records grouped by (method, jump_t, control), each sorted by evaluations; no reference."""
    fam: dict[tuple, list[dict]] = {}
    for r in records:
        if r.get("reference"):
            continue
        fam.setdefault((r["method"], r.get("jump_t"), r.get("control", "point")), []).append(r)
    return {k: sorted(v, key=lambda r: r["nfe_per_window"]) for k, v in fam.items()}


def _family_label(method: str, jump: bool | None, control: str) -> str:
    tail = "" if jump is None else (" + jump_t" if jump else " (no jump_t)")
    return method + tail + (" avg control" if control == "average" else "")


def _style(method: str, jump: bool | None, control: str = "point") -> dict:
    hollow = jump is False
    if control == "average":  # same colour as the method, dashed, plus-shaped markers
        return {"marker": "P", "color": COLORS.get(method, "k"), "linestyle": "--", "alpha": 0.8}
    return {"marker": MARKERS.get(method, "x"), "color": COLORS.get(method, "k"),
            "markerfacecolor": "none" if hollow else COLORS.get(method, "k"), "linestyle": ":" if hollow else "-"}


def plot_error_vs_nfe(study: dict, path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for (method, jump, control), recs in _families(study["solvers"]).items():
        x = [r["nfe_per_window"] for r in recs]
        y = [max(r["max_logit_err"], ERR_FLOOR) for r in recs]
        ax.plot(x, y, label=_family_label(method, jump, control), **_style(method, jump, control))
    ax.set(xscale="log", yscale="log", xlabel="vector-field evaluations per window",
           ylabel="max |logit - reference logit|")
    ax.set_title(f"solver error vs cost\n{study['meta']['sample']}", fontsize=10)
    return _finish(fig, ax, path)


def _finish(fig, ax, path: Path) -> Path:
    """Log-grid, legend, tight layout, atomic PNG: how every study figure ends."""
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def plot_f1_vs_latency(study: dict, path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    for (method, jump, control), recs in _families(study["solvers"]).items():
        recs = sorted(recs, key=lambda r: r["latency_us"])
        ax.plot([r["latency_us"] / 1e3 for r in recs], [r["macro_f1"] for r in recs],
                label=_family_label(method, jump, control), **_style(method, jump, control))
    ref = study["reference"]
    ax.axhline(ref["macro_f1"], color="k", lw=0.8, ls="--", label=f"reference ({ref['macro_f1']:.4f})")
    ax.set(xscale="log", xlabel="batch-1 latency per window, ms (PyTorch eager, this process)",
           ylabel=f"macro F1 ({study['meta']['n_windows']} windows)", title="macro F1 vs latency")
    return _finish(fig, ax, path)


def plot_matrix(matrix: dict, path: Path) -> Path:
    plt = _plt()
    rows = [i["label"] for i in matrix["train"]]
    cols = [d["label"] for d in matrix["deploy"]]
    f1 = np.full((len(rows), len(cols)), np.nan)
    for c in matrix["cells"]:
        f1[rows.index(c["train"]), cols.index(c["deploy"])] = c["macro_f1"]
    fig, ax = plt.subplots(figsize=(1.1 * len(cols) + 3, 0.55 * len(rows) + 2.2))
    lo, hi = (np.nanmin(f1), np.nanmax(f1)) if np.isfinite(f1).any() else (0.0, 1.0)
    im = ax.imshow(f1, cmap="viridis", vmin=lo, vmax=max(hi, lo + 1e-3), aspect="auto")
    for i in range(len(rows)):
        for j in range(len(cols)):
            if np.isfinite(f1[i, j]):
                ax.text(j, i, f"{f1[i, j]:.3f}", ha="center", va="center", fontsize=8,
                        color="white" if f1[i, j] < (lo + hi) / 2 else "black")
    short = ["reference" if d.get("reference") else d["label"].replace(" jump", "") for d in matrix["deploy"]]
    ax.set(xticks=range(len(cols)), yticks=range(len(rows)), xticklabels=short, yticklabels=rows,
           xlabel="deploy solver", ylabel="training solver",
           title=f"macro F1 on the test split ({matrix['meta']['epochs']} epochs)")
    plt.setp(ax.get_xticklabels(), rotation=35, ha="right")
    fig.colorbar(im, ax=ax, shrink=0.8)
    fig.tight_layout()
    return _save(fig, path)


def plot_controls(matrix: dict, path: Path) -> Path:
    plt = _plt()
    rows = [r for r in matrix["controls"] if r["nfe_per_window"] is not None]
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for name, style in (("point", dict(marker="^", color="tab:green")), ("average", dict(marker="o", color="tab:brown"))):
        pts = sorted((r["nfe_per_window"], r[f"{name}_macro_f1"], r[f"{name}_max_logit_err"]) for r in rows
                     if r[f"{name}_macro_f1"] is not None)
        if pts:
            x, f1, err = zip(*pts)
            a.plot(x, f1, label=f"{name} control", **style)
            b.plot(x, [max(e, ERR_FLOOR) for e in err], label=f"{name} control", **style)
    for info in matrix["train"]:  # the adaptive-trained models at their own solver, for scale
        if info["steps"] is None:
            own = next((c for c in matrix["cells"] if c["train"] == info["label"] and not c["deploy"].startswith("reference")
                        and c["deploy"].startswith(info["method"])), None)
            if own:
                a.scatter([own["nfe_per_window"]], [own["macro_f1"]], marker="D", color="tab:red",
                          label=f"trained and deployed {own['deploy']}")
    a.set(xscale="log", xlabel="evaluations per window", ylabel="macro F1 (test split)",
          title="trained and deployed at the same N")
    b.set(xscale="log", yscale="log", xlabel="evaluations per window", ylabel="max |logit - own ODE reference|",
          title="distance to the model's ODE limit")
    for ax in (a, b):
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def draw_study(study: dict, figures: Path) -> list[Path]:
    return [plot_error_vs_nfe(study, figures / STUDY_FIGURES[0]), plot_f1_vs_latency(study, figures / STUDY_FIGURES[1])]


def draw_matrix(matrix: dict, figures: Path) -> list[Path]:
    out = [plot_matrix(matrix, figures / MATRIX_FIGURES[0])]
    if matrix.get("controls"):
        out.append(plot_controls(matrix, figures / MATRIX_FIGURES[1]))
    return out
