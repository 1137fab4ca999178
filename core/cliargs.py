"""Command-line options every stage shares (the stages' thin CLIs import this, not the app layer)."""

from __future__ import annotations

import argparse

from quadfdi.core.resources import config_names


def add_config_args(p: argparse.ArgumentParser, config: bool = True) -> None:
    """``--config`` and repeated ``--set section.key=value``."""
    if config:
        p.add_argument("--config", default="paper", help=f"a shipped config by name ({', '.join(config_names())}) "
                                                         "or a TOML file's path (default: %(default)s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one config value; repeatable")
