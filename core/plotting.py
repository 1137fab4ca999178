"""Figures: a headless matplotlib and one atomic PNG writer, shared by every stage."""

from __future__ import annotations

from pathlib import Path

from quadfdi.core.atomic import atomic_path


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display on CI or a flight-test laptop's SSH)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_png(fig, path: str | Path, **savefig_kw) -> Path:
    """Write ``fig`` as a PNG atomically (temp file + rename), then close it."""
    with atomic_path(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90, **savefig_kw)
    pyplot().close(fig)
    return Path(path)
