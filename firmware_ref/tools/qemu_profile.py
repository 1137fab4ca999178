"""Instructions per function of a Cortex-M image under QEMU, from QEMU's block trace.

    qemu-system-arm -machine mps2-an386 -nographic -serial none -monitor none \
        -semihosting-config enable=on,target=native -icount shift=0 \
        -kernel firmware_ref/build-mcu-m4/fwref_min_cnode_i8.elf -d in_asm,exec,nochain -D /tmp/qlog.txt
    python firmware_ref/tools/qemu_profile.py /tmp/qlog.txt firmware_ref/build-mcu-m4/fwref_min_cnode_i8.elf

``in_asm`` prints each translated block's instructions once, ``exec`` (with ``nochain``) one line per
executed block: instructions per block times executions, attributed to the function (``arm-none-eabi-nm``)
the block starts in. The fwref_min_* images run ``check`` and one inference on a zero window, so
``check``'s count is not part of an inference. Prints the total, the functions and the hottest blocks.
"""

from __future__ import annotations

import bisect
import collections
import re
import subprocess
import sys


def profile(log_lines: list[str]) -> collections.Counter:
    """Instructions executed per block start address."""
    size: dict[int, int] = {}
    cur, n = None, 0
    tot: collections.Counter = collections.Counter()
    for line in log_lines:
        if line.startswith("IN:"):
            cur, n = None, 0
            continue
        m = re.match(r"^0x([0-9a-f]+):\s", line)
        if m:
            cur = int(m.group(1), 16) if cur is None else cur
            n += 1
            size[cur] = n
            continue
        m = re.match(r"^Trace \d+: \S+ \[[0-9a-f]+/([0-9a-f]+)/", line)
        if m:
            pc = int(m.group(1), 16)
            tot[pc] += size.get(pc, 0)
    return tot


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 1
    tot = profile(open(argv[0]).read().splitlines())
    nm = subprocess.run(["arm-none-eabi-nm", "-C", "-n", argv[1]], capture_output=True, text=True, check=True).stdout
    syms = [(int(p[0], 16), p[2][:70]) for p in (line.split(" ", 2) for line in nm.splitlines())
            if len(p) == 3 and p[1] in "tTwW"]
    starts = [a for a, _ in syms]

    def fn(pc: int) -> str:
        i = bisect.bisect_right(starts, pc & ~1) - 1
        return syms[i][1] if i >= 0 else "?"

    byfn: collections.Counter = collections.Counter()
    for pc, c in tot.items():
        byfn[fn(pc)] += c
    print(f"total {sum(tot.values())}")
    for f, c in byfn.most_common(8):
        print(f"{c:9d} {f}")
    print("hottest blocks (instructions, address, function)")
    for pc, c in tot.most_common(12):
        print(f"{c:9d} {pc:#x} {fn(pc)[:50]}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
