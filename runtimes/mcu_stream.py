"""The stream image under QEMU: fwref_mcu_stream.elf (firmware_ref/mcu/stream_main.cpp) replays
compiled-in stream files sample by sample through each compiled-in model and prints every stride
and, per model, precision and flight, the instructions of its pushes (SysTick under ``-icount``):

    STREAM cpu=<cpu> flights=<n> calib_ticks=<t> instructions_per_tick_x1000=<r>
    STRIDE <model> <prec> <flight> <index> <status> <logit bits (u32) x K> <vote> <active> <cls> <motor> <wmotor>
    PERF <model> <prec> <flight> samples=<n> push_n= push_sum= push_max= decide_n= decide_sum= decide_max= other_n= ...
    RESULT DONE

(push: a push without a stride; decide: a push whose stride ran the model; other: a stride without
a decision, nohover or skipped). ``run_image(cpu, elf, trace=True)`` also records QEMU's block
trace (runtimes/mcu_trace.py) and cuts it at each call of ``board::ticks()``: the image reads the
counter just before and just after every push, so each push is one segment of the trace, whose
instructions are the push's -icount figure within ``icount_slack``, and whose cycles are the
Cortex-M4 estimate (runtimes/mcu_cycles.py). ``check_against_host`` holds every stride against the
host's ``fwref_stream`` on the same stream files.
"""

from __future__ import annotations

import math
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from quadfdi.core.contracts import FP32_CPP_REL_TOL
from quadfdi.core.errors import QuadfdiError
from quadfdi.runtimes.build import mcu_build_dir, require
from quadfdi.runtimes.fwref import fwref_stream, stream_lines
from quadfdi.runtimes.mcu import QEMU_TIMEOUT_S, qemu_command
from quadfdi.runtimes.mcu_trace import Trace

STREAM_ELF = "fwref_mcu_stream.elf"
TRACE_FLAGS = "in_asm,exec,nochain"
MODELS = ("cnode", "gru", "sgru", "scnode")  # the image's replay order
TICKS, PUTS = "board::ticks()", "board::puts(char const*)"


def stream_elf(cpu: str) -> Path:
    """The stream image ``quadfdi parity`` last built for ``cpu`` (its build folder's)."""
    return mcu_build_dir(cpu) / STREAM_ELF


@dataclass
class StreamRun:
    """One run of the stream image: its output parsed, and with a trace the cost of every push."""

    cpu: str
    text: str
    classes: int
    ratio: float  # instructions per SysTick tick (the image's calibration)
    calib_ticks: int  # the calibration loop's ticks: the ratio is known to 1 tick in these
    strides: dict[tuple[str, str, int], list[tuple]] = field(default_factory=dict)
    perf: dict[tuple[str, str, int], dict[str, int]] = field(default_factory=dict)
    pushes: dict[str, np.ndarray] | None = None  # traced: per push, in replay order (``push_table``)
    trace: Trace | None = None


def parse_output(cpu: str, text: str) -> StreamRun:
    """The image's lines (module docstring) as a StreamRun; a run that did not finish is an error."""
    if "RESULT DONE" not in text:
        last = [ln for ln in text.splitlines() if ln.strip()][-1:] or ["no output"]
        raise QuadfdiError(f"the {cpu} stream image did not finish its replays (last line: {last[0][:160]})")
    head = next(ln for ln in text.splitlines() if ln.startswith("STREAM "))
    fields = dict(a.split("=") for a in head.split()[1:])
    ratio, calib = int(fields["instructions_per_tick_x1000"]) / 1000, int(fields["calib_ticks"])
    first = next((ln.split() for ln in text.splitlines() if ln.startswith("STRIDE ")), None)
    k = len(first) - 11 if first else 0
    run = StreamRun(cpu, text, k, ratio, calib)
    for line in text.splitlines():
        p = line.split()
        if p and p[0] == "STRIDE":
            bits = np.array([int(v) for v in p[6:6 + k]], np.uint32).view(np.float32)
            run.strides.setdefault((p[1], p[2], int(p[3])), []).append(
                (int(p[4]), p[5], bits, *(int(v) for v in p[6 + k:11 + k])))
        elif p and p[0] == "PERF":
            run.perf[(p[1], p[2], int(p[3]))] = {a.split("=")[0]: int(a.split("=")[1]) for a in p[4:]}
    return run


def icount_slack(run: StreamRun, instructions: int, pushes: int) -> int:
    """How far the image's -icount figure for ``pushes`` pushes of ``instructions`` in all may be from
    the trace's count of the same: per push one SysTick tick (the counter is read before and after,
    a tick being ``ratio`` = 40 instructions) and the rounding to an integer; and the calibration's
    own tick (the ratio is measured to 1 tick in ``calib_ticks``, 2 allowed) over the whole count."""
    return pushes * (math.ceil(run.ratio) + 1) + math.ceil(2 * instructions / max(run.calib_ticks, 1))


