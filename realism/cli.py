"""``quadfdi realism --run RUN --logs LOG...`` (placeholder until the comparison lands)."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("realism", help="compare a run's simulated telemetry with real flight logs")
    p.add_argument("--run", required=True)
    p.add_argument("--logs", nargs="+", required=True)
    p.set_defaults(func=lambda args: 0)
