"""One alarm policy per network: [alarm.<net>] tables in the config, ``quadfdi
export --alarm-from evaluation``, the manifest's ``alarm_per_model``, weights.bin's ``alarm.models``
as Python and the C++ (fwref_stream --info --model) read it, an old record without the table, and
detect running each network's own policy. The session's flightlog-min export (tests/conftest.py) has
a GRU policy that is not the CNODE's (FLIGHTLOG_ALARM); the stream parity tests (tests/test_stream.py)
hold each network's alarms to Python's under its own policy."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

KEYS = ("threshold", "k", "n", "clear_m", "latch")


def _manifest(export: Path) -> dict:
    return json.loads((export / "manifest.json").read_text())


def _info(exe: Path, weights: Path, *args: str) -> dict:
    res = subprocess.run([str(exe / "fwref_stream"), "--weights", str(weights), "--info", *args], capture_output=True,
                         text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    return dict(line.split("=", 1) for line in res.stdout.splitlines())


def _policy(info: dict) -> dict:
    return {"threshold": float(info["threshold"]), "k": int(info["k"]), "n": int(info["n"]),
            "clear_m": int(info["clear_m"]), "latch": bool(int(info["latch"]))}


def test_config_tables_parse_validate_and_round_trip():
    import tomllib

    from quadfdi.core.config import build_config, dumps_toml

    cfg = build_config(tomllib.loads("[alarm]\nk = 1\nn = 2\n[alarm.gru]\nthreshold = 0.9\nn = 5\n"),
                       ["alarm.cnode.latch=true", "alarm.gru.k=3"])
    assert cfg.alarm.policy_for("gru") == {"threshold": 0.9, "k": 3, "n": 5, "clear_m": 3, "latch": False}
    assert cfg.alarm.policy_for("cnode") == {"threshold": 0.5, "k": 1, "n": 2, "clear_m": 3, "latch": True}
    assert cfg.alarm.policy_for("sgru") == cfg.alarm.policy() and not cfg.alarm.sgru
    assert build_config(tomllib.loads(dumps_toml(cfg))) == cfg  # the run folder's config.toml reads back
    assert "cnode" not in build_config({}).to_dict()["alarm"]  # no table given: the section as before
    for sets, msg in ((["alarm.gru.k=4"], "alarm.gru.k and alarm.gru.n must satisfy"),
                      (["alarm.cnode.threshold=0"], r"alarm.cnode.threshold must be in \(0, 1\]"),
                      (["alarm.gru.clear_m=0"], "alarm.gru.clear_m must be at least 1"),
                      (["alarm.gru.window=3"], "unknown key alarm.gru.window"),
                      (["alarm.lstm.k=1"], "unknown key alarm.lstm.k"),
                      (["alarm.gru.latch=2"], "alarm.gru.latch must be true or false"),
                      (["alarm.gru=3"], "alarm.gru must be a table")):
        with pytest.raises(QuadfdiError, match=msg):
            build_config({}, sets)


def test_record_table_round_trip_and_an_old_record():
    """alarm.models survives pack/unpack with a threshold float32 cannot hold; a record without it
    (written before it) reads every network as the single policy; a bad row is refused in one line."""
    from quadfdi.core.profiles import channel_names
    from quadfdi.formats.binfmt import Section, pack, unpack
    from quadfdi.formats.onboard import check_onboard, onboard_dict, onboard_section, policy_of

    default = {"threshold": 0.5, "k": 2, "n": 3, "clear_m": 3, "latch": False}
    per = {"cnode": {**default, "threshold": 0.1 + 0.2}, "sgru": {**default, "k": 5, "n": 8, "latch": True}}
    sec = onboard_section("flightlog-min", channel_names("flightlog-min", []), 40, 10, 0.04, default,
                          ["Healthy", "BatteryFault", "MotorFault"], per)
    (back,) = unpack(pack(b"QFDIWTS\0", 1, [sec]), b"QFDIWTS\0", 1, "w")[1]
    check_onboard(back, "w")
    rec = onboard_dict(back)
    assert rec["alarm_models"] == per and policy_of(rec, "cnode") == (per["cnode"], "alarm.models")
    assert policy_of(rec, "gru") == (default, "alarm.policy")  # a network the table omits
    old = Section(sec.model, sec.precision, sec.dims, {k: t for k, t in sec.tensors.items() if k != "alarm.models"})
    check_onboard(old, "w")
    assert onboard_dict(old)["alarm_models"] is None
    assert all(policy_of(onboard_dict(old), net) == (default, "alarm.policy") for net in ("cnode", "gru", "sgru"))
    for row, msg in (([1, 3, 2, 1, 0, 0, 1071644672], "not a valid policy"), ([7, 1, 1, 1, 0, 0, 1071644672], "names models")):
        bad = Section(sec.model, sec.precision, sec.dims, dict(old.tensors))
        bad.add("alarm.models", np.array([row], np.int32), np.int32)
        with pytest.raises(QuadfdiError, match=msg):
            check_onboard(bad, "w")
    from quadfdi.formats.onboard import ALARM_POLICY_COLUMNS

    for key, value in (("k", 4), ("k", 0), ("clear_m", 0), ("latch", 2)):  # the single policy is checked as a row is
        bad = Section(sec.model, sec.precision, sec.dims, dict(old.tensors))
        pol = bad.tensors["alarm.policy"].array.copy()
        pol[ALARM_POLICY_COLUMNS.index(key)] = value
        bad.add("alarm.policy", pol, np.int32)
        with pytest.raises(QuadfdiError, match="alarm.policy .* is not a valid policy"):
            check_onboard(bad, "w")


def test_cpp_refuses_an_invalid_single_policy_in_one_line(flightlog_export, host_build, tmp_path):  # noqa: F811
    """fwref_stream reads the record's single policy as strictly as an alarm.models row: k beyond n, one line, exit 2."""
    from quadfdi.formats.binfmt import pack, unpack
    from quadfdi.formats.onboard import ALARM_POLICY_COLUMNS
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    version, sections = unpack((flightlog_export / "weights.bin").read_bytes(), MAGIC, VERSION, "w")
    pol = sections[-1].tensors["alarm.policy"].array.copy()
    pol[ALARM_POLICY_COLUMNS.index("k")] = pol[ALARM_POLICY_COLUMNS.index("n")] + 1
    sections[-1].add("alarm.policy", pol, np.int32)
    bad = tmp_path / "weights.bin"
    bad.write_bytes(pack(MAGIC, version, sections))
    res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(bad), "--info"], capture_output=True,
                         text=True, timeout=60, check=False)
    assert res.returncode == 2 and "alarm.policy" in res.stderr and "not a valid policy" in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


