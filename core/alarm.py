"""The alarm policy, specified once: per-window class probabilities -> alarms.

Inputs per flight: the windows in time order, each with class probabilities ``proba`` (K,)
(``Healthy`` is one column, index ``healthy``) and optionally ``motor_proba`` (4,).

1. **Vote.** Window i votes fault when ``p_fault_i = 1 - proba_i[healthy] >= threshold``
   (``>=``: a probability exactly at the threshold votes).
2. **Raise.** An inactive alarm is raised at window i when window i votes AND at least ``k`` of
   the last ``n`` windows i-n+1..i vote (integer count; windows before the first count as not
   voting). The vote buffer is never reset: after a clear, the next voting window re-raises at
   once if the buffer still holds ``k`` votes.
3. **Clear.** An active alarm counts consecutive non-voting windows (a voting window resets the
   count to 0; the raising window starts it at 0). When the count reaches ``clear_m`` at window i
   the alarm clears at i: window i is the first inactive one. A clearing window cannot raise
   (it does not vote). With ``latch`` the alarm never clears.
4. **Class.** An alarm episode keeps S (K,), the sum of ``proba`` over its voting windows: at the
   raise, the voting windows among i-n+1..i; then every voting window while active. The alarm's
   class at a window is the argmax of S over the fault columns (every column but ``healthy``);
   a tie goes to the lowest class index. Likewise the motor: argmax of the summed ``motor_proba``
   over the same voting windows (ties: lowest motor index). Python sums in float64; a float32
   mirror can differ only on near-exact ties.
5. **Which motor is reported** (``reported_motor``: detect's alarms.json, evaluate's "motor
   right"): the motor of rule 4 where the alarm's class is rotor-side (``rotor``: MotorFault,
   OverheatFault, PropellerFault for the realistic classes: core.contracts.CLASS_TABLE), none
   otherwise. The ONE motor rule (why this one and not a mean over rotor-side windows: docs/detect.md
   "Which motor").

Which policy a network runs (``resolve_policy``): the ONE rule for the config ([alarm] and its
[alarm.<net>] tables), an export's manifest (``alarm`` and ``alarm_per_model``) and weights.bin's
on-board record (``alarm.policy`` and ``alarm.models``; the C++ ``fwref::policy_for`` is its mirror):
the network's own entry over the single policy over AlarmConfig's defaults.

Everything is integer logic on the vote bits except the threshold comparison and the sums, so a
C++ mirror (firmware_ref) reproduces it exactly given the same p_fault comparisons.
``run_alarm`` is vectorised over flights (rows of a padded (F, W) batch, each row may carry its
own policy parameters: the validation sweep stacks the grid along rows) and loops over windows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from quadfdi.core.contracts import POLICY_KEYS, POLICY_NETWORKS as NETWORKS, POLICY_TYPES, ROTOR_SIDE_CLASSES
from quadfdi.core.sections import coerce
from quadfdi.core.errors import QuadfdiError


def rotor_columns(names, rotor_side_classes=ROTOR_SIDE_CLASSES) -> np.ndarray:
    """(K,) bool: the class columns of ``names`` that are rotor-side (rule 5 reports a motor for these)."""
    return np.array([str(n) in rotor_side_classes for n in names], dtype=bool)


@dataclass(frozen=True)
class AlarmConfig:
    """The [alarm] section: the default policy (``quadfdi evaluate`` chooses one on validation), and
    optional per-network tables [alarm.cnode], [alarm.gru], [alarm.sgru] overriding any of its keys
    for that network (``policy_for``; ``quadfdi export`` writes each network's policy)."""

    threshold: float = 0.5  # p_fault >= threshold votes fault
    k: int = 2  # votes among ...
    n: int = 3  # ... the last n windows raise
    clear_m: int = 3  # consecutive non-voting windows clear
    latch: bool = False  # never clear once raised
    cnode: dict = field(default_factory=dict)  # [alarm.cnode]: the keys above it overrides
    gru: dict = field(default_factory=dict)
    sgru: dict = field(default_factory=dict)

    def validate(self) -> None:
        check_policy(self.threshold, self.k, self.n, self.clear_m, "alarm.")
        for net in NETWORKS:
            if getattr(self, net):
                p = self.policy_for(net)
                check_policy(p["threshold"], p["k"], p["n"], p["clear_m"], f"alarm.{net}.")

    def policy(self) -> dict:
        """The default policy: threshold, k, n, clear_m, latch."""
        return {key: getattr(self, key) for key in POLICY_KEYS}

    def policy_for(self, net: str) -> dict:
        """``net``'s policy: the default with its table's keys (``resolve_policy``)."""
        return resolve_policy(net, {n: getattr(self, n) for n in NETWORKS if getattr(self, n)}, self.policy())[0]

    @staticmethod
    def fold_tables(body: dict, source: str) -> dict:
        """[alarm]'s parsed keys with ``--set alarm.<net>.<key>=v`` (a dotted key) folded into ``<net>``'s table."""
        out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in body.items() if "." not in k}
        for key, value in ((k, v) for k, v in body.items() if "." in k):
            net, _, sub = key.partition(".")
            if net not in NETWORKS:
                raise QuadfdiError(f"{source}: unknown key alarm.{key}; per-network tables are alarm.{'/'.join(NETWORKS)}")
            if not isinstance(out.setdefault(net, {}), dict):
                raise QuadfdiError(f"{source}: alarm.{net} must be a table of {', '.join(POLICY_KEYS)}")
            out[net][sub] = value
        return out

    @staticmethod
    def coerce_key(value, typ, where: str):
        """core.config's check of one [alarm] key; a per-network table's keys are checked as the default's."""
        net = where.rsplit(".", 1)[-1]
        if net not in NETWORKS:
            return coerce(value, typ, where)
        if not isinstance(value, dict):
            raise QuadfdiError(f"{where} must be a table of {', '.join(POLICY_KEYS)}, found {value!r}")
        unknown = sorted(set(value) - set(POLICY_KEYS))
        if unknown:
            raise QuadfdiError(f"unknown key {where}.{unknown[0]}; valid keys of [{where}]: {', '.join(POLICY_KEYS)}")
        return {key: coerce(value[key], POLICY_TYPES[key], f"{where}.{key}") for key in POLICY_KEYS if key in value}


