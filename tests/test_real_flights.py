"""`quadfdi real-flights`: the whole command on tiny settings (the fixed flightlog-min and the masked
profile, the UAVCAN mission, a log that ingest refuses and three CrazyPAD logs), the suite's table
under every mask pattern against evaluate, its refusals (one line, exit 2, nothing written) and its
tables."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from quadfdi.cli import main
from quadfdi.core.channels import MASK_PATTERNS
from quadfdi.real_flights_crazypad import group_of, group_key
from quadfdi.real_flights_table import crazypad_tables, disagreements, healthy_lines, table
from tests.conftest import ROOT, quadfdi

LOGS = Path(os.environ.get("QUADFDI_FLIGHTLOGS", ROOT.parent / "shared" / "data" / "flightlogs"))
if not LOGS.is_dir():
    LOGS = Path("/work/shared/data/flightlogs")
CRAZYPAD = LOGS.parent / "crazypad"
MISSION, GROUND = "px4_quad_6s_uavcan_mission.ulg", "ardupilot_copter_quadx_ground.BIN"
# a healthy E9 log, an E8 log of a cut propeller without yaw, a log with tape on a propeller
CP_LOGS = ("normal_flight/E9_log00", "cut_propeller_M3_2mm/E8_log01", "tape_on_propeller_M3/E8_log00")
TINY = ["sim.n_traj=20", "sim.ood_traj=2", "sim.duration_s=12.0", "sim.chunk=14", "sim.window=40", "train.epochs=1",
        "train.latent=8", "train.hidden=16", "train.gru_hidden=16", "train.max_train_windows=60",
        "train.motor_head=auto"]


@pytest.fixture(scope="module")
def rf(tmp_path_factory):
    """The command on tiny settings: flightlog-min and flightlog-mask, two shared logs, three CrazyPAD
    logs (copied with the licence that must travel with them)."""
    if not (LOGS / MISSION).is_file() or not (CRAZYPAD / "motor_data" / CP_LOGS[0]).is_file():
        pytest.skip("the shared real flight logs are not here")
    tmp = tmp_path_factory.mktemp("rf")
    cp = tmp / "crazypad"
    for rel in CP_LOGS:
        (cp / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(CRAZYPAD / "motor_data" / rel, cp / rel)
    shutil.copy(CRAZYPAD / "LICENSE", cp / "LICENSE")
    out = tmp / "rf"
    res = quadfdi("real-flights", str(out), "--profiles", "min,mask", "--logs", str(LOGS), "--flights",
                  f"{MISSION},{GROUND}", "--crazypad", str(cp), "--workers", "2",
                  *[a for v in TINY for a in ("--set", v)])
    assert res.returncode == 0, res.stderr[-3000:]
    return out, res, json.loads((out / "real_flights.json").read_text())


@pytest.mark.slow
def test_real_flights_on_tiny_settings(rf):
    """sim, train, apply, evaluate, export and parity for flightlog-min and -mask, then detect on the
    mission (8 cases per profile, and again with the gap bridged) and on a ground log that ingest refuses."""
    out, res, r = rf
    md = (out / "real_flights.md").read_text()
    assert md.startswith("# Real flights\n") and md.endswith("|\n") and md in res.stdout
    assert r["exports"] == {p: str(out / p / "export") for p in ("min", "mask")} and r["export_refused"] == {}
    assert all((out / p / "parity" / "parity.json").is_file() for p in ("min", "mask"))
    for prof in ("min", "mask"):
        mission = [c for c in r["flights"] if c["flight"] == MISSION.split(".")[0] and c["profile"] == f"flightlog-{prof}"]
        assert len(mission) == 8 and all("record" in c for c in mission)
        for c in mission:
            alarms = json.loads((out / "flights" / prof / c["flight"] / c["net"] / c["runtime"] / c["precision"]
                                 / "alarms.json").read_text())
            assert alarms == c["record"] and alarms["net"] == c["net"] and alarms["runtime"] == c["runtime"]
    assert "channels" in mission[0]["record"]  # the masked model lists the channels it used and lacked
    ground = [c for c in r["flights"] if c["flight"] == GROUND.split(".")[0]]
    assert len(ground) == 16 and all(c["refused"].startswith("ingest: ") for c in ground)
    assert not (out / "flights" / "ingest" / GROUND.split(".")[0] / "flight.npz").exists()
    assert f"- flightlog-min {GROUND.split('.')[0]}: ingest: " in md and "never airborne" in md
    for prof in ("min", "mask"):  # one row per network, C++ as ONNX Runtime in both precisions
        for net in ("cnode", "gru"):
            head = f"| flightlog-{prof} | {net} | {MISSION.split('.')[0]} |"
            row = next(ln for ln in md.splitlines() if ln.startswith(head))
            assert row.split(" | ")[8] == "yes"
    gap7 = r["flights_gap7"]
    assert len(gap7) == 16 and {c["flight"] for c in gap7} == {MISSION.split(".")[0]}
    assert "--gap-factor 7" in md and md.count(f"| flightlog-min | cnode | {MISSION.split('.')[0]} |") == 2
    assert gap7[0]["record"]["decided_windows"] >= mission[0]["record"]["decided_windows"]  # gaps bridged
    assert "- flightlog-mask cnode: " in md and "healthy flights decided" in md


@pytest.mark.slow
def test_suite_rows_are_evaluates_and_patterns_keep_the_policy(rf):
    """Each network's every-channel row is evaluation.json's test row (evaluate.fixed under the policy
    evaluate chose reproduces the protocol); the masked networks have one row per mask pattern under
    that same policy, and their sets are the network on the masked windows; the paired difference is
    evaluate's."""
    out, _, r = rf
    rows = r["suite"]["rows"]
    assert len(rows) == 2 + 2 * len(MASK_PATTERNS)
    for prof in ("min", "mask"):
        ev = json.loads((out / prof / "evaluation" / "evaluation.json").read_text())
        for net in ("cnode", "gru"):
            mine = [x for x in rows if x["profile"] == f"flightlog-{prof}" and x["net"] == net]
            want = next(x for x in ev["results"] if x["model"] == net and x["set"] == "test")
            every = next(x for x in mine if x["pattern"] == "all")
            assert every["metrics"] == want["metrics"] and every["false_alarms"] == want["false_alarms"]
            assert every["flights"] == want["flights"] and every["policy"] == ev["models"][net]["policy"]
            assert all(x["policy"] == every["policy"] for x in mine)  # never re-tuned to a pattern
            if prof == "mask":
                assert [x["pattern"] for x in mine] == [p.name for p in MASK_PATTERNS]
                assert set(r["suite"]["goal"]) == {"cnode", "gru"}
                assert r["suite"]["goal"][net]["diff"] == every["vs_min"]["diff"]["macro_f1"]["diff"]
    ev = json.loads((out / "min" / "evaluation" / "evaluation.json").read_text())
    pair = next(p for p in ev["paired"] if p["set"] == "test" and {p["a"], p["b"]} == {"cnode", "gru"})
    from quadfdi.evaluate.fixed import paired_fixed, score_fixed
    from quadfdi.evaluate.load import load_run
    from quadfdi.core.config import load_config

    sets, infos = load_run(out / "min")
    cfg = load_config(out / "min" / "config.toml")
    _, pooled = score_fixed({n: [s for s in sets if s.model == n] for n in ("cnode", "gru")},
                            {n: ev["models"][n]["policy"] for n in ("cnode", "gru")}, infos, "test", cfg)
    assert paired_fixed(pooled, pair["a"], pair["b"], cfg)["diff"]["macro_f1"] == pair["diff"]["macro_f1"]
    _pattern_set_is_the_network_on_masked_windows(out / "mask")
    md = (out / "real_flights.md").read_text()
    summary = md.split("## Summary\n", 1)[1].split("\n## ", 1)[0]  # CNODE / GRU side by side
    rows = [ln for ln in summary.splitlines() if ln.startswith("| flightlog-")]
    assert [ln.split(" | ")[1] for ln in rows] == ["every", "every"] + [p.name for p in MASK_PATTERNS if p.name != "all"]
    every_min = next(x for x in r["suite"]["rows"] if x["profile"] == "flightlog-min" and x["net"] == "gru")
    assert rows[0].split(" | ")[2].endswith(f" / {every_min['metrics']['macro_f1']['value']:.3f} "
                                            f"[{every_min['metrics']['macro_f1']['lo']:.3f}, "
                                            f"{every_min['metrics']['macro_f1']['hi']:.3f}]")
    assert "flightlog-mask minus flightlog-min with every channel" in summary
    index = json.loads((out / "mask" / "predictions" / "index.json").read_text())["entries"]
    assert {e["model"] for e in index} == {"cnode", "gru"}  # pattern sets are not evaluate's models


