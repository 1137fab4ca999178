"""The on-board streaming runtime (issue 16): fwref/alarm.hpp against core/alarm.py, weights.bin's
on-board record as the C++ reads it, and fwref_stream replaying a simulated and a real flight against
the Python window path at every stride (int8 logits bit-identical, fp32 within the parity tolerance,
alarms identical), plus the defined behaviour on NaN samples, timestamp gaps and refusals.

Cheap: the flightlog-min export is the session's (tests/conftest.py, shared with test_detect.py),
the C++ programs the session's host build."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from core.alarm import run_alarm
from core.contracts import FP32_CPP_REL_TOL, SPLIT_TEST
from tests.conftest import quadfdi
from tests.test_firmware_fixtures import asan_build, host_build  # noqa: F401 (fixtures)

REAL = Path("/work/shared/data/flightlogs")
MISSION = REAL / "px4_quad_6s_uavcan_mission.ulg"
PREDICTIONS = Path("/work/main/runs/realistic/predictions/cnode_sim0_train0.npz")
SANITIZER_MARKERS = ("AddressSanitizer", "runtime error", "LeakSanitizer", "UndefinedBehaviorSanitizer")
POLICIES = [(0.5, 2, 3, 3, False), (0.3, 1, 1, 1, False), (0.7, 3, 5, 2, True), (0.45, 4, 8, 6, False)]


def _alarm_cpp(exe: Path, tmp: Path, proba, valid, policy, healthy=0, motor=None) -> np.ndarray:
    """fwref_alarm on (F, W, K) proba: (F, W, 6) vote, active, raised, cleared, cls, motor."""
    f, w, k = proba.shape
    parts = [valid[..., None].astype(np.float64), proba] + ([motor] if motor is not None else [])
    np.concatenate(parts, axis=2).astype("<f8").tofile(tmp / "seq.f64")
    thr, kk, n, m, latch = policy
    cmd = [str(exe / "fwref_alarm"), "--in", str(tmp / "seq.f64"), "--out", str(tmp / "steps.i32"), "--windows",
           str(w), "--classes", str(k), "--healthy", str(healthy), "--threshold", repr(thr), "--k", str(kk), "--n",
           str(n), "--clear-m", str(m)] + (["--latch"] if latch else []) + (["--motor"] if motor is not None else [])
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


@pytest.mark.skipif(not PREDICTIONS.is_file(), reason="the realistic run's prediction sets are not here")
def test_alarm_mirror_on_a_prediction_set(host_build, tmp_path):  # noqa: F811
    z = np.load(PREDICTIONS)
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
    from detect.streamfile import record_of

    rec = record_of(flightlog_export)
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


def test_onboard_record_round_trip_and_refusals():
    """A threshold float32 cannot hold survives exactly; nocur streams carry no current; a record
    that differs from the layout is refused in one line."""
    from core.errors import QuadfdiError
    from core.profiles import channel_names, required_raw
    from export.binfmt import Section, pack, unpack
    from export.onboard_record import check_onboard, onboard_dict, onboard_section

    policy = {"threshold": 0.35, "k": 3, "n": 5, "clear_m": 4, "latch": True}
    sec = onboard_section("flightlog-nocur", channel_names("flightlog-nocur", []), 50, 10, 0.04, policy,
                          ["BatteryFault", "Healthy", "MotorFault"])
    (back,) = unpack(pack(b"QFDIWTS\0", 1, [sec]), b"QFDIWTS\0", 1, "w")[1]
    d = onboard_dict(back)
    assert d["alarm"] == policy and d["healthy"] == 1 and d["window"] == 50 and d["stride"] == 10
    assert d["raw_channels"] == required_raw("flightlog-nocur") + ["airborne"] and "I_b" not in d["raw_channels"]
    bad = Section(sec.model, sec.precision, sec.dims, dict(sec.tensors))
    bad.tensors.pop("alarm.policy")
    with pytest.raises(QuadfdiError, match="on-board record holds tensors"):
        check_onboard(bad, "w")
    with pytest.raises(QuadfdiError, match="knows profiles"):
        onboard_section("flightlog-x", [], 50, 10, 0.04, policy, ["Healthy"])


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
        from detect.streamfile import from_flight, record_of, write_stream

        write_stream(paths["real"], from_flight(MISSION, record_of(flightlog_export)))
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
    """The Python window path on the stream's samples: windows, ORT and C++ window logits, the alarm."""
    from detect.run import softmax
    from detect.runtimes import ort_logits
    from detect.streamref import windows_of

    sw = windows_of(rs, record)
    x = sw.windows(record["window"])
    ort = ort_logits(export / _manifest(export)["artifacts"][f"{net}_{precision}"], x)
    cpp = _infer(exe, export, net, precision == "int8", x, tmp)
    proba = np.zeros((len(sw.starts), ort.shape[1]))
    proba[:, record["healthy"]] = 1.0  # undecided windows never vote (detect/run.py)
    proba[sw.decided] = softmax(ort)
    a = record["alarm"]
    trace = run_alarm(proba[None], a["threshold"], a["k"], a["n"], a["clear_m"], a["latch"], healthy=record["healthy"],
                      valid=sw.decided[None])
    return sw, ort, cpp, proba, trace


