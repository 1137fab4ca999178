"""``quadfdi train scnode --run RUN``: the streaming CNODE (train/stream_cnode_run.py). Its settings are the
run's [scnode] section (train/config.py); ``--set scnode.key=value`` and one flag per key (``--latent 16``,
which wins over ``--set``) override it for this command."""

from __future__ import annotations

import argparse
from dataclasses import fields

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import replace_section
from quadfdi.core.rundir import open_run


def add_scnode_parser(acts: argparse._SubParsersAction) -> None:
    from quadfdi.train.config import StreamCnodeConfig

    p = acts.add_parser("scnode", help="the streaming CNODE: one RK4 step of the CNODE's field per sample, trained on "
                                       "whole-flight segments (truncated BPTT); its prediction set at every window end")
    p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    for f in fields(StreamCnodeConfig):
        p.add_argument("--" + f.name.replace("_", "-"), type=_bool if isinstance(f.default, bool) else type(f.default),
                       default=None,
                       help=f"overrides the run's scnode.{f.name} (default {f.default})")
    add_config_args(p, config=False)
    p.set_defaults(func=run_scnode_cmd)


def _bool(text: str) -> bool:
    if text.lower() not in ("true", "false"):
        raise argparse.ArgumentTypeError(f"expected true or false, found {text!r}")
    return text.lower() == "true"


def run_scnode_cmd(args: argparse.Namespace) -> int:
    from quadfdi.train.config import StreamCnodeConfig
    from quadfdi.train.stream_cnode_run import train_scnode_run

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    given = {f.name: getattr(args, f.name) for f in fields(StreamCnodeConfig) if getattr(args, f.name) is not None}
    if given:
        cfg = replace_section(cfg, "scnode", **given)
    for path in train_scnode_run(run.root, cfg):
        print(f"wrote {path}")
    return 0