def _pattern_set_is_the_network_on_masked_windows(run: Path) -> None:
    from quadfdi.core.npzio import read_npz
    from quadfdi.formats.dataset import gather_windows, load_dataset, split_rows, window_index
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.models.inputs import profiled_dataset
    from quadfdi.train.loop import predict_proba
    from quadfdi.train.masks import Masker

    k = [p.name for p in MASK_PATTERNS].index("crazyflie")
    got = read_npz(run / "predictions" / "gru_crazyflie_sim1_train0.npz")
    ds = profiled_dataset(load_dataset(run / "sims" / "seed1" / "dataset.npz"), "flightlog-mask", patterns=False)
    rows = split_rows(ds, "test")[:2]
    w = gather_windows(ds, *window_index(ds, rows))
    model, _ = load_checkpoint(run / "gru.pt", "gru")
    masked = Masker("flightlog-mask", ds.channel_names).apply(w.x.copy(), np.full(len(w.x), k))
    n = len(w.x)
    assert np.array_equal(got["traj"][:n], w.traj) and np.array_equal(got["t_end"][:n], w.t_end)
    assert np.allclose(got["proba"][:n], predict_proba(model, masked), atol=1e-6)
    assert not np.allclose(got["proba"][:n], predict_proba(model, w.x), atol=1e-6)  # the mask did something


