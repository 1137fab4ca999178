"""The masked profile (flightlog-mask: whatever channels a log has): the channel table's groups, fills
and patterns; the profile's arithmetic and its C++ mirror; the masked training windows; a tiny masked
model (tests/conftest.py masked_export, trained and exported through the CLI) deciding the shared real
flights, a CrazyPAD flight and a simulated ArduCopter log with ORT and the C++ alike, refusing only a
flight without its minimum or too short; and the stream (version 2 files, the carried flags) against
the window path on the host. The Cortex-M: tests/test_masks_mcu.py."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.channels import (ALL_CHANNELS_PROBABILITY, AVAILABILITY_GROUPS, GROUP_NAMES, MASK_PATTERNS,
                                   MINIMUM_RAW, MODEL_CHANNELS, PROFILE_BY_NAME, group_of_model, stream_raw)
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import apply_profile, channel_names, mask_layout, pattern_available
from tests.conftest import ROOT, SHARED_DATA, quadfdi
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

MASK = "flightlog-mask"
LOGS = SHARED_DATA / "flightlogs"
CRAZYPAD = SHARED_DATA / "crazypad" / "motor_data" / "normal_flight" / "E9_log00"
FLIGHTS = {"gps": LOGS / "px4_quad_6s_gps_interference.ulg", "uavcan": LOGS / "px4_quad_6s_uavcan_mission.ulg",
           "battery": LOGS / "px4_quad_battery_monitor_disconnected.ulg", "crazyflie": CRAZYPAD}
# the groups each flight lacks (ingest's channel_status; the DataFlash log: written from a simulated flight)
LACKS = {"gps": {"current", "vib_ap", "esc_rpm", "esc_cur", "esc_temp"}, "uavcan": {"vib_ap"},
         "battery": {"battery", "current", "vib_ap", "esc_rpm", "esc_cur", "esc_temp"},
         "crazyflie": {"pitch", "rates", "current", "vib_px4", "vib_ap", "esc_rpm", "esc_cur", "esc_temp"},
         "ardupilot": {"vib_px4", "esc_rpm", "esc_cur", "esc_temp"}}
pytestmark = pytest.mark.skipif(not all(p.exists() for p in FLIGHTS.values()), reason="the shared logs are not here")


def test_table_groups_minimum_fills_and_patterns():
    p = PROFILE_BY_NAME[MASK]
    grouped = [r for g in AVAILABILITY_GROUPS for r in g.raw]
    assert len(grouped) == len(set(grouped)) and not set(grouped) & set(MINIMUM_RAW)
    assert sorted(p.raw) == sorted(grouped + list(MINIMUM_RAW))  # every channel a group or the minimum names
    names = channel_names(MASK, [])
    assert names[-len(GROUP_NAMES):] == [f"avail_{g}" for g in GROUP_NAMES] and "vib_ap" in names and "vib" in names
    derived = [c.name for c in MODEL_CHANNELS if set(c.raw) <= set(p.raw) and not (c.reference or c.physics)]
    assert names[:-len(GROUP_NAMES)] == derived and len(names) == 38
    fills = {c.name: c.fill for c in MODEL_CHANNELS}
    assert fills["v_cell"] == 3.7 and fills["vib"] == fills["vib_ap"] == 5.5 and fills["esc1_t_rel"] == 0.0
    assert {fills[n] for n in ("i_rel", "m1_rel", "rpm2_rel", "esc3_i_rel")} == {1.0}
    assert {fills[n] for n in ("roll", "pitch", "p", "vx_h", "vy_h", "vz")} == {0.0}
    assert all(group_of_model(c) is None for c in MODEL_CHANNELS if set(c.raw) <= set(MINIMUM_RAW))
    assert MASK_PATTERNS[0].name == "all" and not MASK_PATTERNS[0].groups and 0 < ALL_CHANNELS_PROBABILITY < 1
    assert all(set(m.groups) <= set(GROUP_NAMES) for m in MASK_PATTERNS)
    assert {m.name for m in MASK_PATTERNS} >= {"no_current", "no_esc", "no_position_fix", "no_rates", "no_pitch",
                                              "no_yaw", "px4_vibration_only", "ardupilot_vibration_only",
                                              "no_vibration", "crazyflie", "no_battery_monitor"}
    assert stream_raw(p)[-1] == "airborne" and PROFILE_BY_NAME["flightlog-min"].model == \
        tuple(c for c in MODEL_CHANNELS if c.name in channel_names("flightlog-min", []))
    from quadfdi.core.config import load_config

    masked = load_config("realistic-mask")  # the realistic suite's dataset, byte for byte, trained masked
    assert masked.to_dict()["sim"] == load_config("realistic").to_dict()["sim"] and masked.train.profile == MASK


def _raw(n: int, seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    raw = {r: rng.normal(0.0, 0.3, n).astype(np.float32) for r in PROFILE_BY_NAME[MASK].raw}
    raw["yaw"] = rng.uniform(-np.pi, np.pi, n).astype(np.float32)
    raw["V_b"] = rng.uniform(14, 25, n).astype(np.float32)
    raw["I_b"] = rng.uniform(5, 40, n).astype(np.float32)
    for k in range(1, 5):
        raw[f"thr{k}"] = rng.uniform(0.3, 0.7, n).astype(np.float32)
        raw[f"rpm{k}"] = rng.uniform(4000, 9000, n).astype(np.float32)
        raw[f"esc_cur{k}"] = rng.uniform(2, 15, n).astype(np.float32)
        raw[f"esc_temp{k}"] = np.round(rng.uniform(20, 70, n) * 4).astype(np.float32) / 4
    raw["vib_px4"], raw["vib_ap"] = (rng.uniform(2, 20, n).astype(np.float32) for _ in range(2))
    return raw


def test_available_groups_read_as_the_fixed_profiles_and_absent_ones_as_their_fills():
    raw = _raw(500, 3)
    full = apply_profile(MASK, raw, 6, np.float32(0.45), np.float32(18.0))
    esc = apply_profile("flightlog-esc", raw, 6, np.float32(0.45), np.float32(18.0))
    names, esc_names = channel_names(MASK, []), channel_names("flightlog-esc", [])
    np.testing.assert_array_equal(full[:, [names.index(n) for n in esc_names]], esc)  # the same bits
    np.testing.assert_array_equal(full[:, -len(GROUP_NAMES):], 1.0)
    cols, fill, avail = mask_layout(MASK)
    for pat in MASK_PATTERNS[1:]:
        have = pattern_available(pat)
        x = apply_profile(MASK, {r: v for r, v in raw.items() if not any(r in g.raw and g.name in pat.groups
                                                                          for g in AVAILABILITY_GROUPS)},
                          6, np.float32(0.45), np.float32(18.0), have)
        lost = [j for g in pat.groups for j in cols[g]]
        kept = [j for j in range(len(names) - len(GROUP_NAMES)) if j not in lost]
        np.testing.assert_array_equal(x[:, lost], np.broadcast_to(fill[lost], (500, len(lost))))
        np.testing.assert_array_equal(x[:, kept], full[:, kept])
        assert [x[0, avail[g]] for g in GROUP_NAMES] == [float(have[g]) for g in GROUP_NAMES]


MIRROR = r"""
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "fwref/profile.hpp"
int main(int argc, char** argv) {  // in: n x (R + 1) float32 (raw, then the availability mask); out: n x C
  const float cells = std::strtof(argv[3], nullptr), cmd = std::strtof(argv[4], nullptr), cur = std::strtof(argv[5], nullptr);
  const fwref::Profile p = fwref::Profile::kFlightlogMask;
  const fwref::ProfileSpec& s = fwref::profile_spec(p);
  FILE* f = std::fopen(argv[1], "rb");
  FILE* o = std::fopen(argv[2], "wb");
  std::vector<float> raw(s.raw + 1), x(s.channels);
  while (std::fread(raw.data(), 4, s.raw + 1, f) == static_cast<size_t>(s.raw + 1)) {
    const std::uint32_t avail = static_cast<std::uint32_t>(raw[s.raw]);
    fwref::profile_prep(p, raw.data(), s.raw, cells, x.data(), avail);
    fwref::profile_hover(p, cmd, cur, x.data(), avail);
    const fwref::HoverInputs h = fwref::hover_inputs(p, raw.data(), avail);
    x.push_back(h.pitch), x.push_back(h.current);
    std::fwrite(x.data(), 4, x.size(), o);
    x.resize(s.channels);
  }
  std::fclose(f);
  std::fclose(o);
  return 0;
}
"""


@pytest.mark.skipif(shutil.which("c++") is None, reason="no C++ compiler")
def test_cpp_mirror_fills_bit_for_bit(tmp_path):
    """fwref/profile.hpp's masked profile under every pattern, NaN in the absent columns: apply_profile's
    bits; the hover estimate's pitch 0 and current NaN where the groups are absent."""
    src, exe = tmp_path / "m.cpp", tmp_path / "m"
    src.write_text(MIRROR)
    subprocess.run(["c++", "-std=c++17", "-O2", "-ffp-contract=off", "-fno-fast-math",
                    f"-I{ROOT / 'firmware_ref/include'}", str(src), "-o", str(exe)], check=True)
    n, order = 240, list(stream_raw(PROFILE_BY_NAME[MASK]))
    raw, pats = _raw(n, 5), np.arange(n) % len(MASK_PATTERNS)
    raw["airborne"] = np.ones(n, np.float32)
    have = {g: np.array([pattern_available(MASK_PATTERNS[k])[g] for k in pats]) for g in GROUP_NAMES}
    table = np.stack([raw[r] for r in order], 1)
    for g in AVAILABILITY_GROUPS:  # an absent column holds NaN: the fills must replace it
        table[np.ix_(~have[g.name], [order.index(r) for r in g.raw])] = np.nan
    bits = sum(have[g].astype(np.int64) << i for i, g in enumerate(GROUP_NAMES)).astype(np.float32)
    np.concatenate([table, bits[:, None]], 1).astype("<f4").tofile(tmp_path / "raw.f32")
    cmd, cur = np.float32(0.4637), np.float32(17.31)
    subprocess.run([str(exe), str(tmp_path / "raw.f32"), str(tmp_path / "x.f32"), "4", repr(float(cmd)),
                    repr(float(cur))], check=True)
    got = np.fromfile(tmp_path / "x.f32", "<f4").reshape(n, -1)
    # one sample per flight: the availability is per flight
    want = apply_profile(MASK, {r: table[:, order.index(r), None] for r in order[:-1]}, 4, cmd, cur, have)[:, 0]
    assert np.isfinite(want).all()
    np.testing.assert_array_equal(got[:, :-2].view(np.uint32), want.view(np.uint32))
    np.testing.assert_array_equal(got[:, -2], np.where(have["pitch"], raw["pitch"], 0.0))
    assert (np.isnan(got[:, -1]) == ~have["current"]).all()


