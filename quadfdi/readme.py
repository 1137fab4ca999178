"""``quadfdi readme --run R --readme README.md``: the README's generated blocks, from a run.

Rewrites the ``<!-- deployment:start -->`` ... ``<!-- deployment:end -->`` block of the README
from the run's own files (export/manifest.json, parity/parity.json, parity/mcu.json, bench.json,
solvers/solvers.json) and names the machine that measured them (CPU model, vector ISA, date from
bench.json), because these numbers move with the CPU; ``--block results`` writes the seed study's
headline tables (quadfdi.readme_study), ``--block realistic`` the realistic suite's
(quadfdi.readme_realistic), ``--block comparison`` the networks against the baselines
(quadfdi.comparison); ``--marker`` names another block of the file for it (a second comparison, another
run). Nothing is typed in by hand; a missing file is a one-line error naming
the command that writes it. The deployment and results blocks keep every line within 100
characters, the README's width.
"""

from __future__ import annotations

import argparse
import datetime as dt
from pathlib import Path

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json
from quadfdi.core.machine import isa_summary
from quadfdi.core.mdblock import rewrite_file_block
from quadfdi.core.tables import md_table
from quadfdi.readme_text import wrap

BLOCK = "deployment"
BLOCKS = (BLOCK, "results", "realistic", "comparison")
MODELS = (("cnode", "CNODE"), ("gru", "GRU"))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("readme", help="rewrite the README's deployment tables from a run's files",
                       description="Rewrite the README's deployment block from a run's files.")
    p.add_argument("--run", required=True, help="run folder made by quadfdi run")
    p.add_argument("--readme", default="README.md", help="markdown file with the block (default: %(default)s)")
    p.add_argument("--block", choices=BLOCKS, default=BLOCK,
                   help="deployment: export, parity, bench and Cortex-M tables; results: the seed study's "
                        "Tables 3 and 4 (seeds.json; quadfdi.readme_study); realistic: the evaluation's "
                        "model x test-set tables (quadfdi.readme_realistic); comparison: windowed and streaming "
                        "networks against the baselines (quadfdi.comparison) (default: %(default)s)")
    p.add_argument("--marker", default=None,
                   help="the block of the file to rewrite, <!-- MARKER:start --> ... <!-- MARKER:end --> (default: the "
                        "--block's own name), e.g. a second comparison block for another run")
    p.set_defaults(func=_cli)


def _cli(args: argparse.Namespace) -> int:
    if args.block == "realistic":
        from quadfdi.readme_realistic import realistic_block

        text = realistic_block(Path(args.run))
    elif args.block == "comparison":
        from quadfdi.comparison import comparison_block

        text = comparison_block(Path(args.run), args.marker)
    elif args.block == "results":
        from quadfdi.readme_study import results_block

        text = results_block(Path(args.run))
    else:
        text = deployment_block(Path(args.run))
    marker = args.marker or args.block
    path = rewrite_file_block(args.readme, marker, text)
    print(f"wrote the {marker} block of {path}")
    return 0


def _need(root: Path, rel: str, command: str) -> dict:
    path = root / rel
    if not path.is_file():
        raise QuadfdiError(f"{path} is missing: run `{command}` first")
    return read_json(path, rel)


def _us(x: float | None) -> str:
    if x is None:
        return "—"
    return f"{x / 1000:.2f} ms" if x >= 1000 else f"{x:.1f} us"


def machine_sentence(bench: dict) -> str:
    m = bench.get("machine", {})
    facts = {"cpu": m.get("cpu", "unknown CPU"), "isa": m.get("isa", []), "logical_cpus": m.get("logical_cpus")}
    when = m.get("date") or dt.date.today().isoformat()
    load = m.get("load_average_start")
    busy = (f"; load average {load[0]:.1f} when the bench started (above 0.5 the machine was shared: timings "
            "are noisy, compare within a table)") if load else ""
    return (f"Measured on {facts['cpu']} ({isa_summary(facts)}, {facts['logical_cpus']} logical CPUs, pinned to "
            f"{m.get('pinned_cpus', '?')}), {when}; onnxruntime {m.get('onnxruntime', '?')}, torch "
            f"{m.get('torch', '?')}{busy}. Another CPU gives other numbers.")


def precision_table(manifest: dict, parity: dict) -> list[str]:
    rows = []
    for key, label in MODELS:
        v = manifest["verification"][f"{key}_int8_vs_fp32"]
        cov = manifest["quantization"]["coverage"][key]["summary"]
        pm = parity["models"][key]
        f32 = pm["cpp_fp32_vs_ort_fp32"]
        i8 = pm["cpp_int8_vs_ort_int8"]
        steps = i8["target"]["max_diff_steps"]
        same = (f"bit-identical ({i8['bitwise_identical_windows']}/{i8['windows']})"
                if i8["bitwise_identical_windows"] == i8["windows"] else f"max {steps:.2f} logit steps")
        rows.append([label, f"{v['macro_f1_fp32_points']:.2f} -> {v['macro_f1_int8_points']:.2f}",
                     f"{100 * cov['int8_mac_share']:.0f} %", f"{100 * cov['initializer_bytes_ratio']:.1f} %",
                     f"{f32['max_abs_diff']:.1e}", same])
    return md_table(["model", "macro F1 fp32 -> int8", "int8 MACs", "int8/fp32 bytes", "C++ vs ORT fp32",
                     "C++ vs ORT int8"], rows)


