"""Instructions and estimated Cortex-M4 cycles of a QEMU run, from QEMU's block trace, cut into
segments at every entry of one function.

``qemu-system-arm ... -d in_asm,exec,nochain -D LOG`` writes each translated block's instructions
once (``in_asm``: ``IN:``, then ``0x<addr>:  <encoding>  <mnemonic> <operands>`` lines, then an
empty line, then the block's first ``Trace`` line) and, with ``nochain``, one ``Trace`` line per
executed block (``Trace 0: <host ptr> [<cs base>/<pc>/<flags>/<cflags>]``). A block is known by its
host pointer (a block translated again for an instruction budget or an I/O access has its own), so
every executed block's instructions are known, each weighted by its Cortex-M4 cycles
(runtimes/mcu_cycles.py). Three corrections make the count that of the executed instructions, the
figure ``-icount`` counts:

- ``Stopped execution of TB chain before <ptr>``: the block was entered but not executed (the
  instruction budget, refilled every 65,535 instructions, ran out): not counted;
- ``cpu_io_recompile: rewound execution of TB to <addr>``: an I/O access (the SysTick counter read)
  not at the end of its block: only the instructions before ``addr`` ran (the access then runs as a
  block of its own);
- a branch that ends a block is taken when the next executed block does not start at the address
  after it: then it adds the pipeline refill (``mcu_cycles.REFILL``).

``Trace.read(stream, boundary)`` reads a log (a file or a FIFO, in chunks: a paper-scale log is
hundreds of MB) into one array of executed blocks, cut into segments at every entry of the block
at address ``boundary`` (e.g. ``board::ticks()``): segment 0 is everything before the first
entry, segment i >= 1 starts at the i-th.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import BinaryIO

import numpy as np

from quadfdi.core.errors import QuadfdiError
from quadfdi.runtimes.mcu_cycles import CLASSES, REFILL, Insn, decode, taken_cycles

CHUNK_BYTES = 64 << 20
_BLOCK = re.compile(rb"IN:[^\n]*\n((?:0x[^\n]*\n)+)\nTrace 0: (0x[0-9a-f]+) \[[0-9a-f]+/([0-9a-f]{8})/")
_TRACE = re.compile(rb"Trace 0: (0x[0-9a-f]+) ")
_STOP = re.compile(rb"\nStopped execution of TB chain before ")
_REWIND = re.compile(rb"\ncpu_io_recompile: rewound execution of TB to ([0-9a-f]+)")
_STOPPED = -1  # event codes below 0; a rewind to address a is -2 - a


@dataclass
class Block:
    """One translated block: the address, size and decoded class of each instruction."""

    pc: int
    addrs: list[int]
    insns: list[Insn]
    fallthrough: int  # the address after its last instruction

    @property
    def leaves(self) -> bool:
        """Its last instruction can leave it for another address than the fall-through."""
        return bool(self.insns) and taken_cycles(self.insns[-1]) > 0

    def prefix(self, addr: int) -> "Block":
        """Its instructions before ``addr``, where an I/O access rewound it (no branch left it)."""
        k = self.addrs.index(addr) if addr in self.addrs else len(self.addrs)
        return Block(self.pc, self.addrs[:k], self.insns[:k], -1)


def parse_block(text: bytes) -> Block:
    """A block from its ``in_asm`` lines (``0x00003ac4:  f04f 22e0  mov.w    r2, #-0x1fff2000``)."""
    addrs, insns, end = [], [], 0
    for raw in text.decode("ascii", "replace").splitlines():
        enc = raw[13:22].strip()
        parts = raw[22:].strip().split(None, 1)
        addr = int(raw[2:10], 16)
        insns.append(decode(parts[0] if parts else "?", parts[1] if len(parts) > 1 else "",
                            insns[-1] if insns else None))
        addrs.append(addr)
        end = addr + (4 if len(enc) > 4 else 2)
    return Block(addrs[0], addrs, insns, end)


def _cut(buf: bytes) -> int:
    """Where ``buf`` may be split: before a ``Trace`` line whose previous line is one too (no
    translated block is then parted from the first execution that names it); 0 if nowhere."""
    pos = buf.rfind(b"\nTrace ")
    while pos > 0:
        prev = buf.rfind(b"\n", 0, pos) + 1
        if buf.startswith(b"Trace ", prev):
            return pos + 1
        pos = buf.rfind(b"\nTrace ", 0, pos)
    return 0


class Trace:
    """The executed blocks of one run, in order (``codes``: indices into ``blocks``)."""

    def __init__(self) -> None:
        self.blocks: list[Block] = []
        self._ids: dict[bytes, int] = {}  # host pointer -> block index
        self._prefixes: dict[tuple[int, int], int] = {}
        self._parts: list[np.ndarray] = []
        self.codes = np.zeros(0, np.int64)

    @classmethod
    def read(cls, stream: BinaryIO, chunk: int = CHUNK_BYTES) -> "Trace":
        tr, rest = cls(), b""
        while True:
            data = stream.read(chunk)
            buf = rest + data
            if not data:
                tr._chunk(buf)
                break
            at = _cut(buf)
            tr._chunk(buf[:at])
            rest = buf[at:]
        tr._finish()
        return tr

    def _chunk(self, buf: bytes) -> None:
        for text, ptr, pc in _BLOCK.findall(buf):
            block = parse_block(text)
            if block.pc != int(pc, 16):
                raise QuadfdiError(f"QEMU trace: block at {block.pc:#x} first executed at {pc.decode()}")
            if ptr in self._ids and self.blocks[self._ids[ptr]].addrs != block.addrs:
                raise QuadfdiError("QEMU trace: a host block pointer was reused (the translation cache was "
                                   "flushed): trace a shorter run")
            self._ids[ptr] = len(self.blocks)
            self.blocks.append(block)
        # the rare events split the chunk; the Trace lines between them are read in one pass each
        events = sorted([(m.start(), _STOPPED) for m in _STOP.finditer(buf)]
                        + [(m.start(), -2 - int(m.group(1), 16)) for m in _REWIND.finditer(buf)])
        ids, at, codes = self._ids, 0, []
        try:
            for pos, code in events + [(len(buf), None)]:
                codes += [ids[p] for p in _TRACE.findall(buf, at, pos)]
                if code is not None:
                    codes.append(code)
                at = pos
        except KeyError as exc:
            raise QuadfdiError(f"QEMU trace: block {exc.args[0].decode()} executed but never translated in the log")
        self._parts.append(np.array(codes, np.int64))

    def _finish(self) -> None:
        codes = np.concatenate(self._parts) if self._parts else np.zeros(0, np.int64)
        self._parts = []
        keep = codes >= 0
        for i in np.flatnonzero(codes < 0):
            prev = int(codes[i - 1]) if i > 0 else -1
            if prev < 0:
                continue  # nothing entered before it: nothing to correct
            if codes[i] == _STOPPED:
                keep[i - 1] = False
            else:
                codes[i - 1] = self._prefix(prev, -2 - int(codes[i]))
        codes = codes[keep]
        sizes = np.array([len(b.insns) for b in self.blocks], np.int64)
        self.codes = codes[sizes[codes] > 0]  # a block rewound before its first instruction did not run

    def _prefix(self, block: int, addr: int) -> int:
        key = (block, addr)
        if key not in self._prefixes:
            self._prefixes[key] = len(self.blocks)
            self.blocks.append(self.blocks[block].prefix(addr))
        return self._prefixes[key]

    def segments(self, boundary: int, marks: tuple[int, ...] = ()) -> dict[str, np.ndarray]:
        """Per segment (module docstring): ``start`` (index into ``codes``), ``instructions``,
        ``cycles`` (refills included), ``taken`` (taken branches), and ``mark_<hex address>``:
        the entries of each block address in ``marks``."""
        pc = np.array([b.pc for b in self.blocks], np.int64)[self.codes]
        n = np.array([len(b.insns) for b in self.blocks], np.int64)[self.codes]
        cyc = np.array([sum(i.cycles for i in b.insns) for b in self.blocks], np.int64)[self.codes]
        leaves = np.array([b.leaves for b in self.blocks], bool)[self.codes]
        fall = np.array([b.fallthrough for b in self.blocks], np.int64)[self.codes]
        taken = np.zeros(len(self.codes), np.int64)
        taken[:-1] = leaves[:-1] & (pc[1:] != fall[:-1])
        starts = np.concatenate([[0], np.flatnonzero(pc == boundary)]).astype(np.int64)
        empty0 = len(starts) > 1 and starts[1] == 0  # the run starts at the boundary: segment 0 is empty
        idx = starts[1:] if empty0 else starts
        out = {"start": starts, "instructions": self._sums(n, idx, empty0), "taken": self._sums(taken, idx, empty0)}
        out["cycles"] = self._sums(cyc, idx, empty0) + REFILL * out["taken"]
        for m in marks:
            out[f"mark_{m:x}"] = self._sums((pc == m).astype(np.int64), idx, empty0)
        return out

    @staticmethod
    def _sums(values: np.ndarray, idx: np.ndarray, empty0: bool) -> np.ndarray:
        s = np.add.reduceat(values, idx, dtype=np.int64) if len(values) else np.zeros(len(idx), np.int64)
        return np.concatenate([[0], s]) if empty0 else s

    def class_cycles(self, lo: int, hi: int) -> dict[str, int]:
        """Cycles per instruction class (CLASSES) of the executed blocks ``codes[lo:hi]`` (the
        refills of taken branches not included: ``segments`` counts them)."""
        counts = np.bincount(self.codes[lo:hi], minlength=len(self.blocks))
        per = dict.fromkeys(CLASSES, 0)
        for b in np.flatnonzero(counts):
            for insn in self.blocks[b].insns:
                per[insn.cls] += int(counts[b]) * insn.cycles
        return {k: v for k, v in per.items() if v}
