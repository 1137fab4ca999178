"""Generated blocks inside hand-written markdown: the text between two HTML-comment markers.

``<!-- NAME:start -->`` ... ``<!-- NAME:end -->``: a command rewrites what lies between, and
nothing else, so the prose around a results table stays the author's.
"""

from __future__ import annotations

import re
from pathlib import Path

from quadfdi.core.atomic import write_text
from quadfdi.core.errors import QuadfdiError


def markers(name: str) -> tuple[str, str]:
    return f"<!-- {name}:start -->", f"<!-- {name}:end -->"


def replace_block(text: str, name: str, body: str, where: str = "text") -> str:
    """``text`` with the block ``name`` replaced by ``body``; one-line error when a marker is missing."""
    start, end = markers(name)
    pattern = re.compile(re.escape(start) + r".*?" + re.escape(end), re.S)
    if len(pattern.findall(text)) != 1:
        raise QuadfdiError(f"{where} must hold exactly one '{start}' ... '{end}' block")
    return pattern.sub(lambda _: f"{start}\n{body.rstrip()}\n{end}", text)


def rewrite_file_block(path: str | Path, name: str, body: str) -> Path:
    """Rewrite block ``name`` of the markdown file ``path`` atomically."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise QuadfdiError(f"cannot read {p}: {exc}") from None
    write_text(p, replace_block(text, name, body, str(p)))
    return p