def test_export_writes_each_networks_policy_and_cpp_reads_it(flightlog_export, host_build):  # noqa: F811
    """The session's export: manifest alarm_per_model (source "config"), the record's table, and
    fwref_stream --info --model picking each network's policy (the GRU's is not the CNODE's)."""
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.onboard import policy_of

    ex = Export.open(flightlog_export)
    m, rec = ex.manifest, ex.onboard()
    per = m["alarm_per_model"]
    assert sorted(per) == ["cnode", "gru"] and {p["source"] for p in per.values()} == {"config"}
    assert per["cnode"]["policy"] == m["alarm"] != per["gru"]["policy"]
    assert per["gru"]["policy"] == {"threshold": 0.4, "k": 1, "n": 2, "clear_m": 2, "latch": False}
    for net in ("cnode", "gru"):
        info = _info(host_build, flightlog_export / "weights.bin", "--model", net)
        assert _policy(info) == per[net]["policy"] == policy_of(rec, net)[0] and info["policy_from"] == "alarm.models"
        assert ex.policy(net) == (per[net]["policy"], "config")  # the manifest side: the same rule, the same policy
    plain = _info(host_build, flightlog_export / "weights.bin")
    assert _policy(plain) == m["alarm"] and plain["policy_from"] == "alarm.policy"
    assert plain["alarm_models"] == "cnode:0.5,2,3,3,0;gru:0.40000000000000002,1,2,2,0"


def _strip_table(export: Path, dst: Path) -> Path:
    """export's weights.bin without alarm.models: a record written before the table."""
    from quadfdi.formats.binfmt import Section, pack, read_file
    from quadfdi.formats.weights_layout import MAGIC, VERSION

    _, sections = read_file(export / "weights.bin", MAGIC, VERSION, "weights file")
    rec = sections[-1]
    old = Section(rec.model, rec.precision, rec.dims, {k: t for k, t in rec.tensors.items() if k != "alarm.models"})
    dst.mkdir()
    (dst / "weights.bin").write_bytes(pack(MAGIC, VERSION, sections[:-1] + [old]))
    return dst


def test_cpp_reads_an_old_record_as_one_policy_for_every_model(flightlog_export, host_build, tmp_path):  # noqa: F811
    from quadfdi.formats.export_folder import read_record

    folder = _strip_table(flightlog_export, tmp_path / "old")
    rec = read_record(folder / "weights.bin")
    assert rec["alarm_models"] is None
    for net in ("cnode", "gru", "sgru"):
        info = _info(host_build, folder / "weights.bin", "--model", net)
        assert _policy(info) == rec["alarm"] == _manifest(flightlog_export)["alarm"]
        assert info["policy_from"] == "alarm.policy" and info["alarm_models"] == "none"


def _eval_json(run: Path, models: dict) -> str:
    """Publish an evaluation.json choosing ``models`` as the run's evaluate stage (core.stage), as
    ``quadfdi evaluate`` would; its sha256."""
    from quadfdi.core.rundir import EVALUATION_JSON
    from quadfdi.core.stage import stage

    data = json.dumps({"schema_version": 1, "models": {m: {"network": True, "policy": p} for m, p in models.items()}})
    with stage(run, "evaluate", {}) as st:
        st.path(EVALUATION_JSON).write_text(data)
    return hashlib.sha256(data.encode()).hexdigest()


@pytest.fixture(scope="module")
def run_copy(flightlog_export, tmp_path_factory) -> Path:
    """The flightlog run with its export (a copy: these tests export into it)."""
    dst = tmp_path_factory.mktemp("pernet") / "run"
    shutil.copytree(flightlog_export.parent, dst)
    return dst


