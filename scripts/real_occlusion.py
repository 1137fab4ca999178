"""Which inputs make a model call a real flight faulty: `quadfdi detect`'s path with one channel group
replaced, per export and group (an occlusion test; diagnostic, nothing written).

    PYTHONPATH=. python scripts/real_occlusion.py FLIGHT --export NAME=EXPORT:NET [...] [--kind median|smooth|zero]

FLIGHT: a log or an ingested flight.npz. Each group's channels are replaced, on the decided samples,
by the flight's own median (``median``: no level change within the flight, no jitter) or by a 1 s
moving average (``smooth``: jitter removed, slow part kept), or by 0 (``zero``: for the per-sample
shares of flightlog-esc, ``esc*_t_rel`` = 0 is each ESC at the four's mean temperature). Printed per group and export: the
alarms under the export's policy and the mean p(fault) = 1 - p(Healthy) over the decided windows.
A group that a profile lacks (``i_rel`` in flightlog-nocur) is left out for that export.
"""

from __future__ import annotations

import argparse

import numpy as np

import quadfdi.detect.run as detect_run
from quadfdi.detect import inputs as detect_inputs

GROUPS = {"none": [], "attitude": ["roll", "pitch"], "rates": ["p", "q", "r"], "velocity": ["vx_h", "vy_h", "vz"],
          "v_cell": ["v_cell"], "i_rel": ["i_rel"], "motors": ["m1_rel", "m2_rel", "m3_rel", "m4_rel"],
          "vib": ["vib"], "rpm": [f"rpm{k}_rel" for k in range(1, 5)], "esc_i": [f"esc{k}_i_rel" for k in range(1, 5)],
          "esc_t": [f"esc{k}_t_rel" for k in range(1, 5)], "all but motors": ["roll", "pitch", "p", "q", "r", "vx_h", "vy_h", "vz", "v_cell", "i_rel", "vib"]}
SMOOTH_SAMPLES = 25  # 1 s at 25 Hz


def replaced(v: np.ndarray, kind: str) -> np.ndarray:
    out, ok = v.copy(), np.isfinite(v)
    if kind == "median":
        out[ok] = np.median(v[ok])
    elif kind == "zero":
        out[ok] = 0.0
    else:
        box = np.ones(SMOOTH_SAMPLES)
        num = np.convolve(np.where(ok, v, 0.0), box, "same")
        den = np.maximum(np.convolve(ok.astype(float), box, "same"), 1.0)
        out[ok] = (num / den)[ok]
    return out


def occluded_inputs(group: list[str], kind: str):
    """flight_inputs with the group's channels replaced (patched into detect.run for one call)."""
    original = detect_inputs.flight_inputs

    def inputs(*args, **kwargs):
        fi = original(*args, **kwargs)
        for name in group:
            if name in fi.channel_names:
                j = fi.channel_names.index(name)
                fi.x[:, j] = replaced(fi.x[:, j], kind)
        return fi
    return inputs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("flight")
    ap.add_argument("--export", action="append", required=True, help="NAME=EXPORT_DIR:NET")
    ap.add_argument("--kind", choices=("median", "smooth", "zero"), default="median")
    args = ap.parse_args()
    exports = []
    for spec in args.export:
        name, rest = spec.split("=", 1)
        folder, net = rest.rsplit(":", 1)
        exports.append((name, folder, net))
    how = {"median": "its flight median", "smooth": "a 1 s moving average", "zero": "0"}[args.kind]
    print(f"{args.flight}, each group replaced by {how}\n")
    print("| group | " + " | ".join(name for name, _, _ in exports) + " |")
    print("|---|" + "---|" * len(exports))
    original = detect_run.flight_inputs
    try:
        for group, channels in GROUPS.items():
            detect_run.flight_inputs = occluded_inputs(channels, args.kind)
            cells = []
            for _, folder, net in exports:
                r = detect_run.detect(folder, args.flight, net)
                if channels and not set(channels) & set(r["inputs"].channel_names):
                    cells.append("-")
                    continue
                a = r["arrays"]
                healthy = list(a["class_names"]).index("Healthy")
                pf = 1.0 - a["proba"][a["decided"], healthy]
                cells.append(f"{len(r['record']['alarms'])} alarm(s), p(fault) {pf.mean():.2f}")
            print(f"| {group} | " + " | ".join(cells) + " |", flush=True)
    finally:
        detect_run.flight_inputs = original
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
