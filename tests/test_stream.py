"""The on-board streaming runtime: fwref/alarm.hpp against core/alarm.py, weights.bin's
on-board record as the C++ reads it, and fwref_stream replaying a simulated and a real flight against
the Python window path at every stride (int8 logits bit-identical, fp32 within the parity tolerance,
alarms identical), plus the defined behaviour on NaN samples, timestamp gaps and refusals; the motor
head in the stream; and the streaming GRU on board (its own weights file, one step per usable sample
against ONNX Runtime's one-step graph and the Python evaluation's prediction set, the state held over
a NaN sample) and Stream::reset() between flights.

Cheap: the flightlog-min export is the session's (tests/conftest.py, shared with test_detect.py),
the C++ programs the session's host build."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.alarm import reported_motor, rotor_columns, run_alarm
from quadfdi.core.contracts import FP32_CPP_REL_TOL, SPLIT_TEST
from tests.conftest import SHARED_DATA, copy_run, quadfdi
from tests.test_firmware_fixtures import asan_build, host_build  # noqa: F401 (fixtures)
from tests.test_stream_gru import TINY, _cli

REAL = SHARED_DATA / "flightlogs"
MISSION = REAL / "px4_quad_6s_uavcan_mission.ulg"
SANITIZER_MARKERS = ("AddressSanitizer", "runtime error", "LeakSanitizer", "UndefinedBehaviorSanitizer")
POLICIES = [(0.5, 2, 3, 3, False), (0.3, 1, 1, 1, False), (0.7, 3, 5, 2, True), (0.45, 4, 8, 6, False)]


def _alarm_cpp(exe: Path, tmp: Path, proba, valid, policy, healthy=0, motor=None, rotor=None) -> np.ndarray:
    """fwref_alarm on (F, W, K) proba: (F, W, 6) vote, active, raised, cleared, cls, motor; ``rotor``
    (K,) bool: the rotor-side classes (--rotor-mask; None: the default, every class)."""
    f, w, k = proba.shape
    parts = [valid[..., None].astype(np.float64), proba] + ([motor] if motor is not None else [])
    np.concatenate(parts, axis=2).astype("<f8").tofile(tmp / "seq.f64")
    thr, kk, n, m, latch = policy
    cmd = [str(exe / "fwref_alarm"), "--in", str(tmp / "seq.f64"), "--out", str(tmp / "steps.i32"), "--windows",
           str(w), "--classes", str(k), "--healthy", str(healthy), "--threshold", repr(thr), "--k", str(kk), "--n",
           str(n), "--clear-m", str(m)] + (["--latch"] if latch else []) + (["--motor"] if motor is not None else [])
    if rotor is not None:
        cmd += ["--rotor-mask", hex(sum(1 << c for c in np.flatnonzero(rotor)))]
    subprocess.run(cmd, check=True, capture_output=True)
    return np.fromfile(tmp / "steps.i32", "<i4").reshape(f, w, 6)


def _same_alarm(cpp: np.ndarray, trace) -> None:
    for j, name in enumerate(("votes", "active", "raised", "cleared", "cls", "motor")):
        np.testing.assert_array_equal(cpp[..., j], getattr(trace, name).astype(np.int64), err_msg=name)


@pytest.mark.parametrize("policy", POLICIES)
def test_alarm_mirror_on_random_sequences(host_build, tmp_path, policy):  # noqa: F811
    rng = np.random.default_rng(7)
    f, w, k = 30, 80, 5
    # bursts of fault-looking windows so that alarms raise, hold and clear
    burst = np.repeat(rng.random((f, w // 8, 1)) < 0.35, 8, axis=1)  # runs of 8 fault-looking windows
    logits = rng.normal(size=(f, w, k)) + 2.0 * np.eye(k)[0] + 4.0 * burst * np.eye(k)[rng.integers(1, k, (f, w))]
    proba = np.exp(logits) / np.exp(logits).sum(axis=2, keepdims=True)
    valid = rng.random((f, w)) > 0.1
    motor = rng.dirichlet(np.ones(4), size=(f, w))
    p_in = np.where(valid[..., None], proba, 0.0)
    cpp = _alarm_cpp(host_build, tmp_path, p_in, valid, policy, motor=motor)
    trace = run_alarm(p_in, *policy, healthy=0, valid=valid, motor_proba=motor)
    _same_alarm(cpp, trace)
    assert trace.raised.sum() > 10 and (policy[4] or trace.cleared.sum() > 5)  # the sequences exercise the policy
    # The rotor-side gate (rule 5): classes 1, 2 and 4 rotor-side, 3 not (a BatteryFault-like class).
    rotor = np.array([False, True, True, False, True])
    gated = _alarm_cpp(host_build, tmp_path, p_in, valid, policy, motor=motor, rotor=rotor)
    np.testing.assert_array_equal(gated[..., :5], cpp[..., :5])  # the gate changes the motor only
    np.testing.assert_array_equal(gated[..., 5], reported_motor(trace.cls, trace.motor, rotor))
    assert ((trace.cls == 3) & (trace.motor >= 0)).any() and (gated[..., 5] >= 0).any()  # both sides of the gate


def test_alarm_mirror_on_a_prediction_set(flightlog_export, host_build, tmp_path):  # noqa: F811
    """The C++ alarm against core.alarm on a trained network's own prediction set (`quadfdi train`'s)."""
    z = np.load(flightlog_export.parent / "predictions" / "cnode_sim0_train0.npz")
    test = z["split"] == z["split"].max()  # one split's flights: enough, and cheap
    traj, t_end, proba = z["traj"][test], z["t_end"][test], z["proba"][test].astype(np.float64)
    flights = np.unique(traj)[:60]
    rows = [np.argsort(t_end[traj == fl]) for fl in flights]
    w = min(len(r) for r in rows)
    batch = np.stack([proba[traj == fl][r[:w]] for fl, r in zip(flights, rows)])
    valid = np.ones(batch.shape[:2], bool)
    healthy = list(z["class_names"]).index("Healthy")
    cpp = _alarm_cpp(host_build, tmp_path, batch, valid, POLICIES[0], healthy=healthy)
    trace = run_alarm(batch, *POLICIES[0], healthy=healthy, valid=valid)
    _same_alarm(cpp, trace)
    assert trace.raised.any() and (~trace.active).any()


# ------------------------------------------------------------------------------- the record


def _fwref_stream(exe: Path, export: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(exe / "fwref_stream"), "--weights", str(export / "weights.bin"), *args],
                          capture_output=True, text=True, timeout=300, check=False)


def test_onboard_record_as_the_cpp_reads_it(flightlog_export, host_build):  # noqa: F811
    rec = _record(flightlog_export)
    res = _fwref_stream(host_build, flightlog_export, "--info")
    assert res.returncode == 0, res.stderr
    got = dict(line.split("=", 1) for line in res.stdout.splitlines())
    assert got["profile"] == rec["profile"] == "flightlog-min"
    assert int(got["window"]) == rec["window"] == 40 and int(got["stride"]) == rec["stride"]
    assert got["raw_channels"].split(",") == rec["raw_channels"] and rec["raw_channels"][-1] == "airborne"
    assert got["channels"].split(",") == rec["channels"] == [c["name"] for c in _manifest(flightlog_export)["channels"]]
    pol = _manifest(flightlog_export)["alarm"]
    assert float(got["threshold"]) == pol["threshold"] == rec["alarm"]["threshold"]
    assert [int(got[k]) for k in ("k", "n", "clear_m", "latch")] == [pol["k"], pol["n"], pol["clear_m"], pol["latch"]]
    assert int(got["hover_steady_samples"]) == 50 and int(got["healthy"]) == rec["healthy"] == 0
    rotor = rotor_columns(_manifest(flightlog_export)["class_names"])  # core.alarm rule 5's classes
    assert rotor.any() and not rotor.all()
    assert got["rotor_side"] == ",".join(str(int(v)) for v in rotor) and rec["rotor_side"] == rotor.tolist()


def test_onboard_record_round_trip_and_refusals():
    """A threshold float32 cannot hold survives exactly; nocur streams carry no current; a record
    that differs from the layout is refused in one line."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.core.profiles import channel_names, required_raw
    from quadfdi.formats.binfmt import Section, pack, unpack
    from quadfdi.formats.onboard import check_onboard, onboard_dict, onboard_section

    policy = {"threshold": 0.35, "k": 3, "n": 5, "clear_m": 4, "latch": True}
    sec = onboard_section("flightlog-nocur", channel_names("flightlog-nocur", []), 50, 10, 0.04, policy,
                          ["BatteryFault", "Healthy", "MotorFault"])
    (back,) = unpack(pack(b"QFDIWTS\0", 1, [sec]), b"QFDIWTS\0", 1, "w")[1]
    d = onboard_dict(back)
    assert d["alarm"] == policy and d["healthy"] == 1 and d["window"] == 50 and d["stride"] == 10
    assert d["raw_channels"] == required_raw("flightlog-nocur") + ["airborne"] and "I_b" not in d["raw_channels"]
    assert d["rotor_side"] == [False, False, True]
    old = Section(sec.model, sec.precision, sec.dims, dict(sec.tensors))
    old.tensors.pop("alarm.rotor_side")  # a record written before the flags: readable, every class rotor-side
    check_onboard(old, "w")
    assert onboard_dict(old)["rotor_side"] is None
    two = Section(sec.model, sec.precision, sec.dims, dict(sec.tensors))
    two.add("alarm.rotor_side", [0, 2, 1], np.int32)
    with pytest.raises(QuadfdiError, match="rotor_side"):
        check_onboard(two, "w")
    bad = Section(sec.model, sec.precision, sec.dims, dict(sec.tensors))
    bad.tensors.pop("alarm.policy")
    with pytest.raises(QuadfdiError, match="on-board record holds tensors"):
        check_onboard(bad, "w")
    with pytest.raises(QuadfdiError, match="knows profiles"):
        onboard_section("flightlog-x", [], 50, 10, 0.04, policy, ["Healthy"])