def test_masked_training_windows_are_masked_flights(tmp_path):
    """train.masks on a window equals the profile on a flight lacking the same groups; the draw keeps
    "all" at its probability; availability channels are not normalised."""
    from quadfdi.train.masks import Masker, MaskDraw, draw_patterns, fixed_availability

    raw, names = _raw(200, 9), channel_names(MASK, [])
    full = apply_profile(MASK, raw, 6, np.float32(0.5), np.float32(20.0))
    windows = np.stack([full[i:i + 40] for i in range(0, 160, 10)])  # (16, 40, C)
    masker = Masker(MASK, names)
    pats = np.arange(len(windows)) % len(MASK_PATTERNS)
    got = masker.apply(windows.copy(), pats)
    for w, k in enumerate(pats):
        want = apply_profile(MASK, raw, 6, np.float32(0.5), np.float32(20.0), pattern_available(MASK_PATTERNS[k]))
        np.testing.assert_array_equal(got[w], want[w * 10:w * 10 + 40])
    draws = draw_patterns(np.random.default_rng(0), 20000)
    assert abs((draws == 0).mean() - ALL_CHANNELS_PROBABILITY) < 0.015 and set(draws) == set(range(len(MASK_PATTERNS)))
    batch = MaskDraw(masker, 3)
    assert np.array_equal(batch.patterns(50, 1, 2), batch.patterns(50, 1, 2))
    assert not np.array_equal(batch.patterns(50, 1, 2), batch.patterns(50, 2, 2))
    mean, std = fixed_availability(MASK, np.full(len(names), 5, np.float32), np.full(len(names), 2, np.float32))
    assert (mean[-len(GROUP_NAMES):] == 0).all() and (std[-len(GROUP_NAMES):] == 1).all() and (mean[:5] == 5).all()


