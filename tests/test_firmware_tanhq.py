"""fwref/tanhq.hpp: the Cortex-M table of quantize(tanh_approx(a), 1/127) is exact and up to date.

``fwref_tanhq --check`` compares the table lookup with the direct computation on every float32 in
[-9.5, 9.5] (about 2.2e9 values, a minute of one core, split over every core) and on +-inf and NaN; regenerating the table
must give the committed header byte for byte (a change of tanh_approx or quantize would otherwise
leave a stale table that the check, compiled against the same header, could not see)."""

from __future__ import annotations

import subprocess
from pathlib import Path

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

HEADER = Path(__file__).resolve().parents[1] / "firmware_ref" / "include" / "fwref" / "tanhq_table.hpp"


def test_tanhq_table_is_regenerated_identically_and_exact_on_every_float(host_build):  # noqa: F811
    tool = host_build / "fwref_tanhq"
    gen = subprocess.run([str(tool)], capture_output=True, text=True, timeout=1200)
    assert gen.returncode == 0, gen.stderr
    assert gen.stdout == HEADER.read_text(), "fwref/tanhq_table.hpp is stale: regenerate it with fwref_tanhq"
    chk = subprocess.run([str(tool), "--check"], capture_output=True, text=True, timeout=2400)
    assert chk.returncode == 0, chk.stderr
    assert chk.stdout.startswith("tanhq check: OK, 2184183810 floats")  # every float in [-9.5, 9.5], both signs
