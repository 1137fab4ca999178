"""``quadfdi parity --run runs/<name> [--no-mcu | --mcu]``: the C++ reference against ONNX Runtime and
PyTorch on the test split, fwref_parity on reference.bin, and the Cortex-M build under QEMU."""

from __future__ import annotations

import argparse
import shlex
import sys

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.rundir import open_run


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "parity", help="C++ firmware reference vs ONNX Runtime and PyTorch; Cortex-M build under QEMU",
        description="Build firmware_ref (CMake, Release, in the per-user cache), run the whole test split one window "
                    "at a time through C++ fp32/int8, ONNX Runtime fp32/int8 and PyTorch, run fwref_parity on "
                    "reference.bin and (by default) the Cortex-M4/M7 builds under QEMU, with the on-board streaming "
                    "cost of every model (a few test flights replayed through the stream image, every stride held "
                    "against the host's fwref_stream; instructions, estimated M4 cycles, duty cycle); write "
                    "<run>/parity/parity.json, parity.md, mcu.json and mcu_stream.json. Exits 2 if a parity target "
                    "is missed.")
    add_config_args(p, config=False)
    p.add_argument("--run", required=True, help="run folder holding export/ (after `quadfdi export`)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--no-mcu", action="store_true",
                       help="skip the Cortex-M cross-build and QEMU runs (and the streaming cost table)")
    which.add_argument("--mcu", action="store_true",
                       help="only the Cortex-M part: cross-build, QEMU runs, mcu.json and mcu_stream.json "
                            "(updates parity.json/md)")
    which.add_argument("--scnode", action="store_true",
                       help="only the streaming CNODE (`quadfdi export scnode`) on the Cortex-M4 under QEMU: every "
                            "sample of its replay flight against ONNX Runtime, estimated M4 cycles per step, the 1 %% "
                            "duty-cycle target; writes parity/scnode_mcu.json and scnode_mcu.md")
    p.set_defaults(func=run_parity)


def run_parity(args: argparse.Namespace) -> int:
    from quadfdi.parity.run import parity_run

    run, cfg = open_run(args.run, args.overrides, need=("export",))
    if args.scnode:
        return _run_scnode(run.root, cfg.sim.sample_dt_s)
    command = "quadfdi " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:] else None
    report = parity_run(run, cfg, mcu=not args.no_mcu, host=not args.mcu, command=command)
    if "models" in report:
        for model, pairs in report["models"].items():
            f, q = pairs["cpp_fp32_vs_ort_fp32"], pairs["cpp_int8_vs_ort_int8"]
            i8 = (f"{q['bitwise_identical_windows']}/{q['windows']} windows bit-identical" if q["target"].get("bitwise")
                  else f"{q['target']['max_diff_steps']:.3g} logit steps")  # a motor head (parity.run.motor_pairs)
            print(f"parity: {model}: C++ fp32 vs ORT max |diff| {f['max_abs_diff']:.3g}, argmax "
                  f"{100 * f['argmax_agreement']:.2f} %; C++ int8 vs ORT {i8}, argmax {100 * q['argmax_agreement']:.2f} %")
    print(f"parity: passed; report {run.root / 'parity' / 'parity.md'}")
    return 0


def _run_scnode(root, period_s: float) -> int:
    from quadfdi.parity.scnode import scnode_parity

    r = scnode_parity(root, period_s)
    for prec in ("fp32", "int8"):
        p, c = r["parity"][prec], r["cost"][prec]
        print(f"parity: scnode {prec}: {p['bit_identical_samples']}/{p['samples']} samples bit-identical to ONNX "
              f"Runtime, max |diff| {p['max_abs_diff']:.3g}; M4 step {c['cycles_max']:,} cycles (est.), duty "
              f"{100 * c['duty']:.3f} % ({'meets' if c['meets_target'] else 'misses'} 1 %)")
    print(f"parity: {'passed' if r['passed'] else 'FAILED'}; report {root / 'parity' / 'scnode_mcu.md'}")
    return 0 if r["passed"] else 2
