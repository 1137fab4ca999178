"""Why an alarm was raised: occlusion of the model's input groups, and the motor shares at the time.

For each alarm, over its windows (the decided windows whose end lies in [start_s, end_s]; at most
``MAX_WINDOWS`` of them, evenly spaced, so that a long alarm costs what a short one does), each
input group's channels (attitude, rates, velocities, battery, each motor's command share, vibration,
ESC) are replaced, over the whole window, by the flight's own reference value: the median of that
channel over the flight's usable samples outside every alarm (the whole flight's usable samples when
the alarms cover all but less than one window of it). The windows are re-run through the export's
graph in ONNX Runtime (the net and precision detect ran; with ``--runtime cpp`` the graph stands in
for weights.bin, which it matches to the export's parity bound) and each group's effect is
reported as

- ``drop``: the mean over the alarm's windows of p_fault (1 - p(Healthy)) minus the same with the
  group occluded: how much of the fault probability that group carried;
- ``crossed``: how many of the alarm's voting windows (p_fault >= the policy's threshold) fall
  below the threshold with the group occluded: the groups that moved p_fault past the threshold.

A group whose occlusion raises p_fault has a negative drop. Occlusion is one-at-a-time: two groups
that each suffice alone both show small drops (reported as it is; the motor shares below help).

The motor shares: each motor's command over the four's mean (``thrk / mean(thr1..4)``, the same
sample), its median over the alarm's span, over the flight's usable airborne samples outside every
alarm, and the difference: a rotor working harder than the others after damage shows there.
"""

from __future__ import annotations

import numpy as np

MAX_WINDOWS = 32
GROUPS = (("attitude", ("roll", "pitch")), ("rates", ("p", "q", "r")), ("velocities", ("vx_h", "vy_h", "vz")),
          ("battery", ("v_cell", "i_rel")), ("motor 1 share", ("m1_rel",)), ("motor 2 share", ("m2_rel",)),
          ("motor 3 share", ("m3_rel",)), ("motor 4 share", ("m4_rel",)), ("vibration", ("vib",)),
          ("ESC", tuple(f"{k}{m}{s}" for k, s in (("rpm", "_rel"), ("esc", "_i_rel"), ("esc", "_t_rel"))
                        for m in range(1, 5))))


def input_groups(channels: list[str]) -> list[tuple[str, list[int]]]:
    """(group name, column indices) of the model's input channels; a channel no group names is its
    own group, so that every input can be occluded."""
    out, named = [], set()
    for name, chans in GROUPS:
        cols = [channels.index(c) for c in chans if c in channels]
        named.update(chans)
        if cols:
            out.append((name, cols))
    out += [(c, [j]) for j, c in enumerate(channels) if c not in named]
    return out


def _span_mask(t: np.ndarray, alarms: list[dict]) -> np.ndarray:
    inside = np.zeros(len(t), bool)
    for a in alarms:
        inside |= (t >= a["start_s"]) & (t <= (a["end_s"] if a["end_s"] is not None else np.inf))
    return inside


def reference_values(fi, alarms: list[dict], window: int) -> tuple[np.ndarray, str]:
    """(C',) per-channel medians over the usable samples outside every alarm, and what they are."""
    outside = fi.used & ~_span_mask(fi.time, alarms)
    what = "median over the flight's usable samples outside every alarm"
    if outside.sum() < window:
        outside = fi.used
        what = "median over all the flight's usable samples (the alarms cover the rest)"
    return np.nanmedian(fi.x[outside], axis=0), f"{what} ({outside.sum() * 0.04:.1f} s)"


def alarm_windows(arrays: dict, alarm: dict) -> np.ndarray:
    """Indices (on the window grid) of the decided windows ending inside the alarm, at most MAX_WINDOWS."""
    t, dec = arrays["t_end"], arrays["decided"]
    end = alarm["end_s"] if alarm["end_s"] is not None else np.inf
    idx = np.flatnonzero(dec & (t >= alarm["start_s"] - 1e-9) & (t <= end + 1e-9))
    if len(idx) > MAX_WINDOWS:
        idx = idx[np.unique(np.linspace(0, len(idx) - 1, MAX_WINDOWS).round().astype(int))]
    return idx


