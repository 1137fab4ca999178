"""``quadfdi train sgru --run RUN``: the streaming GRU (train/stream_gru_run.py); its settings are
flags with the defaults of ``train.stream_gru_fit.StreamFitConfig``."""

from __future__ import annotations

import argparse
from dataclasses import fields

from quadfdi.core.cliargs import add_config_args
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.rundir import open_run


def add_sgru_parser(acts: argparse._SubParsersAction) -> None:
    from quadfdi.train.stream_gru_config import StreamFitConfig

    p = acts.add_parser("sgru", help="the streaming GRU: one GRU step per sample, trained on whole-flight segments "
                                     "(truncated BPTT); its prediction set at every evaluation window end")
    p.add_argument("--run", required=True, help="run folder holding dataset.npz")
    for f in fields(StreamFitConfig):
        p.add_argument("--" + f.name.replace("_", "-"), type=type(f.default), default=None,
                       help=f"(default {f.default})")
    add_config_args(p, config=False)
    p.set_defaults(func=run_sgru_cmd)


def run_sgru_cmd(args: argparse.Namespace) -> int:
    from quadfdi.train.stream_gru_config import StreamFitConfig
    from quadfdi.train.stream_gru_run import train_stream_run

    run, cfg = open_run(args.run, args.overrides, need=("dataset",))
    given = {f.name: getattr(args, f.name) for f in fields(StreamFitConfig) if getattr(args, f.name) is not None}
    fit = StreamFitConfig(**given)
    try:
        fit.validate()
    except ValueError as exc:
        raise QuadfdiError(f"quadfdi train sgru: {exc}") from None
    for path in train_stream_run(run.root, cfg, fit):
        print(f"wrote {path}")
    return 0
