"""`quadfdi vehicle learn`: a reference of one airframe from its healthy flights, on the real CrazyPAD
Crazyflie (two logging sessions that disagree on motors 1 and 2) and the shared PX4 UAVCAN mission;
the refusals (too short, two vehicles, bad input) are one line, exit 2, nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import file_sha256
from quadfdi.formats.flight import load_flight, write_flight
from quadfdi.formats.vehicle import load_vehicle
from quadfdi.vehicle import stats
from quadfdi.vehicle.flights import read_flight
from quadfdi.vehicle.learn import MIN_AIRBORNE_S, learn
from quadfdi.vehicle.rules import RULES, score_flight, thresholds
from quadfdi.vehicle.show import show
from tests.conftest import SHARED_DATA, quadfdi

PAD = SHARED_DATA / "crazypad" / "motor_data"
REFERENCE = [PAD / "normal_flight" / n for n in ("E8_log00", "E8_log01", "E9_log00", "E9_log01")]
needs_pad = pytest.mark.skipif(not PAD.is_dir(), reason=f"the CrazyPAD logs are not at {PAD}")


def cut(arrays: dict, t0: float, t1: float) -> dict:
    """A flight.npz's arrays restricted to t0 <= t < t1 (grid, raw samples and intervals)."""
    t = arrays["time"]
    keep = (t >= t0) & (t < t1)
    out = {}
    for key, v in arrays.items():
        if key in ("time", "telemetry", "mask", "airborne"):
            out[key] = v[keep]
        elif key.startswith("raw.") and key.endswith(".t"):
            k = (v >= t0) & (v < t1)
            out[key], out[key[:-2] + ".v"] = v[k], arrays[key[:-2] + ".v"][k]
        elif key in ("airborne_segments", "armed_segments"):
            s = np.clip(v, t0, t1 - 1e-6)
            out[key] = s[s[:, 1] > s[:, 0]].reshape(-1, 2)
        elif not key.startswith("raw."):
            out[key] = v
    return out