def _p50(records: list[dict], **match) -> float | None:
    hits = [r for r in records if all(r.get(k) == v for k, v in match.items()) and r.get("p50_us") is not None]
    return min(r["p50_us"] for r in hits) if hits else None


def latency_table(bench: dict) -> list[str]:
    lat, rows = bench["latency"], []
    floors = {(f["model"], f["precision"]): f for f in bench.get("floors", [])}
    for key, label in MODELS:
        f32 = floors.get((key, "fp32"), {})
        row = [label, f"{_us(f32.get('floor_us'))} ({f32.get('bound', '?')})" if f32 else "—"]
        for runtime in ("cpp", "ort"):
            for precision in ("fp32", "int8"):
                p = _p50(lat, runtime=runtime, model=key, precision=precision, batch=1, threads=1)
                fl = floors.get((key, precision), {}).get("floor_us")
                ratio = f" ({p / fl:.1f}x)" if runtime == "cpp" and p and fl else ""
                row.append(_us(p) + ratio)
        rows.append(row)
    return md_table(["model", "fp32 floor", "C++ fp32 (x floor)", "C++ int8 (x floor)", "ORT fp32", "ORT int8"], rows)


def torch_sentence(bench: dict) -> str:
    """PyTorch's batch-1 p50 per model and solver, one thread (the eager reference, not a deployment)."""
    lat, parts = bench["latency"], []
    for key, label in MODELS:
        solvers = sorted({r.get("solver") for r in lat if r.get("runtime") == "torch" and r.get("model") == key} - {None})
        times = [(f"{s} " if s != key else "") + _us(_p50(lat, runtime="torch", model=key, batch=1, threads=1, solver=s))
                 for s in solvers]
        if times:
            parts.append(f"{label} {', '.join(times)}")
    return "PyTorch, batch 1, 1 thread: " + ("; ".join(parts) or "not measured") + "."


def mcu_table(mcu: dict) -> list[str]:
    cpus = mcu.get("cpus") or {}
    m4, m7 = cpus.get("cortex-m4", {}).get("models", {}), cpus.get("cortex-m7", {}).get("models", {})
    rows = []
    for key in ("cnode_int8", "cnode_fp32", "gru_int8", "gru_fp32"):
        a, b = m4.get(key), m7.get(key)
        if not a:
            continue
        flash = f"{a['flash_bytes']:,} B (M4)" + (f" / {b['flash_bytes']:,} B (M7)" if b else "")
        rows.append([key.replace("_", " ").upper().replace("FP32", "fp32").replace("INT8", "int8"), flash,
                     f"{a['static_ram_bytes']:,} B", f"{a['instructions_per_inference']:,}"])
    return md_table(["model", "flash", "static RAM", "instructions / inference (M4, QEMU -icount)"], rows)


def deployment_block(root: Path) -> str:
    """The markdown of the block: machine, command, and the four deployment tables."""
    manifest = _need(root, "export/manifest.json", f"quadfdi export --run {root}")
    parity = _need(root, "parity/parity.json", f"quadfdi parity --run {root}")
    mcu = _need(root, "parity/mcu.json", f"quadfdi parity --run {root}")
    bench = _need(root, "bench.json", f"quadfdi bench --run {root}")
    cpu = bench.get("machine", {}).get("cpu", "")
    lines = [*wrap(f"Made by `quadfdi readme --run {root}` from the files of `quadfdi run --out {root}`. "
                   + machine_sentence(bench), keep=(cpu,)), "",
             *wrap(f"**Precision and runtime** (test split, {parity['test_windows']} windows; `export/manifest.json`, "
                   "`parity/parity.json`; ORT: ONNX Runtime; C++ vs ORT: max abs logit difference):"), "",
             *precision_table(manifest, parity),
             *wrap("**Latency, batch 1, p50, 1 thread** (`bench.json`; floor = max(compute at the measured peak, "
                   "weights at the measured L2 bandwidth); x floor: against the precision's own floor):"), "",
             *latency_table(bench), *wrap(torch_sentence(bench)), "",
             "**Cortex-M** (`parity/mcu.json`, minimal images, `arm-none-eabi-size`):", "", *mcu_table(mcu)]
    solvers = root / "solvers" / "solvers.json"
    if solvers.is_file():
        from quadfdi.solverstudy.report import headline

        lines += ["**Solvers** (`solvers/solvers.md`):", "", *(w for h in headline(root) for w in wrap(h)), ""]
    return "\n".join(lines)
