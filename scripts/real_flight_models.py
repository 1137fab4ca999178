"""README's real-flight table from nothing: the three profiles' realistic-suite models, then
`quadfdi detect` on every shared real quad flight (issue 14 point 6). `make real-flights` runs it.

    PYTHONPATH=. python scripts/real_flight_models.py OUT [--profiles min,nocur,esc] [--workers 1]

1. ``quadfdi sim --config configs/realistic.toml --out OUT/base`` (sim seed 0);
2. per profile P, a copy of that sim stage in ``OUT/P``, then
   ``quadfdi train --run OUT/P --set train.profile=flightlog-P``,
   ``quadfdi train apply --run OUT/P --seeds 0 --sim-seeds 1`` (sim seed 1 for validation and test),
   ``quadfdi evaluate --run OUT/P`` (each network's alarm policy chosen on the validation flights),
   ``quadfdi export --run OUT/P --alarm-from evaluation`` and ``quadfdi parity --run OUT/P --no-mcu``;
3. scripts/real_flights.py into ``OUT/flights`` (every log, the default gap rule) and
   ``OUT/flights_gap7`` (the UAVCAN mission with ``--gap-factor 7``);
4. both tables into ``OUT/real_flights.md``, beside each profile's test figures
   (``OUT/P/evaluation/evaluation.md``).

A stage that fails (parity included) stops the script with its exit code. 11 min 21 s on the 2-core
AVX2 EPYC (`time make real-flights`, 2026-12-03, idle machine).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

from quadfdi.cli import main as quadfdi
from scripts.real_flights import LOGS as FLIGHT_LOGS
from scripts.real_flights import LOGS_DIR, PROFILES, run_all, table

ROOT = Path(__file__).resolve().parents[1]
SIM_STAGE = ("config.toml", "dataset.npz", ".stages/sim.json")
MISSION = "px4_quad_6s_uavcan_mission.ulg"


def _step(argv: list[str]) -> None:
    print("quadfdi " + " ".join(argv), flush=True)
    rc = quadfdi(argv)
    if rc:
        sys.exit(rc)


def model(out: Path, prof: str, workers: str) -> Path:
    """One profile's export, from the shared sim stage in ``out / "base"``."""
    run = out / prof
    shutil.rmtree(run, ignore_errors=True)
    for name in SIM_STAGE:
        (run / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "base" / name, run / name)
    _step(["train", "--run", str(run), "--set", f"train.profile={PROFILES[prof]}"])
    _step(["train", "apply", "--run", str(run), "--seeds", "0", "--sim-seeds", "1", "--workers", workers])
    _step(["evaluate", "--run", str(run)])
    _step(["export", "--run", str(run), "--alarm-from", "evaluation"])
    _step(["parity", "--run", str(run), "--no-mcu"])
    return run / "export"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--profiles", default="min,nocur,esc", help="comma-separated, of " + ", ".join(PROFILES))
    ap.add_argument("--workers", default="1", help="sim and apply workers (default 1)")
    args = ap.parse_args()
    profs = args.profiles.split(",")
    if not profs or set(profs) - set(PROFILES):
        ap.error(f"--profiles: each of {sorted(PROFILES)}")
    if not LOGS_DIR.is_dir():
        ap.error(f"the shared flight logs are not at {LOGS_DIR}")
    args.out.mkdir(parents=True, exist_ok=True)
    _step(["sim", "--config", str(ROOT / "configs/realistic.toml"), "--out", str(args.out / "base"),
           "--workers", args.workers])
    exports = {p: str(model(args.out, p, args.workers)) for p in profs}
    run_all(args.out / "flights", exports, LOGS_DIR.resolve(), FLIGHT_LOGS)
    run_all(args.out / "flights_gap7", exports, LOGS_DIR.resolve(), [MISSION], "7")
    text = ("# Real flights\n\nEvery shared real quad log, default gap rule:\n\n" + table(args.out / "flights")
            + "\n\nThe UAVCAN mission with `--gap-factor 7`:\n\n" + table(args.out / "flights_gap7") + "\n")
    (args.out / "real_flights.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
