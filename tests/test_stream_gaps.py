"""fwref/stream.hpp's bounded push (src/stream.cpp): timestamp jumps of +1e6 s and +1e9 s, a one-sample
glitch of +1e9 s, a backwards jump of 50 s and a repeated time, replayed through fwref_stream and through
the Cortex-M stream image under QEMU, and a NaN sample period refused.

Each replay ends in bounded time with at most one stride line per pushed sample, and gives the documented
lines: those of the same flight with the missing samples pushed as NaN samples (the held gap), minus the
strides that end inside the gap, and with a gap long enough to leave no trace standing in for the jump
(the state saturates: W ring slots, the alarm's n strides). On the Cortex-M (QEMU -icount) every push
around a gap costs fewer instructions than the worst decision."""

from __future__ import annotations

import math
import subprocess
import time
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.contracts import SPLIT_TEST
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

AT = 150  # the sample the jump happens at: decisions before it, and W samples after it for more
JUMPS = {"jump_1e6": 1e6, "jump_1e9": 1e9}


def _llround(q: float) -> int:
    return math.floor(Fraction(q) + Fraction(1, 2))


@pytest.fixture(scope="module")
def flight(flightlog_export):
    """A simulated test flight with a fault (300 samples), the on-board record and each model's alarm n."""
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset

    record = Export.open(flightlog_export).onboard()
    dataset = flightlog_export.parent / "dataset.npz"
    z = np.load(dataset)
    row = int(np.flatnonzero((z["split"] == SPLIT_TEST) & (z["fault_class"] > 0))[0])
    return from_dataset(dataset, row, record), record


def _copy(rs, time_, values):
    from quadfdi.formats.stream import RawStream

    return RawStream(rs.source, rs.profile, list(rs.names), rs.sample_dt_s, rs.cells, np.asarray(time_, np.float64),
                     np.asarray(values, np.float32))


def _nan_rows(rs, n: int) -> np.ndarray:
    """n samples without data, airborne as the flight (what the stream's held gap stands for)."""
    rows = np.full((n, rs.values.shape[1]), np.nan, np.float32)
    rows[:, rs.names.index("airborne")] = rs.values[0, rs.names.index("airborne")]
    return rows


