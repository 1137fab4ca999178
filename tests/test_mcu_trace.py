"""The Cortex-M4 cycle table (runtimes/mcu_cycles.py) and the QEMU block-trace reader
(runtimes/mcu_trace.py) on a hand-made trace whose instructions, cycles, taken branches and
segments are counted by hand below; the same trace read in small chunks gives the same figures.
The reader against QEMU's own -icount on a real run: tests/test_parity.py (the streaming table)."""

from __future__ import annotations

import io

import pytest

from quadfdi.runtimes import mcu_cycles
from quadfdi.runtimes.mcu_cycles import base_of, decode
from quadfdi.runtimes.mcu_trace import Trace


@pytest.mark.parametrize("mnemonic,operands,cls,cycles", [
    ("vldmia", "r6!, {s0, s1, s2, s3, s4, s5, s6, s7}", "fpu_ldm", 9),  # 1 + N
    ("vldmia", "r6!, {s0-s7}", "fpu_ldm", 9),
    ("vpush", "{d8, d9}", "fpu_ldm", 5),  # a double counts two singles
    ("vmla.f32", "s0, s8, s16", "fpu_mac", 3),
    ("vfma.f32", "s0, s1, s2", "fpu_mac", 3),
    ("vdiv.f32", "s0, s1, s2", "fpu_div", 14),
    ("vsqrt.f32", "s0, s1", "fpu_div", 14),
    ("vmulle.f32", "s0, s1, s2", "fpu", 1),  # conditional in an IT block
    ("vldr", "s15, [r3, #0x48]", "fpu_load", 2),
    ("vldr", "d8, [pc, #0x290]", "fpu_load", 3),
    ("vmov", "d0, r0, r1", "fpu_move2", 2),
    ("ldr", "r0, [pc, #0x48]", "load", 2),
    ("ldrsblt.w", "r1, [r2]", "load", 2),
    ("str.w", "r3, [r2, #0xd88]", "store", 1),
    ("strh", "r1, [r0, r2]", "store_reg", 2),
    ("ldrd", "r2, r3, [sp]", "ldrd", 3),
    ("pop", "{r4, r5, pc}", "ldm", 4),
    ("push.w", "{r4, r5, r6, r7, r8, lr}", "ldm", 7),
    ("sdiv", "r0, r1, r2", "div", mcu_cycles.DIV_CYCLES),
    ("umull", "r0, r1, r2, r3", "mul", 1),
    ("smlad", "r0, r1, r2, r0", "mul", 1),
    ("mla", "r0, r1, r2, r3", "mla", 1),
    ("bls", "#0x100", "branch", 1),  # + REFILL when taken: the trace decides
    ("bl", "#0x200", "call", 1),
    ("mov", "pc, lr", "alu_pc", 1),
    ("addge.w", "r0, r1, #4", "alu", 1),
    ("itte", "eq", "it", 1),
    ("dsb", "sy", "other", 1),
])
def test_cycle_classes(mnemonic, operands, cls, cycles):
    insn = decode(mnemonic, operands)
    assert (insn.cls, insn.cycles) == (cls, cycles)
    assert cls in mcu_cycles.CLASSES


def test_a_load_after_a_load_or_store_pipelines():
    first = decode("ldr", "r3, [r2]")
    assert decode("ldr", "r3, [r2, #4]", first).cycles == 1
    assert decode("ldr", "r3, [r2, #4]", decode("str", "r1, [r0]")).cycles == 1
    assert decode("ldr", "r3, [r2, #4]", decode("adds", "r1, #1")).cycles == 2


def test_mnemonic_bases_and_conditions():
    assert base_of("bls") == ("b", True) and base_of("blt.w") == ("b", True) and base_of("bl") == ("bl", False)
    assert base_of("bics") == ("bic", False) and base_of("biceq") == ("bic", True)
    assert base_of("teqeq.w") == ("teq", True) and base_of("mvnsne.w") == ("mvn", True)
    assert base_of("ldrhi") == ("ldr", True) and base_of("ldrsh") == ("ldrsh", False)
    assert base_of("frobnicate") == (None, False)
    assert {row[0] for row in mcu_cycles.CYCLE_TABLE} == set(mcu_cycles.CLASSES)