def symbol_address(elf: Path, name: str) -> int:
    """The address of function ``name`` (demangled) in ``elf`` (arm-none-eabi-nm)."""
    nm = subprocess.run([require("arm-none-eabi-nm", "it reads the stream image's symbols"), "-C", str(elf)],
                        capture_output=True, text=True, check=True).stdout
    for line in nm.splitlines():
        p = line.split(" ", 2)
        if len(p) == 3 and p[2] == name and p[1] in "tTwW":
            return int(p[0], 16) & ~1
    raise QuadfdiError(f"{elf} has no function {name}")


def run_image(cpu: str, elf: Path, trace: bool = False) -> StreamRun:
    """Run the stream image under QEMU; with ``trace`` read QEMU's block trace as it is written
    (a stripped copy of the image: the trace lines then carry no symbol names) and cut it per push."""
    if not trace:
        try:
            res = subprocess.run(qemu_command(cpu, elf), capture_output=True, text=True, timeout=QEMU_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise QuadfdiError(f"QEMU ({cpu}) did not finish the stream image within {QEMU_TIMEOUT_S} s") from None
        return parse_output(cpu, res.stdout)
    with tempfile.TemporaryDirectory(prefix="quadfdi-mcu-trace-") as tmp:
        stripped, out, log = Path(tmp) / "stream.elf", Path(tmp) / "semihosting.txt", Path(tmp) / "trace.log"
        subprocess.run([require("arm-none-eabi-objcopy", "it strips the traced image"), "--strip-all", str(elf),
                        str(stripped)], check=True, capture_output=True)
        cmd = [a.replace("stdio,id=sh0", f"file,id=sh0,path={out}") for a in qemu_command(cpu, stripped)]
        proc = subprocess.Popen(cmd + ["-d", TRACE_FLAGS, "-D", str(log)], stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, text=True)
        try:
            tr = Trace.read(FollowLog(log, proc))  # read while QEMU writes it: the two overlap
        finally:
            if proc.poll() is None:
                proc.kill()
            err = proc.communicate()[1]
        if proc.returncode != 0:
            last = (err.strip().splitlines() or ["?"])[-1]
            raise QuadfdiError(f"QEMU ({cpu}, traced) exited {proc.returncode}: {last}")
        run = parse_output(cpu, out.read_text(errors="replace") if out.is_file() else "")
    run.trace = tr
    run.pushes = push_table(run, symbol_address(elf, TICKS), symbol_address(elf, PUTS))
    return run


class FollowLog:
    """A file that QEMU is still writing, read as it grows (``read`` waits for more while QEMU
    runs; end of file once it has exited and everything was read); QEMU is killed after
    QEMU_TIMEOUT_S."""

    def __init__(self, path: Path, proc: subprocess.Popen):
        self.path, self.proc, self.fh = path, proc, None
        self.deadline = time.monotonic() + QEMU_TIMEOUT_S

    def read(self, n: int) -> bytes:
        while True:
            if self.fh is None and self.path.exists():
                self.fh = open(self.path, "rb")
            done = self.proc.poll() is not None
            data = self.fh.read(n) if self.fh is not None else b""
            if data or done:
                return data
            if time.monotonic() > self.deadline:
                self.proc.kill()
                raise QuadfdiError(f"QEMU did not finish the traced stream image within {QEMU_TIMEOUT_S} s")
            time.sleep(0.05)

    def __del__(self) -> None:
        if self.fh is not None:
            self.fh.close()


def replays(run: StreamRun) -> list[tuple[str, str, int]]:
    """(model, precision, flight) in the image's replay order."""
    return sorted(run.perf, key=lambda key: (MODELS.index(key[0]), ("fp32", "int8").index(key[1]), key[2]))


def push_table(run: StreamRun, ticks: int, puts: int) -> dict[str, np.ndarray]:
    """Per push, in replay order: ``replay`` (index into ``replays(run)``), ``kind`` (0 push, 1 decision,
    2 other), and the trace's ``instructions``, ``cycles``, ``taken`` and segment ``lo``/``hi``.

    A push is the trace segment between the two ticks() calls around it; the STRIDE lines printed
    after it (board::puts entries in the next segment, less the PERF line that ends a flight and the
    RESULT line that ends the run) say what its strides were."""
    seg = run.trace.segments(ticks, (puts,))
    keys = replays(run)
    n = np.array([run.perf[r]["samples"] for r in keys], np.int64)
    total = int(n.sum())
    first = len(seg["start"]) - 2 * total
    if first < 1:
        raise QuadfdiError(f"the {run.cpu} trace has {len(seg['start']) - 1} ticks() calls for {total} pushes")
    at = first + 2 * np.arange(total)
    lines = seg[f"mark_{puts:x}"][at + 1].copy()
    lines[np.cumsum(n) - 1] -= 1  # the PERF line after a flight's last push
    lines[-1] -= 1  # RESULT
    replay = np.repeat(np.arange(len(keys)), n)
    kind = np.zeros(total, np.int64)
    queues = {r: iter(run.strides.get(r, [])) for r in keys}
    for j in np.flatnonzero(lines > 0):
        status = [next(queues[keys[replay[j]]])[1] for _ in range(int(lines[j]))]
        kind[j] = 1 if "decided" in status else 2
    for i, r in enumerate(keys):
        got = np.bincount(kind[replay == i], minlength=3).tolist()
        want = [run.perf[r]["push_n"], run.perf[r]["decide_n"], run.perf[r]["other_n"]]
        if got != want:
            raise QuadfdiError(f"the {run.cpu} trace does not match its run: {r} pushes/decisions/other {got} "
                               f"in the trace, {want} printed")
    ends = np.append(seg["start"], len(run.trace.codes))
    return {"replay": replay, "kind": kind, "instructions": seg["instructions"][at], "cycles": seg["cycles"][at],
            "taken": seg["taken"][at], "lo": ends[at], "hi": ends[at + 1]}


def check_against_host(run: StreamRun, export: Path, streams: list[Path], host_exe: Path) -> tuple[list[str], dict]:
    """Every stride of ``run`` against the host's fwref_stream on the same files: the same index and
    status, int8 logits bit-identical, fp32 within FP32_CPP_REL_TOL x max(1, max |host|), no int8
    vote flip, and where the votes agree the same alarm state, class and motor (the stride's motor
    head too in int8). (problems, {"<model>_<prec>": {"strides", "vote_flips", "motor_strides"}})."""
    problems, summary = [], {}
    for net in [m for m in MODELS if any(key[0] == m for key in run.strides)]:
        weights = export / ("sgru_weights.bin" if net == "sgru" else "weights.bin")
        for prec in ("fp32", "int8"):
            flips = strides = heads = 0
            step = export / f"scnode_weights{'_i8' if prec == 'int8' else ''}.bin" if net == "scnode" else None
            for f, path in enumerate(streams):
                host = stream_lines(fwref_stream(host_exe, weights, net, prec == "int8", path, step), run.classes)
                mcu = run.strides.get((net, prec, f), [])
                where = f"{run.cpu} {net} {prec} flight {f}"
                strides, heads = strides + len(mcu), heads + sum(m[7] >= 0 for m in mcu)
                if [m[0] for m in mcu] != host["index"].tolist() or [m[1] for m in mcu] != host["status"].tolist():
                    problems.append(f"{where}: strides or their status differ from the host's fwref_stream")
                    continue
                problems += _stride_problems(where, prec, mcu, host)
                flips += int((np.array([m[3] for m in mcu], bool) != host["vote"]).sum())
            summary[f"{net}_{prec}"] = {"strides": strides, "vote_flips": flips, "motor_strides": heads}
    return problems, summary


def _stride_problems(where: str, prec: str, mcu: list[tuple], host: dict) -> list[str]:
    out = []
    dec = host["status"] == "decided"
    if dec.any():
        got, ref = np.stack([m[2] for m in mcu])[dec], host["logits"][dec]
        if prec == "int8" and not (got.view(np.uint32) == ref.view(np.uint32)).all():
            out.append(f"{where}: int8 logits not bit-identical to the host's")
        bound = FP32_CPP_REL_TOL * max(1.0, float(np.abs(ref).max()))
        if prec == "fp32" and not float(np.abs(got - ref).max()) <= bound:
            out.append(f"{where}: fp32 logits differ from the host's by {float(np.abs(got - ref).max()):.3g} "
                       f"(bound {bound:.3g})")
    votes = np.array([m[3] for m in mcu], bool)
    if prec == "int8" and (votes != host["vote"]).any():
        out.append(f"{where}: {int((votes != host['vote']).sum())} votes differ from the host's")
    if not (votes != host["vote"]).any():
        for j, name in ((4, "active"), (5, "cls"), (6, "motor")) + (((7, "wmotor"),) if prec == "int8" else ()):
            col = np.array([m[j] for m in mcu])
            if not (col.astype(host[name].dtype) == host[name]).all():
                out.append(f"{where}: the alarm's {name} differs from the host's")
    return out