def test_metrics_report_every_pattern(masked_export):
    m = json.loads((masked_export.parent / "metrics.json").read_text())
    for net in ("cnode", "gru"):
        for split in ("validation", "test"):
            scores = m["mask_patterns"][net][split]
            assert list(scores) == [p.name for p in MASK_PATTERNS]
            assert all(0 <= s["macro_f1"] <= 1 and s["windows"] > 0 for s in scores.values())
    assert set(m["cnode"]) == set(m["baseline"])  # the test metrics themselves as for any profile


@pytest.fixture(scope="module")
def flights(masked_export, tmp_path_factory) -> dict[str, dict]:
    """flight.npz arrays of the four real flights and of a simulated ArduCopter log (DataFlash, written
    from a test flight of the masked run's own dataset with the shared ArduCopter log as template)."""
    from quadfdi.detect.inputs import read_flight
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.ingest.dataflash_writer import dataflash_bytes

    out = {name: read_flight(path) for name, path in FLIGHTS.items()}
    ds = load_dataset(masked_export.parent / "dataset.npz")
    path = tmp_path_factory.mktemp("ardupilot") / "sim.BIN"
    path.write_bytes(dataflash_bytes(ds.arrays, 0, LOGS / "ardupilot_copter_quadx_ground.BIN"))
    out["ardupilot"] = read_flight(path)
    return out