def _replay(exe: Path, export: Path, rs, path: Path, net: str = "cnode", int8: bool = True) -> tuple[dict, str, float]:
    from quadfdi.detect.streamref import read_lines
    from quadfdi.formats.stream import write_stream

    write_stream(path, rs)
    out = path.with_suffix(".txt")
    t0 = time.perf_counter()
    res = subprocess.run([str(exe / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", net,
                          "--in", str(path), "--out", str(out)] + (["--int8"] if int8 else []),
                         capture_output=True, text=True, timeout=120, check=False)
    seconds = time.perf_counter() - t0
    assert res.returncode == 0, res.stderr
    text = out.read_text()
    return read_lines(text, 5), text, seconds


def _end(text: str) -> dict[str, float]:
    line = next(ln for ln in text.splitlines() if ln.startswith("# end "))
    return {k: float(v) for k, v in (kv.split("=") for kv in line.split()[2:])}


def _policy_n(exe: Path, export: Path, net: str) -> int:
    res = subprocess.run([str(exe / "fwref_stream"), "--weights", str(export / "weights.bin"), "--info", "--model", net],
                         capture_output=True, text=True, check=True)
    return int(dict(ln.split("=", 1) for ln in res.stdout.splitlines())["n"])


def _held(rs, at: int, missing: int, drop: int = 0):
    """The flight with samples at..at+drop-1 removed and ``missing`` NaN samples before the next one, on the
    grid: what the stream's documented rule says a jump (or a new clock after ``drop`` refusals) is."""
    dt = rs.sample_dt_s
    values = np.concatenate([rs.values[:at], _nan_rows(rs, missing), rs.values[at + drop:]])
    return _copy(rs, dt * np.arange(len(values)), values)


def _same_but_gap(got: dict, want: dict, lo: int, hi: int, shift: int) -> None:
    """``got`` (the jump) equals ``want`` (the held reference) without the strides ending in [lo, hi) (inside the
    gap: not reported), with the later indices shifted by ``shift``; t is the only column let differ."""
    keep = (want["index"] < lo) | (want["index"] >= hi)
    assert (~keep).any()  # the gap did swallow strides
    index = np.where(want["index"][keep] >= hi, want["index"][keep] + shift, want["index"][keep])
    np.testing.assert_array_equal(got["index"], index)
    for key in ("status", "logits", "vote", "active", "raised", "cleared", "cls", "motor", "wmotor"):
        np.testing.assert_array_equal(got[key], want[key][keep], err_msg=key)


def _ends_below(hi: int, window: int, stride: int) -> int:
    """How many stride ends window - 1 + k stride (k >= 0) lie below ``hi``."""
    return max(0, -(-(hi - (window - 1)) // stride))


@pytest.mark.parametrize("name", list(JUMPS))
def test_a_jump_forward_is_a_held_gap_in_constant_time(flightlog_export, flight, host_build, tmp_path, name):  # noqa: F811
    rs, record = flight
    dt_rec, window, stride = record["sample_dt_s"], record["window"], record["stride"]
    times = rs.time.copy()
    times[AT:] += JUMPS[name]
    got, text, seconds = _replay(host_build, flightlog_export, _copy(rs, times, rs.values), tmp_path / "jump.bin")
    g = _llround((times[AT] - times[AT - 1]) / dt_rec)  # the stream's count of periods
    missing = g - 1
    n = _policy_n(host_build, flightlog_export, "cnode")
    # the saturated reference: as many missing samples as leave no trace, in the same stride phase
    small = window + n * stride + (missing - window - n * stride) % stride
    want, _, _ = _replay(host_build, flightlog_export, _held(rs, AT, small), tmp_path / "held.bin")
    _same_but_gap(got, want, AT, AT + small, missing - small)
    end = _end(text)
    # the stride ends window - 1 + k stride in [AT, AT + missing), counted (an arange of them: 10 GB at 1e9 s)
    inside = _ends_below(AT + missing, window, stride) - _ends_below(AT, window, stride)
    assert end["gap_strides"] == inside > 10 ** 6 and end["dropped"] == 0 == end["resyncs"]
    assert len(got["index"]) <= len(rs.time) and seconds < 10, (len(got["index"]), seconds)
    assert got["status"][got["index"] >= AT + missing + window].tolist().count("decided") >= 1  # decides again
    print(f"{name}: {missing} missing samples, {int(end['gap_strides'])} strides inside the gap, "
          f"{len(got['index'])} lines for {len(rs.time)} samples, {seconds:.3f} s")


def test_a_short_gap_gives_the_nan_samples_lines(flightlog_export, flight, host_build, tmp_path):  # noqa: F811
    """A gap shorter than a window: exactly the lines of the NaN-filled flight, minus the stride inside the gap."""
    rs, record = flight
    missing = 25  # spans the stride end at 159
    keep = np.ones(len(rs.time), bool)
    keep[AT:AT + missing] = False
    got, text, _ = _replay(host_build, flightlog_export, _copy(rs, rs.time[keep], rs.values[keep]), tmp_path / "gap.bin")
    values = rs.values.copy()
    values[AT:AT + missing] = _nan_rows(rs, missing)
    want, _, _ = _replay(host_build, flightlog_export, _copy(rs, rs.time, values), tmp_path / "nan.bin")
    _same_but_gap(got, want, AT, AT + missing, 0)
    assert _end(text)["gap_strides"] == 1


@pytest.mark.parametrize("net", ["cnode", "gru"])
def test_a_backwards_jump_is_a_new_clock_after_eight_refusals(flightlog_export, flight, host_build, tmp_path, net):  # noqa: F811
    rs, record = flight
    times = rs.time.copy()
    times[AT:] -= 50.0
    got, text, seconds = _replay(host_build, flightlog_export, _copy(rs, times, rs.values), tmp_path / "back.bin",
                                 net, False)
    resync = record["window"] + _policy_n(host_build, flightlog_export, net) * record["stride"]
    want, _, _ = _replay(host_build, flightlog_export, _held(rs, AT, resync, drop=7), tmp_path / "held.bin", net, False)
    _same_but_gap(got, want, AT, AT + resync, 0)
    end = _end(text)
    assert end["dropped"] == 7 and end["resyncs"] == 1 and seconds < 10


def test_a_repeated_time_and_a_glitch_are_dropped(flightlog_export, flight, host_build, tmp_path):  # noqa: F811
    rs, record = flight
    times = rs.time.copy()
    times[AT] = times[AT - 1]
    got, text, _ = _replay(host_build, flightlog_export, _copy(rs, times, rs.values), tmp_path / "dup.bin")
    keep = np.arange(len(rs.time)) != AT  # the stream without that sample: a gap of one at its place
    want, _, _ = _replay(host_build, flightlog_export, _copy(rs, rs.time[keep], rs.values[keep]), tmp_path / "cut.bin")
    for key in ("index", "status", "logits", "active", "cls"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)
    assert _end(text)["dropped"] == 1
    times = rs.time.copy()
    times[AT] += 1e9  # one corrupt time: accepted as a gap, then the true times are refused until a new clock
    got, text, seconds = _replay(host_build, flightlog_export, _copy(rs, times, rs.values), tmp_path / "glitch.bin")
    end = _end(text)
    assert end["dropped"] == 7 and end["resyncs"] == 1 and end["gap_strides"] > 10 ** 9 and seconds < 10
    assert len(got["index"]) <= len(rs.time)


def test_a_nan_or_foreign_sample_period_is_refused(flightlog_export, flight, host_build, tmp_path):  # noqa: F811
    from quadfdi.formats.stream import write_stream

    rs, _ = flight
    for period, why in ((float("nan"), "sample period nan s"), (float("inf"), "sample period inf s"),
                        (-0.04, "sample period -0.04 s"), (0.05, "sample period 0.05 s")):
        path, out = tmp_path / "p.bin", tmp_path / "p.txt"
        write_stream(path, type(rs)(rs.source, rs.profile, rs.names, period, rs.cells, rs.time, rs.values))
        res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(flightlog_export / "weights.bin"),
                              "--model", "cnode", "--in", str(path), "--out", str(out)], capture_output=True, text=True,
                             timeout=60, check=False)
        assert res.returncode == 2 and res.stderr.count("\n") == 1 and why in res.stderr, res.stderr
        assert not out.exists() and not list(tmp_path.glob("p.txt.tmp.*"))


# ------------------------------------------------------------------ the Cortex-M stream image under QEMU


@pytest.fixture(scope="module")
def mcu(flightlog_export, flight, tmp_path_factory) -> dict:
    """The stream image (cortex-m4) with the clean flight and its jumps compiled in, run under QEMU."""
    from quadfdi.runtimes.build import configure_and_build, mcu_options, source_dir
    from quadfdi.runtimes.mcu import qemu_command, tools_missing
    from quadfdi.formats.stream import write_stream

    why = tools_missing()
    if why:
        pytest.skip(f"Cortex-M toolchain or QEMU missing: {why}")
    rs, _ = flight
    tmp = tmp_path_factory.mktemp("mcu_gaps")
    edits = {"clean": 0.0, **JUMPS, "back": -50.0}
    paths = []
    for name, jump in edits.items():
        times = rs.time.copy()
        times[AT:] += jump
        paths.append(tmp / f"{name}.bin")
        write_stream(paths[-1], _copy(rs, times, rs.values))
    build = tmp / "build"
    build.mkdir()
    src = source_dir()
    options = mcu_options(src, "cortex-m4", flightlog_export / "weights.bin", flightlog_export / "reference.bin",
                          tuple(paths))
    configure_and_build(src / "mcu", build, options, "the cortex-m4 stream image", ("fwref_mcu_stream",))
    res = subprocess.run(qemu_command("cortex-m4", build / "fwref_mcu_stream.elf"), capture_output=True, text=True,
                         timeout=1200, check=False)
    assert "RESULT DONE" in res.stdout, res.stdout[-2000:] + res.stderr[-2000:]
    return {"text": res.stdout, "names": list(edits), "paths": paths}


def _mcu_lines(text: str, kind: str) -> list[list[str]]:
    return [ln.split()[1:] for ln in text.splitlines() if ln.startswith(kind + " ")]


def test_cortex_m_push_around_a_gap_costs_less_than_a_decision(mcu, flightlog_export, host_build):  # noqa: F811
    """Per model and precision: every push whose time was not the next period (the jump, the refused times,
    the new clock) reports at most one stride and costs fewer instructions than the worst decision; the
    gap flights' worst push and worst undecided stride too; and the strides are the host's."""
    from quadfdi.detect.streamref import read_lines

    perf = {}
    for p in _mcu_lines(mcu["text"], "PERF"):
        perf[(p[0], p[1], int(p[2]))] = {kv.split("=")[0]: int(kv.split("=")[1]) for kv in p[3:]}
    gaps = _mcu_lines(mcu["text"], "GAP")
    strides = _mcu_lines(mcu["text"], "STRIDE")
    report = []
    for net, prec in sorted({(m, p) for m, p, _ in perf}):
        decide = max(v["decide_max"] for (m, p, _), v in perf.items() if (m, p) == (net, prec))
        mine = [g for g in gaps if (g[0], g[1]) == (net, prec)]
        kv = [{x.split("=")[0]: int(x.split("=")[1]) for x in g[4:]} for g in mine]
        assert len(mine) == 2 + 8 and all(k["strides"] <= 1 for k in kv), mine  # 2 jumps; back: 7 refused, 1 new clock
        worst = max(k["instructions"] for k in kv)
        for f in range(1, len(mcu["names"])):
            v = perf[(net, prec, f)]
            worst = max(worst, v["push_max"], v["other_max"])
            assert v["decide_n"] >= 2, (net, prec, f, v)
        assert 0 < worst < decide, (net, prec, worst, decide)
        for f, path in enumerate(mcu["paths"]):
            res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(flightlog_export / "weights.bin"),
                                  "--model", net, "--in", str(path)] + (["--int8"] if prec == "int8" else []),
                                 capture_output=True, text=True, check=True, timeout=120)
            host = read_lines(res.stdout, 5)
            ours = [s for s in strides if (s[0], s[1], int(s[2])) == (net, prec, f)]
            assert [int(s[3]) for s in ours] == host["index"].tolist(), (net, prec, f)
            assert [s[4] for s in ours] == host["status"].tolist(), (net, prec, f)
            if prec == "int8":
                bits = np.array([[int(b) for b in s[5:10]] for s in ours], np.uint32).view(np.float32)
                np.testing.assert_array_equal(bits[host["status"] == "decided"], host["logits"][host["status"] == "decided"])
        report.append(f"{net} {prec}: worst decision {decide} instructions, worst push around a gap {worst}")
    print("; ".join(report))


