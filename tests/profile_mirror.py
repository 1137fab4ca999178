"""One C++ program for the reference profiles' bit-for-bit tests (tests/test_vehicle_record.py,
tests/test_phys_profile.py): fwref/profile.hpp and the record loader compiled as the firmware build
compiles them (-ffp-contract=off: no fused multiply-add), the profile chosen at compile time.

``mirror load <record.bin>`` prints the record's floats' bits, one per line (exit 2 and the loader's line
on a bad file); ``mirror <raw.f32 (n x R)> <out.f32 (n x C)> cells hover_cmd hover_cur carried
[record.bin]`` writes one flight's model inputs, the physics state carried from its first sample to its
last as the stream carries it.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.formats.vehicle_record_bin import write_record
from tests.conftest import ROOT

SOURCE = r"""
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
#include "fwref/profile.hpp"
#include "fwref/vehicle_record.hpp"
int main(int argc, char** argv) {
  const fwref::Profile p = fwref::Profile::MIRROR_PROFILE;
  const fwref::ProfileSpec& s = fwref::profile_spec(p);
  fwref::VehicleRecord rec;
  const fwref::VehicleRecord* vehicle = nullptr;
  const bool load = std::strcmp(argv[1], "load") == 0;
  const char* path = load ? argv[2] : argc > 7 ? argv[7] : nullptr;
  if (path != nullptr) {
    std::string error;
    if (fwref::load_vehicle_record(path, p, &rec, &error) != fwref::Status::kOk) {
      std::fprintf(stderr, "%s\n", error.c_str());
      return 2;
    }
    vehicle = &rec;
  }
  if (load) {
    for (float v : rec.v) {
      std::uint32_t bits;
      std::memcpy(&bits, &v, 4);
      std::printf("%u\n", bits);
    }
    return 0;
  }
  const float cells = std::strtof(argv[3], nullptr), cmd = std::strtof(argv[4], nullptr), cur = std::strtof(argv[5], nullptr);
  std::uint32_t avail = 0;
  if (!fwref::profile_available(p, s.raw, std::strtoull(argv[6], nullptr, 10), &avail)) return 3;
  FILE* f = std::fopen(argv[1], "rb");
  FILE* o = std::fopen(argv[2], "wb");
  std::vector<float> raw(s.raw), x(s.channels);
  fwref::PhysState state;
  while (std::fread(raw.data(), 4, s.raw, f) == static_cast<size_t>(s.raw)) {
    fwref::profile_prep(p, raw.data(), s.raw, cells, x.data(), avail, vehicle, &state);
    fwref::profile_hover(p, cmd, cur, x.data(), avail, vehicle);
    std::fwrite(x.data(), 4, x.size(), o);
  }
  std::fclose(f);
  std::fclose(o);
  return 0;
}
"""
ENUMS = {"flightlog-ref": "kFlightlogRef", "flightlog-phys": "kFlightlogPhys"}


def build_mirror(out: Path, profile: str) -> Path:
    """The mirror program for ``profile`` (a reference profile), compiled into ``out``."""
    if shutil.which("c++") is None:
        pytest.skip("no C++ compiler")
    fw = ROOT / "firmware_ref"
    (out / "m.cpp").write_text(SOURCE)
    subprocess.run(["c++", "-std=c++17", "-O2", "-ffp-contract=off", "-fno-fast-math", "-Wall", "-Wextra",
                    f"-DMIRROR_PROFILE={ENUMS[profile]}", f"-I{fw / 'include'}", str(out / "m.cpp"),
                    *(str(fw / "src" / f) for f in ("vehicle_record.cpp", "file_read.cpp", "container.cpp", "status.cpp")),
                    "-o", str(out / "m")], check=True)
    return out / "m"


def cpp_inputs(mirror: Path, tmp: Path, rs, hover_est, record: np.ndarray | None, profile: str) -> np.ndarray:
    """The mirror's model inputs of stream ``rs`` (hover estimate ``hover_est``, ``record`` or none)."""
    rs.values.astype("<f4").tofile(tmp / "raw.f32")
    carried = sum(1 << i for i, c in enumerate(rs.carried_flags) if c)
    args = [str(mirror), str(tmp / "raw.f32"), str(tmp / "x.f32"), str(rs.cells), repr(float(hover_est.cmd)),
            repr(float(hover_est.cur)), str(carried)]
    if record is not None:
        write_record(tmp / "rec.bin", record, profile)
        args.append(str(tmp / "rec.bin"))
    subprocess.run(args, check=True)
    return np.fromfile(tmp / "x.f32", "<f4").reshape(len(rs.time), -1)
