"""``--set section.key=value`` parsing (core.config; its own module because config.py is at the
400-line cap)."""

from __future__ import annotations

import tomllib
from typing import Any

from quadfdi.core.errors import QuadfdiError


def parse_override(text: str) -> tuple[str, str, Any]:
    """(section, key, value) of one override; the value parsed as TOML, or a bare word as a string."""
    if "=" not in text or "." not in text.split("=", 1)[0]:
        raise QuadfdiError(f"--set expects section.key=value, found {text!r}")
    dotted, raw = text.split("=", 1)
    section, key = dotted.strip().split(".", 1)
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw.strip()  # a bare word such as cnode is a string
    return section, key, value
