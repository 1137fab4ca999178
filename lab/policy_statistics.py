"""Does another per-window statistic let a threshold fixed on simulation sit lower? For one model of a
fleet run, over the VALIDATION flights of every indexed prediction set of that model (reference flights
left out, as evaluate leaves them), three statistics of a decided window's class probabilities:
``fault`` = 1 - p(Healthy) (what the alarm policy reads), ``rotor`` = p(MotorFault) + p(PropellerFault)
(the classes a damaged propeller belongs to), ``top`` = the largest fault class. For each, the threshold of
a 1-of-1 rule that alarms 0, 2 or 5 healthy validation flights (their flight maxima, in order), and the
faulty flights it detects (a decided window after onset above it), per class. Then the healthy validation
flights whose largest 1 - p(Healthy) sets those thresholds (the top 8 over the sets): their vehicle, mission type
(sim/mission.py: 0 hover, 1 survey, 2 aggressive), vibration floor, and the class of their top window, beside the
mean mission type and vibration floor of all healthy validation flights.

    python lab/policy_statistics.py RUN MODEL       # e.g. a fleet run and gru
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from quadfdi.evaluate.load import load_run

ROTOR = ("MotorFault", "PropellerFault")
HEALTHY_ALARMED = (0, 2, 5)


def statistics(proba: np.ndarray, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    h = names.index("Healthy")
    return {"fault": 1.0 - proba[..., h], "rotor": proba[..., [names.index(c) for c in ROTOR]].sum(-1),
            "top": np.max(np.delete(proba, h, axis=-1), axis=-1)}


def flight_maxima(sets: list, infos: dict, model: str) -> tuple[dict, dict, tuple[str, ...]]:
    """Per statistic: healthy validation flights' maxima; faulty flights' (maximum after onset, class)."""
    healthy: dict[str, list] = {}
    faulty: dict[str, list] = {}
    names: tuple[str, ...] = ()
    for fl in (s for s in sets if s.model == model):
        info = infos[fl.dataset]
        val = fl.subset(fl.split == info.split_names.index("validation"))
        names = fl.class_names
        h = names.index("Healthy")
        decided = val.decided if val.decided is not None else val.valid
        fault_class = info.arrays["fault_class"][val.rows]
        for key, s in statistics(val.proba, names).items():
            s = np.where(decided, s, -1.0)
            for i in range(val.rows.size):
                if fault_class[i] == h:
                    healthy.setdefault(key, []).append(float(s[i].max()))
                else:
                    after = (val.y_true[i] != h) & decided[i]
                    faulty.setdefault(key, []).append((float(s[i][after].max()) if after.any() else -1.0,
                                                       names[fault_class[i]]))
    if not healthy:
        raise SystemExit(f"{run}: no prediction set of model {model!r}")
    return healthy, faulty, names


def top_healthy(sets: list, infos: dict, run: Path, model: str, n: int = 8) -> list[str]:
    """The ``n`` healthy validation flights (over the model's sets) with the largest 1 - p(Healthy)."""
    found, every = [], {"mission_type": [], "vib_floor_ms2": []}
    for fl in (s for s in sets if s.model == model):
        info = infos[fl.dataset]
        with np.load(run / fl.dataset) as z:
            arrays = {k: z[k] for k in ("mission_type", "vib_floor_ms2", "vehicle_id", "fault_class")}
        val = fl.subset(fl.split == info.split_names.index("validation"))
        h = fl.class_names.index("Healthy")
        decided = val.decided if val.decided is not None else val.valid
        pf = np.where(decided, 1.0 - val.proba[..., h], -1.0)
        for i, row in enumerate(val.rows):
            if arrays["fault_class"][row] != h:
                continue
            for k in every:
                every[k].append(float(arrays[k][row]))
            w = int(pf[i].argmax())
            found.append((float(pf[i, w]), f"sim {fl.sim_seed} train {fl.train_seed} row {row}: vehicle "
                                           f"{arrays['vehicle_id'][row]}, mission {arrays['mission_type'][row]}, "
                                           f"vibration floor {arrays['vib_floor_ms2'][row]:.1f} m/s2, top window "
                                           f"{fl.class_names[int(val.proba[i, w].argmax())]}"))
    found.sort(key=lambda t: -t[0])
    return ([f"all healthy validation flights: mission type mean {np.mean(every['mission_type']):.2f}, vibration "
             f"floor mean {np.mean(every['vib_floor_ms2']):.1f} m/s2"]
            + [f"{p:.4f} {text}" for p, text in found[:n]])


def main(run: Path, model: str) -> None:
    sets, infos = load_run(run)
    healthy, faulty, _ = flight_maxima(sets, infos, model)
    print(f"{model}: {len(healthy['fault'])} healthy and {len(faulty['fault'])} faulty validation flights "
          "(every prediction set of the model)")
    for key in healthy:
        top = np.sort(healthy[key])[::-1]
        classes = sorted({c for _, c in faulty[key]})
        for n_fa in HEALTHY_ALARMED:
            t = top[n_fa] if n_fa < top.size else 0.0
            found = {c: sum(1 for s, cc in faulty[key] if cc == c and s > t) for c in classes}
            total = {c: sum(1 for _, cc in faulty[key] if cc == c) for c in classes}
            print(f"{key:6s} healthy flights alarmed {n_fa}: threshold {t:.4f}, faulty detected "
                  f"{sum(found.values())}/{len(faulty[key])} "
                  + ", ".join(f"{c} {found[c]}/{total[c]}" for c in classes))
    print("\n".join(top_healthy(sets, infos, run, model)))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]), sys.argv[2])
