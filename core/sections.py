"""Config sections: which exist, and parsing and checking values into them.

A section is a frozen dataclass with typed fields (their defaults are the paper's) and a ``validate()``
that raises a one-line QuadfdiError naming ``section.key``. Each stage owns its sections beside its code
(``sim/config.py``, ``train/config.py``, ...) and declares them as entry points of the group
``quadfdi.config_sections`` in pyproject.toml (``sim = "quadfdi.sim.config:SimConfig"``): core composes
them into one Config without importing any stage, and the installed package (editable in a checkout, or
a wheel) carries the list. Entry points have no order (setuptools writes them sorted by name), so
``FILE_ORDER`` says where each section goes in a config file; a section installed but not listed there
follows them in name order.

A section module imports core modules only, never ``core.config`` (which loads it while it composes
Config), and nothing heavy such as torch: building a Config loads every section.

Values come from a parsed TOML file or from ``--set section.key=value`` (``parse_override``); ``coerce``
checks each against its field's type (ints stay ints, a float field takes an int, tuples take lists of the
declared length), and the range checks below name the key in their message.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import tomllib
from importlib.metadata import entry_points
from typing import Any, get_args, get_origin

from quadfdi.core.errors import QuadfdiError

GROUP = "quadfdi.config_sections"
# The sections in config-file order: the stages' order, then [alarm], [evaluate] and [run] (quadfdi run).
FILE_ORDER = ("sim", "train", "sgru", "scnode", "export", "solvers", "bench", "alarm", "evaluate", "run")


@functools.cache
def section_classes() -> dict[str, type]:
    """Section name -> its dataclass (the installed entry points of GROUP), in config-file order."""
    eps = {}
    for ep in entry_points(group=GROUP):
        if ep.name in eps:
            raise QuadfdiError(f"config section [{ep.name}] is declared by two installed entry points of {GROUP}")
        eps[ep.name] = ep
    missing = [name for name in FILE_ORDER if name not in eps]
    if missing:
        raise QuadfdiError(f"config section [{missing[0]}] is not installed (entry points of {GROUP}): the package "
                           "metadata is stale; reinstall quadfdi (pip install -e . in a checkout)")
    out = {}
    for name in (*FILE_ORDER, *sorted(set(eps) - set(FILE_ORDER))):
        cls = eps[name].load()
        if not dataclasses.is_dataclass(cls) or not callable(getattr(cls, "validate", None)):
            raise TypeError(f"entry point {name} = {eps[name].value} of {GROUP} is not a config section dataclass")
        out[name] = cls
    return out


def section_name(section: Any) -> str:
    """The name of ``section``'s class in the config (its entry point); the class name if it has none."""
    cls = section if isinstance(section, type) else type(section)
    for name, known in section_classes().items():
        if known is cls:
            return name
    return cls.__name__


def section_dict(section: Any) -> dict[str, Any]:
    """The section's keys (tuples as lists); an empty table ([alarm.<net>] not given) is left out."""
    return {f.name: (list(v) if isinstance(v := getattr(section, f.name), tuple) else v)
            for f in dataclasses.fields(section) if getattr(section, f.name) != {}}


def parse_override(text: str) -> tuple[str, str, Any]:
    """(section, key, value) of one ``--set``; the value parsed as TOML, or a bare word as a string."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise QuadfdiError(f"--set expects section.key=value, found {text!r}")
    dotted, raw = text.split("=", 1)
    section, key = dotted.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()  # a bare word such as cnode is a string
    return section, key, value


MAX_INT = 10**9  # no count or size of quadfdi comes near it; a larger integer is a typo


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
        if abs(value) > MAX_INT:  # every size and count has a tighter bound in its section's validate
            raise QuadfdiError(f"{where} must be at most {MAX_INT:.0e} in size, found {value}")
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


def positive(section: Any, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if not value > 0:
            raise QuadfdiError(f"{section_name(section)}.{name} must be positive, found {value}")


def not_negative(section: Any, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if value < 0:
            raise QuadfdiError(f"{section_name(section)}.{name} must not be negative, found {value}")


def at_most(section: Any, limit: int, *names: str) -> None:
    for name in names:
        value = getattr(section, name)
        if value > limit:
            raise QuadfdiError(f"{section_name(section)}.{name} must be at most {limit}, found {value}")


def choice(section: Any, name: str, allowed: tuple[str, ...]) -> None:
    value = getattr(section, name)
    if value not in allowed:
        raise QuadfdiError(f"{section_name(section)}.{name} must be one of {', '.join(allowed)}; found {value!r}")
