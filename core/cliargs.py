"""Command-line options every stage shares (the stages' thin CLIs import this, not the app layer)."""

from __future__ import annotations

import argparse
import sys
from typing import Any, Callable

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resources import config_names


def one_line_main(prog: str, body: Callable[[], Any], errors: tuple[type[BaseException], ...] = ()) -> int:
    """A ``python -m`` entry point's body: run it, print what it returns, and turn a QuadfdiError (or one of
    ``errors``) into one line on stderr and exit 2."""
    try:
        out = body()
    except (QuadfdiError, *errors) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    if out is not None:
        print(out)
    return 0


def add_config_args(p: argparse.ArgumentParser, config: bool = True) -> None:
    """``--config`` and repeated ``--set section.key=value``."""
    if config:
        p.add_argument("--config", default="paper", help=f"a shipped config by name ({', '.join(config_names())}) "
                                                         "or a TOML file's path (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one config value; repeatable")
