"""quadfdi evaluate end to end on a tiny realistic suite (two simulator seeds) with real fitted
logistic-regression models: sets, pooling, intervals, the validation-only policy, paired
differences, the ceiling, provenance, and the one-line error of an empty index."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import f1_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from quadfdi.core.config import dumps_toml, load_config
from quadfdi.core.npzio import write_npz
from quadfdi.formats.predictions import add_entries, prediction_path
from quadfdi.formats.dataset import dataset_arrays, load_dataset, make_windows, split_names
from quadfdi.sim.simulate import generate
from tests.conftest import ROOT, quadfdi
from quadfdi.train.baseline import window_features

SMALL = ["sim.n_traj=24", "sim.ood_traj=3", "sim.duration_s=16.0", "sim.chunk=36", "sim.window=40", "sim.stride=10"]
MODELS = {"lrnet": 1.0, "logreg": 1e-3}  # name -> inverse regularisation C
FAST = ["--set", "evaluate.bootstrap=1000", "--set", "evaluate.thresholds=[0.5, 0.9]",
        "--set", "evaluate.kn=['1/1', '2/3']", "--set", "evaluate.clear_m=[2]", "--set", "evaluate.networks=['lrnet']"]


def _predict(ds, c: float, seed: int) -> dict:
    tr = make_windows(ds, "train")
    rng = np.random.default_rng(seed)
    sub = rng.choice(len(tr.y), size=int(0.8 * len(tr.y)), replace=False)  # train seeds differ by their subset
    clf = make_pipeline(StandardScaler(), LogisticRegression(C=c, max_iter=1000))
    clf.fit(window_features(tr.x[sub].astype(float)), tr.y[sub])
    parts = []
    for name in split_names(ds.arrays)[1:]:
        w = make_windows(ds, name)
        p = np.zeros((len(w.y), len(ds["class_names"])), np.float32)
        p[:, clf.classes_] = clf.predict_proba(window_features(w.x.astype(float)))
        parts.append((p, w))
    motor = [np.abs(np.sin(np.arange(len(w.y))[:, None] + np.arange(4))) for _, w in parts]
    motor = np.concatenate(motor).astype(np.float32)
    return {"proba": np.concatenate([p for p, _ in parts]), "y_true": np.concatenate([w.y for _, w in parts]),
            "traj": np.concatenate([w.traj for _, w in parts]), "t_end": np.concatenate([w.t_end for _, w in parts]),
            "split": ds["split"][np.concatenate([w.traj for _, w in parts])].astype(np.int8),
            "class_names": ds["class_names"], "motor_proba": motor / motor.sum(1, keepdims=True)}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("evaluate") / "run"
    root.mkdir()
    entries = []
    for sim_seed, rel in ((0, "dataset.npz"), (1, "sim1/dataset.npz")):
        cfg = load_config(ROOT / "configs/realistic.toml", SMALL + [f"sim.seed={sim_seed}"])
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        write_npz(root / rel, dataset_arrays(generate(cfg.sim), cfg.sim))
        if sim_seed == 0:
            (root / "config.toml").write_text(dumps_toml(cfg))
        ds = load_dataset(root / rel)
        for model, c in MODELS.items():
            for train_seed in (0, 1):
                path = prediction_path(root, model, sim_seed, train_seed)
                path.parent.mkdir(exist_ok=True)
                write_npz(path, _predict(ds, c, train_seed))
                entries.append({"model": model, "sim_seed": sim_seed, "train_seed": train_seed, "dataset": rel,
                                "predictions": str(path.relative_to(root))})
    add_entries(root, entries)
    res = quadfdi("evaluate", "--run", str(root), *FAST)
    assert res.returncode == 0, res.stderr
    return root


def _ev(root):
    return json.loads((root / "evaluation/evaluation.json").read_text())


def test_files_sets_and_provenance(run):
    ev = _ev(run)
    assert (run / "evaluation/evaluation.md").read_text().startswith("# Evaluation")
    assert (run / "evaluation/alarm_sweep.png").stat().st_size > 1000
    assert len(ev["git_commit"]) == 40 and isinstance(ev["git_dirty"], bool)
    sets = {r["set"] for r in ev["results"]}
    assert sets == {"validation", "test", "test_ood_mission", "test_ood_vehicle", "test_ood_wind", "test_incipient",
                    "test_ood_all"}
    assert len(ev["per_seed"]) == len(ev["results"]) * 4  # 2 sim seeds x 2 train seeds per model x set
    assert {i["path"] for i in ev["inputs"]} >= {"dataset.npz", "sim1/dataset.npz"}
    assert ev["models"]["lrnet"]["network"] and not ev["models"]["logreg"]["network"]
    assert ev["best_baseline"] == "logreg"


def test_pooled_macro_f1_matches_sklearn_on_the_windows(run):
    """One train seed's windows of both sim seeds, pooled, against the evaluation's per-seed rows and,
    for the set, the train-seed average of per-flight counts (here: equal window counts per flight)."""
    ev = _ev(run)
    row = next(r for r in ev["per_seed"] if r["model"] == "lrnet" and r["set"] == "test" and r["sim_seed"] == 0
               and r["train_seed"] == 0)
    z = np.load(prediction_path(run, "lrnet", 0, 0))
    m = z["split"] == 2
    y, pred = z["y_true"][m], z["proba"][m].argmax(1)
    assert row["macro_f1"] == pytest.approx(f1_score(y, pred, labels=np.unique(y), average="macro", zero_division=0))
    assert row["accuracy"] == pytest.approx(np.mean(y == pred))


def test_intervals_bracket_values_and_the_ceiling_is_below_one(run):
    ev = _ev(run)
    for r in ev["results"]:
        for name, m in r["metrics"].items():
            if m["value"] is not None and m["lo"] is not None:
                assert m["lo"] - 1e-9 <= m["hi"], (r["set"], name)
        fa = r["false_alarms"]
        assert fa["poisson_lo"] <= fa["rate_per_h"] <= fa["poisson_hi"]
        assert fa["runs"] == 4
    c = ev["ceiling"]["test"]
    assert c["ambiguous_windows"] > 0 and 0.5 < c["macro_f1"] < 1.0


def test_paired_differences_are_antisymmetric_in_value_and_paired(run):
    ev = _ev(run)
    p = next(p for p in ev["paired"] if p["set"] == "test")
    a = next(r for r in ev["results"] if r["model"] == p["a"] and r["set"] == "test")["metrics"]["macro_f1"]["value"]
    b = next(r for r in ev["results"] if r["model"] == p["b"] and r["set"] == "test")["metrics"]["macro_f1"]["value"]
    assert p["diff"]["macro_f1"]["diff"] == pytest.approx(a - b)
    assert p["diff"]["macro_f1"]["lo"] <= p["diff"]["macro_f1"]["hi"]
    # The delay on the fault flights both detect (evaluate.common_delay): a flight counts only when
    # every train seed of both models detects it, so at most what each single run detects.
    c = p["common_delay_onset"]
    for m in (p["a"], p["b"]):
        for seed in (0, 1):
            runs = [r for r in ev["per_seed"] if r["model"] == m and r["set"] == "test" and r["train_seed"] == seed]
            assert c["flights"] <= sum(r["detected"] for r in runs)
    assert all("common_delay_onset" in q for q in ev["paired"])
    assert "| faults both detect |" in (run / "evaluation/evaluation.md").read_text()


def test_policy_is_chosen_without_looking_at_test(run, tmp_path):
    """Scrambling every test-set probability leaves the chosen policies and the sweep unchanged."""
    other = tmp_path / "run"
    shutil.copytree(run, other, ignore=shutil.ignore_patterns("evaluation", ".stages"))
    shutil.copytree(run / ".stages", other / ".stages", ignore=shutil.ignore_patterns("evaluate.json"))
    rng = np.random.default_rng(0)
    for f in (other / "predictions").glob("*.npz"):
        z = dict(np.load(f))
        m = z["split"] >= 2
        z["proba"][m] = rng.dirichlet(np.ones(z["proba"].shape[1]), size=m.sum()).astype(np.float32)
        write_npz(f, z)
    res = quadfdi("evaluate", "--run", str(other), *FAST)
    assert res.returncode == 0, res.stderr
    a, b = _ev(run), _ev(other)
    assert {m: d["policy"] for m, d in a["models"].items()} == {m: d["policy"] for m, d in b["models"].items()}
    assert a["models"]["lrnet"]["sweep"] == b["models"]["lrnet"]["sweep"]
    ta = next(r for r in a["results"] if r["set"] == "test")["metrics"]["macro_f1"]["value"]
    tb = next(r for r in b["results"] if r["set"] == "test")["metrics"]["macro_f1"]["value"]
    assert ta != tb


def test_empty_index_is_one_line_and_writes_nothing(run, tmp_path):
    other = tmp_path / "empty"
    other.mkdir()
    shutil.copy(run / "config.toml", other / "config.toml")
    res = quadfdi("evaluate", "--run", str(other))
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "lists no prediction set" in res.stderr and "run a producer" in res.stderr
    assert not (other / "evaluation").exists()


def test_report_section_and_headline_read_the_json_alone(run, tmp_path):
    from quadfdi.evaluate.report import HEADING, headline, report_section

    lines = report_section(run)
    assert lines[0] == HEADING and any("label-noise ceiling" in s for s in lines)
    assert any("evaluation/alarm_sweep.png" in s for s in lines)
    assert headline(run)[0].startswith("- Evaluation, test: best macro F1")
    assert "Not run" in " ".join(report_section(tmp_path)) and headline(tmp_path) == []


def test_network_against_best_baseline_is_network_minus_baseline(run):
    ev = _ev(run)
    g = next(g for g in ev["vs_best_baseline"] if g["set"] == "test_ood_all")
    assert (g["network"], g["baseline"]) == ("lrnet", "logreg")
    res = {r["model"]: r["metrics"]["macro_f1"]["value"] for r in ev["results"] if r["set"] == "test_ood_all"}
    assert g["macro_f1_diff"] == pytest.approx(res["lrnet"] - res["logreg"])
    assert g["lo"] <= g["hi"] and g["goal_met"] == (g["macro_f1_diff"] >= 0.03 and g["lo"] > 0)


def test_readme_realistic_block_comes_from_the_evaluation(run, tmp_path):
    """`quadfdi readme --block realistic` rewrites only its block, with every model and the ceiling."""
    readme = tmp_path / "README.md"
    readme.write_text("# x\n\n<!-- realistic:start -->\nSTALE-BLOCK\n<!-- realistic:end -->\n\ntail\n")
    res = quadfdi("readme", "--run", str(run), "--block", "realistic", "--readme", str(readme))
    assert res.returncode == 0, res.stderr
    text = readme.read_text()
    block = text.split("<!-- realistic:start -->")[1].split("<!-- realistic:end -->")[0]
    assert "STALE-BLOCK" not in block and text.endswith("tail\n")
    ev = _ev(run)
    for model in ev["models"]:
        assert f"| {model} |" in block
    assert "*label-noise ceiling*" in block and "Realism: not run" in block
    missing = quadfdi("readme", "--run", str(tmp_path), "--block", "realistic", "--readme", str(readme))
    assert missing.returncode == 2 and "quadfdi evaluate" in missing.stderr
