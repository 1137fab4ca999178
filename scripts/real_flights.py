"""`quadfdi detect` on every real quad log of ../shared/data/flightlogs (issue 14 point 6), then the table.

    PYTHONPATH=. python scripts/real_flights.py OUT --export min=EXPORT [--export esc=EXPORT]
        [--export nocur=EXPORT] [--logs DIR] [--gap-factor F] [LOG ...]

Each log is ingested once (``quadfdi ingest``); each export (a profile's realistic-suite model)
(``--gap-factor F``: ``quadfdi ingest --gap-factor F``, bridging logging gaps) then runs ``quadfdi detect`` for both nets, both runtimes (ort, cpp) and both precisions, into
``OUT/<profile>/<flight>/<net>/<runtime>/<precision>/`` (alarms.json ...; a refused flight leaves
its one-line reason in ``<precision>.stderr``). The flightlog-esc model runs only on logs with ESC
telemetry. Printed: per profile, flight and net, the ORT fp32 alarms, decided windows and exposure,
whether C++ and ORT (and int8 and fp32) gave the same alarms; then every refusal's reason.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
from pathlib import Path

from quadfdi.cli import main as quadfdi

LOGS = ["px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_quad_6s_gps_interference.ulg",
        "px4_fmuv5_quad_real_short.ulg", "px4_quad_battery_monitor_disconnected.ulg", "px4_sitl_quad_esc.ulg",
        "ardupilot_copter_quadx_ground.BIN"]
LOGS_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "flightlogs"  # CI puts shared/ beside the clone
ESC_LOGS = {"px4_quad_6s_uavcan_mission.ulg", "px4_quad_6s_vibration_tipover.ulg", "px4_sitl_quad_esc.ulg"}
PROFILES = {"min": "flightlog-min", "esc": "flightlog-esc", "nocur": "flightlog-nocur"}
CASES = [(net, rt, pr) for net in ("cnode", "gru") for rt in ("ort", "cpp") for pr in ("fp32", "int8")]


def _quiet(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = quadfdi(argv)
    return rc, err.getvalue()


def run_all(out: Path, exports: dict[str, str], logs_dir: Path, logs: list[str], gap: str | None = None) -> None:
    for log in logs:
        stem = log.split(".")[0]
        ing = out / "ingest" / stem
        shutil.rmtree(ing, ignore_errors=True)
        rc, _ = _quiet(["ingest", str(logs_dir / log), "--out", str(ing)] + (["--gap-factor", gap] if gap else []))
        src = ing / "flight.npz" if rc == 0 else logs_dir / log  # refused by ingest: detect says why
        for prof, export in exports.items():
            if prof == "esc" and log not in ESC_LOGS:
                continue
            for net, rt, pr in CASES:
                d = out / prof / stem / net / rt / pr
                shutil.rmtree(d, ignore_errors=True)
                d.parent.mkdir(parents=True, exist_ok=True)
                rc, err = _quiet(["detect", "--model", export, str(src), "--net", net, "--runtime", rt,
                                  "--precision", pr, "--out", str(d)])
                (d.parent / f"{pr}.stderr").write_text(err)
                print(prof, stem, net, rt, pr, f"rc={rc}", err.strip()[-160:], flush=True)


def _key(a: dict) -> list:
    return [(x["class"], x["motor"], x["start_s"], x["end_s"]) for x in a["alarms"]]


def _fmt(a: dict) -> str:
    if not a["alarms"]:
        return "none"
    return "; ".join(f"{x['class']}{'' if x['motor'] is None else ' m' + str(x['motor'])} {x['start_s']:.1f}-"
                     f"{'end' if x['end_s'] is None else format(x['end_s'], '.1f')} (peak {x['peak_p_fault']:.2f})"
                     for x in a["alarms"])


def _row(prof: str, flight: Path, net: str, refused: dict) -> str | None:
    res = {}
    for _, rt, pr in CASES[:4]:
        f = flight / net / rt / pr / "alarms.json"
        if f.is_file():
            res[rt, pr] = json.loads(f.read_text())
        else:
            why = (flight / net / rt / f"{pr}.stderr").read_text().strip()
            refused[(PROFILES[prof], flight.name)] = why.splitlines()[-1] if why else "?"
    if ("ort", "fp32") not in res:
        return None
    a = res["ort", "fp32"]
    same_rt = all(_key(res["ort", p]) == _key(res["cpp", p]) for p in ("fp32", "int8") if ("cpp", p) in res)
    same_pr = _key(a) == _key(res["ort", "int8"]) if ("ort", "int8") in res else False
    return (f"| {PROFILES[prof]} | {net} | {flight.name} | {a['airborne_s']:.1f} | {a['hover']['freeze_s']:.1f} | "
            f"{a['decided_windows']}/{a['windows']} | {a['exposure_s']:.1f} | {_fmt(a)} | "
            f"{'yes' if same_rt else 'NO'} | {'yes' if same_pr else 'int8: ' + _fmt(res['ort', 'int8'])} |")


def table(out: Path) -> str:
    rows, refused = [], {}
    for prof in PROFILES:
        for flight in sorted((out / prof).glob("*")) if (out / prof).is_dir() else []:
            rows += [r for net in ("cnode", "gru") if (r := _row(prof, flight, net, refused))]
    head = ["| profile | net | flight | airborne s | hover frozen s | decided windows | exposure s | "
            "alarms, ORT fp32 (class, motor, s) | cpp = ort (fp32, int8) | int8 = fp32 |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    return "\n".join(head + rows + [""] + [f"- {p} {f}: {why}" for (p, f), why in sorted(refused.items())])


def cli() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--export", action="append", default=[], metavar="PROFILE=DIR",
                    help="min=, esc= or nocur= and a realistic-suite export folder")
    ap.add_argument("--logs", type=Path, default=LOGS_DIR)
    ap.add_argument("--gap-factor", help="passed to quadfdi ingest (bridge logging gaps up to F x the median interval)")
    ap.add_argument("log", nargs="*", help="log file names under --logs (default: every real quad log)")
    args = ap.parse_intermixed_args()  # OUT --export ... LOG: the logs may follow the options
    exports = dict(e.split("=", 1) for e in args.export)
    if not exports or set(exports) - set(PROFILES):
        ap.error(f"--export PROFILE=DIR with PROFILE in {sorted(PROFILES)}")
    args.out.mkdir(parents=True, exist_ok=True)
    run_all(args.out, exports, args.logs.resolve(), args.log or LOGS, args.gap_factor)
    print(table(args.out))


if __name__ == "__main__":
    cli()