@pytest.mark.parametrize("precision", ["fp32", "int8"])
@pytest.mark.parametrize("net", ["cnode", "gru"])
def test_stream_gives_the_window_path_at_every_stride(flightlog_export, streams, host_build, tmp_path, net,  # noqa: F811
                                                      precision):
    print("; ".join(_check_replay(flightlog_export, streams, host_build, tmp_path, net, precision)))


def test_paper_profile_stream_gives_the_window_path(fault_exported, host_build, tmp_path):  # noqa: F811
    """The identity profile (no hover estimate, no airborne channel) on the session's paper-config export."""
    from detect.streamfile import from_dataset, record_of, write_stream

    export = fault_exported / "export"
    record = record_of(export)
    assert record["profile"] == "paper" and not record["cells_from_stream"]
    assert record["raw_channels"] == record["channels"] == [c["name"] for c in _manifest(export)["channels"]]
    z = np.load(fault_exported / "dataset.npz")
    flight = int(np.flatnonzero(z["split"] == SPLIT_TEST)[0])
    write_stream(tmp_path / "paper.bin", from_dataset(fault_exported / "dataset.npz", flight, record))
    for net, precision in (("cnode", "int8"), ("gru", "fp32")):
        print(_check_replay(export, {"sim": tmp_path / "paper.bin"}, host_build, tmp_path, net, precision))


def _check_replay(export: Path, streams: dict[str, Path], exe: Path, tmp: Path, net: str, precision: str) -> list[str]:
    """fwref_stream on each stream against the window path at every stride; a report line per stream."""
    from detect.streamfile import read_stream, record_of
    from detect.streamref import read_lines

    record = record_of(export)
    report = []
    for name, path in streams.items():
        rs = read_stream(path)
        sw, ort, cpp, proba, trace = _window_path(export, exe, tmp, rs, record, net, precision)
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
        if not flips.any():
            for key, ref in (("active", trace.active), ("raised", trace.raised), ("cleared", trace.cleared),
                             ("cls", trace.cls)):
                np.testing.assert_array_equal(out[key], ref[0], err_msg=f"{name} {key}")
        report.append(f"{name}: {int(sw.decided.sum())} decided / {len(sw.ends)} strides, {int(flips.sum())} vote flips")
    return report


@pytest.mark.skipif(not MISSION.is_file(), reason="the shared real flight logs are not here")
def test_stream_reference_is_detects_window_path(flightlog_export, streams):
    """detect/streamref.py on the stream file decides the windows detect/inputs.py decides, with the same inputs."""
    from detect.inputs import flight_inputs, read_flight, windows
    from detect.streamfile import read_stream, record_of
    from detect.streamref import windows_of

    record = record_of(flightlog_export)
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
    from detect.streamfile import read_stream, write_stream

    rs = read_stream(src)
    edit(rs)
    write_stream(dst, rs)


def test_nan_samples_skip_their_windows_and_gaps_are_held(flightlog_export, streams, host_build, tmp_path):  # noqa: F811
    from detect.streamref import read_lines

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
