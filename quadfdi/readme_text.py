"""Text of the README's generated blocks: prose filled into the README's 100-character lines."""

from __future__ import annotations

import re

WIDTH = 100  # the README's line width


def wrap(text: str, keep: tuple[str, ...] = (), width: int = WIDTH) -> list[str]:
    """``text`` filled into lines of at most ``width`` characters, never breaking inside a `code span`
    or inside one of the ``keep`` phrases (a CPU's name)."""
    for phrase in filter(None, keep):
        text = text.replace(phrase, phrase.replace(" ", "\x00"))
    lines, line = [], ""
    for word in re.findall(r"[^\s`]*`[^`]*`\S*|\S+", text):
        if line and len(line) + 1 + len(word) > width:
            lines.append(line)
            line = word
        else:
            line = f"{line} {word}" if line else word
    return [w.replace("\x00", " ") for w in lines + [line]]
