"""flightlog-esc (core/profiles.py): its values, the dataset path through the realistic suite's
``esc_telemetry`` key (models/inputs.py), the inputs of the other profiles unchanged by that key,
and its C++ mirror (firmware_ref/include/fwref/profile.hpp) bit for bit."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from quadfdi.core.config import load_config
from quadfdi.core.channels import ESC_RAW
from quadfdi.core.profiles import apply_profile, channel_names, required_raw
from quadfdi.formats.dataset import Dataset
from tests.conftest import ROOT
from quadfdi.models.inputs import profiled_dataset

RAW = ["x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "V_b", "I_b", "SoC",
       "T1", "T2", "T3", "T4", "thr1", "thr2", "thr3", "thr4", "vib_px4", "vib_ap"]
STREAM = required_raw("flightlog-esc") + ["airborne"]  # the stream's raw order (export/onboard_record)


def _raw(t: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    raw = {k: rng.normal(0.0, 1.0, t).astype(np.float32) for k in RAW}
    raw["yaw"] = rng.uniform(-np.pi, np.pi, t).astype(np.float32)
    raw["V_b"] = rng.uniform(10.0, 25.0, t).astype(np.float32)
    raw["I_b"] = rng.uniform(2.0, 40.0, t).astype(np.float32)
    for k in range(1, 5):
        raw[f"thr{k}"] = rng.uniform(0.2, 0.9, t).astype(np.float32)
        raw[f"rpm{k}"] = np.round(rng.uniform(3000.0, 12000.0, t) / (100 / 7)).astype(np.float32) * np.float32(100 / 7)
        raw[f"esc_cur{k}"] = rng.uniform(-0.1, 12.0, t).astype(np.float32)
        raw[f"esc_temp{k}"] = np.round(rng.uniform(-10.0, 90.0, t)).astype(np.float32)  # whole degC, as reported
    raw["esc_temp2"][::3] += np.float32(0.25)  # UAVCAN's float16 kelvin steps too
    return raw


def test_flightlog_esc_is_flightlog_min_plus_rpm_shares_esc_currents_and_temperatures():
    names = channel_names("flightlog-esc", [])
    assert names[:15] == channel_names("flightlog-min", []) and len(names) == 27
    assert set(ESC_RAW) <= set(required_raw("flightlog-esc")) and not {"T1", "SoC", "x"} & set(required_raw("flightlog-esc"))
    raw = _raw(50)
    raw["rpm1"][:], raw["rpm2"][:], raw["rpm3"][:], raw["rpm4"][:] = 6000.0, 5000.0, 5000.0, 4000.0
    raw["esc_cur1"][:], raw["esc_cur2"][:], raw["esc_cur3"][:], raw["esc_cur4"][:] = 3.0, 3.0, 6.0, 4.0
    raw["esc_temp1"][:], raw["esc_temp2"][:], raw["esc_temp3"][:], raw["esc_temp4"][:] = 30.0, 31.0, 35.0, 28.0
    x = apply_profile("flightlog-esc", raw, cells=4, hover_cmd=0.5, hover_cur=12.0)
    col = {n: x[:, names.index(n)] for n in names}
    np.testing.assert_array_equal(x[:, :15], apply_profile("flightlog-min", raw, 4, 0.5, 12.0))
    np.testing.assert_allclose([col[f"rpm{k}_rel"][0] for k in range(1, 5)], [1.2, 1.0, 1.0, 0.8], rtol=1e-6)
    np.testing.assert_allclose([col[f"esc{k}_i_rel"][0] for k in range(1, 5)], [0.75, 0.75, 1.5, 1.0], rtol=1e-6)
    np.testing.assert_array_equal([col[f"esc{k}_t_rel"][0] for k in range(1, 5)], [-1.0, 0.0, 4.0, -3.0])
    # no battery-monitor scale: the ESC shares do not move with the hover current
    np.testing.assert_array_equal(x[:, 19:], apply_profile("flightlog-esc", raw, 4, 0.5, 30.0)[:, 19:])
    # no ambient: the same ESCs 25 K warmer (a hot day, a long flight's common heating) read the same
    warm = {**raw, **{f"esc_temp{k}": raw[f"esc_temp{k}"] + np.float32(25.0) for k in range(1, 5)}}
    np.testing.assert_array_equal(x, apply_profile("flightlog-esc", warm, 4, 0.5, 12.0))
    raw["rpm1"][0] = raw["rpm2"][0] = raw["rpm3"][0] = raw["rpm4"][0] = 0.0  # motors stopped: undefined, not 0
    assert not np.isfinite(apply_profile("flightlog-esc", raw, 4, 0.5, 12.0)[0, 15:19]).any()


def _dataset(tmp_path, with_esc: bool) -> Dataset:
    cfg = load_config(None, ["sim.window=20", "sim.stride=10"])
    f, t = 2, 120
    raws = [_raw(t, seed=i) for i in range(f)]
    for r in raws:  # hover-like so that the estimate freezes
        for k in ("vz", "roll", "pitch"):
            r[k][:] = 0.01
    arrays = {"telemetry": np.stack([np.stack([r[k] for k in RAW], 1) for r in raws]),
              "channel_names": np.array(RAW), "channel_units": np.array(["u"] * len(RAW)),
              "pack_cells": np.array([3, 6], np.int8), "time": np.arange(t) * 0.04}
    if with_esc:
        arrays.update(esc_telemetry=np.stack([np.stack([r[k] for k in ESC_RAW], 1) for r in raws]),
                      esc_channel_names=np.array(ESC_RAW), esc_channel_units=np.array(["rpm"] * 4 + ["A"] * 4 + ["degC"] * 4))
    return Dataset(tmp_path / "d.npz", arrays, cfg)


def test_the_esc_key_changes_no_other_profiles_inputs(tmp_path):
    """The ESC channels are a key of their own: the paper profile's telemetry and flightlog-min's
    inputs are the same with or without it; flightlog-esc reads them from it."""
    plain, esc = _dataset(tmp_path, False), _dataset(tmp_path, True)
    assert profiled_dataset(esc, "paper")["telemetry"] is esc["telemetry"]
    np.testing.assert_array_equal(esc["telemetry"], plain["telemetry"])
    for key in ("telemetry", "hover_cmd", "hover_cur", "hover_freeze"):
        np.testing.assert_array_equal(profiled_dataset(esc, "flightlog-min")[key], profiled_dataset(plain, "flightlog-min")[key])
    pe = profiled_dataset(esc, "flightlog-esc")
    assert pe.channel_names == channel_names("flightlog-esc", []) and pe["telemetry"].shape == (2, 120, 27)
    np.testing.assert_array_equal(pe["telemetry"][..., :15], profiled_dataset(plain, "flightlog-min")["telemetry"])
    with pytest.raises(Exception, match="needs raw channels rpm1"):
        profiled_dataset(plain, "flightlog-esc")


MIRROR = r"""
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "fwref/profile.hpp"
int main(int argc, char** argv) {  // in: n x 29 raw float32; cells hover_cmd hover_cur as argv; out: n x 27
  const float cells = std::strtof(argv[3], nullptr), cmd = std::strtof(argv[4], nullptr), cur = std::strtof(argv[5], nullptr);
  const fwref::ProfileSpec& s = fwref::profile_spec(fwref::Profile::kFlightlogEsc);
  FILE* f = std::fopen(argv[1], "rb");
  FILE* o = std::fopen(argv[2], "wb");
  std::vector<float> raw(s.raw), x(s.channels);
  while (std::fread(raw.data(), 4, s.raw, f) == static_cast<size_t>(s.raw)) {
    fwref::profile_prep(fwref::Profile::kFlightlogEsc, raw.data(), s.raw, cells, x.data());
    fwref::profile_hover(fwref::Profile::kFlightlogEsc, cmd, cur, x.data());
    std::fwrite(x.data(), 4, s.channels, o);
  }
  std::fclose(f);
  std::fclose(o);
  return 0;
}
"""


@pytest.mark.skipif(shutil.which("c++") is None, reason="no C++ compiler")
def test_cpp_mirror_is_bit_identical(tmp_path):
    """profile.hpp's prep + hover steps on 4000 random samples (every yaw, zero-rpm and zero-current rows,
    whole-degree and quarter-kelvin ESC temperatures from -10 to 90 degC) give
    apply_profile's float32 bits, NaN where Python has NaN."""
    src, exe = tmp_path / "m.cpp", tmp_path / "m"
    src.write_text(MIRROR)
    subprocess.run(["c++", "-std=c++17", "-O2", "-ffp-contract=off", "-fno-fast-math", f"-I{ROOT / 'firmware_ref/include'}",
                    str(src), "-o", str(exe)], check=True)
    raw = _raw(4000, seed=7)
    for k in range(1, 5):
        raw[f"rpm{k}"][:20] = 0.0
        raw[f"esc_cur{k}"][10:30] = 0.0
    raw["airborne"] = np.ones(4000, np.float32)
    cells, cmd, cur = 6, np.float32(0.4637), np.float32(17.31)
    np.stack([raw[k] for k in STREAM], 1).astype("<f4").tofile(tmp_path / "raw.f32")
    subprocess.run([str(exe), str(tmp_path / "raw.f32"), str(tmp_path / "x.f32"), str(cells), repr(float(cmd)),
                    repr(float(cur))], check=True)
    got = np.fromfile(tmp_path / "x.f32", "<f4").reshape(4000, 27)
    want = apply_profile("flightlog-esc", raw, cells, cmd, cur)
    assert np.isnan(want[:20, 15:19]).all() and np.isnan(want[10:30, 19:23]).all() and np.isfinite(want[:, 23:]).all()
    np.testing.assert_array_equal(got.view(np.uint32)[np.isfinite(want)], want.view(np.uint32)[np.isfinite(want)])
    assert (np.isfinite(got) == np.isfinite(want)).all()


