"""``quadfdi train``: train the CNODE, the GRU and the baseline on a run's dataset;
``quadfdi train study``: the multi-seed results table;
``quadfdi train baselines``: the three tuned baselines' prediction sets (train/baselines_run.py)."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.executor import ExecSettings, add_executor_args, strip_executor_args
from quadfdi.core.rundir import open_run


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("train", help="train the CNODE, the GRU and the baseline",
                       description="Train on <run>/dataset.npz; write checkpoints, predictions, metrics, figures.")
    p.add_argument("--run", default=None, help="run folder holding dataset.npz (e.g. runs/paper)")
    p.add_argument("--model", choices=("cnode", "gru", "both"), default=None, help="which model (default: train.model)")
    p.add_argument("--seed", type=int, default=None, help="training seed (default: train.seed)")
    add_config_args(p, config=False)
    p.set_defaults(func=run_train)
    acts = p.add_subparsers(dest="action", metavar="{study,apply,baselines,sgru,scnode}")
    # the two seed sweeps: (name, help, --run, --seeds, --sim-seeds (required?, help), handler)
    for name, what, run_help, seeds_help, (sim_required, sim_help), func in (
            ("study", "train with several seeds: seeds.json and results.md (Tables 3-4)",
             "run folder holding dataset.npz", "comma-separated seeds (default: train.seeds)",
             (False, "comma-separated simulator seeds (default: the run's sim.seed); each other seed is simulated "
                     "into <run>/sims/seed<S>/ first"), run_study_cmd),
            ("apply", "the run's networks (trained on its sim seed) predicting on other sim seeds' datasets, without "
                      "retraining: prediction sets for evaluate",
             "run folder holding dataset.npz and the train stage",
             "comma-separated training seeds (default: train.seeds); a seed whose network the train stage does not "
             "hold is retrained (cached)",
             (True, "comma-separated simulator seeds to predict on (other than the run's); each is simulated into "
                    "<run>/sims/seed<S>/ when missing"), run_apply_cmd)):
        ps = acts.add_parser(name, help=what)
        ps.add_argument("--run", required=True, help=run_help)
        ps.add_argument("--seeds", default=None, help=seeds_help)
        ps.add_argument("--sim-seeds", required=sim_required, default=None, help=sim_help)
        if name == "study":
            ps.add_argument("--readme", default=None, help="also copy the table into this README between the results "
                            "markers")
        add_config_args(ps, config=False)
        add_executor_args(ps)
        ps.set_defaults(func=func)
    pb = acts.add_parser("baselines", help="logreg (statistics), logreg (physics features), gradient-boosted trees: "
                                          "prediction sets tuned on validation")
    pb.add_argument("--run", required=True, help="run folder holding dataset.npz")
    pb.add_argument("--datasets", choices=("run", "all"), default="all",
                    help="run: dataset.npz only; all: also every dataset the prediction index lists (default)")
    pb.add_argument("--seed", type=int, default=None, help="the baselines' seed (default: train.seed)")
    pb.add_argument("--max-train-windows", type=int, default=None,
                    help="seeded subsample of the training windows; 0 = all (default: train.baselines.MAX_TRAIN_WINDOWS)")
    add_config_args(pb, config=False)
    add_executor_args(pb)  # one job per dataset (simulator seed)
    pb.set_defaults(func=run_baselines_cmd)
    from quadfdi.train.stream_cnode_cli import add_scnode_parser
    from quadfdi.train.stream_gru_cli import add_sgru_parser

    add_sgru_parser(acts)
    add_scnode_parser(acts)


def run_train(args: argparse.Namespace) -> int:
    if args.run is None:
        raise QuadfdiError("quadfdi train needs --run <run folder>")
    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    from quadfdi.train.run import train_run  # torch: after the refusals of the run folder and the config

    model = args.model or cfg.train.model
    train_run(run, cfg, model, args.seed)
    print(f"wrote checkpoints, predictions, metrics.json and figures into {run.root}")
    return 0


def run_study_cmd(args: argparse.Namespace) -> int:
    from quadfdi.train.study import check_readme, run_study, update_readme

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    seeds = _seed_list("--seeds", args.seeds, list(cfg.train.seeds))
    sim_seeds = _seed_list("--sim-seeds", args.sim_seeds, [cfg.sim.seed])
    readme = Path(args.readme) if args.readme else None
    if readme is not None:
        check_readme(readme)
    argv = strip_executor_args(sys.argv[1:])  # where it ran is not part of the result
    command = "quadfdi " + " ".join(shlex.quote(a) for a in argv) if argv else "quadfdi train study"
    out = run_study(run, cfg, seeds, command, settings=ExecSettings.from_args(args), sim_seeds=sim_seeds)
    print(out["table"])
    if readme is not None:
        update_readme(readme, out["table"])
    return 0


def run_apply_cmd(args: argparse.Namespace) -> int:
    from quadfdi.train.study_apply import run_apply, with_stage_train

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    cfg = with_stage_train(run, cfg, {o.split("=", 1)[0][len("train."):] for o in args.overrides if o.startswith("train.")})
    seeds = _seed_list("--seeds", args.seeds, list(cfg.train.seeds))
    summary = run_apply(run, cfg, seeds, _seed_list("--sim-seeds", args.sim_seeds, []), ExecSettings.from_args(args))
    for s in summary["sets"]:
        check = {True: ", reproduces its indexed set", False: ", DIFFERS from its indexed set", None: ""}
        print(f"{s['predictions']}: {s['model']} train seed {s['train_seed']} ({s['network']}"
              f"{check[s['reproduces_indexed_set']]}) on sim seed {s['sim_seed']}")
    return 0


def _seed_list(flag: str, text: str | None, default: list[int]) -> list[int]:
    """A comma-separated list of distinct non-negative integers (``default`` when not given)."""
    if not text:
        return default
    try:
        seeds = [int(s) for s in text.split(",")]
    except ValueError:
        raise QuadfdiError(f"{flag} expects comma-separated integers, found {text!r}") from None
    if min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise QuadfdiError(f"{flag} expects distinct non-negative integers, found {text!r}")
    return seeds


def run_baselines_cmd(args: argparse.Namespace) -> int:
    from quadfdi.core.profiles import uses_hover

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    seed = cfg.train.seed if args.seed is None else args.seed
    if seed < 0 or (args.max_train_windows or 0) < 0:
        raise QuadfdiError(f"--seed and --max-train-windows must not be negative, found {seed} and "
                           f"{args.max_train_windows}")
    from quadfdi.train.baselines import MAX_TRAIN_WINDOWS  # scikit-learn: after the refusals above
    from quadfdi.train.baselines_run import run_baselines

    cap = MAX_TRAIN_WINDOWS if args.max_train_windows is None else args.max_train_windows
    written, lines = run_baselines(run.root, seed, args.datasets, cap=cap, reference=cfg.train.baselines_reference,
                                   logged=uses_hover(cfg.train.profile), settings=ExecSettings.from_args(args))
    print("\n".join(lines))
    print(f"wrote {len(written)} files into {run.root / 'predictions'}")
    return 0
