"""The simulated ESC temperatures of a realistic-suite dataset, per class (docs/params.md "ESC temperature"):

    python lab/esc_temp_summary.py DATASET.npz [--last S] [--true]

Per flight: the rise of the four ESCs' mean over the flight, the mean above the flight's ambient at
the end, and ``esck_t_rel`` (each ESC minus the four's mean, the flightlog-esc channel) averaged over
the last S seconds (default 5); for rotor faults the faulty motor's value, the largest |value| of the
other three, and the faulty ESC's current over the four's mean. Medians (p10 .. p90) per class.
``--true`` also regenerates the rotor-fault flights (the dataset's embedded config) with the sensor
offset and the 1 degC quantisation removed: the faulty ESC's TRUE board temperature over the others'.
"""

from __future__ import annotations

import argparse

import numpy as np

from quadfdi.formats.dataset import load_dataset


def _q(x: np.ndarray) -> str:
    if x.size == 0:
        return "-"
    p10, p50, p90 = np.percentile(x, [10, 50, 90])
    return f"{p50:+.2f} ({p10:+.2f} .. {p90:+.2f})"


def _cols(arrays, prefix: str) -> np.ndarray:
    names = [str(n) for n in arrays["esc_channel_names"]]
    return arrays["esc_telemetry"][..., [names.index(f"{prefix}{k}") for k in range(1, 5)]].astype(np.float64)


def _own_and_others(rel: np.ndarray, motor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    own = rel[np.arange(len(motor)), motor]
    others = np.array([np.abs(np.delete(r, m)).max() for r, m in zip(rel, motor)])
    return own, others


def summary(arrays, n_last: int) -> None:
    T, I = _cols(arrays, "esc_temp"), _cols(arrays, "esc_cur")[:, -n_last:].mean(axis=1)
    common = T.mean(axis=2)
    rel = (T - common[..., None])[:, -n_last:].mean(axis=1)  # (N, 4)
    share = I / I.mean(axis=1, keepdims=True)
    cls, motor = arrays["fault_class"], arrays["fault_motor"]
    print("class | n | rise of the mean | end mean - ambient | faulty ESC t_rel | max |t_rel| of the others "
          "(healthy: of all 4) | faulty ESC current / the four's mean")
    for c, name in enumerate(str(n) for n in arrays["class_names"]):
        sel = np.flatnonzero(cls == c)
        rise = common[sel, -n_last:].mean(1) - common[sel, :n_last].mean(1)
        above = common[sel, -n_last:].mean(1) - arrays["t_amb"][sel]
        if sel.size and motor[sel].min() >= 0:
            own, others = _own_and_others(rel[sel], motor[sel])
            cur = share[sel, motor[sel]]
        else:
            own, others, cur = np.array([]), np.abs(rel[sel]).max(axis=1), np.array([])
        print(f"{name} | {sel.size} | {_q(rise)} K | {_q(above)} K | {_q(own)} K | {_q(others)} K | {_q(cur)}")


def true_board(ds, n_last: int) -> None:
    from quadfdi.sim import esc_thermal
    from quadfdi.sim.simulate import generate

    esc_thermal.reported = lambda T, d: T  # the board temperature itself (this process only)
    a = ds.arrays
    print("class | n | faulty ESC true t_rel | hottest ESC is the faulty one")
    for c in sorted(set(int(x) for x in a["fault_class"][a["fault_motor"] >= 0])):
        idx = np.flatnonzero(a["fault_class"] == c)
        T = _cols(generate(ds.config.sim, indices=idx), "esc_temp")[:, -n_last:].mean(axis=1)
        rel = T - T.mean(axis=1, keepdims=True)
        own = rel[np.arange(len(idx)), a["fault_motor"][idx]]
        hottest = int((rel.argmax(axis=1) == a["fault_motor"][idx]).sum())
        print(f"{a['class_names'][c]} | {len(idx)} | {_q(own)} K | {hottest} of {len(idx)}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset")
    ap.add_argument("--last", type=float, default=5.0)
    ap.add_argument("--true", action="store_true")
    a = ap.parse_args(argv)
    ds = load_dataset(a.dataset)
    n_last = int(round(a.last / float(ds["time"][1] - ds["time"][0])))
    print(f"{len(ds['fault_class'])} flights of {ds['time'][-1] + ds['time'][1]:.0f} s; the last {a.last:g} s")
    summary(ds.arrays, n_last)
    if a.true:
        true_board(ds, n_last)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
