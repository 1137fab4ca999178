"""reference.bin: a few test windows with every intermediate tensor, for the C++ parity programs.

Container: quadfdi.formats.binfmt (magic b"QFDIREF\\0"); one section per (model, precision) with the
same dims as weights.bin's. Written by the export stage (quadfdi.export.reference_bin), read by
fwref_parity, the Cortex-M harness generator and the tests.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from quadfdi.formats.binfmt import Section, read_file
from quadfdi.formats.weights_layout import REFERENCE_MAGIC as MAGIC, REFERENCE_VERSION as VERSION


@dataclass(frozen=True)
class ReferenceFile:
    version: int
    sections: list[Section]

    def section(self, model: str, precision: str) -> Section:
        return next(s for s in self.sections if (s.model, s.precision) == (model, precision))


def read_reference(path: str | Path) -> ReferenceFile:
    version, sections = read_file(path, MAGIC, VERSION, "reference file")
    return ReferenceFile(version, sections)
