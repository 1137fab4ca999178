"""Windowed or streaming chosen on validation (evaluation.json ``deployment``) and the comparison table
(report.md, README block), on a tiny realistic run whose prediction sets are real fitted logistic
regressions written with formats.predictions, named as the four networks and one baseline.

The informative sets are a fitted model's probabilities; a wrong one is the same probabilities with the
class columns rotated by one (a real prediction set whose every decision names the next class), so
which member wins validation is known in advance without fixing any number."""

from __future__ import annotations

import hashlib
import json
import shutil

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from quadfdi.core.config import dumps_toml, load_config
from quadfdi.core.npzio import write_npz
from quadfdi.formats.dataset import dataset_arrays, load_dataset, make_windows, split_names
from quadfdi.formats.predictions import add_entries, prediction_path
from quadfdi.sim.simulate import generate
from quadfdi.train.baseline import window_features
from tests.conftest import ROOT, quadfdi

SMALL = ["sim.n_traj=24", "sim.ood_traj=3", "sim.duration_s=16.0", "sim.chunk=36", "sim.window=40", "sim.stride=10"]
FAST = ["--set", "evaluate.bootstrap=1000", "--set", "evaluate.thresholds=[0.5, 0.9]",
        "--set", "evaluate.kn=['1/1', '2/3']", "--set", "evaluate.clear_m=[2]"]


def _fitted(ds) -> dict:
    tr = make_windows(ds, "train")
    clf = make_pipeline(StandardScaler(), LogisticRegression(C=1.0, max_iter=1000))
    clf.fit(window_features(tr.x.astype(float)), tr.y)
    parts = []
    for name in split_names(ds.arrays)[1:]:
        w = make_windows(ds, name)
        p = np.zeros((len(w.y), len(ds["class_names"])), np.float32)
        p[:, clf.classes_] = clf.predict_proba(window_features(w.x.astype(float)))
        parts.append((p, w))
    traj = np.concatenate([w.traj for _, w in parts])
    return {"proba": np.concatenate([p for p, _ in parts]), "y_true": np.concatenate([w.y for _, w in parts]),
            "traj": traj, "t_end": np.concatenate([w.t_end for _, w in parts]),
            "split": ds["split"][traj].astype(np.int8), "class_names": ds["class_names"]}


def _rotated(arrays: dict) -> dict:
    out = dict(arrays)
    out["proba"] = np.roll(arrays["proba"], 1, axis=1)
    return out


@pytest.fixture(scope="module")
def sets(tmp_path_factory):
    """One tiny realistic dataset, and its fitted and rotated prediction sets."""
    root = tmp_path_factory.mktemp("deploy_data")
    cfg = load_config(ROOT / "configs/realistic.toml", SMALL)
    write_npz(root / "dataset.npz", dataset_arrays(generate(cfg.sim), cfg.sim))
    (root / "config.toml").write_text(dumps_toml(cfg))
    good = _fitted(load_dataset(root / "dataset.npz"))
    return root, {"good": good, "bad": _rotated(good)}


def _run(sets, dst, models: dict[str, str]):
    """A run folder holding the dataset and ``models`` (name -> "good" or "bad"), evaluated."""
    src, arrays = sets
    dst.mkdir(parents=True)
    for name in ("dataset.npz", "config.toml"):
        shutil.copy(src / name, dst / name)
    entries = []
    for model, kind in models.items():
        path = prediction_path(dst, model, 0, 0)
        path.parent.mkdir(exist_ok=True)
        write_npz(path, arrays[kind])
        entries.append({"model": model, "sim_seed": 0, "train_seed": 0, "dataset": "dataset.npz",
                        "predictions": str(path.relative_to(dst))})
    add_entries(dst, entries)
    res = quadfdi("evaluate", "--run", str(dst), *FAST)
    assert res.returncode == 0, res.stderr
    return dst, json.loads((dst / "evaluation/evaluation.json").read_text())


@pytest.fixture(scope="module")
def both(sets, tmp_path_factory):
    """Streaming CNODE informative and windowed CNODE not; the GRUs the other way round; one baseline."""
    return _run(sets, tmp_path_factory.mktemp("deploy") / "both",
                {"cnode": "bad", "scnode": "good", "gru": "good", "sgru": "bad", "logreg": "good"})


