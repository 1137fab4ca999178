"""The comparison table: windowed and streaming CNODE and GRU beside every baseline, from a run's files.

One row per network (windowed CNODE, streaming CNODE, windowed GRU, streaming GRU: always listed) and
per baseline the evaluation scored; one column per question a user asks of a detector:

| column | from |
|---|---|
| window macro F1 [flight bootstrap] | evaluation.json ``results`` (the set's ``metrics.macro_f1``) |
| Δ macro F1 against the best baseline [paired bootstrap] | evaluation.json ``paired`` (best baseline: ``best_baseline``, chosen on validation) |
| faulty flights detected | ``results`` ``metrics.detection_rate`` |
| false alarms per healthy flight-hour [Garwood] | ``results`` ``false_alarms`` (rate_per_h, poisson_lo, poisson_hi) |
| mean delay from onset | ``results`` ``metrics.delay_onset_s`` |
| motor named (share right) | ``results`` ``metrics.motor_acc`` |
| cost per second of flight on the M4 | int8 cycles by the Cortex-M4 cycle table: parity/mcu_stream.json (duty x clock) and parity/scnode_mcu.json (mean step / sample period); else multiply-accumulates per second: export/manifest.json (windowed) or the prediction set's record predictions/<model>_sim*_train*.json ``compute`` (streaming) |
| deployed | evaluation.json ``deployment`` (evaluate/deployment.py) |

Nothing is recomputed: every figure is read (the cost per second is the recorded per-decision figure
times the recorded decision rate). A missing figure is "—" with a footnote saying why.

    quadfdi report --run R                                   (section of report.md: test, test_ood_all)
    quadfdi readme --run R --block comparison                (README block: the test set, compact)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json
from quadfdi.core.reportmd import not_run, optional_json
from quadfdi.core.rundir import EVALUATION_JSON
from quadfdi.core.tables import md_table
from quadfdi.evaluate.deployment import TITLES, deployed_models
from quadfdi.readme_text import wrap

NETWORKS = ("cnode", "scnode", "gru", "sgru")
HEADING = "## Comparison: windowed and streaming networks against the baselines"
SETS = ("test", "test_ood_all")
M4 = "cortex-m4"


@dataclass
class Notes:
    """Footnotes, numbered in order of first use, each text once; ``compact`` (the README) takes each
    note's short text where one is given."""

    compact: bool = False
    texts: list[str] = field(default_factory=list)

    def mark(self, text: str, short: str | None = None) -> str:
        text = short if self.compact and short else text
        if text not in self.texts:
            self.texts.append(text)
        return f"—({self.texts.index(text) + 1})" if self.compact else f"— ({self.texts.index(text) + 1})"

    def lines(self) -> list[str]:
        return [f"({i}) {t}" for i, t in enumerate(self.texts, 1)]


def _iv(m: dict, scale: float, nd: int, compact: bool, sign: bool = False) -> str | None:
    """value [lo, hi] of an interval dict (keys value or diff, lo, hi) scaled; None without a value."""
    v = m.get("value", m.get("diff"))
    if v is None:
        return None
    f = (lambda x: f"{round(x * scale, nd) + 0.0:+.{nd}f}") if sign else (lambda x: f"{x * scale:.{nd}f}")  # no -0.0
    if m.get("lo") is None:
        return f(v)
    return f"{f(v)} [{f(m['lo'])},{f(m['hi'])}]" if compact else f"{f(v)} [{f(m['lo'])}, {f(m['hi'])}]"


def _first_json(root: Path, model: str) -> dict | None:
    """The first prediction-set record of ``model`` that carries its ``compute`` rows."""
    for p in sorted((root / "predictions").glob(f"{model}_sim*_train*.json")):
        rec = read_json(p, "prediction-set record")
        if isinstance(rec, dict) and rec.get("compute"):
            return {"file": p.relative_to(root).as_posix(), **rec}
    return None