@pytest.mark.parametrize("name", sorted(LACKS))
def test_detect_decides_every_flight_with_ort_and_cpp_alike(masked_export, flights, host_build, name):  # noqa: F811
    """Each flight decides (no refusal) with the groups it lacks; ORT and the C++ give the same alarms in
    each precision (int8: the same logits bit for bit)."""
    from quadfdi.detect.run import detect

    runs = {(rt, prec): detect(masked_export, flights[name], "gru", prec, rt)
            for rt in ("ort", "cpp") for prec in ("fp32", "int8")}
    rec = runs["ort", "fp32"]["record"]
    assert {g for g, ok in rec["channels"]["groups"].items() if not ok} == LACKS[name]
    assert rec["decided_windows"] > 0 and set(rec["channels"]["absent"]).isdisjoint(rec["channels"]["used"])
    assert set(MINIMUM_RAW) <= set(rec["channels"]["used"])
    for prec in ("fp32", "int8"):
        a, b = runs["ort", prec], runs["cpp", prec]
        same = lambda al: [{k: v for k, v in x.items() if k != "peak_p_fault"} for x in al]  # noqa: E731
        assert same(a["record"]["alarms"]) == same(b["record"]["alarms"]), prec
        assert [x["peak_p_fault"] for x in a["record"]["alarms"]] == \
            pytest.approx([x["peak_p_fault"] for x in b["record"]["alarms"]], abs=0 if prec == "int8" else 1e-5)
        np.testing.assert_array_equal(a["arrays"]["active"], b["arrays"]["active"])
    np.testing.assert_array_equal(runs["ort", "int8"]["arrays"]["proba"], runs["cpp", "int8"]["arrays"]["proba"])