def resolve_policy(net: str, own: dict | None, single: dict | None, where: str | None = None) -> tuple[dict, bool]:
    """(policy, whether ``net`` has its own): ``net``'s entry of ``own`` (network -> keys) over the
    ``single`` policy over AlarmConfig's defaults; every key of POLICY_KEYS, in that order. ``where``
    (a prefix for the error) checks the result (check_policy). The one rule of the module docstring."""
    mine = (own or {}).get(net)
    merged = {**AlarmConfig().policy(), **(single or {}), **(mine or {})}
    pol = {key: merged[key] for key in POLICY_KEYS}
    if where is not None:
        check_policy(pol["threshold"], pol["k"], pol["n"], pol["clear_m"], where)
    return pol, mine is not None


def check_policy(threshold: float, k: int, n: int, clear_m: int, where: str = "") -> None:
    """One-line error for parameters outside 0 < threshold <= 1, 1 <= k <= n, clear_m >= 1."""
    if not 0.0 < threshold <= 1.0:
        raise QuadfdiError(f"{where}threshold must be in (0, 1], found {threshold}")
    if not 1 <= k <= n:
        raise QuadfdiError(f"{where}k and {where}n must satisfy 1 <= k <= n, found k={k}, n={n}")
    if clear_m < 1:
        raise QuadfdiError(f"{where}clear_m must be at least 1, found {clear_m}")


@dataclass
class AlarmTrace:
    """Per window of a (F, W) batch: ``active`` / ``raised`` / ``cleared`` (bool), ``cls`` the
    alarm's class index (-1 where inactive), ``motor`` its motor 0..3 (-1 inactive or no
    motor_proba), ``votes`` (bool)."""

    votes: np.ndarray
    active: np.ndarray
    raised: np.ndarray
    cleared: np.ndarray
    cls: np.ndarray
    motor: np.ndarray


def _row_param(value, rows: int, dtype) -> np.ndarray:
    a = np.asarray(value, dtype=dtype)
    return np.broadcast_to(a, (rows,)) if a.ndim == 0 else a