def costs(root: Path) -> tuple[dict[str, str], list[str]]:
    """Model -> cost cell (M4 int8 cycles per s of flight, else MACs per s) and the sources used."""
    out, used = {}, []
    stream = optional_json(root / "parity" / "mcu_stream.json", "mcu_stream.json") or {}
    m4 = (stream.get("cores") or {}).get(M4, {}).get("models", {})
    for m in ("cnode", "gru", "sgru"):
        fig = (m4.get(f"{m}_int8") or {}).get("cycles")
        if fig and fig.get("duty") is not None:
            out[m] = f"{fig['duty'] * m4[f'{m}_int8']['clock_mhz']:.2f}M cyc"  # duty x clock (MHz)
            used.append("parity/mcu_stream.json")
    sc = optional_json(root / "parity" / "scnode_mcu.json", "scnode_mcu.json")
    if sc and (sc.get("cost") or {}).get("int8"):
        out["scnode"] = f"{sc['cost']['int8']['cycles_mean'] / sc['sample_period_s'] / 1e6:.2f}M cyc"
        used.append("parity/scnode_mcu.json")
    manifest = optional_json(root / "export" / "manifest.json", "manifest.json")
    for m in (m for m in ("cnode", "gru") if m not in out and manifest):
        per_s = 1.0 / manifest["sample_dt_s"] / manifest["config"]["sim"]["stride"]
        macs = (manifest.get("models", {}).get(m) or {}).get("macs_per_window")
        if macs is not None:
            out[m] = f"{macs * per_s / 1e6:.2f}M MAC"
            used.append("export/manifest.json")
    for m in (m for m in NETWORKS if m not in out):
        rec = _first_json(root, m)
        row = next((r for r in (rec or {}).get("compute", []) if r.get("model") == m), None)
        if row is not None:
            out[m] = f"{row['macs_per_s'] / 1e6:.2f}M MAC"
            used.append(rec["file"])
    return out, list(dict.fromkeys(used))


def _cost_note(used: list[str], compact: bool) -> str:
    if compact:
        return "M4 cost/s: M cyc = int8 cycles by the TRM table (parity/), else M MAC = multiply-accumulates"
    return ("cost per second of flight: 'M cyc' = millions of int8 Cortex-M4 cycles estimated by the TRM cycle "
            "table (windowed: mean decision + stride − 1 pushes per stride; streaming: mean step per sample), "
            "'M MAC' = millions of multiply-accumulates where no cycle figure exists; read from "
            + (", ".join(used) if used else "no file") + ".")


def _row_cells(ev: dict, model: str, name: str, notes: Notes, compact: bool) -> list[str]:
    """The figure cells of one model on one set (all '—' with a note when it has no result there)."""
    r = next((r for r in ev["results"] if r["model"] == model and r["set"] == name), None)
    if r is None:
        why = (f"{model}: no prediction set in this run (quadfdi train {model})" if model not in ev["models"]
               else f"{model}: its prediction sets hold no flight of {name}")
        return [notes.mark(why, f"no {model} prediction set")] * (6 if compact else 7)
    m, fa = r["metrics"], r["false_alarms"]
    pts = 100.0 if compact else 1.0
    f1 = _iv(m["macro_f1"], pts, 1 if compact else 3, compact) or notes.mark("no scored window")
    pc = "%" if compact else " %"
    flat = (lambda k: {"value": m[k]["value"]}) if compact else (lambda k: m[k])  # noqa: E731
    det = _iv(flat("detection_rate"), 100.0, 0 if compact else 1, compact)
    det = f"{det}{pc}" if det else notes.mark("no faulty flight in the set")
    rate = ("%.2f [%.2f, %.2f]" % (fa["rate_per_h"], fa["poisson_lo"], fa["poisson_hi"]) if fa["rate_per_h"] is not None
            else notes.mark("no healthy flight-hour in the set"))
    delay = _iv(flat("delay_onset_s"), 1.0, 1, compact)
    motor = _iv(flat("motor_acc"), 100.0, 0, compact)
    cells = [f1, _paired_cell(ev, model, name, notes, compact), det, rate.replace(", ", ",") if compact else rate,
             delay or notes.mark("no faulty flight detected"),
             f"{motor}{pc}" if motor else notes.mark("no detected rotor-side fault flight with a motor output "
                                                     "(no motor head or rule in its set, or none detected)",
                                                     "no motor named: no motor output or no rotor fault detected")]
    return cells if compact else [str(r["flights"])] + cells


def _paired_cell(ev: dict, model: str, name: str, notes: Notes, compact: bool) -> str:
    best = ev.get("best_baseline")
    if best is None:
        return notes.mark("no baseline with a validation score: no best baseline")
    if model == best:
        return notes.mark(f"{best} is the best baseline (highest validation macro F1)", "the best baseline")
    for p in ev["paired"]:
        if p["set"] == name and {p["a"], p["b"]} == {model, best}:
            d = p["diff"]["macro_f1"]
            s = 1.0 if p["a"] == model else -1.0
            lo, hi = (None, None) if d["lo"] is None else sorted((s * d["lo"], s * d["hi"]))
            cell = _iv({"diff": None if d["diff"] is None else s * d["diff"], "lo": lo, "hi": hi},
                       100.0 if compact else 1.0, 1 if compact else 3, compact, sign=True)
            return cell or notes.mark("paired difference undefined on these flights")
    return notes.mark(f"no flights of {name} shared with {best}")


