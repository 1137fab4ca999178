"""Train the selected models on a run's dataset and write every training artifact.

Writes into the run folder: ``<kind>.pt`` checkpoints, ``predictions_<kind>.npz`` (test split),
``metrics.json`` ({"cnode", "gru", "baseline"}; test split), ``history.json``, the figures, and each
network's prediction set on every evaluation window (``predictions/<kind>_sim<S>_train<T>.npz``,
formats.predictions), listed in ``predictions/index.json`` once the stage is published; the sets of
other training seeds T published before with the same dataset and config stay (keep_other_seeds).
"""

from __future__ import annotations

import dataclasses
import re
import time
from typing import Callable

import numpy as np
import torch

from quadfdi.core.config import Config, replace_section
from quadfdi.core.contracts import SPLITS
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import read_json, write_json
from quadfdi.core.npzio import write_npz
from quadfdi.formats.predictions import add_entries
from quadfdi.core.rundir import RunDir
from quadfdi.core.stage import StageWriter, stage
from quadfdi.formats.dataset import Dataset, Windows, class_names, load_dataset
from quadfdi.core.profiles import has_reference, is_masked
from quadfdi.train.augment import share_wander_for
from quadfdi.train.masks import Masker, chain, fixed_availability, mask_draw_for, masked_validation, pattern_scores
from quadfdi.train.baseline import fit_baseline, predict_proba_baseline
from quadfdi.models.checkpoint import save_checkpoint
from quadfdi.train.data import class_weights, fit_normalisation, split_windows
from quadfdi.train.loop import predict_proba, train_model
from quadfdi.train.metrics import compute_metrics
from quadfdi.models.networks import build_model
from quadfdi.models.motor import attach_motor_head, motor_targets, wants_motor_head
from quadfdi.models.inputs import PROFILE_KEY
from quadfdi.train.vehicle_ref import profiled
from quadfdi.train.predsets import (drop_missing_entries, index_entry, prediction_set, reference_sets,
                            relative_prediction_path,
                            write_prediction_set)


def kinds_of(model: str) -> list[str]:
    return ["cnode", "gru"] if model == "both" else [model]


def evaluate(ds: Dataset, test: Windows, proba: np.ndarray) -> dict:
    return compute_metrics(test.y, proba, test.traj, test.t_end, ds["fault_class"], ds["detectable_s"],
                           class_names(ds.arrays))


