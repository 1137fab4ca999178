"""`quadfdi vehicle rules` on the real labelled CrazyPAD damage: the protocol's groups and sessions, the
four share rules' scores, thresholds and AUROC checked against independent computations from the
per-flight rows; bad input is one line, exit 2, nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.formats.vehicle import write_vehicle
from quadfdi.vehicle.crazypad import group_of, right_motors
from quadfdi.vehicle.flights import read_flight
from quadfdi.vehicle.learn import learn
from tests.conftest import SHARED_DATA, quadfdi

PAD = SHARED_DATA / "crazypad" / "motor_data"
REFERENCE = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]
pytestmark = pytest.mark.skipif(not PAD.is_dir(), reason=f"the CrazyPAD logs are not at {PAD}")


@pytest.fixture(scope="module")
def pad_rules(tmp_path_factory):
    d = tmp_path_factory.mktemp("rules")
    ref = learn([read_flight(p, f"normal_flight/{p.name}") for p in REFERENCE])
    write_vehicle(d / "vehicle.json", ref)
    res = quadfdi("vehicle", "rules", "--vehicle", str(d / "vehicle.json"), str(PAD), "--out", str(d / "out"))
    assert res.returncode == 0, res.stderr
    return ref, json.loads((d / "out" / "rules.json").read_text()), (d / "out" / "rules.md").read_text()


def _cell(result: dict, rule: str, group: str, session: str = "all") -> dict:
    return next(c for c in result["table"] if (c["rule"], c["group"], c["session"]) == (rule, group, session))


def test_every_crazypad_folder_has_its_group():
    folders = sorted(p.name for p in PAD.iterdir() if p.is_dir())
    assert len(folders) == 59 and all(group_of(f) for f in folders)
    assert group_of("cut_propeller_M3_3mm") == group_of("cut_propeller_M3_4mm_3.5mm_39.5mm") == "M3 cut >= 3 mm"
    assert group_of("cut_propeller_M3_2.5mm_2mm_42.5mm") == group_of("cut_m3_2mm_2mm") == "M3 cut 2-2.5 mm"
    assert group_of("cut_propeller_M3_1.5mm_1.5mm_44mm") == group_of("cut_propeller_M3_0.5mm_46.5mm") == "M3 cut < 2 mm"
    assert group_of("cut_M2_0.5mm_46.5mm") == group_of("cut_M2_3.5mm_3.5mm_40mm_M1_3.5mm_3.5mm_40mm") == \
        "two cuts (M1, M2)"
    assert right_motors("cut_M2_1mm_1mm_45mm_M1_1mm_0.5mm_45.5mm") == ["M1", "M2"]
    assert right_motors("add_weight_W1_near_M3_M4") == ["M3", "M4"] and right_motors("cut_m3_2mm_2mm") == ["M3"]


def test_the_protocol_groups_hold_every_log(pad_rules):
    _, result, md = pad_rules
    assert len(result["flights"]) == 222 and result["refused"] == []
    roles = [r["role"] for r in result["flights"]]
    assert roles.count("reference") == 4 and roles.count("healthy") == 8 and roles.count("damaged") == 210
    counts = {g: _cell(result, "pos_ref", g)["flights"] for g in
              ("healthy test", "M3 cut >= 3 mm", "M3 cut 2-2.5 mm", "M3 cut < 2 mm", "two cuts (M1, M2)", "debris",
               "added mass", "swinging load")}
    assert counts == {"healthy test": 8, "M3 cut >= 3 mm": 24, "M3 cut 2-2.5 mm": 24, "M3 cut < 2 mm": 39,
                      "two cuts (M1, M2)": 84, "debris": 15, "added mass": 12, "swinging load": 12}
    assert (_cell(result, "pos_ref", "M3 cut >= 3 mm", "E8")["flights"],
            _cell(result, "pos_ref", "M3 cut >= 3 mm", "E9")["flights"]) == (21, 3)
    assert "| M3 cut >= 3 mm | 24 |" in md


def test_scores_and_thresholds_follow_from_the_shares(pad_rules):
    """Each score recomputed from the flight's shares and the reference; each threshold from the reference
    flights' own shares (1.5 x the largest score: the noise floor is below it here)."""
    ref, result, _ = pad_rules
    base = {m["log_motor"]: m["mean"] for m in ref["motor_share"]}
    for row in result["flights"]:
        s = row["shares"]
        dev = {m: s[m] - base[m] for m in s}
        assert row["rules"]["pos_ref"]["score"] == pytest.approx(max(dev.values()))
        assert row["rules"]["pos_ref"]["motor"] == max(dev, key=dev.get)
        assert row["rules"]["abs_sym"]["score"] == pytest.approx(max(abs(v - 1) for v in s.values()))
    own = [max(f["mean"] - m["mean"] for m in ref["motor_share"] for f in [m["flights"][i]])
           for i in range(4)]
    lim = result["thresholds"]["pos_ref"]
    assert lim["largest_reference_score"] == pytest.approx(max(own)) and lim["noise_floor"] < 1.5 * max(own)
    assert lim["threshold"] == pytest.approx(1.5 * max(own))
    assert all(r["rules"]["pos_ref"]["alarm"] == (r["rules"]["pos_ref"]["score"] > lim["threshold"])
               for r in result["flights"])