def rows(root: Path, ev: dict, name: str, notes: Notes, compact: bool) -> list[list[str]]:
    """The table's rows on set ``name``: the four networks, then every baseline."""
    cost, used = costs(root)
    chosen = deployed_models(ev)
    base = sorted(m for m, d in ev["models"].items() if not d["network"])
    out = []
    for model in NETWORKS + tuple(base):
        label = TITLES.get(model, model) if compact else (f"{TITLES[model]} ({model})" if model in TITLES else model)
        if model == ev.get("best_baseline"):
            label += " (best)" if compact else " (best baseline)"
        if model in TITLES:
            c = cost.get(model) or notes.mark(f"{model}: no cycle or MAC figure recorded (quadfdi parity / export)",
                                              "no cycle or MAC figure")
            dep = (notes.mark("evaluation.json predates the windowed-or-streaming choice: re-run quadfdi evaluate",
                              "no choice in evaluation.json") if chosen is None else ("✓" if model in chosen else ""))
        else:
            c, dep = notes.mark("baselines run on the host only: no on-board cost", "host-only baseline"), ""
        out.append([label, *_row_cells(ev, model, name, notes, compact), c, dep])
    if cost:
        notes.texts.append(_cost_note(used, compact))
    return out


HEAD_FULL = ["model", "flights", "window macro F1 [95 %]", "Δ macro F1 vs best baseline [paired 95 %]", "faulty flights detected",
             "false alarms / healthy h [Garwood 95 %]", "mean delay from onset s", "motor named (share right)",
             "cost / s of flight (M4)", "deployed"]
HEAD_COMPACT = ["model", "F1 [95%]", "Δ best base", "detected", "FA/h [Garwood]", "delay s", "motor",
                "M4 cost/s", "dep."]


def tight_table(head: list[str], rows: list[list[str]]) -> list[str]:
    """A markdown table without the padding spaces (the README's 100-character lines)."""
    return ["|" + "|".join(head) + "|", "|" + "|".join("---" for _ in head) + "|",
            *("|" + "|".join(str(c) for c in r) + "|" for r in rows)]


def _evaluation(root: Path) -> dict:
    path = root / EVALUATION_JSON
    if not path.is_file():
        raise QuadfdiError(f"{path} is missing: run `quadfdi evaluate --run {root}` first")
    return read_json(path, "evaluation.json")


def _stale_export_note(root: Path, ev_path: Path) -> list[str]:
    """A note when the export deploys from another evaluation.json than the one the table reads."""
    import hashlib

    man = optional_json(root / "export" / "manifest.json", "manifest.json")
    dep = (man or {}).get("deployment")
    if not dep or hashlib.sha256(ev_path.read_bytes()).hexdigest() == dep.get("evaluation_sha256"):
        return []
    return ["export/manifest.json deploys from another evaluation.json than this table's: re-run quadfdi export."]


def report_section(root: Path) -> list[str]:
    """report.md's section: the full table on the test set and on the pooled out-of-distribution set."""
    root = Path(root)
    if not (root / EVALUATION_JSON).is_file():
        return not_run(HEADING, f"no {EVALUATION_JSON} (quadfdi evaluate --run RUN)")
    ev = _evaluation(root)
    out = [HEADING, "", "Every figure is read from the run's files (quadfdi/comparison.py names each column's "
           "source); intervals: flight bootstrap, Garwood for false alarms; deployed: the member of each family "
           "chosen on validation flights.", ""]
    for name in (s for s in SETS if any(r["set"] == s for r in ev["results"])):
        notes = Notes()
        table = rows(root, ev, name, notes, compact=False)
        flights = next(r["flights"] for r in ev["results"] if r["set"] == name)
        out += [f"### {name} ({flights} flights)", "", *md_table(HEAD_FULL, table), *notes.lines(), ""]
    return out + _stale_export_note(root, root / EVALUATION_JSON) + [""]


def comparison_block(root: Path, marker: str | None = None) -> str:
    """The README block: the test set, compact cells (points, no interval on the flight figures); ``marker``:
    the file's block it is written into when not "comparison" (named in the command it quotes)."""
    root = Path(root)
    ev = _evaluation(root)
    notes = Notes(compact=True)
    if not any(r["set"] == "test" for r in ev["results"]):
        raise QuadfdiError(f"{root / EVALUATION_JSON} scores no test set: nothing to compare")
    table = rows(root, ev, "test", notes, compact=True)
    flights = next(r["flights"] for r in ev["results"] if r["set"] == "test")
    lines = [*wrap(f"Networks (windowed, streaming) vs baselines, test set ({flights} flights): `quadfdi readme --run "
                   f"{root} --block comparison{f' --marker {marker}' if marker else ''}` from "
                   "`evaluation/evaluation.json` (code "
                   f"`{(ev.get('git_commit') or '?')[:10]}`); F1, Δ in points (other intervals: report.md); dep.: "
                   "deployed, chosen on validation."),
             "", *tight_table(HEAD_COMPACT, table), "",
             *wrap("; ".join(notes.lines() + _stale_export_note(root, root / EVALUATION_JSON)) + ".")]
    return "\n".join(lines)

