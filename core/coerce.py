"""Checking a value parsed from TOML (or ``--set``) against a config dataclass field's type (core.config;
its own module because config.py is at the 400-line cap, and core.alarm's per-network tables use it)."""

from __future__ import annotations

import math
from typing import Any, get_args, get_origin

from quadfdi.core.errors import QuadfdiError


def coerce(value: Any, typ: Any, where: str) -> Any:
    """Check ``value`` (parsed from TOML) against the dataclass field type ``typ``."""
    origin = get_origin(typ)
    if origin is tuple:
        args = get_args(typ)
        if not isinstance(value, (list, tuple)):
            raise QuadfdiError(f"{where} must be a list, found {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(v, args[0], where) for v in value)
        if len(value) != len(args):
            raise QuadfdiError(f"{where} must be a list of {len(args)} values, found {list(value)!r}")
        return tuple(coerce(v, a, where) for v, a in zip(value, args))
    if typ is bool:
        if not isinstance(value, bool):
            raise QuadfdiError(f"{where} must be true or false, found {value!r}")
        return value
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise QuadfdiError(f"{where} must be an integer, found {value!r}")
        return value
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise QuadfdiError(f"{where} must be a finite number, found {value!r}")
        return float(value)
    if typ is str:
        if not isinstance(value, str):
            raise QuadfdiError(f"{where} must be a string, found {value!r}")
        return value
    raise TypeError(f"unsupported config type {typ} for {where}")
