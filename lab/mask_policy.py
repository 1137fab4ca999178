"""The alarm policy chosen on simulated validation flights seen through one mask pattern (the channels a kind
of log has, core/channels.py MASK_PATTERNS; default ``crazyflie``), against the policy the same network gets on
every channel, and the first on the CrazyPAD flights that decide the gates (healthy test, M3 cut >= 3 mm and
2-2.5 mm), with the protocol's reference. One network: RUN/<net>.pt (training seed 0) on the validation flights
of RUN/dataset.npz and RUN/sims/seed1/dataset.npz (simulator seeds 0 and 1, reference flights left out), the
[evaluate] grid and rule of evaluate/policy.py; no CrazyPAD flight enters the choice.

    python lab/mask_policy.py RUN NET [PATTERN]      # e.g. a fleet run after `quadfdi train study`, gru
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from quadfdi.core.alarm import AlarmConfig, run_alarm
from quadfdi.evaluate import policy
from quadfdi.evaluate.config import EvaluateConfig
from quadfdi.evaluate.load import load_dataset_info, load_run, to_flights
from quadfdi.train.study_apply import SEP, pattern_network

DATASETS = {0: "dataset.npz", 1: "sims/seed1/dataset.npz"}
GROUPS = ("healthy test", "M3 cut >= 3 mm", "M3 cut 2-2.5 mm")
PAD = Path(__file__).resolve().parents[2] / "shared" / "data" / "crazypad" / "motor_data"


def masked_sets(run: Path, net: str, pattern: str) -> tuple[list, dict]:
    sets, infos = [], {}
    for seed, rel in DATASETS.items():
        out = pattern_network(str(run / f"{net}.pt"), str(run / rel), net, "validation")
        arrays = {k.split(SEP, 1)[1]: v for k, v in out.items() if k.startswith(pattern + SEP)}
        info = infos[rel] = load_dataset_info(run / rel)
        entry = {"predictions": f"{net} under {pattern}", "model": net, "sim_seed": seed, "train_seed": 0,
                 "dataset": rel}
        fl = to_flights(entry, arrays, info)
        sets.append(fl.subset(~info.arrays["reference_flight"][fl.rows].astype(bool)))
    return sets, infos


def chosen(sets: list, infos: dict) -> dict:
    ev = EvaluateConfig()
    rows = policy.sweep(sets, infos, policy.grid(ev, AlarmConfig()))
    return rows[policy.choose(rows, ev.target_fa_per_h)]


def crazypad(run: Path, net: str, pol: dict) -> dict[str, list[tuple[bool, float]]]:
    from quadfdi.crazypad import learn_reference, test_logs
    from quadfdi.detect.run import detect
    from quadfdi.vehicle.crazypad import group_of
    from quadfdi.vehicle.flights import read_flight

    reference, paths = learn_reference(PAD)
    out: dict[str, list[tuple[bool, float]]] = {g: [] for g in GROUPS}
    for path, name in test_logs(PAD, paths):
        group = group_of(Path(path).parent.name)
        if group not in out:
            continue
        arrays = detect(str(run / "export"), read_flight(str(path), name).arrays, net, "fp32", "ort",
                        vehicle=reference)["arrays"]
        healthy = [str(c) for c in arrays["class_names"]].index("Healthy")
        proba = np.asarray(arrays["proba"], np.float64)[None]
        decided = np.asarray(arrays["decided"], bool)[None]
        trace = run_alarm(proba, pol["threshold"], pol["k"], pol["n"], pol["clear_m"], healthy=healthy,
                          valid=decided)
        out[group].append((bool(trace.raised.any()), float((1.0 - proba[0, decided[0], healthy]).max())))
    return out


def text(pol: dict) -> str:
    return (f"p >= {pol['threshold']:g}, {pol['k']} of {pol['n']}, clear {pol['clear_m']}: validation "
            f"{pol['fa_per_h']:.2f} false alarms per hour, {pol['detection_rate']:.0%} of {pol['faults']:.0f} faulty "
            "flights")


def main(run: Path, net: str, pattern: str) -> None:
    sets, infos = load_run(run)
    every = chosen([s for s in sets if s.model == net and s.train_seed == 0], infos)
    masked = chosen(*masked_sets(run, net, pattern))
    print(f"{net}, every channel: {text(every)}")
    print(f"{net}, under {pattern}: {text(masked)}")
    for group, flights in crazypad(run, net, masked).items():
        top = [p for _, p in flights]
        print(f"CrazyPAD {group}: {sum(a for a, _ in flights)} of {len(flights)} alarmed under the {pattern} policy; "
              f"largest p(fault) {min(top):.3f}-{max(top):.3f}")


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4):
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), sys.argv[2], sys.argv[3] if len(sys.argv) == 4 else "crazyflie")