def motor_shares(flight: dict, fi, alarm: dict, alarms: list[dict]) -> list[dict] | None:
    """Each motor's command share (median during the alarm, outside every alarm, the difference)."""
    names = [str(n) for n in flight["channel_names"]]
    if not all(f"thr{m}" in names for m in range(1, 5)):
        return None
    thr = np.stack([np.asarray(flight["telemetry"][:, names.index(f"thr{m}")], np.float64) for m in range(1, 5)], 1)
    mean = thr.mean(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(mean > 0.05, thr / mean, np.nan)  # motors idle: no share
    air = np.asarray(flight["airborne"], bool) & np.isfinite(share).all(axis=1)
    during = air & _span_mask(fi.time, [alarm])
    outside = air & ~_span_mask(fi.time, alarms)
    if not during.any():
        return None
    out = []
    for m in range(4):
        d = float(np.median(share[during, m]))
        o = float(np.median(share[outside, m])) if outside.any() else None
        out.append({"motor": m + 1, "during": round(d, 4), "outside": None if o is None else round(o, 4),
                    "change": None if o is None else round(d - o, 4)})
    return out


def occlusion(result: dict, flight: dict, export, net: str, precision: str) -> list[dict]:
    """One evidence record per alarm of ``result`` (detect.run.detect's), in alarms.json's order."""
    from quadfdi.detect.inputs import windows as all_windows
    from quadfdi.runtimes.ort import outputs

    rec, arr, fi, window = result["record"], result["arrays"], result["inputs"], result["window"]
    alarms = rec["alarms"]
    if not alarms:
        return []
    thr = float(rec["policy"]["threshold"])
    healthy = [str(c) for c in arr["class_names"]].index("Healthy")
    groups = input_groups(list(fi.channel_names))
    ref, ref_what = reference_values(fi, alarms, window)
    decided_rows = np.cumsum(arr["decided"]) - 1  # window-grid index -> row of the decided windows
    x_all = all_windows(fi, window)  # (n_decided, W, C')
    graph = export.artifact(net, precision)
    out = []
    for i, a in enumerate(alarms):
        idx = alarm_windows(arr, a)
        if not len(idx):  # an alarm always holds its raising window; nothing to occlude otherwise
            continue
        x = x_all[decided_rows[idx]]
        batch = [x]
        for _, cols in groups:
            xo = x.copy()
            xo[:, :, cols] = ref[cols].astype(np.float32)
            batch.append(xo)
        logits = outputs(graph, np.concatenate(batch), ["logits"])[0].astype(np.float64)
        e = np.exp(logits - logits.max(axis=1, keepdims=True))
        p_fault = (1.0 - e[:, healthy] / e.sum(axis=1)).reshape(len(batch), len(idx))
        base, voting = p_fault[0], p_fault[0] >= thr
        rows = [{"group": name, "channels": [fi.channel_names[j] for j in cols],
                 "p_fault": round(float(p.mean()), 4), "drop": round(float(base.mean() - p.mean()), 4),
                 "crossed": int((voting & (p < thr)).sum())}
                for (name, cols), p in zip(groups, p_fault[1:])]
        rows.sort(key=lambda r: (-r["crossed"], -r["drop"]))
        out.append({"alarm": i + 1, "start_s": a["start_s"], "end_s": a["end_s"], "class": a["class"],
                    "motor": a["motor"], "threshold": thr, "windows": int(len(idx)),
                    "voting_windows": int(voting.sum()), "p_fault": round(float(base.mean()), 4),
                    "reference": ref_what, "runtime": f"onnxruntime {net} {precision} ({graph.name})",
                    "groups": rows, "motor_shares": motor_shares(flight, fi, a, alarms)})
    return out
