"""Strict JSON: every JSON artifact is written through here (no NaN tokens, atomically)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from quadfdi.core.atomic import write_text
from quadfdi.core.errors import QuadfdiError


def to_jsonable(d: Any) -> Any:
    """Recursively convert to plain JSON types; NaN and +-inf become None (JSON null).

    numpy scalars and arrays become Python numbers and lists, tuples become lists, mapping keys
    become strings. The result passes ``json.dumps(..., allow_nan=False)``.
    """
    if isinstance(d, Mapping):
        return {str(k): to_jsonable(v) for k, v in d.items()}
    if isinstance(d, np.ndarray):
        return [to_jsonable(v) for v in d.tolist()]
    if isinstance(d, (list, tuple)):
        return [to_jsonable(v) for v in d]
    if isinstance(d, (bool, np.bool_)):
        return bool(d)
    if isinstance(d, (int, np.integer)):
        return int(d)
    if isinstance(d, (float, np.floating)):
        f = float(d)
        return f if math.isfinite(f) else None
    if d is None or isinstance(d, str):
        return d
    raise TypeError(f"to_jsonable: cannot convert {type(d).__name__}")


def dumps_json(d: Any, indent: int = 2) -> str:
    """Strict JSON text of ``to_jsonable(d)`` with a trailing newline."""
    return json.dumps(to_jsonable(d), indent=indent, allow_nan=False) + "\n"


def write_json(path: str | Path, d: Any, indent: int = 2) -> None:
    """Write ``d`` as strict JSON, atomically."""
    write_text(path, dumps_json(d, indent))


def read_json(path: str | Path, what: str = "file") -> Any:
    """A JSON file's content, or a one-line error for a missing, unreadable or malformed file."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"{what} {p} does not exist or is not a regular file")
    try:
        return json.loads(p.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise QuadfdiError(f"{what} {p} cannot be read as JSON (truncated or foreign file?): {exc}") from None