def train_all(ds: Dataset, cfg: Config, kinds: list[str], log: Callable[[str], None] = print,
              predsets: bool = True, patterns: bool = True, baseline: bool = True) -> dict:
    """Train ``kinds`` and the baseline on ``ds``; return models, histories, test probabilities,
    metrics and each network's prediction set (every evaluation window, ``train.predsets``; not
    made when ``predsets`` is False: train.study_apply keeps only the network). A masked profile's
    scores per mask pattern (``mask_patterns``: 13 patterns x the validation and test windows, about
    a third of a job's time) only when ``patterns``: the seed study's jobs keep none of them. The
    paper's logistic-regression baseline (its test metrics, ``metrics["baseline"]``) only when
    ``baseline``: one study job per seed fits it."""
    torch.set_num_threads(cfg.train.threads)
    profile, masked = cfg.train.profile, is_masked(cfg.train.profile)
    # the models' input channels (paper: ds itself); a masked profile: every channel, masks per window (train.masks)
    ds = profiled(ds, profile, patterns=False)
    predsets = predsets and cfg.train.outputs == "all"
    k = len(class_names(ds.arrays))
    splits = split_windows(ds, cfg.train.max_train_windows, cfg.train.seed)
    for name in SPLITS:
        if len(getattr(splits, name)) == 0:
            raise QuadfdiError(f"the dataset has no {name} windows: raise sim.n_traj or sim.duration_s")
    val_all = splits.validation
    mean, std = fit_normalisation(ds)
    if masked:
        splits = dataclasses.replace(splits, validation=masked_validation(val_all, profile, ds.channel_names,
                                                                          cfg.train.seed))
        mean, std = fixed_availability(profile, mean, std)
    weights = class_weights(splits.train.y, k)
    augment = chain(share_wander_for(cfg.train, ds.channel_names, float(ds["time"][1] - ds["time"][0])),
                    mask_draw_for(profile, ds.channel_names, cfg.train.seed))
    out: dict = {"models": {}, "history": {}, "proba": {}, "metrics": {}, "splits": splits, "predsets": {},
                 "ds": ds, "mask_patterns": {}}
    for kind in kinds:
        torch.manual_seed(cfg.train.seed)  # same initial weights for the same seed
        model = build_model(kind, ds.n_channels, cfg.train, window=cfg.sim.window, n_classes=k)
        motor = None
        if wants_motor_head(cfg.train.motor_head, class_names(ds.arrays)):
            attach_motor_head(model)  # after the other layers: their initial weights stay those of no head
            tr = splits.train
            motor = motor_targets(tr.y, tr.traj, ds["fault_motor"], class_names(ds.arrays))
        model.set_normalisation(mean, std)
        log(f"train {kind} (seed {cfg.train.seed}, {sum(p.numel() for p in model.parameters())} parameters"
            f"{', motor head' if motor is not None else ''}):")
        t0 = time.perf_counter()
        hist = train_model(model, splits.train, splits.validation, cfg.train, weights, log, motor=motor, augment=augment)
        log(f"  {kind}: trained in {time.perf_counter() - t0:.1f} s (best epoch {hist.best_epoch + 1})")
        proba = predict_proba(model, splits.test.x)  # as before the prediction sets: the test metrics keep their bits
        out["models"][kind], out["history"][kind], out["proba"][kind] = model, hist, proba
        t0 = time.perf_counter()
        if predsets and has_reference(profile):  # with the vehicle record and without it
            out["predsets"].update(reference_sets(model, ds, kind, Masker(profile, ds.channel_names)))
        elif predsets:
            out["predsets"][kind] = prediction_set(model, ds)
            log(f"  {kind}: prediction set of {len(out['predsets'][kind]['traj'])} evaluation windows in "
                f"{time.perf_counter() - t0:.1f} s")
        out["metrics"][kind] = evaluate(ds, splits.test, proba)
        if masked and predsets and patterns:
            out["mask_patterns"][kind] = {name: pattern_scores(lambda x: predict_proba(model, x), w, profile,
                                                               ds.channel_names, k)
                                          for name, w in (("validation", val_all), ("test", splits.test))}
    if baseline:
        base = fit_baseline(splits.train.x, splits.train.y, cfg.train.seed, k)
        out["proba"]["baseline"] = predict_proba_baseline(base, splits.test.x)
        out["metrics"]["baseline"] = evaluate(ds, splits.test, out["proba"]["baseline"])
    return out


def write_outputs(out: RunDir, ds: Dataset, cfg: Config, result: dict, previous: RunDir | None = None) -> None:
    """Checkpoints, predictions, metrics.json and history.json (merged with those of ``previous``,
    the published run whose models were not retrained), figures; all into ``out``."""
    from quadfdi.train.figures import draw_all

    test = result["splits"].test
    ds = result.get("ds", ds)  # the profiled dataset the models were trained on
    for kind, model in result["models"].items():
        save_checkpoint(out.checkpoint(kind), model, cfg.to_dict(), ds.channel_names,
                        extra={"history": result["history"][kind].to_dict(times=False), PROFILE_KEY: cfg.train.profile},
                        class_names=class_names(ds.arrays))
        write_npz(out.predictions(kind), {"y_true": test.y, "proba": result["proba"][kind],
                                          "traj": test.traj, "t_end": test.t_end})
    for name, pred in result["predsets"].items():  # a reference profile's: also <kind>_noref
        write_prediction_set(out.root / relative_prediction_path(name, cfg.sim.seed, cfg.train.seed), pred)
    old_metrics, old_hist = None if previous is None else previous.metrics, None if previous is None else previous.root / "history.json"
    metrics = read_json(old_metrics, "metrics") if old_metrics is not None and old_metrics.exists() else {}
    metrics.update(result["metrics"])
    if result.get("mask_patterns"):  # a masked profile: macro F1 per mask pattern (train.masks), per network
        metrics["mask_patterns"] = {**metrics.get("mask_patterns", {}), **result["mask_patterns"]}
    write_json(out.metrics, metrics, indent=2)
    hist = read_json(old_hist, "training history") if old_hist is not None and old_hist.exists() else {}
    hist.update({k: h.to_dict() for k, h in result["history"].items()})
    write_json(out.root / "history.json", hist, indent=2)
    draw_all(out, ds, result)


