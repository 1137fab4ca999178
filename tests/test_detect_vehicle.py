"""`quadfdi detect --vehicle / --vehicles MAP`: flights read beside the vehicle's own healthy reference.

A reference learned from the four CrazyPAD reference flights (normal_flight E8_log00, E8_log01, E9_log00,
E9_log01); a fleet folder with a held-out healthy flight, a 3 mm cut on the log's motor M3, a flight the map
sends to a reference of another cell count (refused, the others go on) and one no glob matches (decided
without a reference, and saying so); the tiny masked model (tests/conftest.py masked_export) decides the
Crazyflie logs. Checked: alarms.json's vehicle_reference, the reference never changing a decision, the index's
reference columns and the page's reference bands in headless Chromium, the alarm's share deviations; the
map's globs and every refusal of a reference or a map (one line, exit 2, nothing written)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import file_sha256
from tests.conftest import SHARED_DATA, quadfdi
from tests.test_html_report import _check_clean, _open, browser  # noqa: F401 (fixture)

PAD = SHARED_DATA / "crazypad" / "motor_data"
REFERENCE = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]
DAMAGED = PAD / "cut_propeller_M3_3mm" / "E8_log01"
needs_pad = pytest.mark.skipif(not PAD.is_dir(), reason=f"the CrazyPAD logs are not at {PAD}")


@pytest.fixture(scope="module")
def refs(tmp_path_factory) -> dict:
    """cf.json (the four reference flights) and cf6s.json (the same but for a 6-cell pack)."""
    if not PAD.is_dir():
        pytest.skip(f"the CrazyPAD logs are not at {PAD}")
    from quadfdi.formats.vehicle import write_vehicle
    from quadfdi.vehicle.flights import read_flight
    from quadfdi.vehicle.learn import learn

    folder = tmp_path_factory.mktemp("refs")
    ref = learn([read_flight(p, f"normal_flight/{p.name}") for p in REFERENCE])
    write_vehicle(folder / "cf.json", ref)
    other = json.loads((folder / "cf.json").read_text())
    other["vehicle"]["cells"] = 6
    write_vehicle(folder / "cf6s.json", other)
    return {"folder": folder, "cf": folder / "cf.json", "cf6s": folder / "cf6s.json", "data": ref}


@pytest.fixture(scope="module")
def fleet(masked_export, refs, tmp_path_factory) -> dict:
    base = tmp_path_factory.mktemp("vfleet")
    logs = base / "logs"
    for src, dst in ((PAD / "normal_flight" / "E8_log02", "crazyflie/normal_flight/E8_log02"),
                     (DAMAGED, "crazyflie/cut_propeller_M3_3mm/E8_log01"),
                     (PAD / "normal_flight" / "E9_log02", "other/E9_log02"),
                     (PAD / "normal_flight" / "E9_log03", "unmapped/E9_log03")):
        (logs / dst).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(src, logs / dst)
    vmap = base / "vehicles.toml"
    vmap.write_text(f'"logs/other/*" = "{refs["cf6s"]}"\n"logs/crazyflie/**" = "{refs["cf"]}"\n')
    out = base / "out"
    res = quadfdi("detect", "--model", str(masked_export), str(logs), "--vehicles", str(vmap), "--out", str(out),
                  "--workers", "2")
    summary = json.loads((out / "summary.json").read_text())
    rows = {r["name"].split("__", 1)[1]: r for r in summary["flights"]}
    return {"res": res, "out": out, "logs": logs, "map": vmap, "summary": summary, "rows": rows}


def _alarms_json(fleet, key: str) -> dict:
    return json.loads((fleet["out"] / fleet["rows"][key]["name"] / "alarms.json").read_text())


DAMAGED_KEY, HEALTHY_KEY, UNMAPPED_KEY = ("crazyflie__cut_propeller_M3_3mm__E8_log01",
                                          "crazyflie__normal_flight__E8_log02", "unmapped__E9_log03")


@needs_pad
def test_the_map_gives_each_flight_its_reference_refuses_another_vehicle_and_says_when_there_is_none(fleet, refs):
    res, s = fleet["res"], fleet["summary"]
    assert res.returncode == s["exit_status"] in (3, 4), res.stderr  # a flight refused; the others decided
    assert sorted(fleet["rows"]) == sorted([DAMAGED_KEY, HEALTHY_KEY, UNMAPPED_KEY])
    assert [r["log"] for r in s["refused"]] == [str(fleet["logs"] / "other" / "E9_log02")]
    reason = s["refused"][0]["reason"]
    assert reason.startswith("vehicle reference cf6s.json refused") and "cells 1 against 6" in reason
    assert len(reason.splitlines()) == 1
    unmapped = fleet["rows"][UNMAPPED_KEY]
    assert unmapped["vehicle_reference"] is None and "no glob of vehicles.toml matches" in unmapped["reference_note"]
    assert _alarms_json(fleet, UNMAPPED_KEY)["vehicle_reference"] is None
    assert "1 of 3 decided flight(s) with no vehicle reference: the model judges them against the simulated" in \
        res.stdout
    rec = _alarms_json(fleet, DAMAGED_KEY)["vehicle_reference"]
    assert rec["version"] == 2 and rec["file"] == "cf.json" and rec["sha256"] == file_sha256(refs["cf"])
    assert rec["chosen_by"] == "--vehicles vehicles.toml" and not rec["reference_flight"]


@needs_pad
def test_the_cut_motor_deviates_most_traced_back_to_the_logs_m3(fleet):
    rec = _alarms_json(fleet, DAMAGED_KEY)["vehicle_reference"]
    dev = {m["log_motor"]: m for m in rec["motor_share"]}
    assert sorted(dev) == ["M1", "M2", "M3", "M4"]
    assert rec["largest_deviation"]["log_motor"] == "M3" == max(dev.values(), key=lambda m: abs(m["deviation"]))[
        "log_motor"]
    assert dev["M3"]["deviation"] > 0.08 and dev["M3"]["z"] > 10  # works harder, far outside the day-to-day spread
    assert abs(dev["M3"]["value"] - dev["M3"]["reference"] - dev["M3"]["deviation"]) < 1e-12
    assert {k: (r["motor"], r["alarm"]) for k, r in rec["rules"].items() if k.endswith("_ref")} == \
        {"abs_ref": ("M3", True), "pos_ref": ("M3", True)}
    healthy = {m["log_motor"]: m for m in _alarms_json(fleet, HEALTHY_KEY)["vehicle_reference"]["motor_share"]}
    assert abs(healthy["M3"]["deviation"]) < dev["M3"]["deviation"] / 3
    assert fleet["rows"][DAMAGED_KEY]["vehicle_reference"]["hover"] == rec["hover_collective"]["deviation"]
    assert rec["sag_v_per_a_cell"]["value"] is None and "no current" in rec["sag_v_per_a_cell"]["why"]


@needs_pad
def test_the_reference_changes_no_decision(masked_export, refs):
    from quadfdi.detect.batch import decide_flight
    from quadfdi.detect.reference import load_reference

    plain = decide_flight(str(DAMAGED), str(masked_export), "gru", "fp32", "ort")
    beside = decide_flight(str(DAMAGED), str(masked_export), "gru", "fp32", "ort", load_reference(refs["cf"]))
    a, b = dict(plain[0]["record"]), dict(beside[0]["record"])
    assert a.pop("vehicle_reference") is None and b.pop("vehicle_reference")["file"] == "cf.json"
    assert a == b
    for key, v in plain[0]["arrays"].items():
        assert np.array_equal(v, beside[0]["arrays"][key], equal_nan=v.dtype.kind == "f"), key
    strip = lambda ev: [{k: v for k, v in e.items() if k != "reference_shares"} for e in ev]  # noqa: E731
    assert strip(plain[2]) == strip(beside[2])


@needs_pad
def test_an_alarms_share_deviations_name_the_cut_motor(refs):
    from quadfdi.detect.inputs import read_flight
    from quadfdi.detect.reference import add_to_evidence, apply, load_reference

    flight = read_flight(DAMAGED)
    record, series = apply(flight, load_reference(refs["cf"]), DAMAGED)
    t = np.asarray(flight["time"], np.float64)
    evidence = [{"start_s": float(t[0]), "end_s": None}, {"start_s": float(t[-1]) + 1, "end_s": None}]
    add_to_evidence(evidence, series, t)
    dev = evidence[0]["reference_shares"]
    assert [d["log_motor"] for d in dev] == [m["log_motor"] for m in record["motor_share"]]
    assert max(dev, key=lambda d: abs(d["deviation"]))["log_motor"] == "M3"
    assert evidence[1]["reference_shares"] is None  # nothing airborne in the span
    add_to_evidence(evidence, None, t)
    assert evidence[0]["reference_shares"] is None


@needs_pad
def test_index_in_chromium_shows_the_reference_columns_and_sorts_them(fleet, browser):  # noqa: F811
    out = fleet["out"]
    _open(browser, out / "index.html")
    _check_clean(browser, out)
    head = [h.text.strip() for h in browser.find_elements("css selector", "#flights th.sortable")]
    assert head[9:] == ["reference", "\u0394 share m1", "\u0394 share m2", "\u0394 share m3", "\u0394 share m4",
                        "\u0394 hover", "\u0394 sag, V/A/cell", "\u0394 vibration", "abs_ref score",
                        "outside reference"]
    row = fleet["rows"][DAMAGED_KEY]
    cells = browser.find_elements("css selector", f'tr[data-name="{row["name"]}"] td')
    rec = _alarms_json(fleet, DAMAGED_KEY)["vehicle_reference"]
    m3 = next(m for m in rec["motor_share"] if m["log_motor"] == "M3")
    cell = cells[9 + m3["rotor"]]
    assert "M3" in cell.text and float(cell.get_attribute("data-v")) == pytest.approx(m3["deviation"], rel=1e-5)
    unmapped = browser.find_elements("css selector", f'tr[data-name="{fleet["rows"][UNMAPPED_KEY]["name"]}"] td')
    assert unmapped[9].text == "none" and unmapped[10].get_attribute("data-v") == ""
    # this E8 log holds no velocity or yaw estimate: its coverage cannot be read, and the index says so
    assert rec["coverage"]["outside"] is None and "logs no forward speed or yaw rate" in rec["coverage"]["why"]
    assert cells[18].get_attribute("data-v") == "" and cells[18].text == "\u2014"
    browser.find_elements("css selector", "#flights th.sortable")[17].click()  # abs_ref score, ascending
    names = [tr.get_attribute("data-name").split("__", 1)[1] for tr in
             browser.find_elements("css selector", "#flights tbody tr")]
    assert names[-1] == DAMAGED_KEY and names[0] == UNMAPPED_KEY  # no score sorts first; the cut scores most


@needs_pad
def test_flight_page_in_chromium_draws_the_reference_band(fleet, browser):  # noqa: F811
    out, row = fleet["out"], fleet["rows"][DAMAGED_KEY]
    _open(browser, out / row["name"] / "index.html")
    _check_clean(browser, out)
    drawn = browser.execute_script(
        "const d = document.getElementById('flight-plot');"
        "const ax = d.data.find(t => t.name === 'motor 1').yaxis;"
        "return {ax: ax, ref: d.data.filter(t => t.meta && t.meta.kind && t.meta.kind.startsWith('reference'))"
        ".map(t => ({kind: t.meta.kind, motor: t.meta.motor, log: t.meta.log_motor, spread: t.meta.spread,"
        " yaxis: t.yaxis, y: t.y.filter(v => v !== null)})),"
        " section: !!document.getElementById('reference-quantities'), reference: window.quadfdi.reference.file}")
    rec = _alarms_json(fleet, DAMAGED_KEY)["vehicle_reference"]
    assert drawn["section"] and drawn["reference"] == "cf.json"
    bands = {t["motor"]: t for t in drawn["ref"] if t["kind"] == "reference band"}
    lines = {t["motor"]: t for t in drawn["ref"] if t["kind"] == "reference"}
    assert sorted(bands) == sorted(lines) == [1, 2, 3, 4]
    assert all(t["yaxis"] == drawn["ax"] for t in drawn["ref"])  # in the motor share panel
    for m in rec["motor_share"]:
        band, line = bands[m["rotor"]], lines[m["rotor"]]
        assert band["log"] == m["log_motor"] and band["spread"] == pytest.approx(m["spread"])
        assert np.median(line["y"]) == pytest.approx(m["reference"], abs=0.02)
        assert max(band["y"]) == pytest.approx(max(line["y"]) + m["spread"], abs=2e-3)
        assert min(band["y"]) == pytest.approx(min(line["y"]) - m["spread"], abs=2e-3)
    evidence = browser.find_elements("css selector", ".evidence")
    assert len(evidence) == len(_alarms_json(fleet, DAMAGED_KEY)["alarms"]) > 0, "the tiny model raised no alarm here"
    for ev in evidence:  # every alarm's evidence lists the share deviations from the reference
        rows = ev.find_elements("css selector", "table.reference-deviation tr")[1:]
        assert [r.find_elements("css selector", "td")[0].text for r in rows] == \
            [f"{m['rotor']} ({m['log_motor']})" for m in rec["motor_share"]]


# ---- the map and the refusals (no model)


def test_globs_match_by_component_relative_to_the_map(tmp_path):
    from quadfdi.detect.reference import glob_match

    assert glob_match(str(tmp_path / "a" / "*"), tmp_path / "a" / "x.ulg")
    assert not glob_match(str(tmp_path / "a" / "*"), tmp_path / "a" / "b" / "x.ulg")  # * stays in one folder
    assert glob_match(str(tmp_path / "a" / "**"), tmp_path / "a" / "b" / "c" / "x.ulg")
    assert glob_match(str(tmp_path / "a" / "**" / "E8_*"), tmp_path / "a" / "E8_log00")  # ** may be no folder
    assert not glob_match(str(tmp_path / "a" / "**" / "E8_*"), tmp_path / "a" / "E9_log00")
    assert glob_match(str(tmp_path / "m" / ".." / "a" / "?.BIN"), tmp_path / "a" / "1.BIN")
    assert not glob_match(str(tmp_path / "a" / "*.BIN"), tmp_path / "a" / "1.bin")  # case kept


@needs_pad
def test_the_first_match_wins_and_globs_are_relative_to_the_map_file(refs, tmp_path):
    from quadfdi.detect.reference import NO_REFERENCE, references

    (tmp_path / "maps" / "sub").mkdir(parents=True)
    vmap = tmp_path / "maps" / "v.json"
    vmap.write_text(json.dumps({"../logs/six/*": str(refs["cf6s"]), "../logs/**": str(refs["cf"])}))
    r = references(None, str(vmap))
    assert r.for_log(tmp_path / "logs" / "six" / "a.ulg")[0].file == "cf6s.json"
    assert r.for_log(tmp_path / "logs" / "six" / "deeper" / "a.ulg")[0].file == "cf.json"
    ref, note = r.for_log(tmp_path / "elsewhere" / "a.ulg")
    assert ref is None and "no glob of v.json matches" in note
    (tmp_path / "maps" / "sub" / "v.toml").write_text('"../../logs/**" = "../../refs_here.json"\n')
    shutil.copy(refs["cf"], tmp_path / "refs_here.json")  # a reference path relative to the map too
    assert references(None, str(tmp_path / "maps" / "sub" / "v.toml")).for_log(tmp_path / "logs" / "x")[0].file == \
        "refs_here.json"
    assert references(str(refs["cf"]), None).for_log("/anywhere/at/all")[0].file == "cf.json"
    assert references(None, None).for_log("x") == (None, NO_REFERENCE)


@needs_pad
@pytest.mark.parametrize("name, text, says", [
    ("v.yaml", "a: b\n", "expected a .toml or .json file"),
    ("v.toml", '"logs/**" = \n', "cannot be read as TOML"),
    ("v.json", '{"logs/**": ', "cannot be read as JSON"),
    ("v.toml", "", "expected at least one line"),
    ("v.json", "[]", "expected at least one line"),
    ("v.toml", '"logs/**" = 3\n', "must map a log path glob to a vehicle.json path"),
    ("v.toml", '"logs/**" = "missing.json"\n', "missing.json does not exist"),
    ("v.toml", '"logs/**" = "notref.json"\n', "is not a quadfdi vehicle reference"),
    ("v.toml", '"logs/**" = "old.json"\n', "has format_version 0"),
    (None, None, "does not exist"),
])
def test_every_bad_map_is_one_line(refs, tmp_path, name, text, says):
    from quadfdi.detect.reference import references

    (tmp_path / "notref.json").write_text('{"kind": "something else"}')
    old = json.loads(refs["cf"].read_text())
    old["format_version"] = 0
    (tmp_path / "old.json").write_text(json.dumps(old))
    path = tmp_path / (name or "absent.toml")
    if text is not None:
        path.write_text(text)
    with pytest.raises(QuadfdiError) as exc:
        references(None, str(path))
    assert says in str(exc.value) and len(str(exc.value).splitlines()) == 1


@needs_pad
@pytest.mark.parametrize("field, value", [("autopilot", "px4"), ("frame", "hexarotor"), ("cells", 6),
                                          ("motor_map", [0, 1, 2, 3])])
def test_a_reference_of_another_vehicle_is_refused_naming_the_field(refs, field, value):
    from quadfdi.detect.inputs import read_flight
    from quadfdi.detect.reference import Reference, apply

    data = json.loads(refs["cf"].read_text())
    data["vehicle"][field] = value
    with pytest.raises(QuadfdiError, match=rf"^vehicle reference x.json refused: .*\({field} .* against") as exc:
        apply(read_flight(DAMAGED), Reference("x.json", "x.json", "0" * 64, data), DAMAGED)
    assert len(str(exc.value).splitlines()) == 1


@needs_pad
@pytest.mark.parametrize("extra, says", [
    (("--vehicle", "{bad}"), "is not a quadfdi vehicle reference"),
    (("--vehicle", "{cf6s}"), "cells 1 against 6"),
    (("--vehicle", "{cf}", "--vehicles", "{map}"), "not both"),
    (("--vehicles", "{map_bad}"), "cannot be read as TOML"),
])
def test_the_command_refuses_in_one_line_and_writes_nothing(masked_export, refs, tmp_path, extra, says):
    (tmp_path / "bad.json").write_text("{}")
    (tmp_path / "map.toml").write_text(f'"**" = "{refs["cf"]}"\n')
    (tmp_path / "map_bad.toml").write_text("= nothing\n")
    paths = {"bad": tmp_path / "bad.json", "cf6s": refs["cf6s"], "cf": refs["cf"], "map": tmp_path / "map.toml",
             "map_bad": tmp_path / "map_bad.toml"}
    res = quadfdi("detect", "--model", str(masked_export), str(DAMAGED), "--out", str(tmp_path / "out"),
                  *[a.format(**paths) for a in extra])
    assert res.returncode == 2 and says in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert not (tmp_path / "out").exists()


@needs_pad
def test_one_flight_prints_its_reference_or_that_it_has_none(masked_export, refs, tmp_path):
    res = quadfdi("detect", "--model", str(masked_export), str(DAMAGED), "--vehicle", str(refs["cf"]),
                  "--out", str(tmp_path / "with"))
    assert res.returncode == 0, res.stderr
    assert "vehicle reference cf.json: largest motor share deviation M3 +0." in res.stdout
    assert json.loads((tmp_path / "with" / "alarms.json").read_text())["vehicle_reference"]["file"] == "cf.json"
    res = quadfdi("detect", "--model", str(masked_export), str(DAMAGED), "--out", str(tmp_path / "without"))
    assert res.returncode == 0, res.stderr
    assert "no vehicle reference: the model judges the flight against the simulated vehicles" in res.stdout
    assert json.loads((tmp_path / "without" / "alarms.json").read_text())["vehicle_reference"] is None


MISSION = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"


@pytest.mark.skipif(not MISSION.is_file(), reason=f"the shared logs are not at {MISSION.parent}")
def test_a_reference_flight_against_its_own_reference_deviates_by_nothing():
    """The PX4 mission (sag, vibration, ESC logged) against a reference of itself: the shares over its steady
    samples meet the share model fitted on them, every other quantity its own value; one flight, no spread."""
    from quadfdi.vehicle.compare import compare
    from quadfdi.vehicle.flights import read_flight
    from quadfdi.vehicle.learn import learn

    fl = read_flight(MISSION, "mission")
    out, (shares, expect, modelled) = compare(fl, learn([fl]))
    assert out["reference_flight"] and modelled.mean() > 0.5  # yaw, velocities logged: the model applies
    # not exactly 0: the model's regressors are clipped to the 5-95 % range it saw (the mission's airborne
    # means sit 0.02-0.03 from the model: climbs and banks, which the steady samples leave out)
    assert all(m["basis"].startswith("steady") and abs(m["deviation"]) < 1e-3 for m in out["motor_share"])
    assert abs(out["hover_collective"]["deviation"]) < 1e-12 and abs(out["sag_v_per_a_cell"]["deviation"]) < 1e-9
    assert out["sag_v_per_a_cell"]["value"] < 0 and abs(out["vibration"]["vib_px4"]["deviation"]) < 1e-9
    assert sorted(out["esc"]) == ["current_share", "rpm_share", "temp_offset"]
    assert all(abs(e["deviation"]) < 1e-9 and e["z"] is None for v in out["esc"].values() for e in v)
    assert {k: r["score"] for k, r in out["rules"].items() if k.endswith("_ref")} == pytest.approx(
        {"abs_ref": 0.0, "pos_ref": 0.0}, abs=1e-9)
