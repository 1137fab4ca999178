"""The paper's figures from a training result: Figs. 5-6 (curves), 8-9 (confusion), 10 (per-class
F1), 11 (any-fault ROC) and 12-27 (one test trajectory per fault class: states, fault variables
and the any-fault probability of each model)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from sklearn.metrics import confusion_matrix, roc_curve

from quadfdi.core.contracts import CLASS_NAMES, HEALTHY
from quadfdi.core.plotting import pyplot as _plt
from quadfdi.core.plotting import save_png as _save

def short_names(names) -> tuple[str, ...]:
    """Axis labels: the class names without "Fault" (Healthy, Battery, Motor, Overheat, ...)."""
    return tuple(str(name).removesuffix("Fault") for name in names)


SHORT = short_names(CLASS_NAMES)  # the paper's four
LABEL = {"cnode": "Neural ODE", "gru": "GRU", "baseline": "LogReg baseline"}


def draw_curves(history: dict, out: Path) -> None:
    plt = _plt()
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    for kind, h in history.items():
        ep = np.arange(1, len(h.loss) + 1)
        a.plot(ep, h.loss, marker="o", label=LABEL.get(kind, kind))
        b.plot(ep, h.val_macro_f1, marker="o", label=LABEL.get(kind, kind))
    a.set(title="training loss (Eq. 12)", xlabel="epoch", ylabel="loss")
    b.set(title="validation macro F1", xlabel="epoch", ylabel="macro F1")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    _save(fig, out)


def draw_confusion(y: np.ndarray, proba: np.ndarray, title: str, out: Path, names=CLASS_NAMES) -> None:
    plt = _plt()
    k, short = len(names), short_names(names)
    cm = confusion_matrix(y, proba.argmax(1), labels=list(range(k)))
    fig, ax = plt.subplots(figsize=(4 + 0.25 * k, 3.3 + 0.25 * k))
    ax.imshow(cm, cmap="Blues")
    for i in range(k):
        for j in range(k):
            ax.text(j, i, str(cm[i, j]), ha="center", va="center", color="white" if cm[i, j] > cm.max() / 2 else "black")
    ax.set(xticks=range(k), yticks=range(k), xticklabels=short, yticklabels=short, xlabel="predicted", ylabel="true",
           title=title)
    fig.tight_layout()
    _save(fig, out)


def draw_per_class_f1(metrics: dict, out: Path, names=CLASS_NAMES) -> None:
    plt = _plt()
    k = len(names)
    fig, ax = plt.subplots(figsize=(7, 4))
    kinds = list(metrics)
    width = 0.8 / len(kinds)
    for n, kind in enumerate(kinds):
        vals = [metrics[kind]["per_class"][c]["f1"] for c in names]
        ax.bar(np.arange(k) + n * width, vals, width, label=LABEL.get(kind, kind))
    ax.set(xticks=np.arange(k) + width * (len(kinds) - 1) / 2, xticklabels=short_names(names), ylabel="F1", ylim=(0, 1.05),
           title="per-class F1 (test)")
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    _save(fig, out)


def draw_roc(y: np.ndarray, probas: dict, metrics: dict, out: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(5, 4.5))
    for kind, p in probas.items():
        fpr, tpr, _ = roc_curve(y != HEALTHY, 1.0 - p[:, HEALTHY])
        auc = metrics[kind]["any_fault_roc_auc"]
        auc_txt = "n/a" if auc is None or not np.isfinite(auc) else f"{auc:.4f}"
        ax.plot(fpr, tpr, label=f"{LABEL.get(kind, kind)} (AUC {auc_txt})")
    ax.plot([0, 1], [0, 1], "k:", lw=0.8)
    ax.set(xlabel="false positive rate", ylabel="true positive rate", title="any-fault ROC (test windows)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    _save(fig, out)


def draw_trajectory_detection(ds, test, probas: dict, row: int, out: Path) -> None:
    """Position, attitude, battery, temperature, effectiveness, severity and the any-fault
    probability of each model at each window end, for dataset row ``row`` (Figs. 12-27)."""
    from quadfdi.formats.dataset import class_names
    from quadfdi.sim.plot import plot_groups

    plt = _plt()
    t = ds["time"]
    onset, det = float(ds["onset_s"][row]), float(ds["detectable_s"][row])
    fig, axes = plt.subplots(4, 2, figsize=(13, 11), sharex=True)
    axes = axes.ravel()
    groups = [("position [m]", ["x", "y", "z"], 1.0), ("attitude [deg]", ["roll", "pitch", "yaw"], 180 / np.pi),
              ("state of charge [-]", ["SoC"], 1.0), ("bus voltage [V] / current [A]", ["V_b", "I_b"], 1.0),
              ("motor temperature [°C]", ["T1", "T2", "T3", "T4"], 1.0)]
    plot_groups(axes, ds, row, groups, t)
    ax = axes[5]
    if "effectiveness" in ds.arrays:
        for m in range(4):
            ax.plot(t, ds["effectiveness"][row, :, m], lw=1, label=f"motor {m + 1}")
        ax.legend(fontsize=7)
    ax.set_title("effectiveness c_i d_m [-]", fontsize=10)
    ax = axes[6]
    ax.plot(t, ds["severity"][row], "k", lw=1.2)
    ax.axhline(ds.severity_threshold, color="r", ls=":", lw=1)
    ax.set_title("severity s_k (red: s_thr)", fontsize=10)
    ax = axes[7]
    sel = test.traj == row
    for kind, p in probas.items():
        ax.plot(test.t_end[sel], 1.0 - p[sel, HEALTHY], marker=".", label=LABEL.get(kind, kind))
    ax.axhline(0.5, color="r", ls=":", lw=1)
    ax.set(title="any-fault probability 1 - p(Healthy) at window end", ylim=(-0.05, 1.05))
    ax.legend(fontsize=7)
    for ax in axes:
        if np.isfinite(det):
            ax.axvline(onset, color="gray", ls=":", lw=0.8)
            ax.axvline(det, color="gray", ls="--", lw=0.8)
        ax.grid(alpha=0.3)
    axes[6].set_xlabel("time [s]")
    axes[7].set_xlabel("time [s]")
    cls = int(ds["fault_class"][row])
    fig.suptitle(f"test trajectory {row}: {class_names(ds.arrays)[cls]} (dotted: onset {onset:.2f} s, dashed: detectable {det:.2f} s)")
    fig.tight_layout()
    _save(fig, out)


def draw_all(run, ds, result: dict) -> list[Path]:
    """Every training figure into ``run.figures``, classes named by the data; returns the paths written."""
    from quadfdi.formats.dataset import class_names

    figs = run.figures
    names = class_names(ds.arrays)
    test = result["splits"].test
    written = []
    if result["history"]:
        draw_curves(result["history"], figs / "train_curves.png")
        written.append(figs / "train_curves.png")
    for kind, p in result["proba"].items():
        path = figs / f"confusion_{kind}.png"
        draw_confusion(test.y, p, f"confusion: {LABEL.get(kind, kind)}", path, names)
        written.append(path)
    draw_per_class_f1(result["metrics"], figs / "per_class_f1.png", names)
    draw_roc(test.y, result["proba"], result["metrics"], figs / "any_fault_roc.png")
    written += [figs / "per_class_f1.png", figs / "any_fault_roc.png"]
    neural = {k: v for k, v in result["proba"].items() if k != "baseline"}
    for cls in (c for c in range(len(names)) if c != HEALTHY):
        rows = [r for r in np.unique(test.traj) if ds["fault_class"][r] == cls]
        if rows:
            path = figs / f"detection_{short_names(names)[cls].lower()}_traj{rows[0]}.png"
            draw_trajectory_detection(ds, test, neural, int(rows[0]), path)
            written.append(path)
    return written
