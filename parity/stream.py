"""The on-board streaming cost of every model the export holds, on the Cortex-M under QEMU: part of
the Cortex-M part of parity (parity/mcu.py), written to ``parity/mcu_stream.json``.

A flight controller gives the runtime one sample every sample period (40 ms); each model must
decide within it, and its share of the core over a stride (stride - 1 pushes and one decision) is
its duty cycle. ``stream_inputs`` takes ``FLIGHTS`` test flights of the run's own dataset
(round-robin over the classes) as stream files (formats.stream.from_dataset), each cut after its
``DECISIONS``-th decided stride (where the host's fwref_stream decides it), so that the Cortex-M4's
instruction trace stays short. A reference profile (flightlog-ref) on a fleet dataset: each stream carries
its vehicle's record (learned from that vehicle's own reference flights, train.vehicle_ref), compiled
into the image beside the flight's samples and loaded at its reset. Cross-built into the stream image (firmware_ref/mcu/stream_main.cpp,
runtimes/mcu_stream.py) with every model of the export (CNODE and GRU, fp32 and int8; the streaming
GRU when the export holds sgru_weights.bin), they run under QEMU on each core:

- every stride is held against the host's fwref_stream on the same files (parity: a mismatch is a
  problem of the stage);
- instructions per push, per decision (mean, worst) from ``-icount``; the worst decision's time at
  the core's clock (168 MHz M4, 216 MHz M7) and the duty cycle;
- on the Cortex-M4 (``TRACED``) the same pushes from QEMU's block trace, each instruction weighted
  by the Cortex-M4 TRM's cycles (runtimes/mcu_cycles.py): estimated cycles per decision, the worst
  decision's time and the duty cycle in cycles; and the trace's instructions held against -icount
  (per push within one SysTick tick, and the tick's calibration over the whole count:
  runtimes.mcu_stream.icount_slack).
"""

from __future__ import annotations

import dataclasses
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import flights_by_class
from quadfdi.formats.export_folder import Export
from quadfdi.formats.stream import RawStream
from quadfdi.runtimes import mcu_cycles
from quadfdi.runtimes.fwref import fwref_stream, stream_lines
from quadfdi.runtimes.mcu import CLOCK_MHZ
from quadfdi.runtimes.mcu_stream import STREAM_ELF, StreamRun, check_against_host, icount_slack, replays, run_image

FLIGHTS = 2  # test flights replayed
DECISIONS = 3  # decided strides kept per flight (the first includes the int8 models' one-off weight expansion)
TRACED = ("cortex-m4",)  # the cores whose instructions are also turned into cycles


@dataclass
class StreamInputs:
    """What the stream image replays: the stream files' contents (name -> RawStream), the export's
    on-board record (stride, sample period), the host's fwref_stream and the dataset rows used."""

    streams: dict[str, RawStream]
    record: dict
    host_exe: Path
    rows: list[int]




def _cut_after_decisions(rs: RawStream, host_exe: Path, weights: Path, classes: int) -> RawStream:
    """``rs`` up to the sample that ends its ``DECISIONS``-th decided stride (the host's CNODE fp32;
    the whole flight if it has fewer)."""
    from quadfdi.formats.stream import write_stream

    with tempfile.TemporaryDirectory(prefix="quadfdi-stream-cut-") as tmp:
        path = Path(tmp) / "flight.bin"
        write_stream(path, rs)
        lines = stream_lines(fwref_stream(host_exe, weights, "cnode", False, path), classes)
    decided = lines["index"][lines["status"] == "decided"]
    if len(decided) < DECISIONS:
        return rs
    end = int(decided[DECISIONS - 1]) + 1
    return dataclasses.replace(rs, time=rs.time[:end], values=rs.values[:end])


def stream_inputs(run_root: Path, host_build: Path) -> StreamInputs | str:
    """The short flights to replay (module docstring), or why there are none."""
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.formats.stream import from_dataset
    from quadfdi.runtimes.build import build_host

    try:
        exp = Export.open(run_root / "export")
        record = exp.onboard()
    except QuadfdiError as exc:
        return str(exc)
    export = exp.root
    host_exe = build_host(host_build, log=lambda _: None) / "fwref_stream"  # built already by the host part
    classes = len(exp.class_names)
    ds = load_dataset(run_root / "dataset.npz")
    rows = flights_by_class(ds, FLIGHTS)
    if not rows:
        return f"{run_root / 'dataset.npz'} has no test flights"
    vehicles = vehicle_records(ds, record["profile"], rows)
    streams = {f"f{row}": _cut_after_decisions(from_dataset(run_root / "dataset.npz", row, record, ds, vehicles[row]),
                                               host_exe, export / "weights.bin", classes) for row in rows}
    return StreamInputs(streams, record, host_exe, rows)


