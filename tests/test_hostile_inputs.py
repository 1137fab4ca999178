"""Inputs that must never pass as success nor reach a traceback: flights whose time axis is
reversed, stretched or NaN, an output that is its own input, an export manifest naming a file
outside its folder, and ingest arguments out of range. Each ends in one line and exit 2, with
nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from quadfdi.formats.flight import load_flight, write_flight
from tests.conftest import SHARED_DATA, quadfdi
from tests.faultkit import one_line_error

MISSION = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"
pytestmark = pytest.mark.skipif(not MISSION.is_file(), reason="the shared real flight logs are not here")



@pytest.mark.parametrize("case, change, words", [
    ("reversed", lambda t: t[::-1].copy(), "goes backwards"),
    ("stretched x3", lambda t: t * 3.0, "steps by 0.12"),
    ("NaN times", lambda t: np.where(np.arange(len(t)) == 7, np.nan, t), "NaN"),
    ("duplicated", lambda t: np.concatenate([t[:5], t[4:-1]]), "repeats"),
])
def test_detect_refuses_a_bad_time_axis(flightlog_export, mission_npz, tmp_path, case, change, words):
    arrays = dict(load_flight(mission_npz))
    arrays["time"] = change(np.asarray(arrays["time"]))
    bad = tmp_path / "flight.npz"
    write_flight(bad, arrays)
    out = tmp_path / "out"
    res = quadfdi("detect", "--model", str(flightlog_export), str(bad), "--out", str(out))
    one_line_error(res)
    assert words in res.stderr and not out.exists(), case


def test_stream_file_refuses_to_overwrite_its_input(flightlog_export, mission_npz, tmp_path):
    flight = tmp_path / "flight.npz"
    shutil.copy(mission_npz, flight)
    before = flight.read_bytes()
    res = quadfdi("stream-file", "--model", str(flightlog_export), str(flight), "--out", str(flight))
    one_line_error(res)
    assert "refusing to overwrite" in res.stderr and flight.read_bytes() == before


def test_a_manifest_artifact_outside_the_export_is_refused(flightlog_export, mission_npz, tmp_path):
    export = tmp_path / "export"
    shutil.copytree(flightlog_export, export)
    m = json.loads((export / "manifest.json").read_text())
    m["artifacts"]["cnode_fp32"] = "../../../../etc/passwd"
    (export / "manifest.json").write_text(json.dumps(m))
    res = quadfdi("detect", "--model", str(export), str(mission_npz), "--out", str(tmp_path / "out"))
    one_line_error(res)
    assert "not a file of the export folder" in res.stderr


@pytest.mark.parametrize("value", ["nan", "-5", "inf"])
def test_ingest_refuses_a_minimum_airborne_out_of_range(tmp_path, value):
    res = quadfdi("ingest", str(MISSION), "--out", str(tmp_path / "f"), "--min-airborne", value)
    one_line_error(res)
    assert "--min-airborne" in res.stderr and not (tmp_path / "f").exists()


def test_ingest_names_a_folder_given_as_the_log(tmp_path):
    res = quadfdi("ingest", str(tmp_path), "--out", str(tmp_path / "f"))
    one_line_error(res)
    assert "is a folder, not a log file" in res.stderr


@pytest.mark.parametrize("setting, words", [
    ("train.latent=1e12", "train.latent must be an integer"),
    ("train.latent=100000", "train.latent must be at most 128"),
    ("train.gru_hidden=100000000", "train.gru_hidden must be at most 256"),
    ("sgru.hidden=4096", "sgru.hidden must be at most 256"),
    ("train.epochs=10000000000", "at most 1e+09"),
    ("sim.window=100000", "sim.window must be at most 256"),
])
def test_config_sizes_have_upper_bounds_checked_before_the_compute(tmp_path, setting, words):
    """The whole config is checked when a command loads it: ``quadfdi sim`` refuses a [train] size too."""
    res = quadfdi("sim", "--out", str(tmp_path / "run"), "--set", setting)
    one_line_error(res)
    assert words in res.stderr and not (tmp_path / "run").exists()


def test_the_size_bounds_are_the_firmwares_capacities():
    import re

    from quadfdi.core import limits
    from quadfdi.core.resources import firmware_sources

    text = (firmware_sources() / "include" / "fwref" / "config.hpp").read_text()
    defaults = {m.group(1): int(m.group(2)) for m in re.finditer(r"#define FWREF_MAX_(\w+) (\d+)", text)}
    assert (limits.MAX_LATENT, limits.MAX_CNODE_HIDDEN, limits.MAX_GRU_HIDDEN, limits.MAX_WINDOW,
            limits.FIRMWARE_MAX_STEPS) == (defaults["LATENT"], defaults["CNODE_HIDDEN"], defaults["GRU_HIDDEN"],
                                           defaults["WINDOW"], defaults["STEPS"])


def test_detect_on_an_interrupted_export_names_quadfdi_check(flightlog_export, mission_npz, tmp_path):
    """New ONNX files beside the old manifest (an export killed after its commit point): detect refuses
    and names `quadfdi check`; after check has rolled the publish forward, detect reads the export."""
    run = tmp_path / "run"
    shutil.copytree(flightlog_export.parent, run, ignore=shutil.ignore_patterns(".lock"))
    pub = run / ".publish" / "export"
    shutil.copytree(run / "export", pub / "export")
    rec = json.loads((run / ".stages" / "export.json").read_text())
    (pub / "record.json").write_text(json.dumps(rec))
    res = quadfdi("detect", "--model", str(run / "export"), str(mission_npz), "--out", str(tmp_path / "out"))
    one_line_error(res)
    assert "quadfdi check" in res.stderr
    assert quadfdi("check", "--run", str(run)).returncode == 0
    res = quadfdi("detect", "--model", str(run / "export"), str(mission_npz), "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr


def test_a_non_onnx_artifact_with_its_hash_in_the_manifest_is_one_line(flightlog_export, mission_npz, tmp_path):
    """The manifest vouches for the bytes, not for them being a graph: ONNX Runtime's protobuf error
    becomes one line."""
    import hashlib

    export = tmp_path / "export"
    shutil.copytree(flightlog_export, export)
    m = json.loads((export / "manifest.json").read_text())
    name = m["artifacts"]["cnode_fp32"]
    data = b"not a graph, but hashed\n" * 40
    (export / name).write_bytes(data)
    m["files"][name] = {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    (export / "manifest.json").write_text(json.dumps(m))
    res = quadfdi("detect", "--model", str(export), str(mission_npz), "--out", str(tmp_path / "out"))
    one_line_error(res)
    assert "not a loadable ONNX graph" in res.stderr
