"""The baselines of one dataset as a job of ``core.executor``: the fits of ``quadfdi train baselines`` run one
dataset (simulator seed) per job, so that a run with two seeds fits them on two cores at once, and a
rerun takes a finished dataset from ``<run>/cache/baselines/<key>.npz``.

A job's key is its dataset's sha256, the baselines' seed, models, training-window cap and channel view, and
the code of ``train`` (core.jobcache). Its result holds what ``baselines_run.write_run`` writes: per model
the probabilities on every evaluation window (float64, as fitted) and its record; the evaluation windows'
labels, flights, end times and split codes; the rule-based suspected motor with and without the reference;
the class and split names and the models skipped. Every fit runs on one thread (train.baselines), so a
result is the same bytes in this process or on a worker.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from quadfdi.core.executor import Job
from quadfdi.core.jobcache import cache_path, job_key
from quadfdi.core.jsonio import to_jsonable

KIND = "baselines"
EVAL_FIELDS = ("y", "traj", "t_end", "split")  # of the evaluation windows: what a prediction set records
PROBA = "proba__"  # + model name
META = "meta_json"


def fit_dataset(path: str, rel: str, sim_seed: int, seed: int, models: tuple[str, ...], cap: int,
                logged: bool) -> dict[str, np.ndarray]:
    """Fit the baselines on one dataset (a job); the arrays of the module docstring."""
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.formats.dataset import class_names, load_dataset, split_names
    from quadfdi.train.baselines import fit_baselines, usable_models
    from quadfdi.train.baselines_channels import logged_view

    ds, temps = load_dataset(path), "T"
    if logged:
        ds, temps = logged_view(ds)
    use = usable_models(ds, models)
    try:
        evals, results = fit_baselines(ds, seed, use, cap)
    except ValueError as exc:
        raise QuadfdiError(f"{path}: {exc}") from None
    temperatures = "esc_temp1..4 (ESC boards)" if temps == "esc_temp" else "T1..T4 (windings)"
    meta = {"dataset": rel, "sim_seed": int(sim_seed), "class_names": list(class_names(ds.arrays)),
            "split_names": list(split_names(ds.arrays)), "skipped": [m for m in models if m not in use],
            "records": {m: dict(r.record, temperatures=temperatures) for m, r in results.items()}}
    out = {f"evals__{f}": getattr(evals, f) for f in EVAL_FIELDS}
    out.update({f"{PROBA}{m}": r.proba.astype(np.float64) for m, r in results.items()})
    for name, ref in (("motor_proba", False), ("motor_proba_ref", True)):
        motor = suspected_motor(evals, ds.channel_names, reference=ref)
        if motor is not None:
            out[name] = motor
    out[META] = np.array(json.dumps(to_jsonable(meta), sort_keys=True, allow_nan=True))
    return out


def suspected_motor(evals, channel_names, reference: bool = False) -> np.ndarray | None:
    """(n, 4) one-hot: the rotor whose window-mean command is highest over the mean of the four (the
    physics feature ``thr_ratio<i>``: a weak motor or a damaged propeller needs more command for its
    share of thrust); with ``reference``, highest over its reference share (``share_dev<i>``; None
    without reference features). A fixed physics rule, not learned; shared by the baselines of each
    kind, so the evaluation can score their localisation. None when the dataset has no motor commands."""
    from quadfdi.train.features import physics_feature_names
    from quadfdi.train.features_ref import ref_feature_names

    names = (ref_feature_names if reference else physics_feature_names)(channel_names)
    feats = evals.ref_phys if reference else evals.physics
    cols = [names.index(f"{'share_dev' if reference else 'thr_ratio'}{i}") for i in range(1, 5)
            if f"{'share_dev' if reference else 'thr_ratio'}{i}" in names]
    if len(cols) != 4 or feats.shape[1] != len(names):
        return None
    return np.eye(4, dtype=np.float32)[np.argmax(feats[:, cols], axis=1)]


def done_entry(arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """A job's result as ``baselines_run.write_run`` reads one dataset: evals (an object with the
    EVAL_FIELDS), results {model: BaselineResult}, motor_proba(_ref), names, skipped."""
    from types import SimpleNamespace

    from quadfdi.train.baselines import BaselineResult

    meta = json.loads(str(arrays[META]))
    results = {m: BaselineResult(proba=arrays[f"{PROBA}{m}"], record=rec) for m, rec in meta["records"].items()}
    return {"dataset": meta["dataset"], "sim_seed": meta["sim_seed"], "results": results,
            "evals": SimpleNamespace(**{f: arrays[f"evals__{f}"] for f in EVAL_FIELDS}),
            "class_names": meta["class_names"], "split_names": meta["split_names"],
            "motor_proba": arrays.get("motor_proba"), "motor_proba_ref": arrays.get("motor_proba_ref"),
            "skipped": meta["skipped"]}


def dataset_jobs(root: Path, datasets: Sequence[tuple[str, int]], seed: int, models: tuple[str, ...], cap: int,
                 logged: bool) -> list[Job]:
    """One job per (dataset relative to ``root``, simulator seed), in that order."""
    jobs = []
    for rel, sim_seed in datasets:
        path = root / rel
        args = {"dataset": rel, "sim_seed": int(sim_seed), "seed": int(seed), "models": list(models), "cap": int(cap),
                "logged": bool(logged)}
        key = job_key(KIND, {}, args, {"dataset": path}, packages=("train",))
        jobs.append(Job(KIND, key, fit_dataset, (str(path), rel, int(sim_seed), int(seed), tuple(models), int(cap),
                                                 bool(logged)),
                        cache_path(root, KIND, key, "npz"), label=f"sim {sim_seed} baselines"))
    return jobs