def test_detect_cli_lists_used_and_absent_channels(masked_export, tmp_path):
    res = quadfdi("detect", "--model", str(masked_export), str(FLIGHTS["battery"]), "--out", str(tmp_path / "d"))
    assert res.returncode == 0, res.stderr
    rec = json.loads((tmp_path / "d" / "alarms.json").read_text())
    assert rec["channels"]["absent"]["V_b"].startswith("unusable: battery monitor disconnected")
    assert rec["channels"]["absent"]["rpm1"] == "absent: esc_status not logged" and rec["hover"]["cur_a"] is None


@pytest.mark.parametrize("log, why", [("px4_sitl_quad_esc.ulg", "never 50 steady airborne samples"),
                                      ("px4_fmuv5_quad_real_short.ulg", "too short")])
def test_detect_refuses_a_flight_that_never_hovers_or_is_too_short(masked_export, tmp_path, log, why):
    res = quadfdi("detect", "--model", str(masked_export), str(LOGS / log), "--out", str(tmp_path / "d"))
    assert res.returncode == 2 and why in res.stderr and res.stderr.count("\n") == 1, res.stderr
    assert not (tmp_path / "d").exists()


def test_a_window_lost_to_logging_gaps_says_which_channels_and_how_to_bridge(mission_npz):
    """The UAVCAN mission at 4.8 s windows: its airborne time suffices, its vibration log's gaps do not; the
    refusal names the channels with gaps (the most unbacked first) and ingest's --gap-factor."""
    from quadfdi.detect.inputs import flight_inputs
    from quadfdi.formats.flight import load_flight

    arrays = load_flight(mission_npz)
    with pytest.raises(QuadfdiError) as exc:
        flight_inputs(arrays, "flightlog-mask", 120, 20)
    msg = str(exc.value)
    assert "too short" in msg and "36.4 s airborne" in msg and "\n" not in msg
    assert "logging gaps leave" in msg and msg.index("of vib_px4") < msg.index("of vz") and "--gap-factor F" in msg


def test_detect_refuses_a_flight_without_the_minimum(masked_export, flights):
    from quadfdi.detect.run import detect

    arrays = dict(flights["uavcan"])
    status = arrays["channel_status"].astype(object)
    status[[str(n) for n in arrays["channel_names"]].index("vz")] = "unusable: no vertical velocity"
    arrays["channel_status"] = np.array(list(status))
    with pytest.raises(QuadfdiError, match="needs channel 'vz' \\(its minimum\\), which is unusable: no vertical"):
        detect(masked_export, arrays)


# ------------------------------------------------------------------------- the stream on the host


@pytest.fixture(scope="module")
def mask_streams(masked_export, tmp_path_factory) -> dict[str, Path]:
    """Stream files of the masked export: simulated test flights under three patterns (each flight's own,
    formats.stream.from_dataset) and the CrazyPAD and battery-monitor-disconnected flights."""
    from quadfdi.core.contracts import SPLIT_TEST
    from quadfdi.core.profiles import flight_pattern
    from quadfdi.detect.stream_cli import from_flight
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset, write_stream

    out, record = tmp_path_factory.mktemp("mask_streams"), Export.open(masked_export).onboard()
    z = np.load(masked_export.parent / "dataset.npz")
    rows, seen = [], set()
    for row in np.flatnonzero(z["split"] == SPLIT_TEST):
        pat = flight_pattern(int(z["traj_index"][row])).name
        if pat not in seen and len(rows) < 3:
            rows.append(int(row)), seen.add(pat)
    assert len(seen) == 3 and seen != {"all"}, seen
    paths = {}
    for row in rows:
        paths[f"sim{row}"] = out / f"sim{row}.bin"
        write_stream(paths[f"sim{row}"], from_dataset(masked_export.parent / "dataset.npz", row, record))
    for name in ("crazyflie", "battery"):
        paths[name] = out / f"{name}.bin"
        write_stream(paths[name], from_flight(FLIGHTS[name], record))
    return paths


