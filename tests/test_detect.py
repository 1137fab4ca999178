"""quadfdi detect: a flightlog-min model with the motor head (tiny realistic run, trained and
exported through the CLI) on real PX4 flights with both runtimes, and the refusals (one line, exit
2, nothing written); the same export through `quadfdi parity` (the motor head's extra output). The
real flight is the UAVCAN mission (PX4 1.9): its vibration metric converts to the profile's m/s^2
(docs/ingest.md "Vibration"), so the profile can use it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SHARED_DATA, quadfdi
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

REAL = SHARED_DATA / "flightlogs"
MISSION = REAL / "px4_quad_6s_uavcan_mission.ulg"

pytestmark = pytest.mark.skipif(not MISSION.is_file(), reason="the shared real flight logs are not here")


@pytest.fixture(scope="module")
def export(flightlog_export) -> Path:
    return flightlog_export  # tests/conftest.py: shared with tests/test_stream.py



def test_manifest_carries_the_profile_and_the_policy(export):
    import torch

    m = json.loads((export / "manifest.json").read_text())
    assert m["profile"]["name"] == "flightlog-min" and len(m["profile"]["channels"]) == 15 == m["n_channels"]
    assert [c["name"] for c in m["channels"]] == [c["name"] for c in m["profile"]["channels"]]
    assert m["profile"]["hover"]["steady_samples"] == 50 and m["profile"]["vibration"] == "px4"
    assert set(m["alarm"]) == {"threshold", "k", "n", "clear_m", "latch"}
    blob = torch.load(export.parent / "cnode.pt", weights_only=True)
    assert blob["profile"] == "flightlog-min"


def test_mission_vibration_reaches_detect_in_m_s2(mission_npz):
    """The PX4 1.9 mission's vibration is ECL's delta-velocity metric: flight.npz carries it divided
    by the logged IMU interval (the profile's m/s^2), with the conversion in `vehicle` (docs/ingest.md)."""
    z = np.load(mission_npz)
    vib = json.loads(str(z["vehicle"]))["vibration"]
    assert vib["source"] == "estimator_status.vibe[2]" and vib["integration_interval_s"] == pytest.approx(0.004)
    j = [str(n) for n in z["channel_names"]].index("vib_px4")
    assert "accelerometer_integral_dt" in str(z["channel_sources"][j]) and str(z["channel_status"][j]) == "ok"
    assert 5 < np.nanmedian(z["telemetry"][:, j]) < 40  # m/s^2 (0.06 before: m/s read as m/s^2)


def _detect(export, flight, out, *extra):
    return quadfdi("detect", "--model", str(export), str(flight), "--out", str(out), *extra)


def test_detect_writes_alarms_windows_and_figure(export, mission_npz, tmp_path):
    res = _detect(export, MISSION, tmp_path / "log")  # the .ulg, ingested on the fly
    assert res.returncode == 0, res.stderr
    rec = json.loads((tmp_path / "log" / "alarms.json").read_text())
    # no evaluation behind this export: the CNODE, and why
    assert "detect: --net cnode: the export records no validation scores to choose by (no evaluation" in res.stdout
    assert rec["net"] == "cnode"
    assert rec["profile"] == "flightlog-min" and rec["hover"]["cells"] == 6 and 0.2 < rec["hover"]["cmd"] < 0.9
    assert 0 < rec["decided_windows"] <= rec["windows"] and 0 < rec["exposure_s"] <= rec["airborne_s"] + 1.6
    for a in rec["alarms"]:
        assert a["class"] != "Healthy" and 0 < a["peak_p_fault"] <= 1 and a["start_s"] >= rec["hover"]["freeze_s"]
    w = np.load(tmp_path / "log" / "windows.npz")
    assert np.isnan(w["proba"][~w["decided"]]).all() and np.allclose(w["proba"][w["decided"]].sum(axis=1), 1, atol=1e-5)
    assert not w["votes"][~w["decided"]].any()
    pol, r = rec["policy"], rec["alarm_reach"]  # the most decided windows among any n consecutive ones
    most = max(int(w["decided"][max(0, i + 1 - pol["n"]):i + 1].sum()) for i in range(len(w["decided"])))
    assert (r["most_votes"], r["possible"], r["k"], r["n"]) == (most, most >= pol["k"], pol["k"], pol["n"])
    assert r["possible"] or not rec["alarms"]
    # the motor head: probabilities on decided windows, a motor 1..4 only on rotor-side windows
    assert np.isnan(w["motor_proba"][~w["decided"]]).all() and np.allclose(w["motor_proba"][w["decided"]].sum(1), 1, atol=1e-5)
    names = [str(c) for c in w["class_names"]]
    fault = np.where(w["decided"][:, None], np.nan_to_num(w["proba"]), 0.0)
    fault[:, names.index("Healthy")] = -1.0
    rotor = np.isin(np.array(names)[fault.argmax(1)], ["MotorFault", "OverheatFault", "PropellerFault"]) & w["decided"]
    assert ((w["motor"] > 0) == rotor).all() and set(np.unique(w["motor"])) <= {0, 1, 2, 3, 4}
    assert (w["motor"][rotor] == w["motor_proba"][rotor].argmax(1) + 1).all()
    for a in rec["alarms"]:
        rotor_alarm = a["class"] in ("MotorFault", "OverheatFault", "PropellerFault")
        assert (a["motor"] in (1, 2, 3, 4)) if rotor_alarm else a["motor"] is None
    assert (tmp_path / "log" / "detect.png").stat().st_size > 10_000
    res = _detect(export, mission_npz, tmp_path / "npz")  # the same flight, already ingested
    assert res.returncode == 0, res.stderr
    assert json.loads((tmp_path / "npz" / "alarms.json").read_text())["alarms"] == rec["alarms"]


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_cpp_runtime_gives_the_ort_alarms(export, mission_npz, tmp_path, host_build, precision):  # noqa: F811
    out = {}
    for rt in ("ort", "cpp"):
        res = _detect(export, mission_npz, tmp_path / rt, "--precision", precision, "--runtime", rt, "--net", "gru")
        assert res.returncode == 0, res.stderr
        out[rt] = np.load(tmp_path / rt / "windows.npz")
    d = out["ort"]["decided"]
    # fp32: the export's parity tolerance; int8: the C++ integer kernels match ORT's to the logit
    np.testing.assert_allclose(out["cpp"]["proba"][d], out["ort"]["proba"][d], atol=1e-4)
    np.testing.assert_allclose(out["cpp"]["motor_proba"][d], out["ort"]["motor_proba"][d], atol=1e-4)
    assert (out["cpp"]["motor"] == out["ort"]["motor"]).all()
    assert (out["cpp"]["votes"] == out["ort"]["votes"]).all() and (out["cpp"]["active"] == out["ort"]["active"]).all()


@pytest.mark.parametrize("log,why", [
    ("px4_quad_battery_monitor_disconnected.ulg", "needs channel 'V_b', which is unusable"),
    ("px4_fmuv5_quad_real_short.ulg", "too short: 0.4 s airborne"),
    ("px4_quad_6s_gps_interference.ulg", "needs channel 'I_b', which is unusable"),
    ("ardupilot_plane_1s.BIN", "not a multirotor"),
    ("px4_cubeorange_vtol_real.ulg", "not a multirotor"),
])
def test_refusals_are_one_line_exit_2_and_write_nothing(export, tmp_path, log, why):
    if not (REAL / log).is_file():
        pytest.skip(f"{log} is not here")
    res = _detect(export, REAL / log, tmp_path / "out")
    assert res.returncode == 2 and why in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert not (tmp_path / "out").exists()


def test_parity_checks_the_motor_head(export, host_build):  # noqa: F811
    """The export's manifest lists the extra output; `quadfdi parity` checks it: C++ fp32 against ORT
    within the class logits' bound, C++ int8 against ORT int8 bit-identical."""
    m = json.loads((export / "manifest.json").read_text())
    assert m["motor_head"]["models"] == ["cnode", "gru"] and m["models"]["gru"]["n_motors"] == 4
    assert [o["name"] for o in m["io"]["outputs"]] == ["logits", "proba", "motor_logits"]
    assert m["verification"]["cnode_motor_fp32_vs_pytorch"]["passed"]
    from quadfdi.formats.weights_bin import read_weights

    wf = read_weights(export / "weights.bin")
    assert [(s.model, s.precision) for s in wf.sections][4:8] == [  # then the on-board record
        ("cnode_motor", "fp32"), ("cnode_motor", "int8"), ("gru_motor", "fp32"), ("gru_motor", "int8")]
    res = quadfdi("parity", "--run", str(export.parent), "--no-mcu")
    assert res.returncode == 0, res.stderr
    p = json.loads((export.parent / "parity" / "parity.json").read_text())
    for net in ("cnode", "gru"):
        pairs = p["models"][f"{net}_motor"]
        assert pairs["cpp_fp32_vs_ort_fp32"]["target"]["passed"]
        i8 = pairs["cpp_int8_vs_ort_int8"]
        assert i8["target"]["passed"] and i8["bitwise_identical_windows"] == i8["windows"] > 0
