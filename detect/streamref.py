"""The Python window path on a stream's samples: what ``fwref_stream`` must reproduce at every stride
(docs/firmware.md "Streaming"), and the reader of its output lines.

``windows_of(rs, record)`` applies the same rules as detect/inputs.py to a RawStream
(formats/stream.py): the hover estimate over the whole stream (core.hover), the profile
(core.profiles.apply_profile), windows on the grid starts 0, stride, ... and a window decided when
it ends at or after the freeze and every one of its samples is usable (every carried raw channel
finite, airborne, every model value finite). ``paper``: the identity, no hover estimate. The masked
profile: a group is available when the stream carries each of its channels (core.profiles
groups_carried), an absent pitch enters the hover estimate as 0, a lacking group's model channels
take their fills; a profile without a mask refuses a stream that does not carry every channel. A
reference profile reads the vehicle record the stream carries (``rs.vehicle``; none: no reference).

``stepped_of(sw)`` and ``sgru_logits`` state the per-sample model's rules (the streaming GRU,
fwref/stream.hpp): a sample is stepped when it is usable and the hover estimate has frozen at or
before it (``paper``: every usable sample); an unstepped sample holds the state; the state starts at
h = 0 on the stream's first sample; a stride is decided when it is not nohover and every sample of
its window was stepped, with the logits of the step at the window's last sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfdi.core import hover
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import apply_profile, groups_carried, has_reference, is_masked, uses_hover
from quadfdi.formats.stream import RawStream
from quadfdi.runtimes.fwref import stream_lines as read_lines  # noqa: F401  (fwref_stream's output reader)


@dataclass
class StreamWindows:
    x: np.ndarray  # (T, C) float32 model values
    starts: np.ndarray  # (n,) window first samples
    ends: np.ndarray  # (n,) window last samples
    decided: np.ndarray  # (n,) bool
    nohover: np.ndarray  # (n,) bool: no decision because the hover estimate had not frozen
    hover: hover.Hover | None
    ok: np.ndarray | None = None  # (T,) bool: the sample is usable

    def windows(self, window: int) -> np.ndarray:
        """(n_decided, W, C) float32."""
        s = self.starts[self.decided]
        return np.ascontiguousarray(self.x[s[:, None] + np.arange(window)[None, :]], np.float32)


def windows_of(rs: RawStream, record: dict) -> StreamWindows:
    window, stride, profile = int(record["window"]), int(record["stride"]), record["profile"]
    t = len(rs.time)
    starts = np.arange(0, t - window + 1, stride, dtype=np.int64) if t >= window else np.zeros(0, np.int64)
    ends = starts + window - 1
    if not uses_hover(profile):
        x = rs.values.astype(np.float32)
        ok = np.isfinite(x).all(axis=1)
        est, nohover = None, np.zeros(len(starts), bool)
    else:
        carried = rs.carried_flags
        if not carried.all() and not is_masked(profile):
            raise QuadfdiError(f"stream {rs.source}: profile {profile!r} needs every channel; the stream lacks "
                               f"{', '.join(n for n, c in zip(rs.names, carried) if not c)}")
        airborne = rs.column("airborne") >= 0.5
        have = {n for n, c in zip(rs.names, carried) if c}
        level = {"pitch": np.zeros(t, np.float32)}  # an absent pitch: level in the steady test (core.hover)
        cols = np.stack([rs.column(c) if c in have else level.get(c, np.full(t, np.nan, np.float32))
                         for c in hover.INPUTS], 1)
        est = hover.estimate(cols, airborne)
        raw = {n: rs.column(n) for n in rs.names if n != "airborne" and n in have}
        available = groups_carried(have) if is_masked(profile) else None
        with np.errstate(invalid="ignore", divide="ignore"):
            x = apply_profile(profile, raw, rs.cells, est.cmd, est.cur, available,
                              record=rs.vehicle if has_reference(profile) else None)
        ok = np.isfinite(rs.values[:, :-1][:, carried[:-1]]).all(axis=1) & airborne & np.isfinite(x).all(axis=1)
        nohover = ~((est.freeze >= 0) & (ends >= est.freeze))
    cs = np.concatenate([[0], np.cumsum(ok)])
    decided = ~nohover & (cs[starts + window] - cs[starts] == window)
    return StreamWindows(x=x, starts=starts, ends=ends, decided=decided, nohover=nohover, hover=est, ok=ok)


def stepped_of(sw: StreamWindows, window: int) -> tuple[np.ndarray, np.ndarray]:
    """The per-sample model's (T,) stepped samples and (n,) decided strides (module docstring)."""
    stepped = sw.ok.copy()
    if sw.hover is not None:
        freeze = int(sw.hover.freeze)
        stepped[:freeze if freeze >= 0 else len(stepped)] = False
    cs = np.concatenate([[0], np.cumsum(stepped)])
    decided = ~sw.nohover & (cs[sw.starts + window] - cs[sw.starts] == window)
    return stepped, decided


