"""The streaming runtime on the Cortex-M under QEMU for a bounded set of recorded flights
(docs/firmware.md "Streaming"): a measurement, not a test.

    PYTHONPATH=. python scripts/stream_mcu.py RUN/export BUILD_DIR STREAM.bin [STREAM.bin ...] [--cpu cortex-m4]

Cross-builds firmware_ref/mcu with the export's weights and -DFWREF_STREAMS (fwref_mcu_stream.elf,
mcu/stream_main.cpp), runs it under QEMU, and holds every stride against the host's fwref_stream on
the same stream files: the same status, int8 logits bit-identical, fp32 within FP32_CPP_REL_TOL,
the same votes and alarm states, and with a motor head the same alarm motor and stride motor
(fp32: counted where they differ). With the export's sgru_weights.bin (``quadfdi export sgru``) the
streaming GRU runs too (model "sgru": a GRU step per push). Prints per model and precision the
instructions per push (without a stride: for the streaming GRU one step, i.e. per sample), per
decision (mean and worst) and per non-decided stride, and the estimated time and duty cycle at
168 MHz (M4) / 216 MHz (M7), one instruction per cycle assumed, against one sample period (40 ms);
the duty cycle is over a stride of samples (stride - 1 pushes and one decision).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from quadfdi.core.contracts import FP32_CPP_REL_TOL
from quadfdi.formats.export_folder import Export
from quadfdi.detect.streamref import read_lines
from quadfdi.runtimes.build import MCU_CPUS, _configure_and_build, build_host, mcu_options, source_dir
from quadfdi.runtimes.mcu import CLOCK_MHZ, qemu_command


def parse(text: str, k: int) -> tuple[dict, dict]:
    strides: dict = {}
    perf: dict = {}
    for line in text.splitlines():
        p = line.split()
        if p and p[0] == "STRIDE":
            key = (p[1], p[2], int(p[3]))
            bits = np.array([int(v) for v in p[6:6 + k]], np.uint32).view(np.float32)
            strides.setdefault(key, []).append((int(p[4]), p[5], bits, int(p[6 + k]), int(p[7 + k]), int(p[8 + k]),
                                                int(p[9 + k]), int(p[10 + k])))
        elif p and p[0] == "PERF":
            perf[(p[1], p[2], int(p[3]))] = {a.split("=")[0]: int(a.split("=")[1]) for a in p[4:]}
    return strides, perf


def models(strides: dict) -> list[str]:
    return [m for m in ("cnode", "gru", "sgru") if any(key[0] == m for key in strides)]


def compare(export: Path, streams: list[Path], strides: dict, k: int) -> list[str]:
    out = []
    for net in models(strides):
        weights = export / ("sgru_weights.bin" if net == "sgru" else "weights.bin")
        for prec in ("fp32", "int8"):
            flips = 0
            for f, path in enumerate(streams):
                res = subprocess.run([str(build_host(log=lambda _: None) / "fwref_stream"), "--weights", str(weights),
                                      "--model", net, "--in", str(path)] + (["--int8"] if prec == "int8" else []),
                                     capture_output=True, text=True, check=True)
                host = read_lines(res.stdout, k)
                mcu = strides[(net, prec, f)]
                assert [m[0] for m in mcu] == host["index"].tolist() and [m[1] for m in mcu] == host["status"].tolist()
                dec = host["status"] == "decided"
                got = np.stack([m[2] for m in mcu])[dec]
                if prec == "int8":
                    assert (got == host["logits"][dec]).all(), (net, prec, f)
                else:
                    ref = host["logits"][dec]
                    assert np.abs(got - ref).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(ref).max()), (net, prec, f)
                votes = np.array([m[3] for m in mcu], bool)
                flips += int((votes != host["vote"]).sum())
                assert prec == "fp32" or flips == 0
                if not (votes != host["vote"]).any():
                    assert (np.array([m[4] for m in mcu], bool) == host["active"]).all()
                    assert (np.array([m[5] for m in mcu]) == host["cls"]).all()
                    assert (np.array([m[6] for m in mcu]) == host["motor"]).all()
                    wm = np.array([m[7] for m in mcu])
                    assert prec == "fp32" or (wm == host["wmotor"]).all()
            heads = sum(m[7] >= 0 for f in range(len(streams)) for m in strides[(net, prec, f)])
            out.append(f"{net} {prec}: every stride as the host's (vote flips {flips}; strides with a motor {heads})")
    return out


def report(perf: dict, cpu: str, stride: int, dt: float) -> list[str]:
    lines = []
    per_second = {}  # (net, prec): instructions per second of flight (one decision + stride - 1 pushes per stride)
    for net in sorted({m for m, _, _ in perf}, key=("cnode", "gru", "sgru").index):
        for prec in ("fp32", "int8"):
            rows = [v for (m, p, _), v in perf.items() if (m, p) == (net, prec)]
            tot = {key: sum(r[key] for r in rows) for key in rows[0]}
            worst = {key: max(r[key] for r in rows) for key in rows[0] if key.endswith("_max")}
            mean_dec = tot["decide_sum"] / max(tot["decide_n"], 1)
            mhz = CLOCK_MHZ[cpu]
            worst_ms = worst["decide_max"] / mhz / 1000
            per_second[(net, prec)] = (mean_dec + (stride - 1) * tot["push_sum"] / max(tot["push_n"], 1)) / (stride * dt)
            duty = per_second[(net, prec)] / (mhz * 1e6)
            lines.append(f"{cpu} {net} {prec}: push {tot['push_sum'] / max(tot['push_n'], 1):.0f} (max "
                         f"{worst['push_max']}), decision {mean_dec:.0f} (max {worst['decide_max']}), no-decision "
                         f"stride max {worst['other_max']} instructions; worst decision {worst_ms:.2f} ms at {mhz:.0f} "
                         f"MHz ({'within' if worst_ms < dt * 1000 else 'OVER'} {dt * 1000:.0f} ms), duty {100 * duty:.2f} %")
    for prec in ("fp32", "int8"):  # issue 16: the streaming GRU at no more than 1/6 of the windowed GRU's compute
        if ("sgru", prec) in per_second and ("gru", prec) in per_second:
            r = per_second[("sgru", prec)] / per_second[("gru", prec)]
            lines.append(f"{cpu} sgru/gru {prec}: {per_second[('sgru', prec)]:.0f} / {per_second[('gru', prec)]:.0f} "
                         f"instructions per second of flight = {r:.4f} ({'within' if r <= 1 / 6 else 'OVER'} 1/6)")
    return lines


def main(argv: list[str]) -> int:
    cpu = "cortex-m4"
    if "--cpu" in argv:
        i = argv.index("--cpu")
        cpu = argv[i + 1]
        argv = argv[:i] + argv[i + 2:]
    export, build = Path(argv[0]).resolve(), Path(argv[1]).resolve()
    streams = [Path(p).resolve() for p in argv[2:]]
    build_host(log=lambda _: None)
    build.mkdir(parents=True, exist_ok=True)
    src = source_dir()
    options = mcu_options(src, cpu, export / "weights.bin", export / "reference.bin")
    options["FWREF_STREAMS"] = ";".join(str(s) for s in streams)
    _configure_and_build(src / "mcu", build, options, f"the {cpu} stream image", ("fwref_mcu_stream",))
    res = subprocess.run(qemu_command(cpu, build / "fwref_mcu_stream.elf"), capture_output=True, text=True, check=False,
                         timeout=3600)
    assert "RESULT DONE" in res.stdout, res.stdout[-2000:] + res.stderr[-2000:]
    record = Export.open(export).onboard()
    k = int(res.stdout.split("STRIDE ", 1)[1].split("\n", 1)[0].split().__len__()) - 10  # after "STRIDE ": 10 fields + K
    strides, perf = parse(res.stdout, k)
    print(f"{export} ({record['profile']}) on {cpu} ({MCU_CPUS[cpu]}): {len(streams)} flights, "
          f"{next(ln for ln in res.stdout.splitlines() if ln.startswith('STREAM '))}")
    for line in compare(export, streams, strides, k) + report(perf, cpu, record["stride"], record["sample_dt_s"]):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