def train_run(run: RunDir, cfg: Config, model: str = "both", seed: int | None = None,
              log: Callable[[str], None] = print) -> dict:
    """Train into a staging folder and publish every training output as one stage (core.stage):
    a crash or Ctrl-C before the publish leaves the previous checkpoints and metrics untouched.
    The other training seeds' prediction sets stay published and indexed (``keep_other_seeds``)."""
    if seed is not None:
        cfg = replace_section(cfg, "train", seed=seed)
    kinds = kinds_of(model)
    targets = tuple(f"{k}.pt" for k in kinds) + ("metrics.json", "history.json")
    sections = cfg.to_dict()
    with stage(run.root, "train", {"sim": sections["sim"], "train": sections["train"]}, targets=targets) as st:
        ds = load_dataset(st.consume("dataset.npz", ("sim",)))
        check_config_matches(ds, cfg)
        result = train_all(ds, cfg, kinds, log)
        previous = run if len(kinds) < 2 and st.carry_previous() else None
        keep_other_seeds(st, cfg, log)
        write_outputs(RunDir(st.out), ds, cfg, result, previous)
    # The index is not a stage output (the study adds to it too): entries are added once the
    # prediction sets they name are published.
    add_entries(run.root, [index_entry(k, cfg.sim.seed, cfg.train.seed) for k in result["predsets"]])
    drop_missing_entries(run.root)
    return result


def keep_other_seeds(st: StageWriter, cfg: Config, log: Callable[[str], None] = print) -> list[str]:
    """Carry the prediction sets of the other training seeds that the previous train stage published
    (``quadfdi train --seed 1`` after ``--seed 0`` adds seed 1's sets and keeps seed 0's, as the
    study does; a re-run of one seed replaces its own), when they were made from the same dataset with
    the same [sim] and [train] but the seed. Otherwise they are dropped (and leave the index):
    evaluate pools a model's seeds as one training recipe. Returns the sets kept."""
    prev = st.previous
    sets = [e["path"] for e in (prev or {}).get("outputs", []) if _set_seed(e["path"], cfg.sim.seed) not in
            (None, cfg.train.seed)]
    if not sets:
        return []
    old, want = prev.get("config", {}), cfg.to_dict()
    same_inputs = {(i["path"], i["sha256"]) for i in prev.get("inputs", [])} == \
        {(i["path"], i["sha256"]) for i in st.inputs.values()}
    if not same_inputs or old.get("sim") != want["sim"] or {**old.get("train", {}), "seed": cfg.train.seed} != want["train"]:
        log(f"train: the {len(sets)} prediction sets of other training seeds were made from another dataset or "
            "[train]: they are dropped")
        st.uncarry(sets)  # also when train --model X carried the previous outputs (same dataset, other [train])
        return []
    return st.carry(sets)


def _set_seed(rel: str, sim_seed: int) -> int | None:
    """The training seed of a train-stage prediction set path on ``sim_seed``'s dataset, else None."""
    m = re.fullmatch(r"predictions/[a-z0-9_-]+_sim(\d+)_train(\d+)\.npz", rel)
    return int(m.group(2)) if m and int(m.group(1)) == sim_seed else None


def check_config_matches(ds: Dataset, cfg: Config) -> None:
    """The run's [sim] must be the one embedded in dataset.npz (an edited config.toml lies)."""
    from quadfdi.core.records import first_difference

    diff = first_difference(ds.config.to_dict()["sim"], cfg.to_dict()["sim"])
    if diff is not None:
        key, was, now = diff
        raise QuadfdiError(f"config [sim].{key} is {now!r} but {ds.path} was simulated with {was!r}: "
                           f"re-run quadfdi sim, or drop the change")