def _auroc_by_pairs(healthy: list[float], damaged: list[float]) -> float:
    """The Mann-Whitney statistic: the share of (healthy, damaged) pairs the damaged flight scores higher
    (ties count one half)."""
    h, d = np.array(healthy)[:, None], np.array(damaged)[None, :]
    return float(((d > h).sum() + 0.5 * (d == h).sum()) / (h.size * d.size))


def test_the_bars_on_the_largest_cuts(pad_rules):
    """By hand on the airborne means: with the reference the largest-deviation rule separates the >= 3 mm
    cuts with AUROC 0.95 and puts 21 of 24 above every healthy test flight; the signed rule all 24 (1.0),
    naming M3 each time, with no false alarm at its threshold."""
    _, result, _ = pad_rules
    rows = result["flights"]
    for rule, auroc, above in (("abs_ref", 0.953, 21), ("pos_ref", 1.0, 24)):
        healthy = [r["rules"][rule]["score"] for r in rows if r["group"] == "healthy test"]
        cut = [r["rules"][rule]["score"] for r in rows if r["group"] == "M3 cut >= 3 mm"]
        cell = _cell(result, rule, "M3 cut >= 3 mm")
        assert cell["auroc"] == pytest.approx(_auroc_by_pairs(healthy, cut)) == pytest.approx(auroc, abs=0.001)
        assert cell["above_every_healthy"] == above == sum(c > max(healthy) for c in cut)
    cell = _cell(result, "pos_ref", "M3 cut >= 3 mm")
    assert cell["alarmed"] == 24 and cell["right_motor"] == 24 and cell["named"] == {"M3": 24}
    assert _cell(result, "pos_ref", "healthy test")["alarmed"] == 0


def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, pad_rules):
    ref, _, _ = pad_rules
    good = tmp_path / "vehicle.json"
    write_vehicle(good, ref)
    other = tmp_path / "old.json"
    other.write_text(json.dumps(dict(ref, format_version=99)))
    foreign = tmp_path / "foreign.json"
    foreign.write_text("{\"a\": 1}")
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    out = tmp_path / "out"
    log = str(REFERENCE[2])
    cases = [
        (("rules", "--vehicle", str(tmp_path / "missing.json"), log, "--out", str(out)), "does not exist"),
        (("rules", "--vehicle", str(other), log, "--out", str(out)), "format_version 99"),
        (("rules", "--vehicle", str(foreign), log, "--out", str(out)), "not a quadfdi vehicle reference"),
        (("rules", "--vehicle", str(good), str(tmp_path / "nowhere"), "--out", str(out)), "does not exist"),
        (("rules", "--vehicle", str(good), str(a_file), "--out", str(out)), "no flight could be scored"),
        (("rules", "--vehicle", str(good), log, "--out", str(a_file)), "is not a folder"),
        (("learn", str(tmp_path / "nowhere"), "--out", str(out / "v.json")), "does not exist"),
        (("learn", log, "--out", str(tmp_path)), "is a folder"),
    ]
    for args, words in cases:
        res = quadfdi("vehicle", *args)
        assert res.returncode == 2 and res.stderr.count("\n") == 1 and words in res.stderr, (args, res.stderr)
        assert not out.exists(), args