@pytest.mark.slow
def test_crazypad_logs_every_case_and_group(rf):
    out, _, r = rf
    cp = r["crazypad"]
    assert cp["logs"] == 3 and cp["workers"] == 2 and len(cp["cases"]) == 3 * 8
    assert [c["flight"] for c in cp["cases"][::8]] == sorted(CP_LOGS)
    for c in cp["cases"]:
        assert "record" in c, c.get("refused")  # the masked model decides every CrazyPAD log
        rec = json.loads((out / "crazypad" / c["flight"] / c["net"] / c["runtime"] / c["precision"]
                          / "alarms.json").read_text())
        assert rec["exposure_s"] == c["record"]["exposure_s"] and len(rec["alarms"]) == len(c["record"]["alarms"])
    e8 = next(c for c in cp["cases"] if c["flight"] == CP_LOGS[1])
    assert e8["group"] == "M3 cut 2 mm" and e8["session"] == "E8" and {"vx", "vy", "yaw"} <= set(e8["record"]["channels_absent"])
    md = (out / "real_flights.md").read_text()
    assert "## CrazyPAD (flightlog-mask)" in md and "| healthy | 0 / 1 | 1 |" in md and "| debris (tape) | 1 / 0 | 1 |" in md
    summary = md.split("## Summary\n", 1)[1].split("\n## ", 1)[0]  # one column per group, E8 / E9
    assert "| | healthy | M3 cut 2 mm | debris (tape) |" in summary
    assert "| logs | 0 / 1 | 1 / 0 | 1 / 0 |" in summary and "| decided | 0 / 1 | 1 / 0 | 1 / 0 |" in summary
    d = disagreements(r["flights"] + cp["cases"])
    assert d["cpp_vs_ort_fp32"]["differ"] == [] and d["cpp_vs_ort_int8"]["differ"] == []
    assert d["cpp_vs_ort_fp32"]["compared"] == 2 * 2 + 3 * 2  # (profile, flight, net) decided: mission, CrazyPAD