def _record(export: Path) -> dict:
    """The export's on-board record, as every reader of an export folder gets it."""
    from quadfdi.formats.export_folder import Export

    return Export.open(export).onboard()


def _manifest(export: Path) -> dict:
    import json

    return json.loads((export / "manifest.json").read_text())


# ------------------------------------------------------------------ replay against the window path


@pytest.fixture(scope="module")
def streams(flightlog_export, tmp_path_factory) -> dict[str, Path]:
    """A simulated test flight with a fault and the real UAVCAN mission, written by `quadfdi stream-file`."""
    out = tmp_path_factory.mktemp("streams")
    ds = flightlog_export.parent / "dataset.npz"
    z = np.load(ds)
    sim = int(np.flatnonzero((z["split"] == SPLIT_TEST) & (z["fault_class"] > 0))[0])
    paths = {"sim": out / "sim.bin", "real": out / "mission.bin"}
    res = quadfdi("stream-file", "--model", str(flightlog_export), "--dataset", str(ds), "--flight", str(sim),
                  "--out", str(paths["sim"]))  # the CLI once; the real flight in process (a second start costs 2 s)
    assert res.returncode == 0, res.stderr
    if MISSION.is_file():
        from quadfdi.detect.stream_cli import from_flight
        from quadfdi.formats.stream import write_stream

        write_stream(paths["real"], from_flight(MISSION, _record(flightlog_export)))
    else:
        paths.pop("real")
    return paths


