"""``quadfdi train sgru --run RUN``: the streaming GRU (train/stream_gru_run.py). Its settings are the
run's [sgru] section (train/config.py); ``--set sgru.key=value`` and one flag per key (``--hidden 40``,
which wins over ``--set``) override it for this command."""

from __future__ import annotations

import argparse
from dataclasses import fields

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.config import replace_section
from quadfdi.core.rundir import open_run


def add_sgru_parser(acts: argparse._SubParsersAction) -> None:
    from quadfdi.train.config import StreamFitConfig

    p = acts.add_parser("sgru", help="the streaming GRU: one GRU step per sample, trained on whole-flight segments "
                                     "(truncated BPTT); its prediction set at every evaluation window end")
    p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    for f in fields(StreamFitConfig):
        p.add_argument("--" + f.name.replace("_", "-"), type=type(f.default), default=None,
                       help=f"overrides the run's sgru.{f.name} (default {f.default})")
    add_config_args(p, config=False)
    p.set_defaults(func=run_sgru_cmd)


def run_sgru_cmd(args: argparse.Namespace) -> int:
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_run import train_stream_run

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    given = {f.name: getattr(args, f.name) for f in fields(StreamFitConfig) if getattr(args, f.name) is not None}
    if given:
        cfg = replace_section(cfg, "sgru", **given)
    for path in train_stream_run(run.root, cfg):
        print(f"wrote {path}")
    return 0
