"""Deterministic, pickle-free .npz files: the container of the dataset and the predictions.

``np.savez`` stamps every member with the current time, so the same arrays give different bytes;
``write_npz`` fixes the timestamps (same content, same bytes) and writes atomically.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from quadfdi.core.atomic import atomic_path
from quadfdi.core.errors import QuadfdiError

_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)  # fixed timestamps: same content, same bytes


def write_npz(path: str | Path, arrays: dict[str, np.ndarray]) -> None:
    """Write ``arrays`` as an uncompressed .npz, deterministically and atomically."""
    with atomic_path(path, "wb") as fh:
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
            for key in sorted(arrays):
                arr = np.asarray(arrays[key])
                if arr.dtype == object:
                    raise TypeError(f"{key}: object arrays would need pickle")
                buf = io.BytesIO()
                np.lib.format.write_array(buf, arr, allow_pickle=False)
                info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_EPOCH)
                info.external_attr = 0o644 << 16
                zf.writestr(info, buf.getvalue())


def read_npz(path: str | Path, what: str = "file") -> dict[str, np.ndarray]:
    """All arrays of an .npz, or a one-line error for a missing, truncated or foreign file."""
    p = Path(path)
    if not p.is_file():
        raise QuadfdiError(f"{what} {p} does not exist")
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise QuadfdiError(f"{what} {p} is not a readable .npz (truncated or foreign file?): {exc}") from None
