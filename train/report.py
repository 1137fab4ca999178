"""Training's section of report.md, from ``metrics.json``, ``history.json``, ``results.md`` and the
training figures; and its headline line."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import demote, figure_links, not_run, num, optional_json
from quadfdi.core.tables import md_table

HEADING = "## Training and test metrics"
TRAIN_FIGURES = ("train_curves", "confusion_", "per_class_f1", "any_fault_roc", "detection_")
COLUMNS = [("macro_f1", "macro F1", 4), ("accuracy", "accuracy", 4), ("balanced_accuracy", "balanced acc.", 4),
           ("mcc", "MCC", 4), ("roc_auc_ovr", "ROC AUC", 4), ("any_fault_f1", "any-fault F1", 4),
           ("mean_detection_delay_s", "detection delay (s)", 2), ("missed_faults", "missed faults", 0),
           ("false_alarm_rate", "false alarms", 3)]


def headline(run_root: Path) -> list[str]:
    """The report's headline bullet on test macro F1 ([] when training has not run)."""
    metrics = optional_json(Path(run_root) / "metrics.json", "test metrics") or {}
    f1 = [f"{k} {v['macro_f1']:.4f}" for k, v in metrics.items() if isinstance(v, dict) and "macro_f1" in v]
    return [f"- Test macro F1 (metrics.json): {', '.join(f1)}."] if f1 else []


def _history_rows(root: Path) -> list[list[str]]:
    hist = optional_json(root / "history.json", "training history") or {}
    rows = []
    for model, h in hist.items():
        if isinstance(h, dict) and h.get("loss"):
            rows.append([model, str(len(h["loss"])), str(int(h.get("best_epoch", 0)) + 1),
                         num(sum(h.get("epoch_s", [])), 1),
                         num(h["val_macro_f1"][-1], 4) if h.get("val_macro_f1") else "—",
                         num(sum(h["nfe_per_forward"]) / len(h["nfe_per_forward"]), 0)
                         if h.get("nfe_per_forward") else "—"])
    return rows


def report_section(run_root: Path) -> list[str]:
    """Test metrics per model, per-class F1, training history, the seeds study, the figures."""
    root = Path(run_root)
    metrics = optional_json(root / "metrics.json", "test metrics")
    if not metrics:
        return not_run(HEADING, f"no metrics.json in this run (`quadfdi train --run {root}` writes it)")
    out = [HEADING, "",
           "Made by `quadfdi train` (`metrics.json`, test split; `history.json` for the training runs).", ""]
    rows = [[model] + [num(m.get(k), nd) if isinstance(m.get(k), (int, float)) else "—" for k, _, nd in COLUMNS]
            for model, m in metrics.items() if isinstance(m, dict) and "macro_f1" in m]
    out += md_table(["model"] + [name for _, name, _ in COLUMNS], rows)
    per = [(model, m["per_class"]) for model, m in metrics.items() if isinstance(m, dict) and "per_class" in m]
    if per:
        classes = list(per[0][1])
        out += ["Per-class F1:", ""]
        out += md_table(["model"] + classes, [[model] + [num(pc[k].get("f1"), 3) for k in classes]
                                              for model, pc in per])
    rows = _history_rows(root)
    if rows:
        out += md_table(["model", "epochs", "best epoch", "training time (s)", "last val. macro F1",
                         "NFE / forward"], rows)
    if (root / "results.md").is_file():
        out += ["### Seeds study (`quadfdi train study`)", ""] + demote((root / "results.md").read_text(), 2)
    figs = sorted(p.name for p in (root / "figures").glob("*.png") if p.name.startswith(TRAIN_FIGURES))
    return out + figure_links(root, figs)