def _window_sums(x: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(F, W, ...) -> sums over windows i-n+1..i (per-row n), via a cumulative sum."""
    cs = np.concatenate([np.zeros_like(x[:, :1]), np.cumsum(x, axis=1)], axis=1)
    w = x.shape[1]
    lo = np.maximum(np.arange(w)[None, :] + 1 - n[:, None], 0)  # (F, W)
    lo = lo.reshape(lo.shape + (1,) * (x.ndim - 2))
    return cs[:, 1:] - np.take_along_axis(cs, lo, axis=1)


def run_alarm(proba: np.ndarray, threshold, k, n, clear_m, latch=False, *, healthy: int = 0,
              valid: np.ndarray | None = None, motor_proba: np.ndarray | None = None,
              classes: bool = True) -> AlarmTrace:
    """The policy above on a batch of flights.

    proba (F, W, K) and motor_proba (F, W, 4): windows in time order; ``valid`` (F, W) marks real
    windows (a shorter flight is padded at the end: padding never votes, raises or clears).
    threshold, k, n, clear_m, latch: scalars or (F,) arrays (one policy per row). ``classes=False``
    skips the class and motor bookkeeping (cls and motor stay -1): the sweep needs only the timing.
    """
    proba = np.asarray(proba, dtype=np.float64)
    if proba.ndim != 3 or not 0 <= healthy < proba.shape[2]:
        raise ValueError(f"proba must be (flights, windows, classes) with column {healthy} Healthy, found {proba.shape}")
    f, w, n_cls = proba.shape
    valid = np.ones((f, w), bool) if valid is None else np.asarray(valid, bool)
    thr, kk, nn, mm = (_row_param(threshold, f, float), _row_param(k, f, int), _row_param(n, f, int),
                       _row_param(clear_m, f, int))
    lt = _row_param(latch, f, bool)
    votes = ((1.0 - proba[:, :, healthy]) >= thr[:, None]) & valid
    count = _window_sums(votes.astype(np.int64), nn)  # (F, W) votes among the last n
    vp = proba * votes[:, :, None]
    buf = _window_sums(vp, nn) if classes else vp  # (F, W, K) summed proba of the voting windows among the last n
    has_motor = motor_proba is not None and classes
    mp = np.asarray(motor_proba, dtype=np.float64) * votes[:, :, None] if has_motor else None
    mbuf = _window_sums(mp, nn) if has_motor else None
    fault_cols = np.array([c for c in range(n_cls) if c != healthy])
    active = np.zeros(f, bool)
    run = np.zeros(f, np.int64)
    s = np.zeros((f, n_cls))
    sm = np.zeros((f, 4))
    out = {key: np.zeros((f, w), bool) for key in ("active", "raised", "cleared")}
    cls = np.full((f, w), -1, np.int64)
    motor = np.full((f, w), -1, np.int64)
    for i in range(w):
        v, ok = votes[:, i], valid[:, i]
        run = np.where(active & ok, np.where(v, 0, run + 1), run)
        clear = active & ok & ~lt & (run >= mm)
        active = active & ~clear
        rise = ~active & v & (count[:, i] >= kk)
        cont = active & v  # already active: a voting window adds to the episode's sums
        if classes:
            s = np.where(rise[:, None], buf[:, i], np.where(cont[:, None], s + vp[:, i], s))
            cls[:, i] = np.where(active | rise, fault_cols[np.argmax(s[:, fault_cols], axis=1)], -1)
        if has_motor:
            sm = np.where(rise[:, None], mbuf[:, i], np.where(cont[:, None], sm + mp[:, i], sm))
        active = active | rise
        run = np.where(rise, 0, run)
        out["active"][:, i], out["raised"][:, i], out["cleared"][:, i] = active, rise, clear
        if has_motor:
            motor[:, i] = np.where(active, np.argmax(sm, axis=1), -1)
    return AlarmTrace(votes=votes, active=out["active"], raised=out["raised"], cleared=out["cleared"], cls=cls,
                      motor=motor)


def reach(valid: np.ndarray, k: int, n: int, window: int, stride: int, dt: float) -> dict:
    """Whether the policy could raise at all on one flight whose decided windows are ``valid`` (W,):
    rule 2 needs ``k`` votes among ``n`` consecutive windows and only decided windows vote, so a
    flight whose decided windows never number ``k`` within ``n`` cannot alarm whatever the network
    says ("no alarm" there is no verdict). ``most_votes``: the largest count of decided windows among
    any ``n`` consecutive ones; ``needs_s``: the shortest decided stretch that holds ``k`` windows,
    ``(window + (k - 1) * stride) * dt`` seconds."""
    v = np.asarray(valid, bool)[None]
    most = int(_window_sums(v.astype(np.int64), np.array([int(n)])).max()) if v.size else 0
    return {"possible": most >= int(k), "most_votes": most, "k": int(k), "n": int(n),
            "needs_s": round((int(window) + (int(k) - 1) * int(stride)) * float(dt), 3)}


def reach_note(r: dict | None) -> str | None:
    """One line when the policy could raise no alarm on a flight (``r``: reach's dict, or None when not
    computed), else None."""
    if r is None or r["possible"]:
        return None
    return (f"no alarm was possible: the policy needs {r['k']} votes among {r['n']} windows ({r['needs_s']:g} s of "
            f"decided flight in a row) and this flight has at most {r['most_votes']} decided windows among {r['n']}")


def reported_motor(cls: np.ndarray, motor: np.ndarray, rotor: np.ndarray | None) -> np.ndarray:
    """Rule 5: ``motor`` (0..3, AlarmTrace.motor) where the alarm's class ``cls`` is a rotor-side
    column of ``rotor`` (K,) bool, else -1 (inactive, no motor_proba, a battery alarm, or no
    ``rotor``). Elementwise over any shape of cls / motor."""
    cls, motor = np.asarray(cls, np.int64), np.asarray(motor, np.int64)
    if rotor is None:
        return np.full(np.broadcast(cls, motor).shape, -1, np.int64)
    ok = (cls >= 0) & (motor >= 0) & np.asarray(rotor, bool)[np.maximum(cls, 0)]
    return np.where(ok, motor, -1)


def alarm_episodes(trace: AlarmTrace, t_end: np.ndarray, proba: np.ndarray, row: int = 0, healthy: int = 0,
                   rotor: np.ndarray | None = None) -> list[dict]:
    """The alarms of one flight (row of the batch) as records: ``start_s`` (end time of the raising
    window), ``end_s`` (end time of the clearing window; None if still active at the last window),
    ``cls`` and ``motor`` (the alarm's class and reported motor, rule 5, at its last active window;
    -1: none), ``peak_p_fault`` (largest 1 - p(Healthy) while active). What ``detect`` writes."""
    raised, cleared, active = trace.raised[row], trace.cleared[row], trace.active[row]
    p_fault = 1.0 - np.asarray(proba, dtype=np.float64)[row, :, healthy]
    out = []
    for start in np.flatnonzero(raised):
        ends = np.flatnonzero(cleared[start + 1:])
        stop = start + 1 + int(ends[0]) if ends.size else None  # first inactive window
        last = (stop if stop is not None else active.size) - 1
        span = slice(start, last + 1)
        out.append({"start_s": float(t_end[row, start]), "end_s": None if stop is None else float(t_end[row, stop]),
                    "cls": int(trace.cls[row, last]),
                    "motor": int(reported_motor(trace.cls[row, last], trace.motor[row, last], rotor)),
                    "peak_p_fault": float(p_fault[span][active[span]].max())})
    return out


def alarm_records(trace: AlarmTrace, t_end: np.ndarray, proba: np.ndarray, class_names, row: int = 0,
                  rotor: np.ndarray | None = None) -> list[dict]:
    """alarm_episodes as detect's alarms.json writes them and evaluate.alarms lists them: ``start_s``,
    ``end_s``, ``class`` (a name), ``motor`` (1..4 or None), ``peak_p_fault``."""
    names = [str(c) for c in class_names]
    eps = alarm_episodes(trace, t_end, proba, row=row, healthy=names.index("Healthy"), rotor=rotor)
    return [{"start_s": e["start_s"], "end_s": e["end_s"], "class": names[e["cls"]],
             "motor": None if e["motor"] < 0 else e["motor"] + 1, "peak_p_fault": e["peak_p_fault"]} for e in eps]
