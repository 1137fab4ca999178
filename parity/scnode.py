"""``quadfdi parity --run RUN --scnode``: the streaming CNODE's step on the Cortex-M4 under QEMU, held against
ONNX Runtime, and its cost per sample by the M4 cycle table.

The export's scnode_fw.bin and scnode_fw_i8.bin (``quadfdi export scnode``) are compiled into the images of
firmware_ref/mcu/scnode (runtimes/mcu_scnode.py). The full image replays the export's whole replay flight
from z = 0; every sample's logits must equal ONNX Runtime's int8 graph stepped with its own state
(scnode_replay.npz ``logits_int8``) bit for bit, and the fp32 ones ``logits`` within the C++ tolerance
(core.contracts.FP32_CPP_REL_TOL, relative to max(1, max |logit|)) with the same argmax. The traced image's
first ``mcu_scnode.TRACE_STEPS`` samples give each step's estimated Cortex-M4 cycles (runtimes/mcu_cycles.py),
checked against the image's own -icount instruction counts; the duty cycle is the worst step's cycles over
one sample period at ``CLOCK_MHZ`` and the target 1 % (``DUTY_TARGET``).

Writes ``<run>/parity/scnode_mcu.json`` and ``scnode_mcu.md``.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from quadfdi.core.atomic import ensure_dir, write_text
from quadfdi.core.contracts import FP32_CPP_REL_TOL
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import write_json
from quadfdi.core.tables import md_table
from quadfdi.runtimes import mcu_scnode
from quadfdi.runtimes.build import locked
from quadfdi.runtimes.mcu import CLOCK_MHZ, image_memory
from quadfdi.runtimes.mcu_cycles import DIV_CYCLES, REFILL

CPU = "cortex-m4"
DUTY_TARGET = 0.01  # one step within 1 % of the sample period


def _parity(run: mcu_scnode.StepRun, rep) -> dict:
    out = {}
    for prec, key in (("fp32", "logits"), ("int8", "logits_int8")):
        got, ref = run.logits.get(prec), rep[key]
        if got is None or got.shape != ref.shape:
            raise QuadfdiError(f"the {CPU} image printed {None if got is None else got.shape} {prec} logits, "
                               f"the replay holds {ref.shape}: rebuild (`quadfdi export scnode` then this again)")
        diff = float(np.abs(got.astype(np.float64) - ref).max())
        bound = FP32_CPP_REL_TOL * max(1.0, float(np.abs(ref).max()))
        same = got.argmax(1) == ref.argmax(1)
        bits = int(np.all(got.view(np.uint32) == ref.view(np.uint32), axis=1).sum())
        passed = bits == len(ref) if prec == "int8" else bool(diff <= bound and same.all())
        out[prec] = {"samples": len(ref), "bit_identical_samples": bits, "max_abs_diff": diff,
                     "argmax_agreement": float(same.mean()), "passed": passed,
                     "target": "bit-identical" if prec == "int8" else f"<= {bound:.3g} (FP32_CPP_REL_TOL)"}
    return out


def _costs(full: mcu_scnode.StepRun, traced: mcu_scnode.StepRun, fig: dict, period_s: float) -> dict:
    budget = DUTY_TARGET * period_s * CLOCK_MHZ[CPU] * 1e6
    out = {}
    for prec, f in fig.items():
        icount = traced.instructions[prec]
        slack = int(np.ceil(traced.ratio)) + 1 + int(np.ceil(2 * icount.max() / max(traced.calib_ticks, 1)))
        worst = int(f["cycles"].max())
        out[prec] = {"instructions_mean": round(float(full.instructions[prec].mean()), 1),
                     "instructions_max": int(full.instructions[prec].max()), "traced_steps": len(f["cycles"]),
                     "cycles_mean": round(float(f["cycles"].mean()), 1), "cycles_max": worst,
                     "cycles_per_instruction": round(float(f["cycles"].sum() / f["instructions"].sum()), 3),
                     "worst_step_ms": worst / CLOCK_MHZ[CPU] / 1e3, "duty": worst / (period_s * CLOCK_MHZ[CPU] * 1e6),
                     "budget_cycles": int(budget), "meets_target": worst <= budget,
                     "margin_cycles": int(budget) - worst, "worst_step": f["worst"],
                     "trace_vs_icount": {"max_abs_diff": int(np.abs(f["instructions"] - icount).max()), "slack": slack,
                                         "within": bool(np.abs(f["instructions"] - icount).max() <= slack)}}
    return out


def scnode_parity(root: Path, period_s: float, log: Callable[[str], None] = print) -> dict:
    """Build, run and trace the streaming CNODE's Cortex-M4 images for the export of ``root``; write and
    return the report (``passed``: parity met and the trace agrees with -icount)."""
    export = Path(root) / "export"
    files = [export / "scnode_fw.bin", export / "scnode_fw_i8.bin"]
    for f in files + [export / "scnode_replay.npz"]:
        if not f.is_file():
            raise QuadfdiError(f"{f} is missing: run `quadfdi export scnode --run {root}` first")
    rep = np.load(export / "scnode_replay.npz")
    build_dir = mcu_scnode.build_scnode(CPU, files)
    log(f"parity: {CPU} streaming CNODE images built in {build_dir}")
    with locked(build_dir):
        full = mcu_scnode.run_steps(CPU, build_dir / mcu_scnode.ELF)
        traced, fig = mcu_scnode.trace_steps(CPU, build_dir / mcu_scnode.TRACE_ELF)
        memory = image_memory(build_dir / mcu_scnode.ELF)
    dims = np.frombuffer(files[1].read_bytes()[16:36], "<i4")
    report = {"cpu": CPU, "clock_mhz": CLOCK_MHZ[CPU], "sample_period_s": period_s, "duty_target": DUTY_TARGET,
              "dims": dict(zip(("channels", "latent", "hidden", "classes", "samples"), dims.tolist())),
              "parity": _parity(full, rep), "cost": _costs(full, traced, fig, period_s),
              "cycle_model": {"refill_cycles": REFILL, "div_cycles": DIV_CYCLES,
                              "not_modelled": "flash wait states, bus contention (runtimes/mcu_cycles.py)"},
              "image": {"static_ram_bytes": memory["static_ram_bytes"], "flash_bytes_with_flights": memory["flash_bytes"]}}
    report["passed"] = all(p["passed"] for p in report["parity"].values()) and all(
        c["trace_vs_icount"]["within"] for c in report["cost"].values())
    out = ensure_dir(Path(root) / "parity")
    write_json(out / "scnode_mcu.json", report, indent=2)
    write_text(out / "scnode_mcu.md", report_md(report))
    return report


def report_md(r: dict) -> str:
    d, budget = r["dims"], int(r["duty_target"] * r["sample_period_s"] * r["clock_mhz"] * 1e6)
    rows = []
    for prec in ("fp32", "int8"):
        p, c = r["parity"][prec], r["cost"][prec]
        rows.append([prec, f"{p['bit_identical_samples']}/{p['samples']}", f"{p['max_abs_diff']:.3g}",
                     f"{c['instructions_mean']:,.0f} ({c['instructions_max']:,})",
                     f"{c['cycles_mean']:,.0f} ({c['cycles_max']:,})", f"{100 * c['duty']:.3f} %",
                     ("met" if c["meets_target"] else "MISSED") + f" by {abs(c['margin_cycles']):,} cycles"])
    return "\n".join([
        "# Streaming CNODE on the Cortex-M4", "",
        f"One RK4 step per sample (latent {d['latent']}, field width {d['hidden']}, {d['channels']} channels, "
        f"{d['classes']} classes) under QEMU; parity against ONNX Runtime over the export's replay flight "
        f"({d['samples']} samples); cycles estimated from QEMU's block trace of the first "
        f"{r['cost']['int8']['traced_steps']} samples by the Cortex-M4 TRM's table (taken-branch refill "
        f"{r['cycle_model']['refill_cycles']}, flash wait states not modelled); duty = worst step / "
        f"{1e3 * r['sample_period_s']:.0f} ms at {r['clock_mhz']:.0f} MHz; target {100 * r['duty_target']:g} % "
        f"= {budget:,} cycles.", "",
        *md_table(["precision", "bit-identical samples", "max abs logit diff", "instructions mean (max)",
                   "est. cycles mean (max)", "duty", "1 % target"], rows), ""])
