"""The export's section of report.md, from ``export/manifest.json`` and ``export/coverage.md``; and
its headline line."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import demote, not_run, num, optional_json, over_bound_clause, pct
from quadfdi.core.tables import md_table

HEADING = "## Export"


def _manifest(root: Path) -> dict | None:
    return optional_json(root / "export" / "manifest.json", "export manifest")


def headline(run_root: Path) -> list[str]:
    """The report's headline bullet on the int8 macro-F1 drop ([] when the export has not run)."""
    man = _manifest(Path(run_root)) or {}
    drops = [f"{k.split('_')[0]} {v['macro_f1_drop_points']:+.2f}" for k, v in man.get("verification", {}).items()
             if isinstance(v, dict) and "macro_f1_drop_points" in v]
    return [f"- int8 macro F1 drop in points (export manifest): {', '.join(drops)}."] if drops else []


def _over_bound_cell(check: dict) -> str:
    """The windows past the fp32 bound and their judgement (``over_bound_clause``); "-" for a manifest without
    the count."""
    n = check.get("windows_over_bound")
    return "-" if n is None else over_bound_clause(check).removeprefix("; ") or "0"


def _checks(v: dict) -> list[str]:
    out = []
    rows = [[key, f"{v[key].get('max_abs_logit_diff', float('nan')):.2e}", f"{v[key].get('bound', float('nan')):.1e}",
             _over_bound_cell(v[key]), "pass" if v[key].get("passed") else "FAIL"]
            for key in ("cnode_fp32_vs_pytorch", "gru_fp32_vs_pytorch") if key in v]
    if rows:
        out += md_table(["check", "max abs logit diff", "bound", "windows past the bound", "result"],
                        rows)
    rows = [[key, pct(x.get("argmax_agreement")), num(x.get("macro_f1_fp32_points"), 2),
             num(x.get("macro_f1_int8_points"), 2), num(x.get("macro_f1_drop_points"), 2),
             "met" if x.get("meets_target") else "missed"]
            for key in ("cnode_int8_vs_fp32", "gru_int8_vs_fp32") if (x := v.get(key)) is not None]
    if rows:
        out += md_table(["int8 vs fp32", "argmax agreement", "macro F1 fp32", "macro F1 int8", "drop (points)",
                         "target"], rows)
    return out


def report_section(run_root: Path) -> list[str]:
    """Verification results, the files with their hashes, and the int8 coverage report."""
    root = Path(run_root)
    m = _manifest(root)
    if not m:
        return not_run(HEADING, f"no export/manifest.json in this run (`quadfdi export --run {root}` writes it)")
    v = m.get("verification", {})
    out = [HEADING, "",
           f"Made by `quadfdi export` (`export/manifest.json`, schema {m.get('schema_version')}): classic RK4 with "
           f"N = {m.get('solver', {}).get('steps')} unrolled, opset {m.get('opset')}; verified on "
           f"{v.get('test_windows')} test windows: **{'passed' if v.get('passed') else 'FAILED'}**.", ""]
    out += _checks(v)
    rows = [[name, f"{e['bytes']:,}", e["sha256"][:12]] for name, e in m.get("files", {}).items()]
    out += ["Files:", ""] + md_table(["file", "bytes", "sha256 (first 12)"], rows)
    cov = root / "export" / "coverage.md"
    if cov.is_file():
        out += demote(cov.read_text(), 2)
    return out