@pytest.fixture(scope="module")
def windowed_only(sets, tmp_path_factory):
    """No streaming CNODE set; the streaming GRU's set the same as the windowed GRU's (a tie)."""
    return _run(sets, tmp_path_factory.mktemp("deploy") / "windowed", {"cnode": "good", "gru": "good", "sgru": "good",
                                                                       "logreg": "bad"})


def _val(ev, model):
    return next(r for r in ev["results"] if r["model"] == model and r["set"] == "validation")["metrics"]["macro_f1"]


def test_the_streaming_member_that_wins_validation_is_deployed(both):
    root, ev = both
    fam = ev["deployment"]["families"]["cnode"]
    assert _val(ev, "scnode")["value"] > _val(ev, "cnode")["value"]
    assert fam["chosen"] == "scnode" and fam["members"] == ["cnode", "scnode"] and fam["not_candidates"] == {}
    for m in ("cnode", "scnode"):  # each candidate's score is evaluate's own validation figure, interval included
        assert fam["candidates"][m]["macro_f1"] == _val(ev, m)
        (ps,) = fam["candidates"][m]["prediction_sets"]
        assert ps["path"] == f"predictions/{m}_sim0_train0.npz"
        assert ps["sha256"] == hashlib.sha256((root / ps["path"]).read_bytes()).hexdigest()
    c = fam["streaming_minus_windowed_common_flights"]
    assert c["diff"] == pytest.approx(_val(ev, "scnode")["value"] - _val(ev, "cnode")["value"])
    md = (root / "evaluation/evaluation.md").read_text()
    assert "| cnode | streaming CNODE (scnode) |" in md and "**deployed**" in md


def test_the_windowed_member_that_wins_validation_is_deployed(both):
    _, ev = both
    fam = ev["deployment"]["families"]["gru"]
    assert _val(ev, "gru")["value"] > _val(ev, "sgru")["value"]
    assert fam["chosen"] == "gru" and set(fam["candidates"]) == {"gru", "sgru"}


def test_without_a_streaming_set_and_on_a_tie_the_windowed_member_is_deployed(windowed_only):
    _, ev = windowed_only
    cnode, gru = ev["deployment"]["families"]["cnode"], ev["deployment"]["families"]["gru"]
    assert cnode["chosen"] == "cnode" and list(cnode["candidates"]) == ["cnode"]
    assert "no prediction set" in cnode["not_candidates"]["scnode"]
    assert cnode["streaming_minus_windowed_common_flights"] is None
    assert _val(ev, "gru")["value"] == _val(ev, "sgru")["value"]  # the same windows' probabilities
    assert gru["chosen"] == "gru"


def test_comparison_block_reads_every_figure_from_the_evaluation(both, tmp_path):
    root, ev = both
    readme = tmp_path / "README.md"
    readme.write_text("head\n<!-- comparison:start -->\nplaceholder\n<!-- comparison:end -->\ntail\n")
    res = quadfdi("readme", "--run", str(root), "--block", "comparison", "--readme", str(readme))
    assert res.returncode == 0, res.stderr
    text = readme.read_text()
    assert text.startswith("head\n<!-- comparison:start -->\n") and text.endswith("<!-- comparison:end -->\ntail\n")
    block = text.split("<!-- comparison:start -->\n")[1].split("<!-- comparison:end -->")[0].splitlines()
    assert len(block) < 20 and max(len(line) for line in block) <= 100
    rows = {r.split("|")[1]: r.split("|")[2:-1] for r in block if r.startswith("|") and not r.startswith("|-")}
    assert list(rows)[:6] == ["model", "windowed CNODE", "streaming CNODE", "windowed GRU", "streaming GRU",
                              "logreg (best)"]
    test = {r["model"]: r for r in ev["results"] if r["set"] == "test"}
    for label, model in (("windowed CNODE", "cnode"), ("streaming GRU", "sgru"), ("logreg (best)", "logreg")):
        m = test[model]["metrics"]["macro_f1"]
        assert rows[label][0] == f"{100 * m['value']:.1f} [{100 * m['lo']:.1f},{100 * m['hi']:.1f}]"
        fa = test[model]["false_alarms"]
        assert rows[label][3] == f"{fa['rate_per_h']:.2f} [{fa['poisson_lo']:.2f},{fa['poisson_hi']:.2f}]"
    assert [rows[k][-1] for k in ("windowed CNODE", "streaming CNODE", "windowed GRU", "streaming GRU")] == \
        ["", "✓", "✓", ""]
    # no on-board figure in this run: every network's cost cell is a footnoted dash, never a number
    marks = {rows[k][-2] for k in ("windowed CNODE", "streaming CNODE", "windowed GRU", "streaming GRU")}
    assert len(marks) == 1 and next(iter(marks)).startswith("—(")
    note = int(next(iter(marks))[2:-1])
    assert f"({note}) no cycle or MAC figure" in " ".join(block)
    assert rows["logreg (best)"][1].startswith("—(")  # the best baseline against itself: a dash with its reason
    # the paired cell of a network is evaluation.json's paired difference against the best baseline
    p = next(p for p in ev["paired"] if p["set"] == "test" and {p["a"], p["b"]} == {"gru", "logreg"})
    sign = 1 if p["a"] == "gru" else -1
    assert rows["windowed GRU"][1].startswith(f"{100 * sign * p['diff']['macro_f1']['diff']:+.1f} [")