def _trace_line(ptr: str, pc: int) -> str:
    return f"Trace 0: {ptr} [00000000/{pc:08x}/00000000/ff020200] \n"


def _block(lines: list[str]) -> str:
    return "----------------\nIN: \n" + "".join(f"{ln}\n" for ln in lines) + "\n"


A, T, TIO, TR, B, C = (f"0x7f000000{i:04x}" for i in range(0x100, 0x700, 0x100))
# A: the caller; T: board::ticks()-like, its counter read (0x202) rewound as an I/O access; B: a loop back to A
LOG = "".join([
    _block(["0x00000100:  b580       push     {r7, lr}", "0x00000102:  6813       ldr      r3, [r2]",
            "0x00000104:  6853       ldr      r3, [r2, #4]", "0x00000106:  f000 f87b  bl       #0x200"]),
    _trace_line(A, 0x100),
    _block(["0x00000200:  6808       ldr      r0, [r1]", "0x00000202:  f8dc 0018  ldr.w    r0, [ip, #0x18]",
            "0x00000206:  4770       bx       lr"]),
    _trace_line(T, 0x200), "cpu_io_recompile: rewound execution of TB to 00000202\n",
    _block(["0x00000202:  f8dc 0018  ldr.w    r0, [ip, #0x18]"]), _trace_line(TIO, 0x202),
    _block(["0x00000206:  4770       bx       lr"]), _trace_line(TR, 0x206),
    _block(["0x0000010a:  3801       subs     r0, #1", "0x0000010c:  d1f8       bne      #0x100"]),
    _trace_line(B, 0x10a),
    _trace_line(A, 0x100), f"Stopped execution of TB chain before {A} [00000100] \n",  # the budget ran out
    _trace_line(A, 0x100),
    _trace_line(T, 0x200), "cpu_io_recompile: rewound execution of TB to 00000202\n",
    _trace_line(TIO, 0x202), _trace_line(TR, 0x206), _trace_line(B, 0x10a),  # bne not taken: on to C
    _block(["0x0000010e:  2000       movs     r0, #0", "0x00000110:  4770       bx       lr"]), _trace_line(C, 0x10e),
])


@pytest.mark.parametrize("chunk", [1 << 20, 97])
def test_trace_segments_by_hand(chunk):
    """Executed: A | T' Tio Tr B A | T' Tio Tr B C (T' = T up to its rewound counter read; the
    stopped entry of A not counted). Instructions 4 | 9 | 7. Cycles: A = push 3 + ldr 2 + ldr 1
    (pipelined) + bl 1 = 7, T' = 2, Tio = 2, Tr = 1, B = 2, C = 2; taken: A->T (bl), Tr->B (bx),
    B->A (bne), A->T | Tr->B, and B->C falls through; with REFILL per taken branch."""
    tr = Trace.read(io.BytesIO(LOG.encode()), chunk=chunk)
    seg = tr.segments(0x200, (0x10a,))
    p = mcu_cycles.REFILL
    assert seg["instructions"].tolist() == [4, 9, 7]
    assert seg["taken"].tolist() == [1, 3, 1]
    assert seg["cycles"].tolist() == [7 + p, 2 + 2 + 1 + 2 + 7 + 3 * p, 2 + 2 + 1 + 2 + 2 + p]
    assert seg["mark_10a"].tolist() == [0, 1, 1]
    lo, hi = int(seg["start"][1]), int(seg["start"][2])
    classes = tr.class_cycles(lo, hi)
    assert sum(classes.values()) + 3 * p == seg["cycles"][1]
    assert classes == {"ldm": 3, "load": 2 + 2 + 2 + 1, "call": 1 + 1, "alu": 1, "branch": 1}


def test_a_block_executed_but_never_translated_is_an_error():
    from quadfdi.core.errors import QuadfdiError

    with pytest.raises(QuadfdiError, match="never translated"):
        Trace.read(io.BytesIO(LOG.encode() + _trace_line("0x7f00deadbeef", 0x300).encode()))