@pytest.mark.parametrize("net, precision", [("cnode", "int8"), ("gru", "int8"), ("cnode", "fp32"), ("gru", "fp32")])
def test_stream_gives_the_window_path_under_every_pattern(masked_export, mask_streams, host_build, tmp_path,  # noqa: F811
                                                          net, precision):
    """fwref_stream on flights lacking different groups: the window path's status, logits (int8: the same
    bits, fp32: within the parity tolerance) and alarm at every stride (tests/test_stream.py's check)."""
    from quadfdi.formats.stream import read_stream
    from tests.test_stream import _check_replay

    for name, path in mask_streams.items():
        rs = read_stream(path)
        assert rs.carried is not None and not rs.carried.all() or name.startswith("sim")
        report = _check_replay(masked_export, {"sim" if name.startswith("sim") else "real": path}, host_build,
                               tmp_path, net, precision)
        print(name, report)


def test_stream_reference_is_detects_window_path_on_a_masked_flight(masked_export, mask_streams, flights):
    from quadfdi.detect.inputs import flight_inputs, windows
    from quadfdi.detect.streamref import windows_of
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import read_stream

    record = Export.open(masked_export).onboard()
    fi = flight_inputs(flights["crazyflie"], MASK, record["window"], record["stride"])
    sw = windows_of(read_stream(mask_streams["crazyflie"]), record)
    np.testing.assert_array_equal(sw.decided, fi.decided)
    np.testing.assert_array_equal(sw.windows(record["window"]), windows(fi, record["window"]))


def _fwref_stream(exe: Path, export: Path, path: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(exe / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "cnode",
                           "--int8", "--in", str(path)], capture_output=True, text=True, timeout=120)


def test_version_1_streams_are_read_as_carrying_every_channel(flightlog_export, host_build, tmp_path):  # noqa: F811
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import FIXED, from_dataset, read_stream, stream_bytes

    record = Export.open(flightlog_export).onboard()
    rs = from_dataset(flightlog_export.parent / "dataset.npz", 1, record)
    v2 = stream_bytes(rs)
    names = b"".join(n.encode() + b"\0" for n in rs.names)
    head = FIXED.size + len(names) + (-(FIXED.size + len(names))) % 8
    v1 = bytearray(v2[:FIXED.size] + names.ljust(head - FIXED.size, b"\0") + v2[int.from_bytes(v2[12:16], "little"):])
    v1[8:12], v1[12:16] = (1).to_bytes(4, "little"), head.to_bytes(4, "little")
    (tmp_path / "v1.bin").write_bytes(bytes(v1))
    (tmp_path / "v2.bin").write_bytes(v2)
    back = read_stream(tmp_path / "v1.bin")
    assert back.carried.all() and np.array_equal(back.values, rs.values)
    one, two = (_fwref_stream(host_build, flightlog_export, tmp_path / f"v{v}.bin") for v in (1, 2))
    assert one.returncode == two.returncode == 0 and one.stdout == two.stdout, one.stderr + two.stderr


def _lacking(rs, names: tuple[str, ...], cells: int | None = None):
    import dataclasses

    carried = rs.carried_flags.copy()
    values = rs.values.copy()
    for n in names:
        carried[rs.names.index(n)] = False
        values[:, rs.names.index(n)] = np.nan
    return dataclasses.replace(rs, carried=carried, values=values, cells=rs.cells if cells is None else cells)


def test_streams_lacking_what_the_profile_needs_are_refused_in_one_line(flightlog_export, masked_export,  # noqa: F811
                                                                        mask_streams, host_build, tmp_path):
    """A fixed profile's stream lacking a channel, a masked stream lacking its minimum or carrying V_b
    without a cell count: fwref_stream exits 2 with one line, streamref refuses the first too."""
    from quadfdi.detect.streamref import windows_of
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset, read_stream, write_stream

    fixed = Export.open(flightlog_export).onboard()
    cases = {"fixed": (flightlog_export, _lacking(from_dataset(flightlog_export.parent / "dataset.npz", 1, fixed),
                                                  ("I_b",)), "profile 'flightlog-min' cannot do without: I_b"),
             "minimum": (masked_export, _lacking(read_stream(mask_streams["crazyflie"]), ("roll",)),
                         "profile 'flightlog-mask' cannot do without: roll,pitch,p"),
             "cells": (masked_export, _lacking(read_stream(mask_streams["crazyflie"]), (), cells=0),
                       "does not give the pack's cell count")}
    for name, (export, rs, why) in cases.items():
        write_stream(tmp_path / f"{name}.bin", rs)
        res = _fwref_stream(host_build, export, tmp_path / f"{name}.bin")
        assert res.returncode == 2 and not res.stdout and res.stderr.count("\n") == 1, (name, res.stderr)
        assert why in res.stderr, (name, res.stderr)
    with pytest.raises(QuadfdiError, match="needs every channel; the stream lacks I_b"):
        windows_of(cases["fixed"][1], fixed)