@pytest.mark.parametrize("argv,message", [
    (["--profiles", "min,huge"], "--profiles takes comma-separated names of min, esc, nocur"),
    (["--logs", "/nonexistent/flightlogs"], "--logs /nonexistent/flightlogs: no such folder"),
    (["--logs", str(LOGS), "--flights", "nope.ulg"], "no log nope.ulg"),
    (["--profiles", "min,mask,min"], "--profiles takes comma-separated names of min, esc, nocur, mask"),
    (["--logs", str(LOGS), "--crazypad", "/nonexistent/crazypad"], "--crazypad /nonexistent/crazypad: no such folder"),
    (["--logs", str(LOGS), "--export", "/nonexistent/export"], "--export /nonexistent/export: no manifest.json"),
    (["--logs", str(LOGS), "--export", "/nonexistent/export", "--set", "train.epochs=1"],
     "--export decides the logs with a finished export: --profiles, --set, --config and --mask-config do not apply"),
    (["--logs", str(LOGS), "--export", "/nonexistent/export", "--config", "fleet"],
     "--export decides the logs with a finished export: --profiles, --set, --config and --mask-config do not apply"),
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


def test_without_crazypad_beside_the_checkout_it_is_skipped(tmp_path, monkeypatch):
    """The default CrazyPAD folder absent: no error, the part is skipped (run_real_flights says so in one line)."""
    import argparse

    from quadfdi import real_flights

    monkeypatch.setattr(real_flights, "default_crazypad", lambda: tmp_path / "no-crazypad")
    args = argparse.Namespace(profiles="min,mask", logs=str(LOGS), flights=MISSION, crazypad=None)
    assert real_flights._checked_args(args)[3] is None


def test_crazypad_groups_from_folder_names():
    """The README's groups; motor 3's cuts by the deepest cut of a blade (a length left is no depth)."""
    got = {f: group_of(f) for f in ("normal_flight", "cut_propeller_M3_1mm", "cut_propeller_M3_0.5mm_46.5mm",
                                     "cut_propeller_M3_2mm_1.5mm_43.5mm", "cut_propeller_M3_4mm_4mm_39mm",
                                     "cut_m3_2mm_2mm", "cut_M2_0.5mm_46.5mm", "cut_M2_3.5mm_3.5mm_40mm_M1_3.5mm_3.5mm_40mm",
                                     "tape_on_propeller_M1_M3", "add_weight_W1_near_M3_M4", "weight_on_string_W2_near_M3",
                                     "something_else")}
    assert got == {"normal_flight": "healthy", "cut_propeller_M3_1mm": "M3 cut 1 mm",
                   "cut_propeller_M3_0.5mm_46.5mm": "M3 cut 0.5 mm", "cut_propeller_M3_2mm_1.5mm_43.5mm": "M3 cut 2 mm",
                   "cut_propeller_M3_4mm_4mm_39mm": "M3 cut 4 mm", "cut_m3_2mm_2mm": "M3 cut 2 mm",
                   "cut_M2_0.5mm_46.5mm": "two damaged propellers",
                   "cut_M2_3.5mm_3.5mm_40mm_M1_3.5mm_3.5mm_40mm": "two damaged propellers",
                   "tape_on_propeller_M1_M3": "debris (tape)", "add_weight_W1_near_M3_M4": "added mass",
                   "weight_on_string_W2_near_M3": "swinging load", "something_else": "something_else"}
    order = sorted(set(got.values()), key=group_key)
    assert order == ["healthy", "M3 cut 0.5 mm", "M3 cut 1 mm", "M3 cut 2 mm", "M3 cut 4 mm", "two damaged propellers",
                     "debris (tape)", "added mass", "swinging load", "something_else"]


def _cp_case(flight: str, group: str, net: str, rt: str, pr: str, alarms: list[dict] | None) -> dict:
    c = {"profile": "flightlog-mask", "flight": flight, "group": group, "session": flight.split("/")[-1][:2],
         "net": net, "runtime": rt, "precision": pr}
    if alarms is None:
        c["refused"] = "too short: 0 decided windows"
    else:
        c["record"] = {"alarms": alarms, "exposure_s": 11.2, "decided_windows": 10, "windows": 12}
    return c


def test_disagreements_healthy_lines_and_crazypad_tables():
    """A C++ alarm that ONNX Runtime lacks and an int8 refusal are listed; an alarm on a healthy flight is
    named with its class, motor and time; the group table counts flights per session and names the
    log's motors."""
    m3 = {"class": "PropellerFault", "motor": 2, "log_motor": "M3", "start_s": 9.3, "end_s": None, "peak_p_fault": 0.97}
    cases = []
    for rt in ("ort", "cpp"):
        for pr in ("fp32", "int8"):
            for net in ("cnode", "gru"):
                cases.append(_cp_case("normal_flight/E9_log00", "healthy", net, rt, pr, []))
                cut = [m3] if net == "cnode" or (rt, pr) != ("cpp", "int8") else None
                cases.append(_cp_case("cut_propeller_M3_1mm/E8_log01", "M3 cut 1 mm", net, rt, pr, cut))
                cases.append(_cp_case("cut_propeller_M3_1mm/E9_log03", "M3 cut 1 mm", net, rt, pr,
                                      [m3] if (net, rt) == ("gru", "cpp") else []))
    d = disagreements(cases)
    assert d["cpp_vs_ort_fp32"]["compared"] == 6 and len(d["cpp_vs_ort_fp32"]["differ"]) == 1
    assert d["cpp_vs_ort_fp32"]["differ"][0] == {"profile": "flightlog-mask", "flight": "cut_propeller_M3_1mm/E9_log03",
                                                 "net": "gru", "a": "PropellerFault m2 9.3-end (peak 0.97)", "b": "none"}
    assert [x["flight"] for x in d["int8_vs_fp32_cpp"]["differ"]] == ["cut_propeller_M3_1mm/E8_log01"]
    assert d["int8_vs_fp32_cpp"]["differ"][0]["a"] == "refused"
    groups, per_log = crazypad_tables({"cases": cases})
    assert groups.splitlines()[2:] == ["| healthy | 0 / 1 | 1 | 0 / 0 | 0 / 0 | — / — | — / — |",
                                       "| M3 cut 1 mm | 1 / 1 | 2 | 1 / 0 | 1 / 0 | PropellerFault 1 / PropellerFault 1 | "
                                       "M3 1 / M3 1 |"]
    assert "| cut_propeller_M3_1mm/E8_log01 | M3 cut 1 mm | 11.2 | PropellerFault M3 9.3 s | PropellerFault M3 9.3 s |" in per_log
    shared = [dict(_case("cnode", rt, pr, [dict(m3, motor=3)] if rt == "cpp" else []), flight="mission")
              for rt in ("ort", "cpp") for pr in ("fp32", "int8")]
    (line,) = healthy_lines(shared, ["mission"])
    assert line.startswith("- flightlog-min cnode: 1 of 1 healthy flights decided (12.5 s): ALARMS ")
    assert "mission PropellerFault m3 at 9.3 s (cpp fp32)" in line and "(cpp int8)" in line
    from quadfdi.real_flights_report import _healthy_alarms  # the summary: one alarm, its cases named

    assert _healthy_alarms(shared, ["mission"]) == {"flightlog-min": ["CNODE on mission: PropellerFault m3 at 9.3 s "
                                                                      "(cpp fp32, cpp int8)"]}


def test_a_finished_export_decides_the_logs_alone(masked_export, tmp_path):
    """--export: no sim, no training, no suite section; the mission (and bridged), a refused ground log
    and two CrazyPAD logs, every case, the CrazyPAD pass under the export's own profile."""
    if not (LOGS / MISSION).is_file() or not (CRAZYPAD / "motor_data" / CP_LOGS[0]).is_file():
        pytest.skip("the shared real flight logs are not here")
    cp = tmp_path / "crazypad"
    for rel in CP_LOGS[:2]:
        (cp / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(CRAZYPAD / "motor_data" / rel, cp / rel)
    out = tmp_path / "rf"
    res = quadfdi("real-flights", str(out), "--export", str(masked_export), "--logs", str(LOGS), "--flights",
                  f"{MISSION},{GROUND}", "--crazypad", str(cp), "--workers", "1")
    assert res.returncode == 0, res.stderr[-3000:]
    r = json.loads((out / "real_flights.json").read_text())
    md = (out / "real_flights.md").read_text()
    assert r["suite"] is None and "realistic suite" not in md and not (out / "base").exists()
    assert f"--export {masked_export}" in r["command"] and r["profile"] == "flightlog-mask"
    assert len(r["flights"]) == 2 * 8 and len(r["flights_gap7"]) == 8 and len(r["crazypad"]["cases"]) == 2 * 8
    assert all("refused" in c for c in r["flights"] if c["flight"] == GROUND.split(".")[0])
    assert all("record" in c for c in r["flights_gap7"] + r["crazypad"]["cases"])
    assert {c["profile"] for c in r["crazypad"]["cases"]} == {"flightlog-mask"} and "## CrazyPAD (flightlog-mask)" in md
    d = disagreements(r["flights"] + r["flights_gap7"] + r["crazypad"]["cases"])
    assert d["cpp_vs_ort_fp32"]["differ"] == [] and d["cpp_vs_ort_int8"]["differ"] == []