def _infer(exe: Path, export: Path, net: str, int8: bool, x: np.ndarray, tmp: Path) -> np.ndarray:
    """fwref_infer (the C++ window path) on windows (n, W, C) -> logits (n, K)."""
    x.astype("<f4").tofile(tmp / "x.f32")
    subprocess.run([str(exe / "fwref_infer"), "--weights", str(export / "weights.bin"), "--model", net, "--in",
                    str(tmp / "x.f32"), "--out", str(tmp / "y.f32")] + (["--int8"] if int8 else []), check=True)
    return np.fromfile(tmp / "y.f32", "<f4").reshape(len(x), -1)


def _window_path(export: Path, exe: Path, tmp: Path, rs, record: dict, net: str, precision: str):
    """The Python window path on the stream's samples: windows, ORT and C++ window logits, ORT's motor
    logits (None without a motor head) and the alarm (with the head's motor probabilities)."""
    from quadfdi.detect.run import model_logits
    from quadfdi.formats.export_folder import Export
    from quadfdi.detect.streamref import stream_alarm, windows_of

    sw = windows_of(rs, record)
    x = sw.windows(record["window"])
    ex = Export.open(export)
    ort, motor = model_logits(ex, net, precision, "ort", x)
    assert (motor is not None) == ex.has_motor(net)
    cpp = _infer(exe, export, net, precision == "int8", x, tmp)
    proba, trace, _ = stream_alarm(record, sw.decided, ort, motor, net=net)  # the stream's rules, in Python
    return sw, ort, cpp, proba, trace, motor


@pytest.mark.parametrize("precision", ["fp32", "int8"])
@pytest.mark.parametrize("net", ["cnode", "gru"])
def test_stream_gives_the_window_path_at_every_stride(flightlog_export, streams, host_build, tmp_path, net,  # noqa: F811
                                                      precision):
    print("; ".join(_check_replay(flightlog_export, streams, host_build, tmp_path, net, precision)))


def test_paper_profile_stream_gives_the_window_path(fault_exported, host_build, tmp_path):  # noqa: F811
    """The identity profile (no hover estimate, no airborne channel) on the session's paper-config export."""
    from quadfdi.formats.stream import from_dataset, write_stream

    export = fault_exported / "export"
    record = _record(export)
    assert record["profile"] == "paper" and not record["cells_from_stream"]
    assert record["raw_channels"] == record["channels"] == [c["name"] for c in _manifest(export)["channels"]]
    z = np.load(fault_exported / "dataset.npz")
    flight = int(np.flatnonzero(z["split"] == SPLIT_TEST)[0])
    write_stream(tmp_path / "paper.bin", from_dataset(fault_exported / "dataset.npz", flight, record))
    for net, precision in (("cnode", "int8"), ("gru", "fp32")):
        print(_check_replay(export, {"sim": tmp_path / "paper.bin"}, host_build, tmp_path, net, precision))


def _with_rotor_side(export: Path, dst: Path, flags) -> Path:
    """A folder holding export's weights.bin with its on-board record's alarm.rotor_side set to ``flags``
    (None: the tensor removed, as in a file written before it)."""
    from quadfdi.formats.binfmt import Section, pack, read_file
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    _, sections = read_file(export / "weights.bin", MAGIC, VERSION, "weights file")
    rec = sections[-1]
    new = Section(rec.model, rec.precision, rec.dims, {k: t for k, t in rec.tensors.items() if k != "alarm.rotor_side"})
    if flags is not None:
        new.add("alarm.rotor_side", flags, np.int32)
    dst.mkdir()
    (dst / "weights.bin").write_bytes(pack(MAGIC, VERSION, sections[:-1] + [new]))
    return dst


