"""`quadfdi crazypad` on a handful of the real CrazyPAD logs with the suite's tiny masked export: the network
and policy chosen from the run's validation figures, the protocol groups, the reference flights (and a
copy of one under another name) in no test group, alarms' motors traced to the log's M1-M4, the PX4
split, and bad input refused in one line with nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.resample import GRID_DT
from quadfdi.crazypad_decide import log_motor_names, network_result
from quadfdi.crazypad_px4 import REFERENCE_FRACTION, split
from quadfdi.formats.flight import load_flight
from quadfdi.formats.vehicle import load_vehicle
from quadfdi.vehicle.flights import Flight, read_flight
from quadfdi.vehicle.learn import MIN_AIRBORNE_S, learn
from tests.conftest import SHARED_DATA, quadfdi

PAD = SHARED_DATA / "crazypad" / "motor_data"
LOGS = SHARED_DATA / "flightlogs"
REFERENCE = ("E8_log00", "E8_log01", "E9_log00", "E9_log01")
# (folder, log) -> the protocol group it must land in
TESTS = {("normal_flight", "E8_log02"): "healthy test", ("normal_flight", "E9_log02"): "healthy test",
         ("cut_propeller_M3_3.5mm_3.5mm_40mm", "E8_log00"): "M3 cut >= 3 mm",
         ("cut_propeller_M3_2mm", "E8_log00"): "M3 cut 2-2.5 mm",
         ("cut_propeller_M3_1mm", "E9_log03"): "M3 cut < 2 mm",
         ("cut_M2_3.5mm_3.5mm_40mm_M1_3.5mm_3.5mm_40mm", "E9_log03"): "two cuts (M1, M2)",
         ("tape_on_propeller_M3", "E9_log00"): "debris"}
pytestmark = pytest.mark.skipif(not (PAD.is_dir() and LOGS.is_dir()),
                                reason=f"the shared logs are not at {SHARED_DATA}")


def _pad(root: Path, drop: str | None = None) -> Path:
    """A CrazyPAD folder of a few logs: the four reference flights (less ``drop``), the TESTS logs and a copy
    of normal_flight/E8_log00 under another name (the same bytes: still a reference flight)."""
    for folder, name in [("normal_flight", n) for n in REFERENCE if n != drop] + list(TESTS):
        (root / folder).mkdir(parents=True, exist_ok=True)
        shutil.copyfile(PAD / folder / name, root / folder / name)
    shutil.copyfile(PAD / "normal_flight" / "E8_log00", root / "normal_flight" / "E8_log07")
    return root


def _logs(root: Path) -> Path:
    root.mkdir(parents=True)
    for name in ("px4_quad_6s_gps_interference.ulg", "px4_fmuv5_quad_real_short.ulg", "px4_quad_6s_uavcan_mission.ulg"):
        shutil.copyfile(LOGS / name, root / name)
    return root


@pytest.fixture(scope="module")
def scored(masked_export, tmp_path_factory):
    d = tmp_path_factory.mktemp("crazypad")
    res = quadfdi("crazypad", str(d / "out"), "--run", str(masked_export.parent), "--crazypad", str(_pad(d / "pad")),
                  "--logs", str(_logs(d / "logs")), "--workers", "2")
    assert res.returncode == 0, res.stderr
    return masked_export.parent, d / "out", json.loads((d / "out" / "crazypad.json").read_text())


def test_the_network_and_policy_come_from_validation(scored):
    run, _, result = scored
    hist = json.loads((run / "history.json").read_text())
    best = {n: max(hist[n]["val_macro_f1"]) for n in ("cnode", "gru")}
    ch = result["choice"]
    assert ch["chosen_by"]["val_macro_f1"] == pytest.approx(best)
    assert ch["net"] == max(best, key=lambda n: (best[n], n == "cnode"))
    manifest = json.loads((run / "export" / "manifest.json").read_text())
    assert ch["policy"] == manifest["alarm_per_model"][ch["net"]]["policy"]
    assert ch["policy_source"] == "config" and ch["policy_chosen_on_validation"] is False  # said so, not hidden


def test_the_network_comes_from_evaluates_validation_scores_when_the_export_records_them(masked_export, tmp_path):
    """An export made after `quadfdi evaluate` records each network's pooled validation macro F1: crazypad
    scores the network `quadfdi detect` would run, whatever training's own figure says."""
    from quadfdi.crazypad_choice import scored_network

    run = tmp_path / "run"
    shutil.copytree(masked_export.parent, run)
    hist = json.loads((run / "history.json").read_text())
    loser = min(("cnode", "gru"), key=lambda n: (max(hist[n]["val_macro_f1"]), n == "cnode"))
    scores = {n: 0.6 if n == loser else 0.5 for n in ("cnode", "gru")}  # the reverse of training's ranking
    path = run / "export" / "manifest.json"
    m = json.loads(path.read_text())
    m["deployment"] = {"evaluation_sha256": "0" * 64, "families": {
        n: {"chosen": n, "candidates": {n: {"macro_f1": {"value": v}, "flights": 10}}} for n, v in scores.items()}}
    path.write_text(json.dumps(m))
    ch = scored_network(run)
    assert ch["net"] == loser and ch["chosen_by"]["val_macro_f1"] == scores
    assert ch["chosen_by"]["file"] == str(path)


