"""Where the streaming GRU's instructions go on the Cortex-M: a stream image's QEMU block trace
attributed per function and per source line, for the streaming GRU's replays only (docs/firmware.md
"Streaming on the Cortex-M under QEMU, and measured"): a measurement, not a test.

    # an image with debug lines (the same code: -g changes no instruction) and a short stream
    head -c $((224 + 100 * 108)) f2.bin > short.bin          # header + 100 samples (R = 25)
    cmake -S firmware_ref/mcu -B BUILD -DCMAKE_TOOLCHAIN_FILE=$PWD/firmware_ref/mcu/toolchain-arm-none-eabi.cmake \\
          -DFWREF_CPU=cortex-m4 -DFWREF_WEIGHTS=EXPORT/weights.bin -DFWREF_REFERENCE=EXPORT/reference.bin \\
          -DFWREF_STREAMS=$PWD/short.bin \\
          "-DCMAKE_CXX_FLAGS=-mcpu=cortex-m4 -mthumb -mfpu=fpv4-sp-d16 -mfloat-abi=hard -g"
    cmake --build BUILD --target fwref_mcu_stream
    qemu-system-arm -machine mps2-an386 -nographic -serial none -monitor none -chardev stdio,id=sh0 \\
        -semihosting-config enable=on,target=native,chardev=sh0 -icount shift=0 \\
        -kernel BUILD/fwref_mcu_stream.elf -d in_asm,exec,nochain -D qlog.txt > /dev/null
    python scripts/stream_mcu_profile.py qlog.txt BUILD/fwref_mcu_stream.elf SAMPLES

The trace is split where the streaming GRU's replays begin (the first block of
``StepRunner<GruF32>`` / ``StepRunner<GruI8>``; they run last in mcu/stream_main.cpp). Per
precision it prints the instructions per sample (divided by SAMPLES) by function and by the
outermost line of src/gru_step.cpp, src/stream.cpp or fwref/alarm.hpp that the instruction was
inlined into (``arm-none-eabi-addr2line -i``), else by function. Every figure includes the replay
harness's own work between pushes (printing, the per-push sink), which the image's PERF lines leave out.
"""

from __future__ import annotations

import bisect
import collections
import re
import subprocess
import sys

OWN_FILES = ("gru_step.cpp", "stream.cpp", "alarm.hpp")


def symbols(elf: str) -> list[tuple[int, str]]:
    nm = subprocess.run(["arm-none-eabi-nm", "-C", "-n", elf], capture_output=True, text=True, check=True).stdout
    return [(int(p[0], 16), p[2]) for p in (line.split(" ", 2) for line in nm.splitlines())
            if len(p) == 3 and p[1] in "tTwW"]


def trace(log: str, marks: dict[int, str]) -> tuple[dict[int, list[int]], dict[str, collections.Counter]]:
    """Blocks (start -> instruction addresses) and, per phase, executions per block start."""
    blocks: dict[int, list[int]] = {}
    execs: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    cur, phase = None, "before"
    with open(log) as f:
        for line in f:
            if line.startswith("IN:"):
                cur = None
                continue
            m = re.match(r"^0x([0-9a-f]+):\s", line)
            if m:
                a = int(m.group(1), 16)
                if cur is None:
                    cur = a
                    blocks[cur] = []
                blocks[cur].append(a)
                continue
            m = re.match(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/", line)
            if m:
                pc = int(m.group(1), 16)
                phase = marks.get(pc, phase)
                execs[phase][pc] += 1
    return blocks, execs


def inline_chains(elf: str, addrs: list[int]) -> dict[int, list[tuple[str, str]]]:
    """address -> [(function, file:line), ...] innermost first (addr2line -a -i -f)."""
    out = subprocess.run(["arm-none-eabi-addr2line", "-a", "-i", "-C", "-f", "-e", elf] + [hex(a) for a in addrs],
                         capture_output=True, text=True, check=True).stdout.splitlines()
    chains: dict[int, list[tuple[str, str]]] = {}
    i = 0
    while i < len(out):
        a = int(out[i], 16)
        i += 1
        chain = []
        while i + 1 < len(out) and not out[i].startswith("0x"):
            chain.append((out[i], out[i + 1]))
            i += 2
        chains[a] = chain
    return chains


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 1
    log, elf, samples = argv[0], argv[1], int(argv[2])
    syms = symbols(elf)
    starts = [a for a, _ in syms]

    def fn(pc: int) -> str:
        i = bisect.bisect_right(starts, pc & ~1) - 1
        return syms[i][1][:60] if i >= 0 else "?"

    marks = {a: ("sgru fp32" if "GruF32" in n else "sgru int8") for a, n in syms
             if n.startswith("fwref::StepRunner<fwref::Gru")}
    blocks, execs = trace(log, marks)
    chains = inline_chains(elf, sorted({a for b in blocks.values() for a in b}))
    for phase in ("sgru fp32", "sgru int8"):
        per_ins: collections.Counter = collections.Counter()
        for b, c in execs[phase].items():
            for a in blocks.get(b, []):
                per_ins[a] += c
        by_fn: collections.Counter = collections.Counter()
        by_line: collections.Counter = collections.Counter()
        for a, c in per_ins.items():
            by_fn[fn(a)] += c
            own = [loc for _, loc in chains.get(a, []) if loc.split("/")[-1].split(":")[0] in OWN_FILES]
            by_line[own[-1].split("/")[-1] if own else "in " + fn(a)] += c
        print(f"== {phase}: {sum(per_ins.values()) / samples:.0f} instructions per sample")
        for name, c in by_fn.most_common(12):
            print(f"  function {c / samples:9.1f}  {name}")
        for name, c in by_line.most_common(20):
            print(f"  line     {c / samples:9.1f}  {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
