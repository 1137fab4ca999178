"""manifest.json ``deployment``: the export records the windowed-or-streaming choice of a real
``quadfdi evaluate`` with that evaluation.json's sha256, says null and why without one, and refuses an
evaluation.json edited after it was published (export/deployment.py, formats/manifest.py)."""

from __future__ import annotations

import hashlib
import json
import shutil

import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.manifest import better_network, deployed, load_manifest
from tests.conftest import quadfdi

FAST = ["--set", "evaluate.bootstrap=1000", "--set", "evaluate.thresholds=[0.5, 0.9]",
        "--set", "evaluate.kn=['1/1']", "--set", "evaluate.clear_m=[2]"]


def test_an_export_without_evaluation_records_no_deployment_and_why(flightlog_export):
    m = load_manifest(flightlog_export / "manifest.json")
    assert m["deployment"] is None
    assert m["deployment_note"].startswith("no evaluation/evaluation.json when exported")
    with pytest.raises(QuadfdiError, match="the export records no deployed member: no evaluation/evaluation.json"):
        deployed(m, flightlog_export.parent / "evaluation/evaluation.json")


@pytest.fixture(scope="module")
def evaluated_export(flightlog_export, tmp_path_factory):
    """A copy of the flightlog run evaluated by the real CLI, then exported in process."""
    from quadfdi.core.rundir import open_run
    from quadfdi.export.run import export_run

    dst = tmp_path_factory.mktemp("deploy_export") / "run"
    shutil.copytree(flightlog_export.parent, dst)
    res = quadfdi("evaluate", "--run", str(dst), *FAST)
    assert res.returncode == 0, res.stderr
    run, cfg = open_run(dst, [])
    return dst, export_run(run, cfg, log=lambda s: None)


def test_the_export_records_the_evaluations_choice_and_its_sha256(evaluated_export):
    from quadfdi.core.records import load_record

    root, manifest = evaluated_export
    ev_bytes = (root / "evaluation/evaluation.json").read_bytes()
    ev = json.loads(ev_bytes)
    dep = load_manifest(root / "export/manifest.json")["deployment"]
    assert dep == manifest["deployment"] and "deployment_note" not in manifest
    assert dep["evaluation_sha256"] == hashlib.sha256(ev_bytes).hexdigest()
    for fam, f in ev["deployment"]["families"].items():
        assert dep["families"][fam]["chosen"] == f["chosen"]
        assert {m: c["macro_f1"] for m, c in dep["families"][fam]["candidates"].items()} == \
            {m: c["macro_f1"] for m, c in f["candidates"].items()}
    # the run trained windowed networks only: each family deploys its windowed member
    assert deployed(manifest, root / "evaluation/evaluation.json") == {"cnode": "cnode", "gru": "gru"}
    inputs = {i["path"]: i["sha256"] for i in load_record(root, "export")["inputs"]}
    assert inputs["evaluation/evaluation.json"] == dep["evaluation_sha256"]


def test_a_changed_evaluation_json_is_refused_in_one_line(evaluated_export, tmp_path, capsys):
    from quadfdi.cli import main

    src, manifest = evaluated_export
    root = tmp_path / "run"
    shutil.copytree(src, root)
    path = root / "evaluation/evaluation.json"
    ev = json.loads(path.read_text())
    ev["deployment"]["families"]["cnode"]["chosen"] = None  # edited by hand after it was published
    path.write_text(json.dumps(ev))
    with pytest.raises(QuadfdiError, match=r"^.*evaluation.json is sha256 [0-9a-f]{16}\.\.\., the export's deployment"):
        deployed(manifest, path)
    before = (root / "export/manifest.json").read_bytes()
    assert main(["export", "--run", str(root)]) == 2
    err = capsys.readouterr().err
    assert "differs from" in err and "recorded in .stages/evaluate.json" in err and len(err.strip().splitlines()) == 1
    assert (root / "export/manifest.json").read_bytes() == before


def test_the_manifest_reader_refuses_a_deployment_outside_its_candidates(evaluated_export, tmp_path):
    root, manifest = evaluated_export
    bad = json.loads(json.dumps(manifest))
    bad["deployment"]["families"]["gru"]["chosen"] = "sgru"  # not a candidate of this run
    (tmp_path / "manifest.json").write_text(json.dumps(bad))
    with pytest.raises(QuadfdiError, match="deployment.families.gru chooses a member that is not a candidate"):
        load_manifest(tmp_path / "manifest.json")


def test_detect_runs_the_network_with_the_higher_validation_score_unless_told(evaluated_export):
    _, manifest = evaluated_export
    cands = {n: manifest["deployment"]["families"][n]["candidates"][n]["macro_f1"]["value"] for n in ("cnode", "gru")}
    net, why = better_network(manifest)
    assert net == ("gru" if cands["gru"] > cands["cnode"] else "cnode")
    assert f"cnode {cands['cnode']:.4f}, gru {cands['gru']:.4f}" in why
    edited = json.loads(json.dumps(manifest))
    c = cands["cnode"]
    for value, expected in ((c + 0.01, "gru"), (c - 0.01, "cnode"), (c, "cnode")):
        edited["deployment"]["families"]["gru"]["candidates"]["gru"]["macro_f1"]["value"] = value
        assert better_network(edited)[0] == expected  # a tie goes to the CNODE
    del edited["deployment"]["families"]["gru"]
    assert better_network(edited) == ("cnode", "the export records no validation scores to choose by "
                                               "(no validation score for both windowed networks)")
