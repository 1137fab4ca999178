"""Markdown tables, written once for every report section."""

from __future__ import annotations

from typing import Any, Sequence


def md_table(head: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """Lines of a GitHub markdown table (header, rule, rows) followed by a blank line."""
    return ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|",
            *("| " + " | ".join(str(c) for c in r) + " |" for r in rows), ""]