def test_groups_and_the_reference_flights_in_none(scored):
    _, out, result = scored
    ref = load_vehicle(out / "vehicle.json")
    assert [f["file"] for f in ref["flights"]] == [f"normal_flight/{n}" for n in REFERENCE]
    rows = result["decided"]["rows"]
    assert result["decided"]["refused"] == []
    got = {tuple(r["flight"].split("/")[-2:]): r for r in rows}
    assert {k: got[k]["group"] for k in TESTS} == TESTS
    assert {k: got[k]["session"] for k in TESTS} == {k: k[1][:2] for k in TESTS}
    copy = got[("normal_flight", "E8_log07")]  # the same bytes as a reference flight
    assert copy["role"] == "reference" and copy["group"] is None
    ref_sha = {f["sha256"] for f in ref["flights"]}
    assert not [r for r in rows if r["group"] and r["sha256"] in ref_sha]
    assert len(rows) == len(TESTS) + 1  # the four reference files themselves are not decided
    cells = result["table"]
    for group in set(TESTS.values()):
        for rule in ("net_ref", "net_noref", "abs_sym", "pos_sym", "abs_ref", "pos_ref"):
            c = [c for c in cells if (c["rule"], c["group"], c["session"]) == (rule, group, "all")]
            assert len(c) == 1 and c[0]["flights"] == sum(g == group for g in TESTS.values())
    gate = next(g for g in result["gates"] if g["gate"] == "healthy test flights alarmed")
    alarmed = sum(got[k]["rules"]["net_ref"]["alarm"] for k, g in TESTS.items() if g == "healthy test")
    assert gate["value"] == f"{alarmed} of 2" and gate["met"] == (alarmed == 0)
    healthy_max = [got[k]["rules"]["net_ref"]["score"] for k, g in TESTS.items() if g == "healthy test"]
    deep = [got[k]["rules"]["net_ref"]["score"] for k, g in TESTS.items() if g == "M3 cut >= 3 mm"]
    auroc = next(c for c in cells if (c["rule"], c["group"], c["session"]) == ("net_ref", "M3 cut >= 3 mm", "all"))
    expect = np.mean([(d > h) + 0.5 * (d == h) for d in deep for h in healthy_max])
    assert auroc["auroc"] == pytest.approx(expect)
    deep_gate = next(g for g in result["gates"] if g["gate"] == "M3 cut >= 3 mm alarmed")
    if not deep_gate["met"]:  # the ranking bound in the note, from the same scores
        above = sum(d > max(healthy_max) for d in deep)
        assert f"({max(healthy_max):.3f}), 1 of 1, would alarm {above})" in deep_gate["missed_by"]


def test_the_ranking_bound_counts_deep_cuts_above_every_healthy_test_flight():
    from quadfdi.crazypad_table import separable

    def row(group, score):
        return {"group": group, "rules": {"net_ref": {"score": score}}}

    rows = [row("healthy test", 0.90), row("healthy test", 0.97), row("M3 cut >= 3 mm", 0.97),
            row("M3 cut >= 3 mm", 0.985), row("M3 cut >= 3 mm", 0.999), row(None, 1.0), row("debris", 0.99)]
    assert separable(rows) == {"healthy_max": 0.97, "above": 2, "flights": 3}  # a tie with a healthy flight is not
    assert separable([r for r in rows if r["group"] != "healthy test"]) is None


def test_motors_are_traced_to_the_log_names(scored):
    _, out, result = scored
    arrays = read_flight(PAD / "normal_flight" / "E8_log02").arrays
    veh = json.loads(str(arrays["vehicle"]))
    names = log_motor_names(arrays)
    assert names == [veh["log_motor_names"][m] for m in veh["motor_map"]]
    ref = load_vehicle(out / "vehicle.json")
    assert names == [m["log_motor"] for m in ref["motor_share"]]  # project rotor k is the same log motor
    # a rotor-side alarm on project rotor 1 names the log motor that rotor is: not "M1" on the Crazyflie
    fake = {"record": {"flight": "f", "windows": 2, "exposure_s": 3.2, "policy": {"threshold": 0.7},
                       "alarm_reach": {"possible": True, "most_votes": 2},
                       "alarms": [{"class": "PropellerFault", "motor": 1, "start_s": 1.0, "peak_p_fault": 0.9}]},
            "arrays": {"decided": np.array([True, True]), "class_names": np.array(["Healthy", "PropellerFault"]),
                       "proba": np.array([[0.2, 0.8], [0.6, 0.4]])}}
    got = network_result(fake, names)
    assert got["motor"] == names[0] == "M4" and got["alarm"]
    assert got["score"] == pytest.approx(0.8) and got["mean_p_fault"] == pytest.approx(0.6)
    assert got["votes"] == 1 and got["alarm_possible"]
    for r in result["decided"]["rows"]:
        for mode in ("net_ref", "net_noref"):
            for a in r["rules"][mode]["alarms"]:
                assert a["motor"] in (None, "M1", "M2", "M3", "M4")
            n = r["rules"][mode]
            assert n["motor"] == next((a["motor"] for a in n["alarms"] if a["motor"]), None)
            k = result["choice"]["policy"]["k"]  # an alarm needs k decided windows within n (core.alarm.reach)
            assert n["alarm_possible"] == (n["most_votes"] >= k) and n["most_votes"] <= n["decided_windows"]
            assert n["alarm_possible"] or not n["alarm"]
            assert 0 <= n["votes"] <= n["decided_windows"] and (n["votes"] > 0 or not n["alarm"])
            right = r["right_motors"]
            assert (r["group"] != "two cuts (M1, M2)") or right == ["M1", "M2"]


