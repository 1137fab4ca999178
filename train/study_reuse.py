"""What the seed study takes from the train stage instead of retraining: the prediction sets (and
the test metrics) of the run's simulator seed and the train stage's training seed, when the train
stage was published with the study's ``[sim]`` and ``[train]`` (its seed aside) and still holds them."""

from __future__ import annotations

from quadfdi.core.config import Config, replace_section
from quadfdi.core.jsonio import read_json
from quadfdi.core.records import load_record
from quadfdi.core.rundir import RunDir
from quadfdi.train.predsets import relative_prediction_path
from quadfdi.train.study_jobs import MODELS


def train_stage_results(run: RunDir, cfg: Config, seeds: list[int]) -> dict[tuple[str, int, int], dict]:
    """(model, sim seed, train seed) -> {"metrics": {model, "baseline"}, "predictions": rel path} for
    each network the published train stage made with this config; {} when there is none."""
    rec = load_record(run.root, "train")
    if rec is None or not run.metrics.is_file():
        return {}
    seed = rec.get("config", {}).get("train", {}).get("seed")
    if seed not in seeds:
        return {}
    sections = replace_section(cfg, "train", seed=seed).to_dict()
    if rec["config"] != {"sim": sections["sim"], "train": sections["train"]}:
        return {}
    outputs = {e["path"] for e in rec["outputs"]}
    metrics = read_json(run.metrics, "metrics")
    out = {}
    for kind in MODELS:
        rel = relative_prediction_path(kind, cfg.sim.seed, seed)
        if rel in outputs and (run.root / rel).is_file() and kind in metrics and "baseline" in metrics:
            out[(kind, cfg.sim.seed, seed)] = {"metrics": {kind: metrics[kind], "baseline": metrics["baseline"]},
                                               "predictions": rel}
    return out