def test_a_current_without_hover_seconds_or_a_pack_without_cell_count_is_a_lacking_group(flights):
    """What a fixed profile refuses the masked one runs without: a current with no sample in the hover
    estimate's steady seconds (current absent, why named), an unknown cell count (battery absent)."""
    from quadfdi.detect.inputs import flight_inputs

    arrays = {k: v.copy() if isinstance(v, np.ndarray) else v for k, v in flights["uavcan"].items()}
    names = [str(n) for n in arrays["channel_names"]]
    arrays["telemetry"][:, names.index("I_b")] = np.nan
    vehicle = json.loads(str(arrays["vehicle"]))
    vehicle["battery"]["cells"] = None
    arrays["vehicle"] = np.array(json.dumps(vehicle))
    fi = flight_inputs(arrays, MASK, 40, 20)
    assert not fi.available["current"] and not fi.available["battery"] and fi.decided.any()
    assert fi.absent["I_b"] == "gaps during the hover estimate's steady seconds" and "cell count" in fi.absent["V_b"]
    assert np.isnan(fi.hover.cur) and fi.cells == 0
    np.testing.assert_array_equal(fi.x[:, channel_names(MASK, []).index("i_rel")], 1.0)
    with pytest.raises(QuadfdiError, match="cell count is unknown"):
        flight_inputs(arrays, "flightlog-min", 40, 20)


@pytest.mark.parametrize("profile", [MASK, "flightlog-phys"])
def test_pattern_scores_mask_in_chunks_as_over_the_whole_set(profile):
    """pattern_scores masks and predicts a chunk at a time in one reused buffer: every pattern (and, for a
    reference profile, the windows without their record) gets what one masked copy of the whole set gets."""
    from quadfdi.formats.dataset import Windows
    from quadfdi.train import masks

    names = channel_names(profile, [])
    n = masks.PATTERN_CHUNK * 2 + 37  # two full chunks and a short one
    rng = np.random.default_rng(3)
    w = Windows(x=rng.normal(size=(n, 6, len(names))).astype(np.float32), y=rng.integers(0, 3, n),
                traj=np.arange(n), start=np.zeros(n, np.int64), t_end=np.zeros(n))
    weights = rng.normal(size=(len(names), 3))
    calls = []

    def predict(x):  # a class score from every value of every channel: a masked value shows
        calls.append(len(x))
        return x.astype(np.float64).sum(axis=1) @ weights

    got = masks.pattern_scores(predict, w, profile, names, 3)
    masker = masks.Masker(profile, names)
    from sklearn.metrics import f1_score
    for k, pat in enumerate(MASK_PATTERNS):
        pred = predict(masker.apply(w.x.copy(), np.full(n, k))).argmax(axis=1)
        assert got[pat.name] == {"macro_f1": round(float(f1_score(w.y, pred, labels=[0, 1, 2], average="macro",
                                                                  zero_division=0)), 6), "windows": n}
    assert ("no_reference" in got) == masker.reference
    if masker.reference:
        pred = predict(masker.drop_reference(w.x.copy(), np.arange(n))).argmax(axis=1)
        assert got["no_reference"]["macro_f1"] == round(float(f1_score(w.y, pred, labels=[0, 1, 2], average="macro",
                                                                        zero_division=0)), 6)
    assert calls[:3] == [masks.PATTERN_CHUNK, masks.PATTERN_CHUNK, 37]
