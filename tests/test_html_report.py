"""detect on a folder of flights and the HTML it writes, opened in headless Chromium (selenium over
Debian's chromium + chromium-driver): the fleet index and a flight that raises an alarm load from
disk with no console error and no request outside the output folder; the alarm marker sits at the
time alarms.json gives, the evidence section is there for it, the index row links to the page, the
zoom link zooms, the columns sort. Also the fleet's exit status, the log discovery and naming, the
evidence's numbers against windows.npz, and `quadfdi report --html`.

The flights: simulated faulty flights of the session's tiny flightlog-min run (tests/conftest.py
``flightlog_export``) written as flight.npz (sim/flight_npz.py), beside a README (not a log: skipped
quietly) and a truncated ULog (refused with its reason)."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import quadfdi

CHROME_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync",
                "--window-size=1400,1000")


def _alarming_flight(export: Path) -> dict:
    """The first faulty simulated flight of the run on which the GRU raises an alarm, as flight.npz arrays."""
    from quadfdi.detect.run import detect
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.flight_npz import flight_arrays

    arrays = load_dataset(export.parent / "dataset.npz").arrays
    for i in np.flatnonzero(arrays["fault_class"] > 0):
        flight = flight_arrays(arrays, int(i), "dataset.npz")
        if detect(export, flight, "gru")["record"]["alarms"]:
            return flight
    pytest.fail("no simulated faulty flight raises an alarm with the tiny GRU")


@pytest.fixture(scope="module")
def fleet(flightlog_export, tmp_path_factory) -> dict:
    from quadfdi.formats.flight import write_flight

    logs = tmp_path_factory.mktemp("logs")
    (logs / "sim").mkdir()
    write_flight(logs / "sim" / "faulty.npz", _alarming_flight(flightlog_export))
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.flight_npz import flight_arrays

    arrays = load_dataset(flightlog_export.parent / "dataset.npz").arrays
    healthy = int(np.flatnonzero(arrays["fault_class"] == 0)[0])
    write_flight(logs / "sim" / "healthy.npz", flight_arrays(arrays, healthy, "dataset.npz"))
    (logs / "README.md").write_text("not a log\n")
    (logs / "broken.ulg").write_bytes(b"ULog\x01\x12\x35\x01" + b"\x00" * 40)  # a ULog header, then nothing
    out = tmp_path_factory.mktemp("fleet") / "out"
    res = quadfdi("detect", "--model", str(flightlog_export), str(logs), "--out", str(out), "--net", "gru",
                  "--workers", "2")
    summary = json.loads((out / "summary.json").read_text())
    row = next(r for r in summary["flights"] if r["alarms"])  # the faulty flight's
    return {"res": res, "out": out, "logs": logs, "summary": summary, "row": row}


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    profile = tempfile.mkdtemp(prefix="quadfdi-chromium-")
    for flag in CHROME_FLAGS + (f"--user-data-dir={profile}",):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
    driver = webdriver.Chrome(options=opts, service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def _open(driver, path: Path) -> None:
    driver.get("about:blank")  # leave the last page (or the start page, which loads chrome:// resources)
    driver.get_log("browser"), driver.get_log("performance")  # and drop what it logged
    driver.get(path.as_uri())


def _check_clean(driver, folder: Path) -> None:
    """No console error; every request the page made is a file inside ``folder`` (or inline data)."""
    errors = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    assert not errors, errors
    urls = [json.loads(e["message"])["message"] for e in driver.get_log("performance")]
    urls = [m["params"]["request"]["url"] for m in urls if m["method"] == "Network.requestWillBeSent"]
    urls += driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    assert urls, "the performance log saw no request at all (not even the page)"
    root = folder.resolve().as_uri() + "/"
    outside = [u for u in urls if not (u.startswith(root) or u.startswith("data:"))]
    assert not outside, outside


def test_fleet_exit_status_summary_and_layout(fleet):
    res, out, s = fleet["res"], fleet["out"], fleet["summary"]
    assert res.returncode == 4, res.stderr  # an alarm raised, and a log refused
    assert s["exit_status"] == 4 and [r["name"] for r in s["flights"]] == \
        [f"{fleet['logs'].name}__sim__{n}.npz" for n in ("faulty", "healthy")]  # found in path order
    assert [r["log"] for r in s["refused"]] == [str(fleet["logs"] / "broken.ulg")]  # README.md skipped quietly
    assert len(s["refused"][0]["reason"].splitlines()) == 1 and s["refused"][0]["reason"]
    row = fleet["row"]
    flight = out / row["name"]
    for f in ("alarms.json", "windows.npz", "evidence.json", "index.html"):
        assert (flight / f).is_file(), f
    assert (out / "plotly.min.js").stat().st_size > 1_000_000 and not (flight / "plotly.min.js").exists()
    rec = json.loads((flight / "alarms.json").read_text())
    assert row["alarms"][0]["start_s"] == rec["alarms"][0]["start_s"] and row["decided_s"] == rec["exposure_s"]
    assert row["vehicle"] == {"autopilot": "sim", "frame": "quadrotor", "cells": row["vehicle"]["cells"]}
    assert row["date"] is None and 0 < row["worst_p_fault"] <= 1


def test_exit_status_scheme():
    from quadfdi.detect.batch import exit_status

    alarm, calm, refused = {"alarms": [{}]}, {"alarms": []}, [{"reason": "x"}]
    assert [exit_status([calm], []), exit_status([calm, alarm], []), exit_status([calm], refused),
            exit_status([alarm], refused), exit_status([], refused)] == [0, 1, 3, 4, 3]


def test_logs_are_found_by_content_and_named_stably(tmp_path):
    from quadfdi.detect.logfiles import find_logs

    (tmp_path / "a" / "deep").mkdir(parents=True)
    (tmp_path / "b").mkdir()
    (tmp_path / "a" / "deep" / "E8_log00").write_bytes(b"\xbc\x02\x00\x01\x00" + b"\x00" * 20)  # Crazyflie v2
    (tmp_path / "a" / "x.ulg").write_bytes(b"ULog\x01" + b"\x00" * 20)
    (tmp_path / "a" / "notes.ulg").write_text("a text file named like a log\n")
    (tmp_path / "b" / "x.ulg").write_bytes(b"\xa3\x95" + b"\x00" * 20)  # DataFlash under a PX4 name
    found = find_logs([tmp_path / "a", tmp_path / "b", tmp_path / "a" / "x.ulg"])
    names = [n for _, n in found]
    assert [p.name for p, _ in found] == ["E8_log00", "x.ulg", "x.ulg"]  # notes.ulg skipped; a/x.ulg once
    assert names[0] == "a__deep__E8_log00" and names[1].startswith("a__x.ulg") and names[2] == "b__x.ulg"
    assert find_logs([tmp_path / "a"])[1][1] == "a__x.ulg"  # no clash without the duplicate: no suffix
    assert find_logs([tmp_path / "a" / "notes.ulg"])[0][1] == "notes.ulg"  # a file given by name is kept


def test_evidence_agrees_with_the_detected_probabilities(fleet):
    out, row = fleet["out"], fleet["row"]
    ev = json.loads((out / row["name"] / "evidence.json").read_text())["alarms"]
    rec = json.loads((out / row["name"] / "alarms.json").read_text())
    assert [e["start_s"] for e in ev] == [a["start_s"] for a in rec["alarms"]]
    from quadfdi.detect.evidence import alarm_windows

    with np.load(out / row["name"] / "windows.npz") as z:
        w = {k: z[k] for k in z.files}
    names = [str(c) for c in w["class_names"]]
    for e, a in zip(ev, rec["alarms"]):
        idx = alarm_windows(w, a)
        p = 1.0 - w["proba"][idx, names.index("Healthy")]
        assert e["windows"] == len(idx) > 0 and abs(e["p_fault"] - p.mean()) < 1e-3  # the same graph, re-run
        assert e["voting_windows"] == int((p >= e["threshold"]).sum())
        chans = [c for g in e["groups"] for c in g["channels"]]
        assert sorted(chans) == sorted(set(chans)) and len(chans) == 15  # flightlog-min: every input once
        assert all(abs(g["drop"] - (e["p_fault"] - g["p_fault"])) < 2e-4 for g in e["groups"])
        assert len(e["motor_shares"]) == 4 and abs(sum(s["during"] for s in e["motor_shares"]) - 4) < 0.05


def test_index_in_chromium_links_sorts_and_stays_offline(fleet, browser):
    out, row = fleet["out"], fleet["row"]
    _open(browser, out / "index.html")
    _check_clean(browser, out)
    link = browser.find_element("css selector", f'tr[data-name="{row["name"]}"] a')
    assert link.get_attribute("href") == (out / row["name"] / "index.html").resolve().as_uri()
    refused = browser.find_elements("css selector", "#refused tr")[1:]
    assert [r.find_element("css selector", "td").text for r in refused] == [str(fleet["logs"] / "broken.ulg")]
    assert fleet["summary"]["refused"][0]["reason"] in refused[0].text
    svg = browser.find_elements("css selector", f'tr[data-name="{row["name"]}"] svg polyline')
    assert svg, "no sparkline drawn"
    head = browser.find_elements("css selector", "#flights th.sortable")
    assert [h.text.strip() for h in head][:2] == ["flight", "vehicle"]
    worst = head[[h.text.strip() for h in head].index("worst p_fault")]
    order = []
    for _ in range(2):  # ascending, then descending
        worst.click()
        order.append([float(td.get_attribute("data-v")) for td in
                      browser.find_elements("css selector", "#flights tbody tr td:nth-child(8)")])
    assert len(order[0]) == 2 and order[0] == sorted(order[0]) and order[1] == sorted(order[0], reverse=True)
    link = browser.find_element("css selector", f'tr[data-name="{row["name"]}"] a')
    link.click()
    assert browser.current_url == (out / row["name"] / "index.html").resolve().as_uri()


def test_flight_page_in_chromium_shows_the_alarm_and_its_evidence(fleet, browser):
    out, row = fleet["out"], fleet["row"]
    page = out / row["name"] / "index.html"
    rec = json.loads((out / row["name"] / "alarms.json").read_text())
    _open(browser, page)
    drawn = browser.execute_script(
        "const d = document.getElementById('flight-plot');"
        "return {markers: d.data.filter(t => t.meta && t.meta.kind === 'alarm').map(t => [t.x[0], t.meta.class]),"
        " rects: d._fullLayout.shapes.filter(s => s.type === 'rect' && s.fillcolor.startsWith('rgba(220')).map(s => s.x0),"
        " panels: Object.keys(d._fullLayout).filter(k => /^yaxis\\d*$/.test(k)).length,"
        " evidence: Array.from(document.querySelectorAll('div.evidence')).map(e => [+e.dataset.startS,"
        "   document.getElementById('evidence-plot-' + e.id.split('-')[1]).data[0].y.length])}")
    _check_clean(browser, out)
    want = [[a["start_s"], a["class"]] for a in rec["alarms"]]
    assert drawn["markers"] == want and drawn["rects"] == [a["start_s"] for a in rec["alarms"]]
    assert drawn["panels"] >= 8  # attitude, rates, velocity, battery (2), motor shares, vibration, p(class)
    groups = len(json.loads((out / row["name"] / "evidence.json").read_text())["alarms"][0]["groups"])
    assert drawn["evidence"] == [[a["start_s"], groups] for a in rec["alarms"]]
    zoom = browser.find_element("css selector", "#alarm-1 a.zoom")
    zoom.click()
    rng = browser.execute_script("return document.getElementById('flight-plot')._fullLayout.xaxis.range")
    assert rng == pytest.approx([rec["alarms"][0]["start_s"] - 5, (rec["alarms"][0]["end_s"] or rng[1] - 5) + 5],
                                abs=0.01)


def test_run_report_html_in_chromium(flightlog_export, browser, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(flightlog_export.parent, run)
    res = quadfdi("report", "--run", str(run), "--html")
    assert res.returncode == 0, res.stderr
    assert (run / "report.md").is_file() and (run / "report.html").is_file() and (run / "plotly.min.js").is_file()
    _open(browser, run / "report.html")
    _check_clean(browser, run)
    heads = [h.text for h in browser.find_elements("css selector", "h2")]
    assert any("train" in h.lower() for h in heads), heads
    imgs = browser.execute_script("return Array.from(document.images).map(i => [i.getAttribute('src'), i.naturalWidth])")
    assert imgs and all(not src.startswith(("/", "http")) and width > 0 for src, width in imgs), imgs


def test_a_folder_without_logs_is_one_line_exit_2_and_writes_nothing(flightlog_export, tmp_path):
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "notes.txt").write_text("no log here\n")
    res = quadfdi("detect", "--model", str(flightlog_export), str(tmp_path / "logs"), "--out", str(tmp_path / "out"))
    assert res.returncode == 2 and "no flight log in" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_drawing_is_downsampled_but_keeps_every_extreme():
    from quadfdi.detect.flightplot import downsample

    t = np.arange(15000) * 0.04  # a 10-minute flight on the 25 Hz grid
    v = np.sin(t)
    v[7777], v[12345], v[3000:3100] = 9.0, -9.0, np.nan  # two one-sample spikes and a gap
    ts, vs = downsample(t, v, 1000)
    assert len(ts) <= 2000 and np.all(np.diff(ts) > 0)
    assert 9.0 in vs and -9.0 in vs and np.isnan(vs).any()  # the spikes survive, the gap stays a gap
    short = downsample(t[:500], v[:500], 1000)
    assert np.array_equal(short[0], t[:500]) and np.array_equal(short[1], v[:500])  # drawn as they are
