"""The [export] section: the deployment graphs' settings."""

from __future__ import annotations

from dataclasses import dataclass

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.limits import FIRMWARE_MAX_STEPS, MAX_BATCH
from quadfdi.core.sections import at_most, positive


@dataclass(frozen=True)
class ExportConfig:
    """Deployment graph settings (SPEC section 4)."""

    steps: int = 8  # N of the unrolled classic RK4 graph
    opset: int = 18
    calib_windows: int = 512  # training windows used to calibrate int8 activation scales
    reference_windows: int = 4  # test windows written to reference.bin

    def validate(self) -> None:
        positive(self, "steps", "opset", "calib_windows", "reference_windows")
        at_most(self, FIRMWARE_MAX_STEPS, "steps")
        at_most(self, MAX_BATCH, "calib_windows", "reference_windows")
        if self.opset < 17:
            raise QuadfdiError(f"export.opset must be 17 or newer, found {self.opset}")
