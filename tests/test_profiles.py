"""core/profiles.py (channel profiles), the [train] profile key and models/inputs.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from quadfdi.core import hover
from quadfdi.core.config import load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.profiles import apply_profile, channel_names, required_raw, uses_hover
from quadfdi.formats.dataset import Dataset
from quadfdi.models.inputs import decided, profile_of, profiled_dataset

RAW = ["x", "y", "z", "vx", "vy", "vz", "roll", "pitch", "yaw", "p", "q", "r", "V_b", "I_b", "SoC",
       "T1", "T2", "T3", "T4", "thr1", "thr2", "thr3", "thr4", "vib_px4", "vib_ap"]


def test_paper_is_the_default_and_the_identity():
    cfg = load_config(None)
    assert cfg.train.profile == "paper" and not uses_hover("paper")
    assert channel_names("paper", RAW) == RAW and required_raw("paper", RAW) == RAW
    assert profile_of({}) == "paper"  # a checkpoint or manifest from before profiles
    assert profile_of({"profile": "flightlog-min"}) == "flightlog-min"  # a checkpoint
    assert profile_of({"profile": {"name": "flightlog-nocur", "channels": []}}) == "flightlog-nocur"  # a manifest


def test_profile_key_is_checked_and_overrides_still_parse():
    assert load_config(None, ["train.profile=flightlog-min", "train.epochs=3"]).train.profile == "flightlog-min"
    with pytest.raises(QuadfdiError, match="unknown channel profile 'nope'"):
        load_config(None, ["train.profile=nope"])
    with pytest.raises(QuadfdiError, match="--set expects"):
        load_config(None, ["trainprofile"])


def test_flightlog_min_reads_no_heading_no_temperature_no_soc():
    req = required_raw("flightlog-min", RAW)
    assert not {"x", "y", "z", "SoC", "T1", "vib_ap"} & set(req)
    assert "I_b" not in required_raw("flightlog-nocur", RAW)
    assert "i_rel" not in channel_names("flightlog-nocur", []) and len(channel_names("flightlog-min", [])) == 15


def _raw(t=100, yaw=0.0):
    speed_fwd, speed_left = 2.0, -0.5  # heading frame
    raw = {k: np.zeros(t, np.float32) for k in RAW}
    raw["yaw"][:] = yaw
    raw["vx"][:] = np.cos(yaw) * speed_fwd - np.sin(yaw) * speed_left
    raw["vy"][:] = np.sin(yaw) * speed_fwd + np.cos(yaw) * speed_left
    raw["V_b"][:] = 22.2
    raw["I_b"][:] = 18.0
    for k, c in enumerate((0.60, 0.50, 0.50, 0.40)):
        raw[f"thr{k + 1}"][:] = c
    return raw


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5, 3.1])
def test_flightlog_min_values_do_not_depend_on_heading_or_vehicle(yaw):
    x = apply_profile("flightlog-min", _raw(yaw=yaw), cells=6, hover_cmd=0.5, hover_cur=12.0)
    names = channel_names("flightlog-min", [])
    col = {n: x[:, names.index(n)] for n in names}
    np.testing.assert_allclose(col["vx_h"], 2.0, atol=1e-5)
    np.testing.assert_allclose(col["vy_h"], -0.5, atol=1e-5)
    np.testing.assert_allclose(col["v_cell"], 3.7, rtol=1e-6)
    np.testing.assert_allclose(col["i_rel"], 1.5, rtol=1e-6)
    # one collective scalar: the motor running 0.1 above the others stays visible
    np.testing.assert_allclose([col[f"m{k}_rel"][0] for k in range(1, 5)], [1.2, 1.0, 1.0, 0.8], rtol=1e-6)


def _dataset(tmp_path: Path) -> Dataset:
    cfg = load_config(None, ["sim.window=20", "sim.stride=10"])
    f, t = 3, 160
    tel = np.zeros((f, t, len(RAW)), np.float32)
    for i in range(f):
        r = _raw(t, yaw=0.3 * i)
        tel[i] = np.stack([r[k] for k in RAW], axis=1)
    tel[2, :70, RAW.index("vz")] = 1.0  # flight 2 climbs first: its estimate freezes at 70 + 49
    arrays = {"telemetry": tel, "channel_names": np.array(RAW), "channel_units": np.array(["u"] * len(RAW)),
              "pack_cells": np.array([3, 4, 6], np.int8)}
    return Dataset(tmp_path / "d.npz", arrays, cfg)


def test_profiled_dataset_and_decided_windows(tmp_path):
    ds = _dataset(tmp_path)
    assert profiled_dataset(ds, "paper") is ds
    pd = profiled_dataset(ds, "flightlog-min")
    assert pd.channel_names == channel_names("flightlog-min", []) and pd["telemetry"].shape == (3, 160, 15)
    assert list(pd["hover_freeze"]) == [hover.STEADY_SAMPLES - 1] * 2 + [70 + hover.STEADY_SAMPLES - 1]
    np.testing.assert_allclose(pd["telemetry"][:, 100, pd.channel_names.index("v_cell")], [7.4, 5.55, 3.7], rtol=1e-6)
    ok = decided(pd, np.array([0, 0, 2, 2]), np.array([0, 30, 90, 100]))
    assert list(ok) == [False, True, False, True]  # window end 19 < 49, 49 >= 49, 109 < 119, 119 >= 119


def test_a_dataset_without_the_raw_channels_is_refused(tmp_path):
    ds = _dataset(tmp_path)
    arrays = dict(ds.arrays, channel_names=np.array([n if n != "vib_px4" else "vib" for n in RAW]))
    with pytest.raises(QuadfdiError, match="needs raw channels vib_px4"):
        profiled_dataset(Dataset(ds.path, arrays, ds.config), "flightlog-min")


def test_a_flight_that_never_hovers_has_no_decided_window(tmp_path):
    ds = _dataset(tmp_path)
    ds.arrays["telemetry"][1, :, RAW.index("vz")] = 1.0  # flight 1 climbs throughout
    pd = profiled_dataset(ds, "flightlog-min")
    assert pd["hover_freeze"][1] == 160 and np.isfinite(pd["telemetry"][1]).all()
    assert not decided(pd, np.array([1]), np.array([140])).any()
