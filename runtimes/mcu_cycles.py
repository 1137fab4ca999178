"""Cycles of Cortex-M4 instructions, by the Cortex-M4 Technical Reference Manual's timing tables:
the weights that turn a QEMU instruction trace (runtimes/mcu_trace.py) into an estimate of cycles.

QEMU counts instructions, not cycles. Each instruction QEMU's disassembler prints (``in_asm``) is
put in one class of ``CLASSES``; a class's cycles come from the ARM Cortex-M4 Technical Reference
Manual (DDI 0439), its instruction set summary with the processor instruction timings, and its
FPU chapter's instruction set table with the FPv4-SP instructions' cycle counts. Where the
manual gives a range or a condition that a block trace cannot see, the value used is an assumption
and its row says so (``ASSUMED``). Not modelled at all: flash wait states and the flash accelerator
(the estimate is for zero-wait-state memory: an STM32F4 at 168 MHz runs its flash with 5 wait
states behind the ART accelerator's cache and prefetch), bus contention, interrupt entry and exit,
IT folding, and the M7 (dual issue, FPU pipelining: no cycle figure is made for it).

``CYCLE_TABLE`` lists every class, its cycles, its instructions and its source, in that order.

P, the pipeline refill after a taken branch, is 1 to 3 cycles in the TRM (by the target's
alignment and width and whether the address was speculated early): ``REFILL`` = 2, the middle,
is ASSUMED; every figure made with it also keeps its count of taken branches, so that the estimate
at P = 1 or P = 3 is that count less or more. Conditional instructions inside an IT block are
costed as executed (a skipped one takes 1 cycle on the core): an upper bound for them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

REFILL = 2  # P, cycles of pipeline refill after a taken branch (TRM: 1-3); ASSUMED the middle
DIV_CYCLES = 12  # SDIV/UDIV: 2-12 in the TRM (early termination); ASSUMED the worst

_TRM = "Cortex-M4 TRM, instruction set summary (processor instruction timings)"
_FPU = "Cortex-M4 TRM, FPU instruction set (cycle counts)"
# (class, cycles, instructions, source); N = registers moved, P = the refill after a taken branch
CYCLE_TABLE: tuple[tuple[str, str, str, str], ...] = (
    ("alu", "1", "data processing, shifts, moves, compares, extends, bit fields, SSAT/USAT, SIMD add/sub, "
                 "CLZ, REV, SEL, NOP", _TRM),
    ("alu_pc", "1 + P", "a data-processing or move instruction that writes the PC", _TRM),
    ("mul", "1", "MUL, SMULL, UMULL, SMLAL, UMLAL, SMLAD, SMUAD, SMLAxy, SMMUL and the other DSP multiplies", _TRM),
    ("mla", "1", "MLA, MLS (ASSUMED: the M4's single-cycle multiply-accumulate; not checked against the manual "
                 "here)", _TRM),
    ("div", str(DIV_CYCLES), "SDIV, UDIV: 2-12 by early termination on the operands; ASSUMED the worst", _TRM),
    ("load", "2, or 1", "LDR, LDRB, LDRH, LDRSB, LDRSH, LDREX: 1 right after a load or store single in the same "
                        "block (neighbouring loads and stores pipeline their address and data phases)", _TRM),
    ("load_pc", "2 + P", "LDR that writes the PC", _TRM),
    ("store", "1", "STR, STRB, STRH with an immediate or no offset (\"STR Rx,[Ry,#imm] is always one cycle\")", _TRM),
    ("store_reg", "2, or 1", "STR, STRB, STRH with a register offset; 1 when pipelined like a load", _TRM),
    ("ldrd", "3", "LDRD, STRD (1 + N, N = 2)", _TRM),
    ("ldm", "1 + N", "LDM, STM, PUSH, POP; with the PC in the list 1 + N + P", _TRM),
    ("branch", "1, or 1 + P", "B, B<cond>, CBZ, CBNZ: 1 + P when taken (the next executed block does not start "
                              "at the fall-through address)", _TRM),
    ("call", "1 + P", "BL, BX, BLX", _TRM),
    ("table_branch", "2 + P", "TBB, TBH", _TRM),
    ("it", "1", "IT (ASSUMED not folded into the previous instruction)", _TRM),
    ("fpu", "1", "VADD, VSUB, VMUL, VNMUL, VABS, VNEG, VCMP, VCMPE, VCVT, VMOV, VMRS, VMSR (.F32)", _FPU),
    ("fpu_mac", "3", "VMLA, VMLS, VNMLA, VNMLS, VFMA, VFMS, VFNMA, VFNMS (.F32)", _FPU),
    ("fpu_div", "14", "VDIV.F32, VSQRT.F32", _FPU),
    ("fpu_load", "2, or 3", "VLDR, VSTR: 2 for a single register, 3 for a double", _FPU),
    ("fpu_move2", "2", "VMOV between two core registers and a double or two singles", _FPU),
    ("fpu_ldm", "1 + N", "VLDM, VSTM, VPUSH, VPOP of N single registers (a double counts 2)", _FPU),
    ("other", "1", "anything else: barriers, hints, BKPT, SVC, MRS, MSR, CPS (ASSUMED 1)", "ASSUMED"),
)
CLASSES = tuple(row[0] for row in CYCLE_TABLE)

_CONDS = ("eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le", "al")
# base mnemonic -> class; ``_FLAGS``: the bases that take an S suffix (set flags)
_BASES = {
    **{m: "alu" for m in ("mov", "movw", "movt", "mvn", "add", "addw", "adc", "sub", "subw", "sbc", "rsb", "and", "orr",
                          "orn", "eor", "bic", "cmp", "cmn", "tst", "teq", "lsl", "lsr", "asr", "ror", "rrx", "adr",
                          "clz", "rbit", "rev", "rev16", "revsh", "sxtb", "sxth", "uxtb", "uxth", "sxtb16", "uxtb16",
                          "sxtab", "sxtah", "uxtab", "uxtah", "sxtab16", "uxtab16", "bfi", "bfc", "sbfx", "ubfx",
                          "ssat", "usat", "ssat16", "usat16", "sel", "usad8", "usada8", "pkhbt", "pkhtb", "qadd",
                          "qsub", "qdadd", "qdsub", "sadd16", "ssub16", "sadd8", "ssub8", "uadd16", "usub16", "uadd8",
                          "usub8", "qadd16", "qsub16", "qadd8", "qsub8", "shadd16", "shsub16", "uqadd16", "uqsub16",
                          "sasx", "ssax", "uasx", "usax", "nop")},
    **{m: "mul" for m in ("mul", "smull", "umull", "smlal", "umlal", "umaal", "smlad", "smladx", "smlsd", "smlsdx",
                          "smuad", "smuadx", "smusd", "smusdx", "smlald", "smlaldx", "smlsld", "smlsldx", "smmul",
                          "smmulr", "smmla", "smmlar", "smmls", "smmlsr", "smlabb", "smlabt", "smlatb", "smlatt",
                          "smlawb", "smlawt", "smulbb", "smulbt", "smultb", "smultt", "smulwb", "smulwt", "smlalbb",
                          "smlalbt", "smlaltb", "smlaltt")},
    "mla": "mla", "mls": "mla", "sdiv": "div", "udiv": "div",
    **{m: "load" for m in ("ldr", "ldrb", "ldrh", "ldrsb", "ldrsh", "ldrex", "ldrexb", "ldrexh", "ldrt", "ldrbt",
                           "ldrht", "ldrsbt", "ldrsht")},
    **{m: "store" for m in ("str", "strb", "strh", "strex", "strexb", "strexh", "strt", "strbt", "strht")},
    "ldrd": "ldrd", "strd": "ldrd",
    **{m: "ldm" for m in ("ldm", "ldmia", "ldmfd", "ldmdb", "ldmea", "stm", "stmia", "stmea", "stmdb", "stmfd", "push",
                          "pop")},
    "b": "branch", "cbz": "branch", "cbnz": "branch", "bl": "call", "bx": "call", "blx": "call",
    "tbb": "table_branch", "tbh": "table_branch",
    **{m: "fpu" for m in ("vadd", "vsub", "vmul", "vnmul", "vabs", "vneg", "vcmp", "vcmpe", "vcvt", "vcvtr", "vcvtb",
                          "vcvtt", "vmov", "vmrs", "vmsr")},
    **{m: "fpu_mac" for m in ("vmla", "vmls", "vnmla", "vnmls", "vfma", "vfms", "vfnma", "vfnms")},
    "vdiv": "fpu_div", "vsqrt": "fpu_div", "vldr": "fpu_load", "vstr": "fpu_load",
    **{m: "fpu_ldm" for m in ("vldm", "vldmia", "vldmdb", "vstm", "vstmia", "vstmdb", "vpush", "vpop")},
}
_FLAGS = {m for m, c in _BASES.items() if c in ("alu", "mul", "mla")} - {"cmp", "cmn", "tst", "teq", "nop"}
_ORDER = sorted(_BASES, key=len, reverse=True)  # longest first: "bic" before "b", "ldrsb" before "ldr"
_IT = re.compile(r"^it[te]{0,3}$")
_REG = re.compile(r"^([rsd])(\d+)$")
_ALIASES = {"sb": "r9", "sl": "r10", "fp": "r11", "ip": "r12", "sp": "r13", "lr": "r14", "pc": "r15"}


@dataclass(frozen=True)
class Insn:
    """One decoded instruction: its class, its cycles (a taken branch's refill not included), and
    whether it can leave the block for somewhere other than the next instruction."""

    cls: str
    cycles: int
    branch: bool


def base_of(mnemonic: str) -> tuple[str | None, bool]:
    """(base mnemonic, conditional) of a disassembled mnemonic (width and type suffixes removed):
    ``"addge.w"`` -> ("add", True), ``"bls"`` -> ("b", True), ``"vmulle.f32"`` -> ("vmul", True)."""
    m = mnemonic.split(".", 1)[0].lower()
    if _IT.match(m):
        return "it", False
    for base in _ORDER:
        if not m.startswith(base):
            continue
        rest = m[len(base):]
        if rest == "" or rest in _CONDS:
            return base, rest != ""
        if base in _FLAGS and rest[:1] == "s" and (rest[1:] == "" or rest[1:] in _CONDS):
            return base, rest[1:] != ""
    return None, False


def _registers(operands: str) -> list[str]:
    """The registers of an operand's register list ``{r4, r5, lr}`` / ``{s0-s7}`` / ``{d8, d9}``."""
    inside = operands[operands.find("{") + 1:operands.find("}")] if "{" in operands else ""
    out: list[str] = []
    for part in (p.strip() for p in inside.split(",") if p.strip()):
        lo, _, hi = part.partition("-")
        a, b = _REG.match(_ALIASES.get(lo, lo)), _REG.match(_ALIASES.get(hi, hi)) if hi else None
        if a and b:
            out += [f"{a.group(1)}{i}" for i in range(int(a.group(2)), int(b.group(2)) + 1)]
        else:
            out.append(_ALIASES.get(lo, lo))
    return out


def _writes_pc(operands: str) -> bool:
    return operands.split(",", 1)[0].strip() == "pc"


def decode(mnemonic: str, operands: str, prev: Insn | None = None) -> Insn:
    """The class and cycles of one instruction; ``prev`` the instruction before it in the same block
    (a load or store single before a load lets it pipeline)."""
    base, _ = base_of(mnemonic)
    cls = "other" if base is None else "it" if base == "it" else _BASES[base]
    pipelined = prev is not None and prev.cls in ("load", "store", "store_reg")
    if cls == "alu":
        return Insn("alu_pc", 1, True) if _writes_pc(operands) else Insn("alu", 1, False)
    if cls == "div":
        return Insn(cls, DIV_CYCLES, False)
    if cls == "load":
        return Insn("load_pc", 2, True) if _writes_pc(operands) else Insn(cls, 1 if pipelined else 2, False)
    if cls == "store":
        reg_offset = re.search(r"\[[^\]#]*,\s*[a-z]", operands) is not None  # [rn, rm] or [rn, rm, lsl #k]
        return Insn("store_reg", 1 if pipelined else 2, False) if reg_offset else Insn(cls, 1, False)
    if cls == "ldm":
        regs = _registers(operands)
        return Insn(cls, 1 + len(regs), "r15" in regs)
    if cls == "fpu_ldm":
        return Insn(cls, 1 + sum(2 if r.startswith("d") else 1 for r in _registers(operands)), False)
    if cls == "fpu_load":
        return Insn(cls, 3 if operands.strip().startswith("d") else 2, False)
    if cls == "fpu" and base == "vmov" and operands.count(",") == 2:
        return Insn("fpu_move2", 2, False)  # vmov d0, r0, r1 / vmov r0, r1, d0
    if cls in ("branch", "call"):
        return Insn(cls, 1, True)
    if cls == "table_branch":
        return Insn(cls, 2, True)
    if cls == "ldrd":
        return Insn(cls, 3, False)
    if cls == "mla":
        return Insn(cls, 1, False)
    if cls in ("mul", "it", "other"):
        return Insn(cls, 1, False)
    return Insn(cls, {"fpu": 1, "fpu_mac": 3, "fpu_div": 14}[cls], False)


def taken_cycles(insn: Insn) -> int:
    """The cycles a block-ending instruction adds when it leaves the block (the refill P): taken
    branches, calls, returns and loads or moves to the PC."""
    return REFILL if insn.branch else 0