def test_stream_reports_the_alarm_motor_for_rotor_side_classes_only(flightlog_export, streams, host_build,  # noqa: F811
                                                                     tmp_path):
    """core.alarm rule 5 on board: the same replay under the export's alarm.rotor_side, without the
    tensor (an older file: every class reports, rule 4 alone) and with no class rotor-side. Everything
    but the alarm motor is identical; the export's motor is core.alarm.reported_motor of the rule-4
    motor; no rotor-side class -> no motor although rule 4 has one at every active stride."""
    from quadfdi.formats.export_folder import Export
    from quadfdi.detect.streamref import read_lines

    manifest = _manifest(flightlog_export)
    names = manifest["class_names"]
    net = next(m for m in ("cnode", "gru") if Export.open(flightlog_export).has_motor(m))
    runs: dict[str, dict] = {}
    for name, flags in (("export", "as is"), ("old", None), ("none", [0] * len(names))):
        folder = flightlog_export if name == "export" else _with_rotor_side(flightlog_export, tmp_path / name, flags)
        parts = []
        for path in streams.values():  # one run per flight (their cell counts differ)
            res = _fwref_stream(host_build, folder, "--model", net, "--int8", "--in", str(path))
            assert res.returncode == 0, res.stderr
            parts.append(read_lines(res.stdout, len(names)))
        runs[name] = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    rule4, active = runs["old"]["motor"], runs["old"]["active"]
    assert active.any() and (rule4[active] >= 0).all() and (rule4[~active] == -1).all()
    assert (runs["none"]["motor"] == -1).all()
    for key in ("status", "vote", "active", "raised", "cleared", "cls", "wmotor"):
        for name in ("export", "none"):
            np.testing.assert_array_equal(runs[name][key], runs["old"][key], err_msg=f"{name} {key}")
    want = reported_motor(runs["old"]["cls"], rule4, rotor_columns(names))
    np.testing.assert_array_equal(runs["export"]["motor"], want)
    print(f"{int(active.sum())} active strides, classes {sorted({names[c] for c in runs['old']['cls'][active]})}, "
          f"{int((want >= 0).sum())} with a reported motor")


def test_cpp_reader_refuses_rotor_flags_it_cannot_use(flightlog_export, streams, host_build, tmp_path):  # noqa: F811
    """alarm.rotor_side on the C++ side: "all" when absent; a flag not 0/1 or a class count that is not the
    model's is refused in one line (exit 2)."""
    k = len(_manifest(flightlog_export)["class_names"])
    old = _fwref_stream(host_build, _with_rotor_side(flightlog_export, tmp_path / "old", None), "--info")
    assert old.returncode == 0 and "rotor_side=all" in old.stdout.splitlines(), old.stderr
    bad = _fwref_stream(host_build, _with_rotor_side(flightlog_export, tmp_path / "bad", [0, 2] + [1] * (k - 2)), "--info")
    assert bad.returncode == 2 and "holds 2 (0/1 expected)" in bad.stderr and bad.stderr.count("\n") == 1, bad.stderr
    short = _fwref_stream(host_build, _with_rotor_side(flightlog_export, tmp_path / "short", [0, 1]), "--model", "cnode",
                          "--in", str(streams["sim"]))
    assert short.returncode == 2 and "has 2 classes, the cnode section" in short.stderr and not short.stdout, short.stderr


def test_stream_alarm_mirror_applies_rule_5():
    """detect/streamref.py stream_alarm (the stream's rules in Python): a BatteryFault alarm reports no
    motor, a MotorFault alarm its rule-4 motor; without the record's flags every class reports one."""
    from quadfdi.detect.streamref import stream_alarm

    names = ["Healthy", "BatteryFault", "MotorFault"]
    rng = np.random.default_rng(3)
    logits = np.zeros((12, 3), np.float32)
    logits[:6, 1], logits[6:, 2] = 6.0, 6.0  # a battery alarm, then a motor alarm after it clears
    logits[4:8] = [6.0, 0.0, 0.0]  # four healthy strides between them: the first alarm clears
    motor_logits = rng.normal(size=(12, 4)).astype(np.float32)
    motor_logits[:, 2] += 5.0
    decided = np.ones(12, bool)
    rec = {"healthy": 0, "alarm": {"threshold": 0.5, "k": 2, "n": 3, "clear_m": 3, "latch": False},
           "rotor_side": rotor_columns(names).tolist()}
    _, trace, _ = stream_alarm(rec, decided, logits, motor_logits)
    _, old, _ = stream_alarm({**rec, "rotor_side": None}, decided, logits, motor_logits)
    cls, motor = trace.cls[0], trace.motor[0]
    assert set(cls[:4]) == {-1, 1} and set(cls[8:]) == {-1, 2}, cls
    assert (motor[cls == 1] == -1).all() and (motor[cls == 2] == 2).all() and (old.motor[0][cls >= 0] == 2).all()