def test_alarm_from_evaluation_refuses_a_missing_file_or_network(run_copy, capsys):
    """Exit 2, one line, the export folder untouched (the CLI in process: a subprocess costs seconds)."""
    from quadfdi.cli import main

    before = (run_copy / "export" / "manifest.json").read_bytes()
    argv = ["export", "--run", str(run_copy), "--alarm-from", "evaluation"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "evaluation.json does not exist" in err and len(err.strip().splitlines()) == 1, err
    _eval_json(run_copy, {"cnode": {"threshold": 0.7, "k": 1, "n": 1, "clear_m": 3, "latch": False}})
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "no chosen policy for network 'gru'" in err and len(err.strip().splitlines()) == 1, err
    # a complete evaluation.json that no evaluate stage published (edited by hand after it): refused
    sha = _eval_json(run_copy, CHOSEN)
    (run_copy / "evaluation" / "evaluation.json").write_text(json.dumps({"models": {
        net: {"policy": {**p, "threshold": 0.2}} for net, p in CHOSEN.items()}}))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"differs from {sha[:16]}... recorded in .stages/evaluate.json" in err and len(err.strip().splitlines()) == 1, err
    assert (run_copy / "export" / "manifest.json").read_bytes() == before
    shutil.rmtree(run_copy / "evaluation")
    (run_copy / ".stages" / "evaluate.json").unlink()


CHOSEN = {"cnode": {"threshold": 0.97, "k": 3, "n": 5, "clear_m": 8, "latch": False},
          "gru": {"threshold": 0.7, "k": 1, "n": 1, "clear_m": 3, "latch": True},
          "sgru": {"threshold": 0.9, "k": 2, "n": 3, "clear_m": 3, "latch": False}}


@pytest.fixture(scope="module")
def chosen_export(flightlog_export, tmp_path_factory):
    """Another copy of the run exported with --alarm-from evaluation (an evaluation.json choosing CHOSEN):
    (run folder, manifest, evaluation.json's sha256, the config). In process, in the fixture: the export
    imports torch and onnx, seconds on a loaded machine."""
    from quadfdi.core.rundir import open_run
    from quadfdi.export.run import export_run

    dst = tmp_path_factory.mktemp("pernet_chosen") / "run"
    shutil.copytree(flightlog_export.parent, dst)
    sha = _eval_json(dst, CHOSEN)
    run, cfg = open_run(dst, [])
    return dst, export_run(run, cfg, log=lambda s: None, alarm_from="evaluation"), sha, cfg


def test_alarm_from_evaluation_writes_the_chosen_policies(chosen_export):
    """Each network's validation-chosen policy in the manifest (with evaluation.json's sha256) and in
    weights.bin's table; the default ``alarm`` stays the config's; detect runs each network's own."""
    from quadfdi.detect.run import detect
    from quadfdi.formats.onboard import onboard_dict
    from quadfdi.formats.weights_bin import read_weights
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.sim.flight_npz import flight_arrays

    run, m, sha, cfg = chosen_export
    assert {net: e["policy"] for net, e in m["alarm_per_model"].items()} == CHOSEN
    assert {e["source"] for e in m["alarm_per_model"].values()} == {f"evaluation.json sha256 {sha}"}
    assert m["alarm"] == cfg.alarm.policy()
    assert onboard_dict(read_weights(run / "export" / "weights.bin").onboard)["alarm_models"] == CHOSEN
    flight = flight_arrays(load_dataset(run / "dataset.npz").arrays, 0, "dataset.npz")
    for net in ("cnode", "gru"):
        rec = detect(run / "export", flight, net=net)["record"]
        assert rec["policy"] == CHOSEN[net] and rec["policy_source"] == f"evaluation.json sha256 {sha}"


def test_evaluation_json_is_an_input_of_the_export_stage(chosen_export):
    """The export's stage record lists evaluation.json with the sha256 its policies name; once evaluate
    publishes another evaluation.json, every export output is stale for the stages that read it."""
    from quadfdi.core.records import load_record, verify_input
    from quadfdi.core.rundir import EVALUATION_JSON

    run, m, sha, _ = chosen_export
    inputs = {i["path"]: i for i in load_record(run, "export")["inputs"]}
    assert inputs[EVALUATION_JSON] == {"path": EVALUATION_JSON, "sha256": sha, "stage": "evaluate"}
    assert sorted(inputs) == ["cnode.pt", "dataset.npz", EVALUATION_JSON, "gru.pt"]
    verify_input(run, "export/manifest.json")  # what parity and bench check before reading the export
    _eval_json(run, {**CHOSEN, "gru": {**CHOSEN["gru"], "k": 2, "n": 3}})
    with pytest.raises(QuadfdiError, match=r"made from evaluation/evaluation.json .* re-run quadfdi export"):
        verify_input(run, "export/manifest.json")


def test_an_export_from_the_config_does_not_read_evaluation_json(flightlog_export):
    from quadfdi.core.records import load_record

    assert all(not i["path"].startswith("evaluation/") for i in load_record(flightlog_export.parent, "export")["inputs"])