def test_comparison_into_a_named_block_leaves_the_other_alone(both, tmp_path):
    """``--marker`` writes the comparison into another block of the file (a second run's table) and quotes
    the command with it; the file's ``comparison`` block is left as it was."""
    root, _ = both
    readme = tmp_path / "README.md"
    first = "<!-- comparison:start -->\nthe fleet's table\n<!-- comparison:end -->\n"
    readme.write_text(first + "<!-- comparison-paper:start -->\n<!-- comparison-paper:end -->\n")
    res = quadfdi("readme", "--run", str(root), "--block", "comparison", "--marker", "comparison-paper",
                  "--readme", str(readme))
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"wrote the comparison-paper block of {readme}"
    text = readme.read_text()
    assert text.startswith(first)
    assert "--block comparison --marker comparison-paper` from" in " ".join(text.split())
    res = quadfdi("readme", "--run", str(root), "--block", "comparison", "--marker", "absent", "--readme", str(readme))
    assert res.returncode != 0 and len(res.stderr.strip().splitlines()) == 1 and readme.read_text() == text


def test_comparison_costs_cycles_first_then_macs(both, tmp_path):
    """The M4 cycle figure of parity's outputs wins over a MAC count; a record's MACs fill in otherwise."""
    from quadfdi.comparison import costs

    root = tmp_path / "run"
    shutil.copytree(both[0], root)
    (root / "parity").mkdir()
    (root / "parity/mcu_stream.json").write_text(json.dumps(
        {"cores": {"cortex-m4": {"models": {"gru_int8": {"clock_mhz": 168.0, "cycles": {"duty": 0.01}}}}}}))
    (root / "parity/scnode_mcu.json").write_text(json.dumps(
        {"sample_period_s": 0.04, "cost": {"int8": {"cycles_mean": 20000.0}}}))
    (root / "predictions/sgru_sim0_train0.json").write_text(json.dumps(
        {"compute": [{"model": "sgru", "macs_per_s": 2.5e6}, {"model": "gru", "macs_per_s": 9e6}]}))
    cells, used = costs(root)
    assert cells == {"gru": "1.68M cyc", "scnode": "0.50M cyc", "sgru": "2.50M MAC"}
    assert used == ["parity/mcu_stream.json", "parity/scnode_mcu.json", "predictions/sgru_sim0_train0.json"]


def test_report_section_has_both_sets_and_a_one_line_error_without_evaluation(both, tmp_path):
    from quadfdi.comparison import report_section

    text = "\n".join(report_section(both[0]))
    assert "### test (" in text and "### test_ood_all (" in text and "streaming CNODE (scnode)" in text
    assert "Not run" in "\n".join(report_section(tmp_path))
    readme = tmp_path / "README.md"
    readme.write_text("<!-- comparison:start -->\nx\n<!-- comparison:end -->\n")
    res = quadfdi("readme", "--run", str(tmp_path), "--block", "comparison", "--readme", str(readme))
    assert res.returncode == 2 and "evaluation.json is missing" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and "x\n" in readme.read_text()
