"""``quadfdi train apply``: the networks trained on the run's own simulator seed, predicting on the
datasets of other simulator seeds, without retraining: more independent flights for the same
deployed networks (the alarm policy is swept on >= 2 h of healthy validation
flight; one sim seed's validation split holds 1.03 h).

For each training seed T and network kind:

- the network is the train stage's checkpoint ``<run>/<kind>.pt`` when that checkpoint was
  trained with the run's ``[sim]`` and this ``[train]`` with seed T (its embedded config says so);
- otherwise it is retrained deterministically on the run's dataset (a job keyed like the study's,
  cached as a checkpoint in ``<run>/cache/study_net/<key>.bin``: the seed study keeps no weights);
- either way its predictions on the run's first evaluation flights are compared, bit for bit, with
  the indexed set of (kind, run's sim seed, T) when there is one: ``reproduces_indexed_set`` in
  the summary (the applied network is the one evaluated on the run's own flights);
- for every other simulator seed S (its dataset in ``<run>/sims/seed<S>/``, simulated when missing,
  train.study_sims), a job computes the network's prediction set on every evaluation window of S's
  dataset (train.predsets), cached in ``<run>/cache/study_apply/``.

Published as the stage ``apply`` (core.stage): the sets at ``predictions/<kind>_sim<S>_train<T>.npz``
and ``predictions/applied.json`` (which network made each set); then indexed (formats.predictions),
the entry's ``dataset`` being S's. The index's ``sim_seed`` is the seed of the flights predicted
on; a set of ``quadfdi train study --sim-seeds`` (networks trained on S) has the same key and
replaces it, and the reverse.

``run_patterns`` (the masked profile, ``quadfdi real-flights``): the train stage's masked networks on
the test flights of each simulator seed with every window under one mask pattern (core/channels.py
MASK_PATTERNS, each but "all": every channel is the indexed set), published as the stage ``patterns``:
``predictions/<kind>_<pattern>_sim<S>_train<T>.npz`` and ``predictions/patterns.json``. They are not
indexed: ``quadfdi evaluate`` chooses a policy per indexed model on its validation flights, and a
pattern's set is to be scored under the policy chosen with every channel, not tuned to the pattern.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.core.config import Config, replace_section
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import SERIAL, ExecSettings, Job, run_jobs
from quadfdi.core.jobcache import cache_path, job_key, read_result
from quadfdi.core.rundir import RunDir
from quadfdi.train.study_jobs import MODELS

NET_KIND, APPLY_KIND, PATTERN_KIND = "study_net", "study_apply", "study_patterns"
SUMMARY, PATTERNS_SUMMARY = "predictions/applied.json", "predictions/patterns.json"
SEP = "__"  # a pattern job's result keys: <pattern>__<prediction-set key>
CHECK_FLIGHTS = 16  # evaluation flights re-predicted to show a retrained network is the indexed one


def train_network(dataset: str, cfg: Config, kind: str, out: str) -> bytes:
    """Train ``kind`` with ``cfg.train.seed`` on ``dataset`` (a job) and return its checkpoint's bytes
    (the train stage's checkpoint format, models.checkpoint)."""
    import tempfile

    from quadfdi.formats.dataset import class_names, load_dataset
    from quadfdi.models.checkpoint import save_checkpoint
    from quadfdi.models.inputs import PROFILE_KEY
    from quadfdi.train.run import train_all

    result = train_all(load_dataset(dataset), cfg, [kind], log=lambda _: None, predsets=False)
    ds = result["ds"]
    with tempfile.TemporaryDirectory(dir=Path(out).parent) as tmp:
        path = Path(tmp) / f"{kind}.pt"
        save_checkpoint(path, result["models"][kind], cfg.to_dict(), ds.channel_names,
                        extra={"history": result["history"][kind].to_dict(times=False),
                               PROFILE_KEY: cfg.train.profile}, class_names=class_names(ds.arrays))
        return path.read_bytes()


def apply_network(checkpoint: str, dataset: str, kind: str, reference: bool = True) -> dict:
    """The prediction set (formats.predictions format) of the network in ``checkpoint`` on every
    evaluation window of ``dataset``, with the network's channel profile applied (a job); a reference
    profile's flights with their vehicle records (``reference`` False: without)."""
    from quadfdi.formats.dataset import class_names, load_dataset
    from quadfdi.models.checkpoint import check_dataset_matches, checkpoint_class_names, load_checkpoint
    from quadfdi.train.predsets import prediction_set
    from quadfdi.models.inputs import profile_of
    from quadfdi.train.vehicle_ref import profiled

    model, blob = load_checkpoint(checkpoint, kind)
    _threads(blob)
    ds = profiled(load_dataset(dataset), profile_of(blob), patterns=False, reference=reference)  # as train's sets
    check_dataset_matches(blob, ds.channel_names, dataset)
    if checkpoint_class_names(blob) != list(class_names(ds.arrays)):
        raise QuadfdiError(f"{dataset}: its classes differ from those of the network in {checkpoint}")
    return prediction_set(model, ds)


def _threads(blob: dict) -> None:
    """The training threads (1 by default): float sums, hence the bits, depend on them."""
    import torch

    torch.set_num_threads(int(blob.get("config", {}).get("train", {}).get("threads", 1)))


def stage_checkpoint(run: RunDir, cfg: Config, kind: str) -> Path | None:
    """``<run>/<kind>.pt`` when it was trained with ``cfg``'s [sim] and [train] (seed included)."""
    from quadfdi.models.checkpoint import load_checkpoint

    path = run.checkpoint(kind)
    if not path.is_file():
        return None
    _, blob = load_checkpoint(path, kind)
    want = cfg.to_dict()
    got = blob.get("config", {})
    return path if all(got.get(s) == want[s] for s in ("sim", "train")) else None


def with_stage_train(run: RunDir, cfg: Config, keep: set[str] = frozenset(),
                     log: Callable[[str], None] = print) -> Config:
    """``cfg`` with [train] taken from the train stage's networks (their seed aside, and the keys in
    ``keep``: the apply command's own ``--set train.*``) when they were trained on ``cfg``'s [sim].
    ``quadfdi train --set train.profile=...`` is not written into config.toml, and apply must apply
    THOSE networks and retrain other seeds like them, not the run's stored [train]."""
    from quadfdi.models.checkpoint import load_checkpoint

    want = cfg.to_dict()
    for kind in MODELS:
        path = run.checkpoint(kind)
        if not path.is_file():
            continue
        got = load_checkpoint(path, kind)[1].get("config", {})
        if got.get("sim") != want["sim"] or "train" not in got:
            continue
        changed = {k: (tuple(v) if isinstance(v, list) else v) for k, v in got["train"].items()
                   if k != "seed" and k not in keep and k in want["train"] and want["train"][k] != v}
        if changed:
            log(f"apply: [train] of the train stage's {path.name}, not config.toml's: "
                + ", ".join(f"train.{k}={v!r}" for k, v in sorted(changed.items())))
            return replace_section(cfg, "train", **changed)
        return cfg
    return cfg


def networks(run: RunDir, cfg: Config, seeds: list[int], settings: ExecSettings,
             log: Callable[[str], None]) -> dict[tuple[str, int], tuple[Path, str]]:
    """(kind, train seed) -> (checkpoint path, where it comes from): the train stage's or retrained."""
    out, jobs = {}, []
    for seed in seeds:
        c = replace_section(cfg, "train", seed=seed)
        for kind in MODELS:
            own = stage_checkpoint(run, c, kind)
            if own is not None:
                out[(kind, seed)] = (own, "train stage")
                continue
            key = job_key(NET_KIND, c.to_dict(), {"model": kind}, {"dataset": run.dataset}, packages=("sim", "train"))
            path = cache_path(run.root, NET_KIND, key, "bin")
            path.parent.mkdir(parents=True, exist_ok=True)
            jobs.append(Job(NET_KIND, key, train_network, (str(run.dataset), c, kind, str(path)), path,
                            label=f"train seed {seed} {kind}", torch=True))
            out[(kind, seed)] = (path, "retrained")
    for r in run_jobs(jobs, settings, desc="networks", log=log):
        if not r.ok:
            raise QuadfdiError(f"training {r.job.label} failed: {r.error}")
    return out


def reproduces(run: RunDir, cfg: Config, kind: str, seed: int, checkpoint: Path) -> bool | None:
    """Whether the network in ``checkpoint`` gives, bit for bit, the indexed prediction set of
    (kind, run's sim seed, seed) on the run's first CHECK_FLIGHTS evaluation flights (None: no such set)."""
    from quadfdi.core.npzio import read_npz
    from quadfdi.formats.predictions import read_index
    from quadfdi.formats.dataset import load_dataset
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.train.predsets import prediction_set
    from quadfdi.models.inputs import profile_of
    from quadfdi.train.vehicle_ref import profiled

    entry = next((e for e in read_index(run.root) if (e["model"], int(e["sim_seed"]), int(e["train_seed"]))
                  == (kind, cfg.sim.seed, seed) and e["dataset"] == "dataset.npz"), None)
    if entry is None or not (run.root / entry["predictions"]).is_file():
        return None
    model, blob = load_checkpoint(checkpoint, kind)
    _threads(blob)
    ds = profiled(load_dataset(run.dataset), profile_of(blob), patterns=False)
    mine = prediction_set(model, ds, max_flights=CHECK_FLIGHTS)  # the set's first chunk: same batches, same bits
    got = read_npz(run.root / entry["predictions"], "prediction set")
    b = got["proba"][np.isin(got["traj"], np.unique(mine["traj"]))]
    return bool(mine["proba"].shape == b.shape and np.array_equal(mine["proba"], b))


def apply_jobs(run: RunDir, nets: dict[tuple[str, int], tuple[Path, str]], data) -> list[tuple[Job, str, int, object]]:
    """(job, kind, train seed, StudyData) per network x other simulator seed, in (sim seed, train
    seed, model) order."""
    from quadfdi.core.profiles import has_reference
    from quadfdi.models.checkpoint import load_checkpoint
    from quadfdi.models.inputs import profile_of
    from quadfdi.train.predsets import NO_REFERENCE

    jobs = []
    for d in data:
        for (kind, seed), (path, _) in sorted(nets.items(), key=lambda kv: (kv[0][1], MODELS.index(kv[0][0]))):
            with_ref = has_reference(profile_of(load_checkpoint(path, kind)[1]))
            for reference in (True, False) if with_ref else (True,):
                name = kind if reference else kind + NO_REFERENCE
                key = job_key(APPLY_KIND, {}, {"model": kind, **({} if reference else {"reference": False})},
                              {"checkpoint": path, "dataset": d.path}, packages=("sim", "train"))
                jobs.append((Job(APPLY_KIND, key, apply_network, (str(path), str(d.path), kind, reference),
                                 cache_path(run.root, APPLY_KIND, key, "npz"),
                                 label=f"seed {seed} {name} on sim {d.sim_seed}", torch=True), name, seed, d))
    return jobs


def run_apply(run: RunDir, cfg: Config, seeds: list[int], sim_seeds: list[int], settings: ExecSettings = SERIAL,
              log: Callable[[str], None] = print) -> dict:
    """Publish the prediction sets of the run's networks (training seeds ``seeds``) on the datasets
    of ``sim_seeds`` (other than the run's), as the stage ``apply``, and index them; return the summary."""
    from quadfdi.core.jsonio import write_json
    from quadfdi.formats.predictions import add_entries
    from quadfdi.core.stage import stage
    from quadfdi.train.predsets import NO_REFERENCE, drop_missing_entries, index_entry, write_prediction_set
    from quadfdi.train.study_sims import study_datasets

    others = [s for s in sim_seeds if s != cfg.sim.seed]
    if not others:
        raise QuadfdiError(f"--sim-seeds names only the run's own simulator seed {cfg.sim.seed}: "
                           "its prediction sets come from quadfdi train and quadfdi train study")
    data = study_datasets(run, cfg, others, settings, log)
    sections = cfg.to_dict()
    with stage(run.root, "apply", {"sim": sections["sim"], "train": sections["train"]}, targets=(SUMMARY,)) as st:
        st.consume("dataset.npz", ("sim",))
        nets = networks(run, cfg, seeds, settings, log)
        summary = {"sim_seed_trained_on": cfg.sim.seed, "sets": []}
        checks = {}
        for (kind, seed), (path, source) in sorted(nets.items()):
            if source == "train stage":
                st.consume(path.relative_to(run.root).as_posix())
            checks[(kind, seed)] = reproduces(run, replace_section(cfg, "train", seed=seed), kind, seed, path)
            log(f"apply: {kind} seed {seed} ({source}) reproduces its indexed set: {checks[(kind, seed)]}")
            if checks[(kind, seed)] is False:  # a network other than the evaluated one: its sets would mislead
                raise QuadfdiError(f"apply: the {source} {kind} network of train seed {seed} does not reproduce the "
                                   f"run's indexed {kind} prediction set: it is not the network the run evaluated "
                                   f"(give apply the same --set train.* as quadfdi train)")
        entries, jobs = [], apply_jobs(run, nets, data)
        for r, (_, kind, seed, d) in zip(run_jobs([j[0] for j in jobs], settings, desc="apply", log=log), jobs):
            if not r.ok:
                raise QuadfdiError(f"prediction set of {r.job.label} failed: {r.error}")
            entry = index_entry(kind, d.sim_seed, seed, d.rel)
            write_prediction_set(st.out / entry["predictions"], read_result(r.job.out))
            entries.append(entry)
            base = kind.removesuffix(NO_REFERENCE)
            summary["sets"].append({"model": kind, "train_seed": seed, "sim_seed": d.sim_seed,
                                    "predictions": entry["predictions"], "network": nets[(base, seed)][1],
                                    "reproduces_indexed_set": checks.get((base, seed))})
        write_json(st.path(SUMMARY), summary, indent=2)
    add_entries(run.root, entries)
    drop_missing_entries(run.root)
    return summary



def pattern_network(checkpoint: str, dataset: str, kind: str, split: str) -> dict:
    """The masked network in ``checkpoint`` on the windows of ``split``'s flights of ``dataset``, every
    window under each mask pattern but "all" in turn (a job): each set's arrays keyed ``<pattern>__<key>``."""
    from quadfdi.core.channels import MASK_PATTERNS
    from quadfdi.formats.dataset import load_dataset, split_rows
    from quadfdi.models.checkpoint import check_dataset_matches, load_checkpoint
    from quadfdi.models.inputs import profile_of
    from quadfdi.train.vehicle_ref import profiled
    from quadfdi.train.masks import Masker
    from quadfdi.train.predsets import prediction_sets

    model, blob = load_checkpoint(checkpoint, kind)
    _threads(blob)
    profile = profile_of(blob)
    ds = profiled(load_dataset(dataset), profile, patterns=False)
    check_dataset_matches(blob, ds.channel_names, dataset)
    masker = Masker(profile, ds.channel_names)
    mask = lambda k: lambda x: masker.apply(x.copy(), np.full(len(x), k))  # noqa: E731
    variants = {p.name: mask(k) for k, p in enumerate(MASK_PATTERNS) if p.name != "all"}
    sets = prediction_sets(model, ds, split_rows(ds, split), variants)
    return {f"{name}{SEP}{key}": a for name, arrays in sets.items() for key, a in arrays.items()}


def run_patterns(run: RunDir, cfg: Config, sim_seeds: list[int], settings: ExecSettings = SERIAL,
                 split: str = "test", log: Callable[[str], None] = print) -> dict:
    """Publish the masked networks' prediction sets under every mask pattern (module docstring) on
    ``split``'s flights of ``sim_seeds``; return the summary (patterns.json). ``cfg``: the run's config
    with the train stage's [train] (``with_stage_train``)."""
    from quadfdi.core.channels import MASK_PATTERNS
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.profiles import is_masked
    from quadfdi.core.stage import stage
    from quadfdi.train.predsets import index_entry, write_prediction_set
    from quadfdi.train.study_sims import study_datasets

    if not is_masked(cfg.train.profile):
        raise QuadfdiError(f"{run.root}: mask patterns need the masked profile's networks; the run's train stage "
                           f"trained profile {cfg.train.profile!r}")
    nets = {kind: stage_checkpoint(run, cfg, kind) for kind in MODELS}
    if any(p is None for p in nets.values()):
        raise QuadfdiError(f"{run.root}: no train-stage network of {', '.join(k for k, p in nets.items() if p is None)} "
                           "trained with the run's [sim] and [train]: run quadfdi train first")
    data = study_datasets(run, cfg, sim_seeds, settings, log)
    sections, seed = cfg.to_dict(), cfg.train.seed
    order = [p.name for p in MASK_PATTERNS]
    with stage(run.root, "patterns", {"sim": sections["sim"], "train": sections["train"]},
               targets=(PATTERNS_SUMMARY,)) as st:
        st.consume("dataset.npz", ("sim",))
        for path in nets.values():
            st.consume(path.relative_to(run.root).as_posix())
        jobs = []
        for d in data:
            for kind, path in nets.items():
                key = job_key(PATTERN_KIND, {}, {"model": kind, "split": split}, {"checkpoint": path, "dataset": d.path},
                              packages=("sim", "train"))
                jobs.append((Job(PATTERN_KIND, key, pattern_network, (str(path), str(d.path), kind, split),
                                 cache_path(run.root, PATTERN_KIND, key, "npz"),
                                 label=f"{kind} on sim {d.sim_seed} under every pattern", torch=True), kind, d))
        summary = {"split": split, "train_seed": seed, "sets": []}
        for r, (_, kind, d) in zip(run_jobs([j[0] for j in jobs], settings, desc="patterns", log=log), jobs):
            if not r.ok:
                raise QuadfdiError(f"prediction sets of {r.job.label} failed: {r.error}")
            arrays: dict[str, dict] = {}
            for k, a in read_result(r.job.out).items():
                name, _, field = k.partition(SEP)
                arrays.setdefault(name, {})[field] = a
            for name, pred in sorted(arrays.items(), key=lambda kv: order.index(kv[0])):
                entry = dict(index_entry(f"{kind}_{name}", d.sim_seed, seed, d.rel), kind=kind, pattern=name)
                write_prediction_set(st.out / entry["predictions"], pred)
                summary["sets"].append(entry)
        write_json(st.path(PATTERNS_SUMMARY), summary, indent=2)
    return summary