def _check_replay(export: Path, streams: dict[str, Path], exe: Path, tmp: Path, net: str, precision: str) -> list[str]:
    """fwref_stream on each stream against the window path at every stride; a report line per stream."""
    from quadfdi.formats.stream import read_stream
    from quadfdi.detect.streamref import read_lines

    record = _record(export)
    report = []
    for name, path in streams.items():
        rs = read_stream(path)
        sw, ort, cpp, proba, trace, motor = _window_path(export, exe, tmp, rs, record, net, precision)
        res = _fwref_stream(exe, export, "--model", net, "--in", str(path), *(["--int8"] if precision == "int8" else []))
        assert res.returncode == 0, res.stderr
        out = read_lines(res.stdout, ort.shape[1])
        np.testing.assert_array_equal(out["index"], sw.ends)  # one line per stride once W samples arrived
        want = np.where(sw.decided, "decided", np.where(sw.nohover, "nohover", "skipped"))
        np.testing.assert_array_equal(out["status"], want)
        assert sw.decided.sum() >= 5 and (name == "sim" or (want == "skipped").any()), name
        got = out["logits"][sw.decided]
        np.testing.assert_array_equal(got, cpp)  # the C++ window path on the same windows: the same bits
        if precision == "int8":
            np.testing.assert_array_equal(got, ort)
        else:
            assert np.abs(got - ort).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(ort).max())
        p_fault = 1.0 - proba[:, record["healthy"]]
        flips = out["vote"] != trace.votes[0]
        near = np.abs(p_fault - record["alarm"]["threshold"]) <= 1e-4
        assert precision == "fp32" or not flips.any(), name
        assert not (flips & ~near).any(), name  # fp32: only a score within tolerance of the threshold may flip
        if not flips.any():  # motor: core.alarm's REPORTED motor (rule 5: -1 unless the class is rotor-side)
            reported = reported_motor(trace.cls, trace.motor, rotor_columns(_manifest(export)["class_names"]))
            for key, ref in (("active", trace.active), ("raised", trace.raised), ("cleared", trace.cleared),
                             ("cls", trace.cls), ("motor", reported)):
                np.testing.assert_array_equal(out[key], ref[0], err_msg=f"{name} {key}")
        _check_motor(out, sw.decided, motor, precision, name)
        report.append(f"{name}: {int(sw.decided.sum())} decided / {len(sw.ends)} strides, {int(flips.sum())} vote flips"
                      + ("" if motor is None else f", motor head: {int((out['motor'] >= 0).sum())} strides with an alarm motor"))
    return report


def _check_motor(out: dict, decided: np.ndarray, motor: np.ndarray | None, precision: str, name: str) -> None:
    """The stride's motor (wmotor) is the head's argmax at every decided stride (int8: ORT's bits, so
    always; fp32: where the two largest motor logits are apart by more than the tolerance), -1 elsewhere."""
    if motor is None:
        assert (out["wmotor"] == -1).all() and (out["motor"] == -1).all(), name
        return
    assert (out["wmotor"][~decided] == -1).all(), name
    want = np.argmax(motor, axis=1)
    top2 = np.sort(motor, axis=1)[:, -2:]
    clear = precision == "int8" or np.ones(len(want), bool)
    clear = clear & (top2[:, 1] - top2[:, 0] > FP32_CPP_REL_TOL * max(1.0, np.abs(motor).max()))
    np.testing.assert_array_equal(out["wmotor"][decided][clear], want[clear], err_msg=name)


@pytest.mark.skipif(not MISSION.is_file(), reason="the shared real flight logs are not here")
def test_stream_reference_is_detects_window_path(flightlog_export, streams):
    """detect/streamref.py on the stream file decides the windows detect/inputs.py decides, with the same inputs."""
    from quadfdi.detect.inputs import flight_inputs, read_flight, windows
    from quadfdi.formats.stream import read_stream
    from quadfdi.detect.streamref import windows_of

    record = _record(flightlog_export)
    fi = flight_inputs(read_flight(MISSION), record["profile"], record["window"], record["stride"])
    sw = windows_of(read_stream(streams["real"]), record)
    np.testing.assert_array_equal(sw.starts, fi.starts)
    np.testing.assert_array_equal(sw.decided, fi.decided)
    np.testing.assert_array_equal(sw.windows(record["window"]), windows(fi, record["window"]))


def test_stream_under_sanitizers_gives_the_release_lines(flightlog_export, streams, asan_build, host_build):  # noqa: F811
    """AddressSanitizer + UBSan (and Eigen's no-malloc assertion around each inference): the ring, the
    gap filling and the record reader stay in bounds; the lines equal the release build's (int8)."""
    for path in streams.values():
        args = ("--model", "cnode", "--int8", "--in", str(path))
        asan, rel = _fwref_stream(asan_build, flightlog_export, *args), _fwref_stream(host_build, flightlog_export, *args)
        assert asan.returncode == 0 and not any(m in asan.stderr for m in SANITIZER_MARKERS), asan.stderr[-2000:]
        assert asan.stdout == rel.stdout


def _edit_stream(src: Path, dst: Path, edit) -> None:
    from quadfdi.formats.stream import read_stream, write_stream

    rs = read_stream(src)
    edit(rs)
    write_stream(dst, rs)