def vehicle_records(ds, profile: str, rows: list[int]) -> dict[int, np.ndarray | None]:
    """Each row's vehicle record for a reference profile (train.vehicle_ref.vehicle_records: the record of
    its vehicle's own reference flights, as host parity reads it); None without one (no record carried)."""
    from quadfdi.core.profiles import has_reference
    from quadfdi.core.vehicle_record import has_record
    from quadfdi.train.vehicle_ref import vehicle_records as records_of

    if not has_reference(profile):
        return {row: None for row in rows}
    records = records_of(ds)
    return {row: records[row] if has_record(records[row]) else None for row in rows}


def write_streams(build_dir: Path, inputs: StreamInputs) -> tuple[Path, ...]:
    """The stream files in ``build_dir``/streams (the stream image's build reads them there, and
    rebuilds when they change); the caller holds the build folder's lock."""
    from quadfdi.formats.stream import write_stream

    folder = build_dir / "streams"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    paths = tuple(folder / f"{name}.bin" for name in inputs.streams)
    for path, rs in zip(paths, inputs.streams.values()):
        write_stream(path, rs)
    return paths


def measure(cpu: str, build_dir: Path, export: Path, paths: tuple[Path, ...], inputs: StreamInputs,
            log: Callable[[str], None] = print) -> dict:
    """Run the stream image built in ``build_dir`` on ``cpu`` (traced on the TRACED cores), hold it
    against the host and return its figures (``figures``) with its problems."""
    t0 = time.perf_counter()
    run = run_image(cpu, build_dir / STREAM_ELF, trace=cpu in TRACED)
    seconds = time.perf_counter() - t0
    problems, host = check_against_host(run, export, list(paths), inputs.host_exe)
    out = figures(run, inputs.record)
    problems += [f"{cpu} {m}: the trace's instructions differ from -icount by more than its slack"
                 for m, f in out.items() if "trace_check" in f and not f["trace_check"]["within"]]
    log(f"parity: {cpu} stream image: {sum(h['strides'] for h in host.values())} strides of "
        f"{len(host)} models {'as the host' if not problems else 'NOT as the host'}"
        + (f", {len(run.trace.codes):,} traced blocks" if run.trace is not None else "") + f" ({seconds:.1f} s)")
    return {"models": out, "host_check": host, "problems": problems, "instructions_per_tick": run.ratio,
            "calibration_ticks": run.calib_ticks,
            "seconds": round(seconds, 2)}


def _sum(rows: list[dict], key: str) -> int:
    return sum(r[key] for r in rows)


def figures(run: StreamRun, record: dict) -> dict[str, dict]:
    """Per ``<model>_<precision>``: instructions (-icount) per push and decision, the worst decision's
    time and the duty cycle at the core's clock; on a traced run the same in estimated cycles."""
    stride, dt, mhz = int(record["stride"]), float(record["sample_dt_s"]), CLOCK_MHZ[run.cpu]
    keys = replays(run)
    out = {}
    for net, prec in dict.fromkeys((m, p) for m, p, _ in keys):
        rows = [run.perf[k] for k in keys if k[:2] == (net, prec)]
        push = _sum(rows, "push_sum") / max(_sum(rows, "push_n"), 1)
        dec = _sum(rows, "decide_sum") / max(_sum(rows, "decide_n"), 1)
        worst = max(r["decide_max"] for r in rows)
        f = {"samples": _sum(rows, "samples"), "pushes": _sum(rows, "push_n"), "decisions": _sum(rows, "decide_n"),
             "other_strides": _sum(rows, "other_n"),
             "instructions": {"push_mean": round(push, 1), "push_max": max(r["push_max"] for r in rows),
                              "decision_mean": round(dec, 1), "decision_max": worst,
                              "other_max": max(r["other_max"] for r in rows)},
             "clock_mhz": mhz, "worst_decision_ms": worst / mhz / 1e3,
             "duty": (dec + (stride - 1) * push) / (stride * dt * mhz * 1e6)}
        if run.pushes is not None:
            idx = [i for i, k in enumerate(keys) if k[:2] == (net, prec)]
            f.update(_cycle_figures(run, idx, rows, stride, dt, mhz))
        out[f"{net}_{prec}"] = f
    return out


