"""parity.md: the parity report in markdown, from the dict that parity.json holds; and parity's
section of the run's report.md (``report_section``)."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.reportmd import demote, not_run, optional_json, over_bound_clause

STREAM_TITLES = {"cnode": "CNODE", "gru": "GRU", "sgru": "streaming GRU", "scnode": "streaming CNODE"}
PAIR_TITLES = {
    "cpp_fp32_vs_ort_fp32": "C++ fp32 vs ONNX Runtime fp32",
    "cpp_fp32_vs_torch": "C++ fp32 vs PyTorch",
    "ort_fp32_vs_torch": "ONNX Runtime fp32 vs PyTorch",
    "cpp_int8_vs_ort_int8": "C++ int8 vs ONNX Runtime int8",
    "cpp_int8_vs_cpp_fp32": "C++ int8 vs C++ fp32 (quantisation)",
    "ort_int8_vs_ort_fp32": "ONNX Runtime int8 vs fp32 (quantisation)",
}


def _g(v: float) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def _pairs_table(model: str, pairs: dict) -> list[str]:
    title = {"cnode": "CNODE", "gru": "GRU", "cnode_motor": "CNODE motor head", "gru_motor": "GRU motor head"}
    rows = [f"### {title.get(model, model)}", "",
            "| pair | max abs diff | RMSE | rel. L2 | cosine | argmax agreement | bit-identical windows | target |",
            "|---|---|---|---|---|---|---|---|"]
    for key, m in pairs.items():
        t = m.get("target")
        if t is None:
            verdict = "(information)"
        else:
            extra = (f", {t['max_diff_steps']:.3g} logit steps" if "max_diff_steps" in t
                     else "" if t.get("bitwise") else f", bound {t['bound']:.2g}" + over_bound_clause(t))
            verdict = f"{'**pass**' if t['passed'] else '**FAIL**'}: {t['rule']}{extra}"
        rows.append(f"| {PAIR_TITLES.get(key, key)} | {_g(m['max_abs_diff'])} | {_g(m['rmse'])} | {_g(m['rel_l2'])} | "
                    f"{m['cosine']:.9f} | {100 * m['argmax_agreement']:.2f} % ({m['argmax_disagreements']} differ) | "
                    f"{m['bitwise_identical_windows']}/{m['windows']} | {verdict} |")
    return rows + [""]


def _mcu_section(mcu: dict) -> list[str]:
    out = ["## Cortex-M (QEMU)", ""]
    if "skipped" in mcu:
        return out + [f"Not run: {mcu['skipped']}.", ""]
    tc = mcu.get("toolchain", {})
    out += [f"Toolchain: {tc.get('arm-none-eabi-gcc')}; {tc.get('qemu-system-arm')}.", "",
            "Flash and static RAM are the minimal image of one model and precision minus the baseline image "
            "(startup + window buffer + empty main), from `arm-none-eabi-size -A`; weights and library code are "
            "the map file's split of the flash. Stack: peak of one inference call (stack painting). "
            "Instructions: SysTick under `-icount shift=0`, calibrated (instructions per tick "
            "measured on a loop of known length), median over the reference windows.", "",
            "| core | model | flash (B) | of which weights (B) | library code (B) | static RAM (B) | stack peak (B) "
            "| instructions / inference | QEMU parity |", "|---|---|---|---|---|---|---|---|---|"]
    for cpu, r in mcu["cpus"].items():
        ok = {(t["model"], t["precision"]): True for t in r["tensors"]}
        for t in r["tensors"]:
            ok[(t["model"], t["precision"])] = ok[(t["model"], t["precision"])] and t["ok"]
        for key, m in r["models"].items():
            model, prec = key.split("_")
            verdict = "OK" if ok.get((model, prec)) else "NOT OK"
            out.append(f"| {cpu} ({r['machine']}) | {model} {prec} | {m['flash_bytes']} | {m['weights_bytes']} | "
                       f"{m['library_bytes']} | {m['static_ram_bytes']} | {m['stack_peak_bytes']} | "
                       f"{m['instructions_per_inference']:,} | {verdict} |")
    out += ["", "Targets: int8 CNODE flash <= 64 KiB and static RAM <= 16 KiB: "
            + ("**met**" if not [p for p in mcu["problems"] if "cnode_int8" in p] else "**MISSED**") + ".", ""]
    copies = {cpu: r["models"]["cnode_int8"].get("int16_weight_copies", True) for cpu, r in mcu["cpus"].items()}
    if not all(copies.values()):
        out += ["The int8 CNODE's stage weights (lin1_z, lin2) stay int8 in flash on "
                + ", ".join(cpu for cpu, c in copies.items() if not c)
                + ": with their int16 copies in RAM (the faster kernel) it missed the static-RAM target.", ""]
    for cpu, r in mcu["cpus"].items():
        out += [f"`{r['qemu_command']}` exited {r['exit_code']} ({r['exit_meaning']}).", ""]
    if mcu["problems"]:
        out += ["Problems:", ""] + [f"- {p}" for p in mcu["problems"]] + [""]
    return out


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f} ms"


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.2f} %"


def _stream_rows(t: dict) -> list[str]:
    m4, m7 = (t["cores"].get(c, {}).get("models", {}) for c in ("cortex-m4", "cortex-m7"))
    rows = []
    for key in dict.fromkeys(list(m4) + list(m7)):
        a, b = m4.get(key, {}), m7.get(key, {})
        ins, cyc = a.get("instructions", {}), a.get("cycles", {})
        net, prec = key.rsplit("_", 1)
        rows.append(f"| {STREAM_TITLES.get(net, net)} {prec} | {ins.get('push_mean', 0):,.0f} | "
                    f"{ins.get('decision_mean', 0):,.0f} ({ins.get('decision_max', 0):,}) | "
                    f"{cyc.get('decision_mean', 0):,.0f} ({cyc.get('decision_max') or 0:,}) | "
                    f"{_ms(a.get('worst_decision_ms'))} / {_ms(cyc.get('worst_decision_ms'))} | "
                    f"{_pct(a.get('duty'))} / {_pct(cyc.get('duty'))} | "
                    f"{b.get('instructions', {}).get('decision_mean', 0):,.0f} "
                    f"({b.get('instructions', {}).get('decision_max', 0):,}) | {_ms(b.get('worst_decision_ms'))} | "
                    f"{_pct(b.get('duty'))} |")
    return rows


def stream_section(t: dict | None) -> list[str]:
    """The on-board streaming cost table (mcu_stream.json, parity/stream.py) in markdown."""
    out = ["## On-board streaming cost (Cortex-M under QEMU)", ""]
    if not t or "skipped" in t:
        return out + [f"Not run: {(t or {}).get('skipped', 'no Cortex-M part')}.", ""]
    fl, cm = t["flights"], t["cycle_model"]
    checks = [f"{cpu}: {sum(h['strides'] for h in r['host_check'].values())} strides, QEMU {r['seconds']:.1f} s"
              + (" traced" if any("cycles" in m for m in r["models"].values()) else "")
              for cpu, r in t["cores"].items()]
    out += [f"Test flights (dataset rows {', '.join(map(str, fl['dataset_rows']))}; "
            f"{', '.join(str(n) for n in fl['samples'].values())} samples, each cut after its first "
            f"{fl['decisions_kept_per_flight']} decided strides"
            + (f"; {fl['vehicle_records']} with its vehicle's record, loaded at reset" if fl.get("vehicle_records") else "")
            + ") replayed sample by sample through every model of the "
            f"export in the stream image (profile {t['profile']}, window {t['window']}, stride {t['stride']}); every "
            f"stride held against the host's fwref_stream ({'; '.join(checks)}): "
            + ("**as the host**." if t["passed"] else "**NOT as the host**: " + "; ".join(t["problems"])), "",
            "Instructions: QEMU `-icount` (SysTick around each push). Cycles: Cortex-M4 only, ESTIMATED from QEMU's "
            "block trace, each instruction weighted by the Cortex-M4 TRM's cycle table (`quadfdi.runtimes.mcu_cycles`:"
            f" taken-branch refill {cm['refill_cycles']}, SDIV/UDIV {cm['div_cycles']}; not modelled: "
            f"{cm['not_modelled']}). Worst decision at {t['clock_mhz']['cortex-m4']:.0f} MHz (M4) / "
            f"{t['clock_mhz']['cortex-m7']:.0f} MHz (M7); duty cycle = (one decision + stride - 1 pushes) / "
            f"(stride x {t['sample_period_ms']:.0f} ms) of the core.", "",
            "| model | M4 push (instr.) | M4 decision, mean (worst), instr. | M4 decision, mean (worst), est. cycles "
            "| M4 worst decision, instr. / cycles | M4 duty, instr. / cycles | M7 decision, mean (worst), instr. "
            "| M7 worst decision | M7 duty |", "|---|---|---|---|---|---|---|---|---|"]
    out += _stream_rows(t) + [""]
    over = []
    for cpu, c in t["cores"].items():
        for key, m in c["models"].items():
            net, prec = key.rsplit("_", 1)
            by_cycles = ((m.get("cycles") or {}).get("worst_decision_ms") or 0) > t["sample_period_ms"]
            if m["worst_decision_ms"] > t["sample_period_ms"] or by_cycles:
                over.append(f"{STREAM_TITLES.get(net, net)} {prec} on the {cpu} ("
                            + ("instructions" if m["worst_decision_ms"] > t["sample_period_ms"] else "estimated cycles")
                            + ")")
    out += [f"Worst decision over the {t['sample_period_ms']:.0f} ms sample period: {'; '.join(over) or 'none'}."]
    if t.get("sgru_vs_gru"):
        out += ["Streaming GRU per second of flight, as a share of the windowed GRU's instructions: "
                + ", ".join(f"{k} {v:.4f}" for k, v in t["sgru_vs_gru"].items()) + "."]
    return out + [""]


def markdown(report: dict) -> str:
    out = [f"# Parity: {report['run']}", "",
           f"Command: `{report['command']}`. {report['test_windows']} test windows, each run alone (batch 1) "
           f"through C++ (`{report['firmware']['infer']}`), ONNX Runtime and PyTorch (classic RK4, "
           f"N = {report['export_steps']}).", "",
           "Targets: C++ fp32 vs ONNX Runtime fp32 max |diff| <= 1e-4 x max(1, max |logit|) with 100 % argmax; "
           "C++ int8 vs ONNX Runtime int8 argmax >= 99.9 % and max |diff| <= "
           f"{report['tolerances']['int8_tol_steps']:g} logit steps (step of class o = 127 * s_in * s_w[o], the "
           "largest change one step of one head input can make; docs/firmware.md).", "",
           f"**Result: {'pass' if report['passed'] else 'FAIL'}**" +
           ("" if report["passed"] else ": " + "; ".join(report["problems"])), "", "## Logits on the test split", ""]
    for model, pairs in report["models"].items():
        out += _pairs_table(model, pairs)
    fp = report["fwref_parity"]
    out += ["## fwref_parity on reference.bin", "", f"`{fp['command']}` exited {fp['exit_code']}:", "", "```"]
    out += fp["output"] + ["```", ""]
    out += _mcu_section(report["mcu"])
    out += stream_section(report["mcu"].get("stream"))
    out += [f"Stage time: {report['timing_s']['total']:.1f} s "
            f"({', '.join(f'{k} {v:.1f} s' for k, v in report['timing_s'].items() if k != 'total')}).", ""]
    return "\n".join(out)


def report_section(run_root: Path) -> list[str]:
    """Parity's section of the run's report.md: parity/parity.md (headings one level down), else a
    short summary of parity/parity.json."""
    root = Path(run_root)
    md = root / "parity" / "parity.md"
    if md.is_file():
        return ["## Parity (C++ reference vs ONNX Runtime and PyTorch; Cortex-M)", ""] + demote(md.read_text(), 2)
    p = optional_json(root / "parity" / "parity.json", "parity results")
    if p is None:
        return not_run("## Parity", f"no parity/parity.json in this run (`quadfdi parity --run {root}` writes it)")
    verdict = "pass" if p.get("passed") else "FAIL"
    return ["## Parity", "", f"Made by `{p.get('command', 'quadfdi parity')}`: **{verdict}**"
            + ("" if p.get("passed") else ": " + "; ".join(p.get("problems", []))) + ".", ""]