def test_nan_samples_skip_their_windows_and_gaps_are_held(flightlog_export, streams, host_build, tmp_path):  # noqa: F811
    from quadfdi.detect.streamref import read_lines

    def run(path):
        res = _fwref_stream(host_build, flightlog_export, "--model", "cnode", "--int8", "--in", str(path))
        assert res.returncode == 0, res.stderr
        return read_lines(res.stdout, 5), res.stdout

    clean, _ = run(streams["sim"])
    lost = slice(150, 153)

    def nan(rs):
        rs.values[lost, 2] = np.nan

    def gap(rs):
        keep = np.ones(len(rs.time), bool)
        keep[lost] = False
        rs.time, rs.values = rs.time[keep], rs.values[keep]

    def backwards(rs):
        rs.time[200] = rs.time[199]  # a time that does not advance: that sample is dropped

    outs = {}
    for name, edit in (("nan", nan), ("gap", gap), ("backwards", backwards)):
        _edit_stream(streams["sim"], tmp_path / f"{name}.bin", edit)
        outs[name] = run(tmp_path / f"{name}.bin")
    hit = (clean["index"] >= lost.start) & (clean["index"] - 39 < lost.stop)  # windows holding a lost sample
    nan_out = outs["nan"][0]
    assert hit.sum() >= 2 and (nan_out["status"][hit] == "skipped").all()
    np.testing.assert_array_equal(nan_out["logits"][~hit], clean["logits"][~hit])
    for key in ("index", "status", "logits", "active", "cls"):  # a gap is held: the missing samples are NaN samples
        np.testing.assert_array_equal(outs["gap"][0][key], nan_out[key], err_msg=key)
    assert "dropped=1 " in outs["backwards"][1] and clean["index"][0] == 39  # no decision before W samples


def _llround(q: float) -> int:
    """C's llround on a positive double, exactly (halves away from zero)."""
    from fractions import Fraction
    import math

    return math.floor(Fraction(q) + Fraction(1, 2))


def test_timestamp_steps_at_the_period_gates_edges(flightlog_export, streams, host_build, tmp_path):  # noqa: F811
    """Stream::push's step t - t_prev against the bounds of fwref/period.hpp (no division): the first
    step set to one ulp below / at lo (half a period) and hi (1.5 periods), the rest of the flight on
    the shifted grid. Expected, by the division's rule computed here: below lo the sample is refused;
    [lo, hi) one period (the clean run); at hi a gap of 2 (a NaN sample filled in)."""
    import math

    from quadfdi.formats.stream import read_stream, write_stream
    from quadfdi.detect.streamref import read_lines

    rs0 = read_stream(streams["sim"])
    dt, dt_rec = rs0.sample_dt_s, _record(flightlog_export)["sample_dt_s"]  # the record's: float32(0.04)
    gate = subprocess.run([str(host_build / "fwref_period"), float.hex(dt_rec)], capture_output=True, text=True)
    row = dict(kv.split("=", 1) for kv in gate.stdout.split())
    lo, hi = float.fromhex(row["lo"]), float.fromhex(row["hi"])
    below = lambda x: math.nextafter(x, -math.inf)  # noqa: E731

    def run(rs, name):
        write_stream(tmp_path / name, rs)
        res = _fwref_stream(host_build, flightlog_export, "--model", "cnode", "--int8", "--in", str(tmp_path / name))
        assert res.returncode == 0, res.stderr
        return read_lines(res.stdout, 5), res.stdout

    def stream(times, values):
        rs = read_stream(streams["sim"])
        rs.time, rs.values = np.asarray(times, np.float64), values
        return rs

    n, v = len(rs0.time), rs0.values
    nan_row = np.full((1, v.shape[1]), np.nan, np.float32)
    nan_row[0, rs0.names.index("airborne")] = 1.0 if v[0, rs0.names.index("airborne")] >= 0.5 else 0.0
    grid = lambda m: dt * np.arange(m)  # noqa: E731
    clean, _ = run(stream(grid(n), v), "clean.bin")
    filled, _ = run(stream(grid(n + 1), np.concatenate([v[:1], nan_row, v[1:]])), "filled.bin")
    first_after_drop = _llround((below(lo) + dt) / dt_rec)  # sample 1 refused: sample 2's step from sample 0
    dropped, _ = run(stream(grid(n - 1), np.delete(v, 1, axis=0)) if first_after_drop == 1 else
                     stream(grid(n), np.concatenate([v[:1], nan_row, v[2:]])), "dropped.bin")
    for d, want, drops in ((below(lo), dropped, 1), (lo, clean, 0), (below(hi), clean, 0), (hi, filled, 0)):
        times = np.concatenate([[0.0], d + dt * np.arange(n - 1)])
        steps = np.diff(times)
        assert steps[0] == d and ((steps[1:] >= lo) & (steps[1:] < hi)).all()  # the edge is the first step only
        got, text = run(stream(times, v), "edge.bin")
        assert f"dropped={drops} " in text, d
        for key in ("index", "status", "logits", "active", "cls"):
            np.testing.assert_array_equal(got[key], want[key], err_msg=f"{d.hex()} {key}")


def test_stream_file_refusals_are_one_line_and_write_nothing(flightlog_export, tmp_path):
    out = tmp_path / "s.bin"
    cases = [(["--dataset", str(flightlog_export.parent / "dataset.npz"), "--flight", "999"], "has flights 0..")]
    ardupilot = REAL / "ardupilot_copter_quadx_ground.BIN"
    if ardupilot.is_file():  # refused as by detect (ingest: never airborne)
        cases.append(([str(ardupilot)], "ardupilot_copter_quadx_ground.BIN"))
    for args, why in cases:
        res = quadfdi("stream-file", "--model", str(flightlog_export), *args, "--out", str(out))
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and not out.exists(), res.stderr
        assert why in res.stderr, res.stderr