@pytest.fixture(scope="module")
def pad_reference(tmp_path_factory):
    if not PAD.is_dir():
        pytest.skip(f"the CrazyPAD logs are not at {PAD}")
    out = tmp_path_factory.mktemp("vehicle") / "crazyflie.json"
    res = quadfdi("vehicle", "learn", *map(str, REFERENCE), "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out, res


@needs_pad
def test_the_four_crazypad_reference_flights_make_a_reference(pad_reference):
    """Accepted; the healthy Crazyflie runs M3 above the four's mean; the sessions' disagreement on M1 and M2
    is a warning naming the quantity and the flights, not a refusal, and it widens the between-flight spread."""
    path, res = pad_reference
    ref = load_vehicle(path)
    share = {m["log_motor"]: m for m in ref["motor_share"]}
    assert share["M3"]["mean"] > 1.08
    assert [f["sha256"] for f in ref["flights"]] == [file_sha256(p) for p in REFERENCE]
    warned = [w.split(":")[0] for w in ref["warnings"]]
    assert "motor M1 command share" in warned and "motor M2 command share" in warned
    assert "motor M3 command share" not in warned and "motor M4 command share" not in warned
    assert all(f"normal_flight/{n}" in " ".join(ref["warnings"]) for n in ("E8_log00", "E9_log01"))
    assert res.stderr.count("warning: motor M1 command share") == 1
    # kept and widening: the M1 spread between flights is several times M3's, the E8 and E9 means ~0.07 apart
    assert share["M1"]["between_std"] > 5 * share["M3"]["between_std"]
    e8, e9 = (np.mean([share["M1"]["flights"][i]["mean"] for i in s]) for s in ((0, 1), (2, 3)))
    assert 0.05 < e8 - e9 < 0.1
    assert ref["hover"]["cmd"]["mean"] > 0.5 and ref["battery"]["mode"] == "level" and ref["battery"]["cells"] == 1
    assert ref["vibration"] == {} and ref["esc"] == {}  # a Crazyflie logs neither
    assert ref["share_model"]["yaw_rate_source"] == ["d(yaw)/dt (no body rates logged)"]


@needs_pad
def test_show_prints_what_the_reference_holds(pad_reference):
    """`quadfdi vehicle show`: the flights, each motor's share with its spreads in the log's names, the share
    model with the range it was fitted on, the hover, the pack, and every warning; a bad file is one line."""
    path, res = pad_reference
    ref = load_vehicle(path)
    shown = quadfdi("vehicle", "show", str(path))
    assert shown.returncode == 0, shown.stderr
    out = shown.stdout
    assert "crazyflie, frame quadrotor, 1 cell(s), motor map [3, 2, 1, 0]" in out
    assert "learned from 4 healthy flight(s)" in out and "normal_flight/E9_log01 (15.9 s)" in out
    for m in ref["motor_share"]:
        assert (f"rotor {m['rotor']} ({m['log_motor']}): {m['mean']:.3f}; between flights {m['between_std']:.3f}, "
                f"within a flight {m['within_std']:.3f}") in out
    lo, hi = ref["share_model"]["range_5_95"]["v_forward"]
    assert f"5-95 % flown forward speed {lo:.2f} to {hi:.2f} m/s" in out  # what `vehicle learn` printed too
    assert f"forward speed {lo:.2f} to {hi:.2f} m/s" in res.stdout
    assert f"hover collective {ref['hover']['cmd']['mean']:.3f}" in out and "no sag per ampere" in out
    assert f"warnings ({len(ref['warnings'])}):" in out and all(w in out for w in ref["warnings"])
    bad = path.parent / "not_a_reference.json"
    bad.write_text("{}")
    res = quadfdi("vehicle", "show", str(bad))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and "not a quadfdi vehicle" in res.stderr


@needs_pad
def test_the_share_is_the_logs_own_motor_command_over_the_four(pad_reference):
    """Against the log itself at 100 Hz (the Crazyflie reader's parse, no resampling): each reference
    flight's mean share of M1..M4 over its airborne intervals agrees within 0.001 (measured: 1.4e-4)."""
    from quadfdi.ingest.crazyflie import parse

    ref = load_vehicle(pad_reference[0])
    for i, path in enumerate(REFERENCE):
        fl = read_flight(path)
        raw = parse(path.read_bytes(), path.name)[0]["fixedFrequency"]
        air = np.zeros(len(raw["t"]), bool)
        for a, b in fl.arrays["airborne_segments"]:
            air |= (raw["t"] >= a) & (raw["t"] <= b)
        m = np.stack([raw[f"motor.m{k}"] for k in range(1, 5)], axis=1)
        m = m[air & (m.mean(axis=1) >= 0.05 * 65535)]  # spinning: the shares' own rule
        direct = (m / m.mean(axis=1, keepdims=True)).mean(axis=0)
        learned = {e["log_motor"]: e["flights"][i]["mean"] for e in ref["motor_share"]}
        np.testing.assert_allclose([learned[f"M{k}"] for k in range(1, 5)], direct, atol=0.001)


@needs_pad
def test_the_share_model_is_least_squares_on_the_steady_samples(pad_reference):
    """Against scikit-learn's LinearRegression on the samples the reference names (core.hover's steady
    samples, forward speed and the yaw rate from d(yaw)/dt): the same coefficients and residual spread."""
    from sklearn.linear_model import LinearRegression

    from quadfdi.vehicle import quantities as q

    model = load_vehicle(pad_reference[0])["share_model"]
    assert model["regressors"] == ["v_forward", "yaw_rate"]
    flights = [read_flight(p) for p in REFERENCE]
    sel = [q.steady(fl) for fl in flights]
    x = np.concatenate([np.stack([q.forward_speed(fl)[s], q.yaw_rate(fl)[0][s]], axis=1)
                        for fl, s in zip(flights, sel)])
    y = np.concatenate([q.motor_shares(fl)[s] for fl, s in zip(flights, sel)])
    ok = np.isfinite(x).all(axis=1) & np.isfinite(y).all(axis=1)
    for k, m in enumerate(model["motors"]):
        fit = LinearRegression().fit(x[ok], y[ok, k])
        np.testing.assert_allclose([m["intercept"], m["per_v_forward"], m["per_yaw_rate"]],
                                   [fit.intercept_, *fit.coef_], rtol=1e-6, atol=1e-9)
        resid = y[ok, k] - fit.predict(x[ok])
        assert m["residual_std"] == pytest.approx(np.std(resid, ddof=3), rel=1e-6)
        assert m["seconds"] == pytest.approx(ok.sum() * 0.04)


@needs_pad
def test_a_too_short_flight_is_refused_in_one_line(tmp_path):
    arrays = load_flight_log(REFERENCE[0])
    t_air = arrays["time"][arrays["airborne"]]
    short = tmp_path / "short.npz"
    write_flight(short, cut(arrays, arrays["time"][0], t_air[0] + MIN_AIRBORNE_S - 2.0))
    out = tmp_path / "v.json"
    res = quadfdi("vehicle", "learn", str(REFERENCE[1]), str(short), "--out", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "short.npz" in res.stderr and f"at least {MIN_AIRBORNE_S:g} s per flight" in res.stderr
    assert not out.exists()


def load_flight_log(path) -> dict:
    return dict(read_flight(path).arrays)


@needs_pad
def test_flights_of_two_vehicles_are_refused(tmp_path, mission_npz):
    """Another autopilot (the PX4 mission beside a Crazyflie), another cell count, another motor map: one
    line naming both flights and the field, nothing written."""
    out = tmp_path / "v.json"
    res = quadfdi("vehicle", "learn", str(REFERENCE[0]), str(mission_npz), "--out", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "not one vehicle: autopilot 'px4' against 'crazyflie'" in res.stderr and not out.exists()
    arrays = load_flight_log(REFERENCE[1])
    veh = json.loads(str(arrays["vehicle"]))
    for field, change, words in (("battery", dict(veh["battery"], cells=2), "cell count 2 against 1"),
                                 ("motor_map", [0, 1, 2, 3], "motor map [0, 1, 2, 3] against [3, 2, 1, 0]")):
        other = tmp_path / f"{field}.npz"
        write_flight(other, dict(arrays, vehicle=np.array(json.dumps(dict(veh, **{field: change})))))
        with pytest.raises(QuadfdiError, match=words.replace("[", r"\[").replace("]", r"\]")):
            learn([read_flight(REFERENCE[0]), read_flight(other)])


def test_the_same_file_twice_and_no_flight_are_refused(tmp_path, mission_npz):
    with pytest.raises(QuadfdiError, match="same file"):
        learn([read_flight(mission_npz), read_flight(mission_npz, "copy")])
    with pytest.raises(QuadfdiError, match="at least one"):
        learn([])


def test_a_reference_from_the_missions_first_half_scores_its_rest_healthy(tmp_path, mission_npz):
    """The shared PX4 UAVCAN mission, cut at the middle of its airborne time: the first half is a reference
    (one flight: the threshold is the noise floor of its mean), the second half is healthy by the signed
    rule; the same half with one motor commanded 50 % harder alarms and names that motor."""
    arrays = load_flight(mission_npz)
    t, air = arrays["time"], arrays["airborne"]
    mid = 0.5 * (t[air][0] + t[air][-1])
    first, rest = tmp_path / "first.npz", tmp_path / "rest.npz"
    write_flight(first, cut(arrays, t[0], mid))
    write_flight(rest, cut(arrays, mid, t[-1] + 1.0))
    ref = learn([read_flight(first)])
    assert ref["battery"]["mode"] == "sag" and ref["battery"]["sag_v_per_a"]["mean"] < 0  # 6S pack, current logged
    assert set(ref["vibration"]) == {"vib_px4"} and set(ref["esc"]) == {"rpm_share", "current_share", "temp_offset"}
    assert ref["share_model"]["yaw_rate_source"] == ["r"] and ref["warnings"] == []
    text = show(ref, "first.json")  # one flight of a 6S quad logging current, vibration and ESCs
    assert "one flight: no between-flight spread" in text and "yaw rate from r" in text
    assert f"sag {ref['battery']['sag_v_per_a']['mean']:.4f} V/A" in text and "vibration vib_px4: floor" in text
    assert all(f"ESC {k} " in text for k in ref["esc"]) and text.endswith("warnings: none")
    limits = thresholds(ref)
    assert limits["pos_ref"]["largest_reference_score"] == 0.0
    assert limits["pos_ref"]["threshold"] == limits["pos_ref"]["noise_floor"] > 0
    row = score_flight(read_flight(rest), ref, limits)
    assert not row["rules"]["pos_ref"]["alarm"], row
    names = [str(n) for n in arrays["channel_names"]]
    harder = dict(cut(arrays, mid, t[-1] + 1.0))
    harder["telemetry"] = harder["telemetry"].copy()
    harder["telemetry"][:, names.index("thr3")] *= 1.5
    write_flight(tmp_path / "harder.npz", harder)
    row = score_flight(read_flight(tmp_path / "harder.npz"), ref, limits)
    motor_map = json.loads(str(arrays["vehicle"]))["motor_map"]
    assert row["rules"]["pos_ref"]["alarm"] and row["rules"]["pos_ref"]["motor"] == f"M{motor_map[2] + 1}"
    assert [r.name for r in RULES] == list(row["rules"])


def test_disagreement_needs_more_than_three_noise_spreads():
    """Four flights whose 2 s window means scatter by 0.01 (se 0.005 each; the noise spread of one flight
    against the other three's mean is 0.005 sqrt(4/3) = 0.0058): a flight 0.015 off stays quiet (2.6
    spreads), one 0.04 off is named (6.9) and only it (the others are 0.013 from the rest: 2.3)."""
    def flight(mean: float) -> dict:
        x = np.repeat(mean + 0.01 * np.array([-1.5, -0.5, 0.5, 1.5]) / np.std([-1.5, -0.5, 0.5, 1.5], ddof=1),
                      stats.WINDOW)
        return stats.flight_stat(x, np.ones(len(x), bool))

    quiet = [flight(m) for m in (1.00, 1.00, 1.00, 1.015)]
    loud = [flight(m) for m in (1.00, 1.00, 1.00, 1.04)]
    assert quiet[0]["windows"] == 4 and quiet[0]["window_std"] == pytest.approx(0.01)
    assert stats.disagreements(quiet) == []
    found = stats.disagreements(loud)
    assert [d["flight"] for d in found] == [3]
    assert found[0]["z"] == pytest.approx(0.04 / np.sqrt(0.005 ** 2 + 3 * 0.005 ** 2 / 9))


@pytest.fixture(scope="module")
def mission_reference(mission_npz, tmp_path_factory) -> dict:
    """A reference holding every section (share model, hover current, sag, vibration, ESC) as plain JSON."""
    from quadfdi.formats.vehicle import write_vehicle

    path = tmp_path_factory.mktemp("mission_ref") / "mission.json"
    write_vehicle(path, learn([read_flight(mission_npz)]))
    return json.loads(path.read_text())


def _set(data: dict, dotted: str, value) -> None:
    *head, last = dotted.split(".")
    for key in head:
        data = data[int(key)] if isinstance(data, list) else data[key]
    if value is DELETE:
        del data[last]
    elif isinstance(data, list):
        data[int(last)] = value
    else:
        data[last] = value


DELETE = object()


@pytest.mark.parametrize("dotted, value, says", [
    ("share_model", DELETE, "share_model: expected regressors"),
    ("share_model.range_5_95.v_forward", [1.0, 0.0], "share_model.range_5_95: v_forward must be [low, high]"),
    ("share_model.motors.2.residual_std", DELETE, "share_model.motors: expected null or four lines"),
    ("share_model.motors.1.rotor", 3, "share_model.motors[1]: expected rotor 2"),
    ("motor_share.0.log_motor", 7, "motor_share[0]: expected rotor 1 and the log's motor name"),
    ("hover.cmd", None, "hover.cmd: expected mean, between_std and flights"),
    ("hover.cmd.mean", None, "hover.cmd: mean None and between_std None must be numbers"),
    ("battery.mode", "volts", "battery: expected null or a pack model"),
    ("battery.sag_v_per_a", DELETE, "battery.sag_v_per_a: expected mean"),
    ("vibration.vib_px4.floor.flights", [], "vibration.vib_px4.floor: flights must hold one number"),
    ("esc.rpm_share.motors", [], "esc.rpm_share: expected unit and four motors"),
    ("motor_temp", [1.0], "motor_temp must be null or four entries"),
    ("warnings", "none", "warnings must be a list of lines"),
    ("flights.0.airborne_s", DELETE, "each with its file, sha256, log_sha256 and airborne_s"),
    ("motor_share.2.flights.0.mean", None, "motor_share[2].flights: each flight's entry needs its mean"),
    ("motor_share.1.se", "small", "motor_share[1]: between_std, within_std, window_std, se and seconds must be"),
    ("vibration.vib_px4.level.flights.0", 3.0, "vibration.vib_px4.level.flights: each flight's entry needs its mean"),
])
def test_a_reference_not_as_learn_writes_it_is_one_line(mission_reference, tmp_path, dotted, value, says):
    """Every section a reader uses is checked on load (formats/vehicle.py), so a hand-edited or truncated
    reference is refused in one line naming the field, not a traceback in detect, rules, record or show."""
    from quadfdi.formats.vehicle import write_vehicle

    data = json.loads(json.dumps(mission_reference))
    _set(data, dotted, value)
    path = tmp_path / "edited.json"
    path.write_text(json.dumps(data))
    with pytest.raises(QuadfdiError) as exc:
        load_vehicle(path)
    assert says in str(exc.value) and len(str(exc.value).splitlines()) == 1, str(exc.value)
    with pytest.raises(QuadfdiError):  # nor can it be written
        write_vehicle(tmp_path / "again.json", data)
    assert not (tmp_path / "again.json").exists()
    res = quadfdi("vehicle", "show", str(path))
    assert res.returncode == 2 and says in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
