"""``<run>/export/sgru_weights.bin``: the streaming GRU on board, beside weights.bin.

The streaming GRU has its own weights file so that weights.bin (its bytes, its sha256 in the
manifest, and every reader written before the streaming GRU) stays exactly what it was. Container
and section format are weights.bin's (formats/binfmt.py: magic b"QFDIWTS\\0", version 1); sections,
in this order:

    sgru fp32   model code 18, precision 1: the GRU's tensors (formats/weights_layout.py "gru")
                with dims [0] C, [1] W = 1 (one step), [2] K, [3] H
    sgru int8   model code 18, precision 2: the same with int8 matrices (per-row scales) and the
                static scales act.x_norm.scale (C,) (folded into gru.weight_ih) and act.h.scale
    none none   a byte copy of weights.bin's on-board record (formats/onboard.py): profile,
                raw and model channels, W, stride, sample period, hover constants, alarm policy

The streaming GRU reads the record's model channels (checked when written); W and stride are the
decision grid (a decision at the end of every window of the windowed models' grid), not an input
length. C++: WeightsFile::bind_sgru (fwref/weights_file.hpp), fwref_stream --model sgru, and the
Cortex-M stream image's generator runtimes/mcu_stream_src.py (sgru_weights.bin beside weights.bin).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from quadfdi.core.atomic import write_bytes
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.binfmt import Section, pack, read_file
from quadfdi.formats.weights_layout import LAYOUTS, MAGIC, VERSION, check_dims, dtype_of, shape_of


FILE_NAME = "sgru_weights.bin"
SECTION_ORDER = (("sgru", "fp32"), ("sgru", "int8"))


def sgru_weights_bytes(p: GruParams, q: GruQuant, onboard: Section) -> bytes:
    """The file's bytes: ``p`` (window 1) fp32, ``p`` + ``q`` int8, then the on-board record."""
    from quadfdi.formats.weights_bin import gru_section

    if p.window != 1:
        raise ValueError(f"the streaming GRU's section has window 1, found {p.window}")
    return pack(MAGIC, VERSION, [gru_section(p, None, "sgru"), gru_section(p, q, "sgru"), onboard])


def export_onboard(export: str | Path, channel_names: list[str]) -> Section:
    """The on-board record of ``export``/weights.bin, checked against the streaming GRU's channels."""
    from quadfdi.formats.onboard import onboard_dict
    from quadfdi.formats.weights_bin import read_weights

    path = Path(export) / "weights.bin"
    if not path.is_file():
        raise QuadfdiError(f"{path} is missing: run `quadfdi export` first (the streaming GRU takes its on-board record)")
    wf = read_weights(path)
    if wf.onboard is None:
        raise QuadfdiError(f"{path} has no on-board record (exported before it: re-run `quadfdi export`)")
    model_channels = onboard_dict(wf.onboard)["channels"]
    if list(model_channels) != list(channel_names):
        raise QuadfdiError(f"the streaming GRU reads channels {list(channel_names)[:4]}..., {path}'s record feeds "
                           f"{list(model_channels)[:4]}... (profile {onboard_dict(wf.onboard)['profile']}): not on board")
    return wf.onboard


def write_sgru_weights(path: str | Path, p: GruParams, q: GruQuant, onboard: Section) -> bytes:
    data = sgru_weights_bytes(p, q, onboard)
    write_bytes(path, data)
    return data


@dataclass(frozen=True)
class SgruWeights:
    fp32: Section
    int8: Section
    onboard: Section


def read_sgru_weights(path: str | Path) -> SgruWeights:
    """Parse and check the file (sections, tensors, dtypes, shapes, window 1, the record); one-line
    QuadfdiError otherwise."""
    from quadfdi.formats.onboard import KIND as ONBOARD, check_onboard

    _, sections = read_file(path, MAGIC, VERSION, "streaming GRU weights file")
    where = f"streaming GRU weights file {path}"
    got = [(s.model, s.precision) for s in sections]
    if got != [*SECTION_ORDER, ONBOARD]:
        raise QuadfdiError(f"{where} holds sections {got}, expected {[*SECTION_ORDER, ONBOARD]}")
    check_onboard(sections[2], where)
    for s in sections[:2]:
        bad = check_dims("sgru", s.dims) or (None if s.dims[1] == 1 else f"window is {s.dims[1]}, not 1")
        if bad:
            raise QuadfdiError(f"{where}: section sgru {s.precision}: {bad}")
        specs = LAYOUTS["sgru"].specs(s.precision)
        if list(s.tensors) != [t.name for t in specs]:
            raise QuadfdiError(f"{where}: section sgru {s.precision} holds tensors {list(s.tensors)}")
        for spec in specs:
            t = s.tensors[spec.name]
            if t.array.dtype != dtype_of(spec, s.precision) or t.array.shape != shape_of("sgru", spec, s.dims):
                raise QuadfdiError(f"{where}: tensor '{spec.name}' of sgru {s.precision} is {t.array.dtype} "
                                   f"{t.array.shape}, expected {shape_of('sgru', spec, s.dims)}")
            if t.array.dtype == np.int8 and (t.axis != 0 or np.any(t.zero_points != 0)):
                raise QuadfdiError(f"{where}: tensor '{spec.name}' is not symmetric int8 with one scale per row")
    return SgruWeights(sections[0], sections[1], sections[2])