# ---------------------------------------------------- the streaming GRU on board, and reset()
# (in this file, not its own: it shares the session's paper-config export with
# test_paper_profile_stream_gives_the_window_path, and `make test` gives a file to one worker)


@pytest.fixture(scope="module")
def sgru_export(fault_exported, tmp_path_factory) -> Path:
    """A copy of the session's exported paper run with a tiny streaming GRU trained and exported."""
    run = copy_run(fault_exported, tmp_path_factory.mktemp("sgru_onboard") / "run")
    shutil.copytree(fault_exported / "export", run / "export")
    assert _cli("train", "sgru", "--run", str(run), *TINY) == 0
    assert _cli("export", "sgru", "--run", str(run)) == 0
    return run


@pytest.fixture(scope="module")
def sgru_flight(sgru_export, tmp_path_factory):
    """A test flight of the run as a stream file, its row and the on-board record."""
    from quadfdi.formats.stream import from_dataset, write_stream

    record = _record(sgru_export / "export")
    z = np.load(sgru_export / "dataset.npz")
    row = int(np.flatnonzero((z["split"] == SPLIT_TEST) & (z["fault_class"] > 0))[0])
    path = tmp_path_factory.mktemp("sgru_streams") / "flight.bin"
    write_stream(path, from_dataset(sgru_export / "dataset.npz", row, record))
    return path, row, record


def _sgru_stream(exe: Path, weights: Path, *args: str) -> str:
    res = subprocess.run([str(exe / "fwref_stream"), "--weights", str(weights), *args], capture_output=True, text=True,
                         timeout=120, check=False)
    assert res.returncode == 0, res.stderr
    return res.stdout


def test_sgru_weights_file(sgru_export, host_build):  # noqa: F811
    """Its sections hold the checkpoint's numbers and weights.bin's record; weights.bin is untouched."""
    from quadfdi.core.jsonio import read_json
    from quadfdi.formats.sgru_weights import read_sgru_weights
    from quadfdi.formats.weights_bin import read_weights
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    export = sgru_export / "export"
    sw = read_sgru_weights(export / "sgru_weights.bin")
    model, _ = load_stream_checkpoint(sgru_export / "sgru_train0.pt")
    sd = {k: v.numpy() for k, v in model.state_dict().items()}
    assert sw.fp32.dims[:4] == (model.n_channels, 1, model.n_classes, model.hidden)
    np.testing.assert_array_equal(sw.fp32.tensors["gru.weight_hh"].array, sd["gru.weight_hh_l0"])
    assert sw.int8.tensors["gru.weight_hh"].array.dtype == np.int8
    wb = read_weights(export / "weights.bin")
    assert {k: t.array.tobytes() for k, t in sw.onboard.tensors.items()} == \
        {k: t.array.tobytes() for k, t in wb.onboard.tensors.items()}
    manifest = read_json(export / "manifest.json")
    rec = read_json(export / "sgru_export.json")["weights"]
    sha = hashlib.sha256((export / "weights.bin").read_bytes()).hexdigest()
    assert rec["record_from_sha256"] == sha == manifest["files"]["weights.bin"]["sha256"]
    assert rec["sha256"] == hashlib.sha256((export / "sgru_weights.bin").read_bytes()).hexdigest()
    info = _sgru_stream(host_build, export / "sgru_weights.bin", "--info")
    assert info == _sgru_stream(host_build, export / "weights.bin", "--info")  # the same record
    res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "sgru",
                          "--in", "-"], capture_output=True, text=True, check=False, input="")
    assert res.returncode == 2 and "sgru_weights.bin" in res.stderr  # weights.bin has no sgru section


def _sgru_mirror(export: Path, rs, record: dict, precision: str, hidden: int):
    """The Python statement of the on-board rules: stepped samples, decided strides, ORT logits, alarm."""
    from quadfdi.detect.streamref import sgru_logits, stepped_of, stream_alarm, windows_of

    sw = windows_of(rs, record)
    stepped, decided = stepped_of(sw, record["window"])
    onnx = export / ("sgru_step.int8.onnx" if precision == "int8" else "sgru_step.onnx")
    logits = sgru_logits(onnx, sw.x, stepped, hidden)[sw.ends]
    _, trace, _ = stream_alarm(record, decided, logits[decided], net="sgru")
    return sw, stepped, decided, logits, trace