def _cycle_figures(run: StreamRun, idx: list[int], rows: list[dict], stride: int, dt: float, mhz: float) -> dict:
    """The traced figures of one model and precision (its replays ``idx``)."""
    p = run.pushes
    sel = np.isin(p["replay"], idx)
    dec, push, other = sel & (p["kind"] == 1), sel & (p["kind"] == 0), sel & (p["kind"] == 2)
    cyc_dec = p["cycles"][dec]
    worst = int(np.flatnonzero(dec)[np.argmax(cyc_dec)]) if dec.any() else None
    push_c = float(p["cycles"][push].mean()) if push.any() else 0.0
    dec_c = float(cyc_dec.mean()) if dec.any() else 0.0
    check = {}
    within = True
    parts = (("decisions", dec, "decide_sum"), ("pushes", push, "push_sum"), ("other", other, "other_sum"))
    for name, mask, key in parts:
        tr, ic, n = int(p["instructions"][mask].sum()), _sum(rows, key), int(mask.sum())
        check[name] = {"trace": tr, "icount": ic, "n": n, "slack": icount_slack(run, ic, n)}
        within = within and abs(tr - ic) <= check[name]["slack"]
    if dec.any():
        ic = max(r["decide_max"] for r in rows)
        check["decision_max"] = {"trace": int(p["instructions"][dec].max()), "icount": ic,
                                 "slack": icount_slack(run, ic, 1)}
        within = within and abs(check["decision_max"]["trace"] - ic) <= check["decision_max"]["slack"]
    check["within"] = within
    out = {"cycles": {"push_mean": round(push_c, 1), "decision_mean": round(dec_c, 1),
                      "decision_max": int(cyc_dec.max()) if dec.any() else None,
                      "per_instruction": round(float(cyc_dec.sum() / max(p["instructions"][dec].sum(), 1)), 3),
                      "worst_decision_ms": float(cyc_dec.max()) / mhz / 1e3 if dec.any() else None,
                      "duty": (dec_c + (stride - 1) * push_c) / (stride * dt * mhz * 1e6)},
           "trace_check": check}
    if worst is not None:
        classes = run.trace.class_cycles(int(p["lo"][worst]), int(p["hi"][worst]))
        classes["branch_refills"] = int(p["taken"][worst]) * mcu_cycles.REFILL
        out["cycles"]["worst_decision"] = {"instructions": int(p["instructions"][worst]),
                                           "cycles": int(p["cycles"][worst]), "taken_branches": int(p["taken"][worst]),
                                           "class_cycles": classes}
    return out


def table(cpus: dict[str, dict], inputs: StreamInputs) -> dict:
    """mcu_stream.json: every core's figures, the flights, the cycle model and the problems."""
    rec = inputs.record
    problems = [p for r in cpus.values() for p in r["problems"]]
    return {"flights": {"dataset_rows": inputs.rows, "samples": {k: len(v.time) for k, v in inputs.streams.items()},
                        "vehicle_records": sum(v.vehicle is not None for v in inputs.streams.values()),
                        "decisions_kept_per_flight": DECISIONS},
            "profile": rec["profile"], "window": int(rec["window"]), "stride": int(rec["stride"]),
            "sample_period_ms": 1e3 * float(rec["sample_dt_s"]), "clock_mhz": dict(CLOCK_MHZ),
            "cycle_model": {"source": "ARM Cortex-M4 Technical Reference Manual, processor instruction timings and "
                                      "FPU instruction cycle times (quadfdi.runtimes.mcu_cycles)",
                            "refill_cycles": mcu_cycles.REFILL, "div_cycles": mcu_cycles.DIV_CYCLES,
                            "not_modelled": "flash wait states, bus contention, IT folding, interrupt entry; "
                                            "no cycle figure for the Cortex-M7 (dual issue)",
                            "traced_cores": list(TRACED),
                            "table": [dict(zip(("class", "cycles", "instructions", "source"), row))
                                      for row in mcu_cycles.CYCLE_TABLE]},
            "cores": cpus, "sgru_vs_gru": _sgru_ratio(cpus), "problems": problems, "passed": not problems}


def _sgru_ratio(cpus: dict[str, dict]) -> dict:
    """The streaming GRU's instructions per second of flight over the windowed GRU's (the ratio of
    their duty cycles), per core and precision."""
    out = {}
    for cpu, r in cpus.items():
        m = r["models"]
        for prec in ("fp32", "int8"):
            if f"sgru_{prec}" in m and f"gru_{prec}" in m:
                out[f"{cpu}_{prec}"] = round(m[f"sgru_{prec}"]["duty"] / m[f"gru_{prec}"]["duty"], 4)
    return out
