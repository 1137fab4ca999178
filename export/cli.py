"""``quadfdi export --run runs/<name> [--steps N]``: deployable graphs and files for the C++ reference."""

from __future__ import annotations

import argparse

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import replace_section
from quadfdi.core.rundir import open_run


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export both models to ONNX (fp32, int8), weights.bin, reference.bin",
                       description="Read cnode.pt, gru.pt and dataset.npz of a run; write <run>/export/: "
                                   "cnode_rk4_<N>.onnx, cnode_rk4_<N>.int8.onnx, gru.onnx, gru.int8.onnx, "
                                   "weights.bin, reference.bin, coverage.md, manifest.json.")
    add_config_args(p, config=False)
    # not required=True: `quadfdi export sgru --run RUN` gives --run to the subcommand; run_export checks it
    p.add_argument("--run", default=None, help="run folder holding dataset.npz, cnode.pt and gru.pt")
    p.add_argument("--steps", type=int, default=None,
                   help="N, classic RK4 steps of the unrolled CNODE graph (default: the config's export.steps)")
    p.add_argument("--alarm-from", choices=("config", "evaluation"), default="config",
                   help="each network's alarm policy: the config's [alarm] / [alarm.<net>] (default) or the one "
                        "`quadfdi evaluate` chose on validation (RUN/evaluation/evaluation.json)")
    p.set_defaults(func=run_export)
    acts = p.add_subparsers(dest="action", metavar="{sgru,scnode}")
    for name, what, func in (("sgru", "the streaming GRU", run_export_sgru), ("scnode", "the streaming CNODE", run_export_scnode)):
        ps = acts.add_parser(name, help=f"{what}: one-step ONNX graphs fp32 and int8, checked on a replayed flight")
        ps.add_argument("--run", required=True, help=f"run folder holding dataset.npz and {name}_train<seed>.pt")
        ps.add_argument("--seed", type=int, default=0, help="training seed of the checkpoint (default 0)")
        add_config_args(ps, config=False)
        ps.set_defaults(func=func)


def run_export_sgru(args: argparse.Namespace) -> int:
    from quadfdi.export.sgru_run import export_sgru_run

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    for path in export_sgru_run(run.root, args.seed, cfg.export.opset):
        print(f"wrote {path}")
    return 0


def run_export_scnode(args: argparse.Namespace) -> int:
    from quadfdi.export.scnode_run import export_scnode_run

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    for path in export_scnode_run(run.root, args.seed, cfg.export.opset):
        print(f"wrote {path}")
    return 0


def run_export(args: argparse.Namespace) -> int:
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.export.alarm_policies import policies_of
    from quadfdi.export.deployment import deployment_of

    if args.run is None:
        raise QuadfdiError("quadfdi export needs --run <run folder>")
    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    if args.steps is not None:
        cfg = replace_section(cfg, "export", steps=args.steps)
    from quadfdi.core.records import verify_input
    from quadfdi.export.manifest import MODEL_KINDS

    sim = {"sim": cfg.to_dict()["sim"]}
    for kind in MODEL_KINDS:  # as the stage consumes them, so that refusals come before torch and onnx load
        verify_input(run.root, f"{kind}.pt", sim, ("sim",))
    policies = policies_of(run, cfg.alarm, args.alarm_from)
    deployment = deployment_of(run)
    from quadfdi.export.run import export_run

    manifest = export_run(run, cfg, policies=policies, deployment=deployment)
    ok = manifest["verification"]["passed"]
    print(f"export: verification {'passed' if ok else 'FAILED'}; manifest {run.export / 'manifest.json'}")
    return 0 if ok else 1