def _sgru_check(out: dict, sw, decided, logits, trace, precision: str) -> None:
    np.testing.assert_array_equal(out["index"], sw.ends)
    np.testing.assert_array_equal(out["status"] == "decided", decided)
    got, want = out["logits"][decided], logits[decided]
    if precision == "int8":
        np.testing.assert_array_equal(got, want)  # the C++ int8 step is ORT's, bit for bit, over every carried step
    else:
        assert np.abs(got - want).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(want).max())
    if precision == "int8":
        for key, ref in (("vote", trace.votes), ("active", trace.active), ("cls", trace.cls)):
            np.testing.assert_array_equal(out[key], ref[0], err_msg=key)


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_stream_sgru_is_onnx_runtimes_one_step_at_every_stride(sgru_export, sgru_flight, host_build, precision):  # noqa: F811
    """fwref_stream --model sgru on a test flight: every stride the ORT one-step graph's logits (int8 identical,
    fp32 within the tolerance), and (fp32) the probabilities the Python evaluation scores (its prediction set)."""
    from quadfdi.formats.stream import read_stream
    from quadfdi.detect.streamref import read_lines
    from quadfdi.train.stream_gru_run import load_stream_checkpoint

    path, row, record = sgru_flight
    model, _ = load_stream_checkpoint(sgru_export / "sgru_train0.pt")
    export = sgru_export / "export"
    text = _sgru_stream(host_build, export / "sgru_weights.bin", "--model", "sgru", "--in", str(path),
                   *(["--int8"] if precision == "int8" else []))
    out = read_lines(text, model.n_classes)
    sw, stepped, decided, logits, trace = _sgru_mirror(export, read_stream(path), record, precision, model.hidden)
    assert stepped.all() and decided.all() and f"steps={len(stepped)} " in text  # a simulated flight: every sample
    _sgru_check(out, sw, decided, logits, trace, precision)
    if precision == "fp32":  # the evaluation's set: the stream from h = 0 at take-off, read at the window ends
        pred = np.load(sgru_export / "predictions" / "sgru_sim0_train0.npz")
        mine = pred["traj"] == row
        assert mine.sum() == len(sw.ends)
        np.testing.assert_allclose(out["proba"], pred["proba"][mine], atol=1e-5)  # float32 set, torch vs C++ order


def test_stream_sgru_holds_its_state_over_a_nan_sample(sgru_export, sgru_flight, host_build, tmp_path):  # noqa: F811
    """A NaN sample is not stepped (h held), the strides whose window holds it are skipped, and the later
    strides carry the held state: the C++ stream equals the Python mirror of that rule (int8: bit for bit)."""
    from quadfdi.formats.stream import read_stream, write_stream
    from quadfdi.detect.streamref import read_lines

    path, _, record = sgru_flight
    rs = read_stream(path)
    lost = len(rs.time) // 2
    rs.values[lost, 3] = np.nan
    write_stream(tmp_path / "nan.bin", rs)
    replay = np.load(sgru_export / "export" / "sgru_replay.npz")
    hidden, classes = int(replay["h"].shape[1]), int(replay["logits"].shape[1])
    text = _sgru_stream(host_build, sgru_export / "export" / "sgru_weights.bin", "--model", "sgru", "--int8", "--in",
                   str(tmp_path / "nan.bin"))
    out = read_lines(text, classes)
    sw, stepped, decided, logits, trace = _sgru_mirror(sgru_export / "export", rs, record, "int8", hidden)
    assert not stepped[lost] and stepped.sum() == len(stepped) - 1 and f"steps={len(stepped) - 1} " in text
    hit = (sw.starts <= lost) & (sw.ends >= lost)
    assert hit.any() and not decided[hit].any() and decided[sw.ends > lost + record["window"]].all()
    _sgru_check(out, sw, decided, logits, trace, "int8")
    # (the later strides' logits may equal the clean flight's: the tiny GRU forgets within a window)


@pytest.mark.parametrize("model", ["cnode", "sgru"])
def test_reset_between_flights_equals_separate_runs(sgru_export, sgru_flight, host_build, model, tmp_path):  # noqa: F811
    """Stream::reset(): two flights in sequence through one stream (repeated --in) give each flight's own run,
    line for line (alarm state, hover estimate, ring and the streaming GRU's state all forgotten)."""
    from quadfdi.formats.stream import from_dataset, write_stream

    path, row, record = sgru_flight
    z = np.load(sgru_export / "dataset.npz")
    other = int(np.flatnonzero(z["split"] == SPLIT_TEST)[-1])
    assert other != row
    write_stream(tmp_path / "other.bin", from_dataset(sgru_export / "dataset.npz", other, record))
    weights = sgru_export / "export" / ("sgru_weights.bin" if model == "sgru" else "weights.bin")
    args = ("--model", model, "--int8")
    both = _sgru_stream(host_build, weights, *args, "--in", str(path), "--in", str(tmp_path / "other.bin"))
    one = _sgru_stream(host_build, weights, *args, "--in", str(path))
    two = _sgru_stream(host_build, weights, *args, "--in", str(tmp_path / "other.bin"))
    strip = lambda text: [ln for ln in text.splitlines() if not ln.startswith("# fwref_stream")]
    assert strip(both) == strip(one) + strip(two)
    assert "flight=1 " in both and sum(not ln.startswith("#") for ln in strip(two)) >= 2


def test_stream_sgru_under_sanitizers_gives_the_release_lines(sgru_export, sgru_flight, asan_build, host_build):  # noqa: F811
    """The per-sample path (StepRunner, the step's state, two flights with reset()) in bounds under ASan + UBSan."""
    path = sgru_flight[0]
    args = ("--model", "sgru", "--int8", "--in", str(path), "--in", str(path))
    weights = sgru_export / "export" / "sgru_weights.bin"
    asan = subprocess.run([str(asan_build / "fwref_stream"), "--weights", str(weights), *args], capture_output=True,
                          text=True, timeout=300, check=False)
    assert asan.returncode == 0 and not any(m in asan.stderr for m in SANITIZER_MARKERS), asan.stderr[-2000:]
    assert asan.stdout == _sgru_stream(host_build, weights, *args)
