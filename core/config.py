"""One TOML config, one section per stage; defaults are the paper's Table 2.

``load_config(path, overrides)`` reads ``configs/paper.toml`` (or any file of the same shape), applies ``--set
section.key=value`` overrides, type-checks every value and validates ranges. An unknown section or key is an error
that lists the valid ones (as nanoGPT's configurator does), so a typo never silently falls back to a default. The
config used by a run is stored in the run folder (``config.toml``) and inside every artifact.

Each stage owns its sections (``sim/config.py``: [sim], ``train/config.py``: [train] and [sgru], ...;
core.sections says how they are declared); this module composes them into ``Config`` without importing
any stage. ``Config`` is a frozen dataclass with one field per section (``cfg.sim.window``), built the
first time it is asked for. Its ``validate`` runs every section's own ``validate()``, then the
``validate_with(cfg)`` of each section that defines one: a check that needs another section's values is
that method of the section it belongs to (none of today's checks needs one).
"""

from __future__ import annotations

import dataclasses
import functools
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any, get_type_hints

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.resources import config_file, config_names
from quadfdi.core.sections import coerce, parse_override, section_classes, section_dict
from quadfdi.core.tomlio import dumps_toml  # noqa: F401 (re-exported: the run folder writes it)


class ComposedConfig:
    """What a Config does with its sections (the fields come from ``compose``)."""

    def validate(self) -> None:
        sections = [getattr(self, f.name) for f in dataclasses.fields(self)]
        for section in sections:
            section.validate()
        for section in sections:
            across = getattr(section, "validate_with", None)
            if across is not None:
                across(self)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        return {f.name: section_dict(getattr(self, f.name)) for f in dataclasses.fields(self)}


def compose(classes: Mapping[str, type]) -> type:
    """A frozen dataclass named Config with one field per section of ``classes`` (in that order), each
    defaulting to its section's defaults."""
    cls = dataclasses.make_dataclass(
        "Config", [(name, sec, dataclasses.field(default_factory=sec)) for name, sec in classes.items()],
        bases=(ComposedConfig,), frozen=True)
    cls.__module__ = __name__  # pickled by reference (Dask jobs carry configs): quadfdi.core.config.Config
    cls.__doc__ = f"The whole config: one field per section ({', '.join(classes)})."
    return cls


@functools.cache
def config_class() -> type:
    """The installed sections composed (the class ``Config`` names)."""
    return compose(section_classes())


def __getattr__(name: str) -> Any:
    # ``Config`` is composed on first use, not at import: a section module imports core, so the
    # sections cannot be loaded while core itself is being imported.
    if name == "Config":
        return config_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def build_config(data: dict[str, Any], overrides: list[str] | tuple[str, ...] = (), source: str = "config") -> Any:
    """Config from a parsed TOML mapping plus ``section.key=value`` overrides, checked."""
    merged: dict[str, dict[str, Any]] = {}
    sections = section_classes()
    for name, body in data.items():
        if name not in sections:
            raise QuadfdiError(f"{source}: unknown section [{name}]; valid sections: {', '.join(sections)}")
        if not isinstance(body, dict):
            raise QuadfdiError(f"{source}: [{name}] must be a table")
        merged[name] = dict(body)
    for text in overrides:
        section, key, value = parse_override(text)
        if section not in sections:
            raise QuadfdiError(f"--set {text}: unknown section {section!r}; valid sections: {', '.join(sections)}")
        merged.setdefault(section, {})[key] = value
    built = {name: _build_section(name, cls, merged.get(name, {}), source) for name, cls in sections.items()}
    cfg = config_class()(**built)
    cfg.validate()
    return cfg


def _build_section(name: str, cls: type, body: dict[str, Any], source: str) -> Any:
    """One section from its parsed keys, every value checked against its field's type."""
    hints = get_type_hints(cls)
    valid = [f.name for f in dataclasses.fields(cls)]
    if hasattr(cls, "fold_tables"):  # [alarm]: per-network tables ([alarm.cnode], --set alarm.cnode.k=3)
        body = cls.fold_tables(body, source)
    kwargs = {}
    for key, value in body.items():
        if key not in hints:
            raise QuadfdiError(f"{source}: unknown key {name}.{key}; valid keys of [{name}]: {', '.join(valid)}")
        kwargs[key] = getattr(cls, "coerce_key", coerce)(value, hints[key], f"{name}.{key}")
    return cls(**kwargs)


def load_config(path: str | Path | None, overrides: list[str] | tuple[str, ...] = ()) -> Any:
    """Read a TOML config (a shipped config's name such as ``paper``, a file, or the defaults when ``path``
    is None: core.resources.config_file) and apply overrides."""
    data: dict[str, Any] = {}
    source = "defaults"
    if path is not None:
        p = config_file(path)
        source = str(p)
        try:
            data = tomllib.loads(p.read_text())
        except FileNotFoundError:
            raise QuadfdiError(f"config file {p} does not exist (shipped configs, by name: "
                               f"{', '.join(config_names())})") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise QuadfdiError(f"cannot read config file {p}: {exc}") from None
        except tomllib.TOMLDecodeError as exc:
            raise QuadfdiError(f"config file {p} is not valid TOML: {exc}") from None
    return build_config(data, overrides, source)


def replace_section(cfg: Any, section: str, **changes: Any) -> Any:
    """A copy of ``cfg`` with some keys of one section changed (validated)."""
    new = dataclasses.replace(cfg, **{section: dataclasses.replace(getattr(cfg, section), **changes)})
    new.validate()
    return new