def test_detect_inputs_read_esc_channels_and_refuse_a_flight_without(tmp_path):
    """A simulated flight as flight.npz (sim.flight_npz): with ESC telemetry detect's inputs equal the
    training path's; without it, the one-line refusal naming the channel."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.detect.inputs import flight_inputs
    from quadfdi.sim.flight_npz import flight_arrays

    esc = _dataset(tmp_path, True)
    fi = flight_inputs(flight_arrays(esc.arrays, 1, "d.npz"), "flightlog-esc", 20, 10)
    pe = profiled_dataset(esc, "flightlog-esc")
    assert fi.hover.freeze == pe["hover_freeze"][1] and list(fi.decided) == list(fi.starts + 19 >= fi.hover.freeze)
    np.testing.assert_array_equal(fi.x, pe["telemetry"][1])
    with pytest.raises(QuadfdiError, match="needs channel 'rpm1', which is absent: not simulated"):
        flight_inputs(flight_arrays(_dataset(tmp_path, False).arrays, 1, "d.npz"), "flightlog-esc", 20, 10)


def test_detect_refuses_a_flight_whose_escs_report_no_temperature(tmp_path):
    """rpm and current but no temperature (ingest: "absent: ESC reports no temperature (always 0)"):
    flightlog-esc refuses it in one line naming the channel."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.detect.inputs import flight_inputs
    from quadfdi.sim.flight_npz import flight_arrays

    arrays = flight_arrays(_dataset(tmp_path, True).arrays, 1, "d.npz")
    names = list(arrays["channel_names"])
    status = arrays["channel_status"].astype(object)
    for k in range(1, 5):
        j = names.index(f"esc_temp{k}")
        status[j] = "absent: ESC reports no temperature (always 0)"
        arrays["mask"][:, j], arrays["telemetry"][:, j] = False, np.nan
    arrays["channel_status"] = np.array(list(status))
    with pytest.raises(QuadfdiError, match="needs channel 'esc_temp1', which is absent: ESC reports no temperature"):
        flight_inputs(arrays, "flightlog-esc", 20, 10)