def test_python_reader_is_bounded_and_checks_the_header(flight, tmp_path):
    """formats/stream.py read_stream: a device or folder, a NaN or negative period, header_bytes or a channel
    count out of range and a partial sample are one-line QuadfdiErrors (fwref_stream refuses the same)."""
    import struct

    from quadfdi.core.errors import QuadfdiError
    from quadfdi.formats.stream import read_stream, stream_bytes

    rs, _ = flight
    good = stream_bytes(rs)
    cases = {"/dev/zero": "not a regular file", str(tmp_path): "not a regular file"}
    for name, blob, why in (("nan", good[:24] + struct.pack("<d", float("nan")) + good[32:], "sample period nan"),
                            ("neg", good[:24] + struct.pack("<d", -0.04) + good[32:], "sample period -0.04"),
                            ("head", good[:12] + struct.pack("<I", 1 << 20) + good[16:], "bad header"),
                            ("chan", good[:16] + struct.pack("<I", 0) + good[20:], "bad header"),
                            ("part", good[:-3], "truncated")):
        (tmp_path / f"{name}.bin").write_bytes(blob)
        cases[str(tmp_path / f"{name}.bin")] = why
    for path, why in cases.items():
        with pytest.raises(QuadfdiError, match=why) as err:
            read_stream(path)
        assert "\n" not in str(err.value)