def sgru_logits(onnx_path, x: np.ndarray, stepped: np.ndarray, hidden: int) -> np.ndarray:
    """ONNX Runtime's one-step graph (sgru_step[.int8].onnx) over the model rows ``x`` (T, C), h = 0
    at the first sample, stepped on ``stepped`` samples only (the state held otherwise): (T, K)
    float32 logits of the step at each sample, NaN where not stepped."""
    from quadfdi.runtimes.ort import session

    sess = session(str(onnx_path))
    h = np.zeros((1, hidden), np.float32)
    out = None
    for t in np.flatnonzero(stepped):
        lg, h = sess.run(["logits", "h_new"], {"sample": np.ascontiguousarray(x[t:t + 1], np.float32), "h": h})
        if out is None:
            out = np.full((len(x), lg.shape[1]), np.nan, np.float32)
        out[t] = lg[0]
    return out if out is not None else np.zeros((len(x), 0), np.float32)


def stream_alarm(record: dict, decided: np.ndarray, logits: np.ndarray, motor_logits: np.ndarray | None = None,
                 net: str | None = None):
    """What the stream decides from the decided strides' class logits (n_decided, K) and, for a net with
    its motor head, motor logits (n_decided, 4): the probabilities (n, K) (an undecided stride all
    Healthy: it never votes) and core.alarm's trace under the record's policy, whose ``motor`` is the
    alarm's REPORTED motor (core.alarm rule 5, reported_motor: the summed head softmax's argmax where
    the alarm's class is rotor-side by the record's ``rotor_side``, -1 otherwise; a record without the
    flags: every class rotor-side) as fwref/stream.hpp's Decision::alarm.motor, and the stride's motor
    (n,) (the head's argmax, -1 where undecided or without a head: Decision::motor). The policy: ``net``'s
    (the record's alarm.models row, formats.onboard.policy_of, as fwref_stream --model picks it), or
    the record's single policy when ``net`` is None."""
    from quadfdi.core.alarm import reported_motor, run_alarm
    from quadfdi.formats.onboard import policy_of

    def softmax(z):
        z = np.asarray(z, np.float64)
        e = np.exp(z - z.max(axis=1, keepdims=True))
        return e / e.sum(axis=1, keepdims=True)

    n = len(decided)
    proba = np.zeros((n, np.shape(logits)[1]))
    proba[:, record["healthy"]] = 1.0
    proba[decided] = softmax(logits)
    motor_p, wmotor = None, np.full(n, -1, np.int64)
    if motor_logits is not None:
        motor_p = np.zeros((n, 4))
        motor_p[decided] = softmax(motor_logits)
        wmotor[decided] = np.argmax(motor_logits, axis=1)
    a = record["alarm"] if net is None else policy_of(record, net)[0]
    trace = run_alarm(proba[None], a["threshold"], a["k"], a["n"], a["clear_m"], a["latch"], healthy=record["healthy"],
                      valid=np.asarray(decided)[None], motor_proba=None if motor_p is None else motor_p[None])
    rotor = record.get("rotor_side")
    trace.motor = reported_motor(trace.cls, trace.motor, np.ones(proba.shape[1], bool) if rotor is None else rotor)
    return proba, trace, wmotor
