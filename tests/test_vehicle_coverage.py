"""Does a vehicle reference cover a flight (vehicle/coverage.py)? A reference learned from the first 40 % of
the shared PX4 tipover flight's airborne time (take-off and hover, up to about 0.5 m/s) does not cover the rest
(forward flight to 12 m/s): it says so, and `quadfdi detect --vehicle` prints it and draws it on the page; the
whole flight against a reference of itself is covered. A range the reference flew only as noise (the
Crazyflie's yaw rate, a few hundredths of a rad/s) does not count a damaged flight's wider noise."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.formats.flight import load_flight, write_flight
from quadfdi.formats.vehicle import write_vehicle
from quadfdi.vehicle import quantities as q
from quadfdi.vehicle.coverage import LIMIT, coverage, matters, said
from quadfdi.vehicle.flights import read_flight
from quadfdi.vehicle.learn import learn
from quadfdi.crazypad_px4 import split
from tests.conftest import SHARED_DATA, quadfdi

TIPOVER = SHARED_DATA / "flightlogs" / "px4_quad_6s_vibration_tipover.ulg"
PAD = SHARED_DATA / "crazypad" / "motor_data"
PAD_REFERENCE = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]


@pytest.fixture(scope="module")
def tipover(tmp_path_factory) -> dict:
    """The tipover flight ingested, cut at 40 % of its airborne time as `quadfdi crazypad` cuts the shared
    PX4 flights (quadfdi/crazypad_px4.py), and a reference of the first part."""
    if not TIPOVER.is_file():
        pytest.skip(f"the shared real flight logs are not at {TIPOVER.parent}")
    folder = tmp_path_factory.mktemp("tipover")
    res = quadfdi("ingest", str(TIPOVER), "--out", str(folder / "whole"))
    assert res.returncode == 0, res.stderr
    first, rest, _ = split(load_flight(folder / "whole" / "flight.npz"), "tipover")
    write_flight(folder / "first.npz", first)
    write_flight(folder / "rest.npz", rest)
    write_vehicle(folder / "first.json", learn([read_flight(folder / "first.npz")]))
    return {"folder": folder, "whole": folder / "whole" / "flight.npz", "rest": folder / "rest.npz",
            "reference": folder / "first.json"}


def test_a_reference_of_the_take_off_does_not_cover_the_forward_flight(tipover):
    ref = json.loads(tipover["reference"].read_text())
    lo, hi = ref["share_model"]["range_5_95"]["v_forward"]
    assert hi < 1.0  # the first 40 %: take-off and hover
    rest = read_flight(tipover["rest"])
    assert np.nanmax(q.forward_speed(rest)) > 8.0
    cov = coverage(rest, ref)
    assert cov["beyond"] and cov["outside"] == cov["regressors"]["v_forward"]["outside"] > 0.8
    assert cov["regressors"]["v_forward"]["seconds_outside"] > 20.0
    line = said(cov)
    assert line.startswith(f"{cov['outside']:.0%} of its airborne samples fly a forward speed outside the reference "
                           f"flights' {lo:.2f} to {hi:.2f} m/s")
    whole = read_flight(tipover["whole"])
    own = coverage(whole, learn([whole]))
    assert not own["beyond"] and own["outside"] <= LIMIT and said(own) is None


def test_only_an_excess_that_moves_a_share_by_more_than_its_scatter_counts():
    """Slope 0.02 per unit, scatter 0.005: an excess of 0.2 moves the share 0.004 (not counted), 0.3 moves
    it 0.006 (counted); a second motor with the larger slope decides."""
    model = {"motors": [{"per_yaw_rate": 0.02, "residual_std": 0.005}, {"per_yaw_rate": -0.001, "residual_std": 0.001}]}
    assert matters(model, "yaw_rate", np.array([0.0, 0.2, -0.2, 0.3, -0.3])).tolist() == [False, False, False, True,
                                                                                        True]
    model["motors"][1]["per_yaw_rate"] = -0.01  # 0.2 x 0.01 = 0.002 > 0.001
    assert matters(model, "yaw_rate", np.array([0.0, 0.2])).tolist() == [False, True]


@pytest.mark.skipif(not PAD.is_dir(), reason=f"the CrazyPAD logs are not at {PAD}")
def test_noise_past_a_range_flown_only_as_noise_is_not_counted():
    """The Crazyflie reference flew yaw rates of a few hundredths of a rad/s; a flight with a weight near M3
    has most of its samples past that range, but none by enough to move a share beyond its scatter."""
    ref = learn([read_flight(p, f"normal_flight/{p.name}") for p in PAD_REFERENCE])
    lo, hi = ref["share_model"]["range_5_95"]["yaw_rate"]
    assert hi - lo < 0.15
    fl = read_flight(PAD / "add_weight_W3_near_M3" / "E9_log00", "add_weight_W3_near_M3/E9_log00")
    yaw = q.yaw_rate(fl)[0][q.share_samples(fl)]
    assert np.mean((yaw < lo) | (yaw > hi)) > LIMIT
    cov = coverage(fl, ref)
    assert not cov["beyond"] and cov["regressors"]["yaw_rate"]["outside"] < LIMIT


def test_detect_prints_and_draws_a_flight_its_reference_does_not_cover(tipover, masked_export, tmp_path):
    """The whole flight (its hover gives detect its estimate) against the reference of its first part: the
    forward flight after the cut is more than LIMIT of it."""
    out = tmp_path / "out"
    res = quadfdi("detect", "--model", str(masked_export), str(tipover["whole"]), "--vehicle",
                  str(tipover["reference"]), "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert "of its airborne samples fly a forward speed outside the reference flights'" in res.stdout
    rec = json.loads((out / "alarms.json").read_text())["vehicle_reference"]
    assert rec["version"] == 2 and rec["coverage"]["beyond"]
    page = (out / "index.html").read_text()
    assert 'id="reference-coverage" class="alarm"' in page and "learn the reference from flights" in page
    folder = tmp_path / "folder"  # a folder of flights: the summary counts those beyond their reference
    res = quadfdi("detect", "--model", str(masked_export), str(tipover["whole"].parent), "--vehicle",
                  str(tipover["reference"]), "--out", str(folder))
    assert res.returncode in (0, 1), res.stderr
    assert "detect: 1 of 1 decided flight(s) fly a forward speed or yaw rate past their reference" in res.stdout
    row = json.loads((folder / "summary.json").read_text())["flights"][0]
    assert row["vehicle_reference"]["outside"] == rec["coverage"]["outside"]


def test_the_crazypad_px4_column_reads_every_coverage():
    from quadfdi.crazypad_report import _outside

    per = {"v_forward": {"what": "forward speed", "outside": 0.88}, "yaw_rate": {"what": "yaw rate", "outside": 0.1}}
    assert _outside({"regressors": per, "outside": 0.88, "beyond": True}) == "88% (forward speed) !"
    assert _outside(None) == "no share model"
    none = {"regressors": {"v_forward": {"what": "forward speed", "outside": None}}, "outside": None, "beyond": False,
            "why": "the flight logs no forward speed on its airborne samples"}
    assert _outside(none) == "unknown: the flight logs no forward speed on its airborne samples"