def test_the_px4_split(scored, mission_npz):
    _, out, result = scored
    px4 = {f["flight"]: f for f in result["px4"]["flights"]}
    assert "too short" in px4["px4_fmuv5_quad_real_short"]["refused"]  # ingest's own refusal: 0.4 s airborne
    gps = px4["px4_quad_6s_gps_interference"]
    assert gps["split"]["reference_airborne_s"] >= MIN_AIRBORNE_S
    assert gps["split"]["reference_airborne_s"] == pytest.approx(REFERENCE_FRACTION * gps["split"]["airborne_s"],
                                                                 abs=GRID_DT)
    assert {"net_ref", "net_noref"} <= set(gps) and (out / "crazypad.md").read_text().count("px4_quad_6s_gps") >= 1
    assert gps["split"]["gap_factor"] is None
    # the mission's logger dropped messages: read with its gaps bridged (as real-flights reads it), so split
    mission = px4["px4_quad_6s_uavcan_mission"]
    assert "refused" not in mission, mission.get("refused")
    assert mission["split"]["gap_factor"] == 7 and mission["net_ref"]["decided_windows"] > 0
    # both first parts cover their rest (the mission's first part already flies its 0-5 m/s legs)
    assert all(not f["coverage"]["beyond"] for f in (gps, mission))
    assert "outside the reference's range" in (out / "crazypad.md").read_text()
    arrays = load_flight(mission_npz)
    head, tail, info = split(arrays, "mission")
    assert len(head["time"]) + len(tail["time"]) == len(arrays["time"])
    assert tail["time"][0] == pytest.approx(info["cut_s"]) and head["time"][-1] < info["cut_s"]
    assert head["airborne"].sum() == int(np.ceil(REFERENCE_FRACTION * arrays["airborne"].sum()))
    for k in (k for k in arrays if k.startswith("raw.") and k.endswith(".t")):
        assert len(head[k]) == len(head[k[:-2] + ".v"]) and (tail[k] >= info["cut_s"] - GRID_DT).all()
    learn([Flight("first part", mission_npz, "0" * 64, head)])  # the reference's part alone is a reference
    short = dict(arrays)
    air = np.flatnonzero(arrays["airborne"])
    short["airborne"] = arrays["airborne"].copy()
    short["airborne"][air[int(20.0 / GRID_DT):]] = False  # 20 s airborne: 8 s for the reference
    with pytest.raises(Exception, match=r"too short to split.*at least 25 s airborne"):
        split(short, "short")


def test_bad_input_is_one_line_exit_2_nothing_written(scored, flightlog_export, tmp_path):
    run, _, _ = scored
    pad = _pad(tmp_path / "pad")
    cases = [(["--run", str(tmp_path)], "no export"),
             (["--run", str(flightlog_export.parent)], "'flightlog-min'"),
             (["--run", str(run), "--crazypad", str(tmp_path / "nope")], "no such folder"),
             (["--run", str(run), "--crazypad", str(_pad(tmp_path / "pad9", drop="E9_log01"))], "E9_log01 missing")]
    for args, said in cases:
        out = tmp_path / "out"
        full = args if "--crazypad" in args else args + ["--crazypad", str(pad)]
        res = quadfdi("crazypad", str(out), *full, "--logs", str(LOGS))
        assert res.returncode == 2, (args, res.stderr)
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and said in lines[0], (args, res.stderr)
        assert not out.exists()


def test_the_run_report_carries_the_table(scored, tmp_path):
    from quadfdi.crazypad_report import report_section

    run, _, result = scored
    assert report_section(run) == []  # no RUN/crazypad: no section
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    res = quadfdi("crazypad", str(copy / "crazypad"), "--run", str(copy), "--crazypad", str(_pad(tmp_path / "pad")),
                  "--logs", str(tmp_path / "no-logs-here-either"))
    assert res.returncode == 2 and "--logs" in res.stderr and not (copy / "crazypad").exists()
    res = quadfdi("crazypad", str(copy / "crazypad"), "--run", str(copy), "--crazypad", str(tmp_path / "pad"),
                  "--logs", str(_logs(tmp_path / "logs")))
    assert res.returncode == 0, res.stderr
    report = (copy / "report.md").read_text()
    section = report[report.index("## CrazyPAD (real labelled damage)"):]
    assert f"**{result['choice']['net']}**" in section and "| M3 cut >= 3 mm | all |" in section
    assert "| healthy test flights alarmed |" in section
