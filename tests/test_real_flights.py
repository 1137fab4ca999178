"""`quadfdi real-flights`: the whole command on tiny settings (one profile, the UAVCAN mission and a
log that ingest refuses), its refusals (one line, exit 2, nothing written) and its table."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from quadfdi.cli import main
from quadfdi.real_flights_table import table
from tests.conftest import ROOT, quadfdi

LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
if not LOGS.is_dir():
    LOGS = Path("/work/shared/data/flightlogs")
MISSION, GROUND = "px4_quad_6s_uavcan_mission.ulg", "ardupilot_copter_quadx_ground.BIN"
TINY = ["sim.n_traj=20", "sim.ood_traj=2", "sim.duration_s=12.0", "sim.chunk=14", "sim.window=40", "train.epochs=1",
        "train.latent=8", "train.hidden=16", "train.gru_hidden=16", "train.max_train_windows=60",
        "train.motor_head=auto"]


@pytest.mark.slow
@pytest.mark.skipif(not (LOGS / MISSION).is_file(), reason="the shared real flight logs are not here")
def test_real_flights_on_tiny_settings(tmp_path):
    """sim, train, apply, evaluate, export and parity for flightlog-min, then detect on the mission
    (8 cases, and again with the gap bridged) and on a ground log that ingest refuses."""
    out = tmp_path / "rf"
    res = quadfdi("real-flights", str(out), "--profiles", "min", "--logs", str(LOGS), "--flights",
                  f"{MISSION},{GROUND}", "--workers", "1", *[a for v in TINY for a in ("--set", v)])
    assert res.returncode == 0, res.stderr[-3000:]
    md = (out / "real_flights.md").read_text()
    assert md.startswith("# Real flights\n") and md.endswith("|\n") and md in res.stdout
    r = json.loads((out / "real_flights.json").read_text())
    assert r["exports"] == {"min": str(out / "min" / "export")} and (out / "min" / "parity" / "parity.json").is_file()
    mission = [c for c in r["flights"] if c["flight"] == MISSION.split(".")[0]]
    assert len(mission) == 8 and all("record" in c for c in mission)
    for c in mission:
        alarms = json.loads((out / "flights" / "min" / c["flight"] / c["net"] / c["runtime"] / c["precision"]
                             / "alarms.json").read_text())
        assert alarms == c["record"] and alarms["net"] == c["net"] and alarms["runtime"] == c["runtime"]
    ground = [c for c in r["flights"] if c["flight"] == GROUND.split(".")[0]]
    assert len(ground) == 8 and all(c["refused"].startswith("ingest: ") for c in ground)
    assert not (out / "flights" / "ingest" / GROUND.split(".")[0] / "flight.npz").exists()
    assert f"- flightlog-min {GROUND.split('.')[0]}: ingest: " in md and "never airborne" in md
    for net in ("cnode", "gru"):  # one row per network, C++ as ONNX Runtime in both precisions
        head = f"| flightlog-min | {net} | {MISSION.split('.')[0]} |"
        row = next(ln for ln in md.splitlines() if ln.startswith(head))
        assert row.split(" | ")[8] == "yes"
    gap7 = r["flights_gap7"]
    assert len(gap7) == 8 and {c["flight"] for c in gap7} == {MISSION.split(".")[0]}
    assert "--gap-factor 7" in md and md.count(f"| flightlog-min | cnode | {MISSION.split('.')[0]} |") == 2
    assert gap7[0]["record"]["decided_windows"] >= mission[0]["record"]["decided_windows"]  # gaps bridged


@pytest.mark.parametrize("argv,message", [
    (["--profiles", "min,huge"], "--profiles takes comma-separated names of min, esc, nocur"),
    (["--logs", "/nonexistent/flightlogs"], "--logs /nonexistent/flightlogs: no such folder"),
    (["--logs", str(LOGS), "--flights", "nope.ulg"], "no log nope.ulg"),
])
def test_refusals_are_one_line_and_write_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "rf"
    assert main(["real-flights", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and err[0].startswith("quadfdi real-flights: error: ")
    assert not out.exists()


def test_without_logs_and_no_checkout_beside_it_says_so(tmp_path, capsys, monkeypatch):
    """From an installed package there is no ../shared/data/flightlogs: --logs must name the folder."""
    from quadfdi import real_flights

    monkeypatch.setattr(real_flights, "default_logs", lambda: tmp_path / "site-packages" / "shared")
    assert main(["real-flights", str(tmp_path / "rf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "give --logs DIR" in err[0] and str(tmp_path / "site-packages") in err[0]
    assert not (tmp_path / "rf").exists()


def _case(net: str, rt: str, pr: str, alarms: list[dict] | None, why: str = "") -> dict:
    c = {"profile": "flightlog-min", "flight": "f1", "net": net, "runtime": rt, "precision": pr}
    if alarms is None:
        c["refused"] = why
    else:
        c["record"] = {"alarms": alarms, "airborne_s": 30.0, "hover": {"freeze_s": 8.0}, "decided_windows": 5,
                       "windows": 9, "exposure_s": 12.5}
    return c


def test_table_rows_and_refusals():
    """C++ differing from ONNX Runtime is NO; int8 differing from fp32 shows int8's alarms; a network
    whose ONNX Runtime fp32 case was refused has no row, and the refusal is listed once."""
    alarm = {"class": "MotorFault", "motor": 2, "start_s": 3.2, "end_s": None, "peak_p_fault": 0.914}
    other = dict(alarm, start_s=4.0)
    cases = [_case("cnode", "ort", "fp32", [alarm]), _case("cnode", "ort", "int8", [other]),
             _case("cnode", "cpp", "fp32", [alarm]), _case("cnode", "cpp", "int8", []),
             *[_case("gru", rt, pr, None, "too short: 2 decided windows") for rt in ("ort", "cpp")
               for pr in ("fp32", "int8")]]
    text = table(cases)
    rows = [ln for ln in text.splitlines() if ln.startswith("| flightlog-min")]
    assert rows == ["| flightlog-min | cnode | f1 | 30.0 | 8.0 | 5/9 | 12.5 | MotorFault m2 3.2-end (peak 0.91) | NO | "
                    "int8: MotorFault m2 4.0-end (peak 0.91) |"]
    assert text.splitlines()[-1] == "- flightlog-min f1: too short: 2 decided windows"
