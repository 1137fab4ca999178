"""A simulated flight written as an ArduCopter DataFlash log with the FMT records of the shared
ArduCopter log, read back by pymavlink (ingest.ardupilot.load is pymavlink's DFReader) and ingested:
the channels come back as simulated, at ArduCopter's 10 Hz logging rate."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import load_dataset
from quadfdi.ingest.ardupilot import load
from quadfdi.ingest.dataflash_writer import RATE_HZ, dataflash_bytes, template_formats
from quadfdi.ingest.flight import ingest
from tests.conftest import ROOT, SHARED_DATA, quadfdi

TEMPLATE = SHARED_DATA / "flightlogs" / "ardupilot_copter_quadx_ground.BIN"
pytestmark = pytest.mark.skipif(not TEMPLATE.is_file(), reason=f"the shared ArduCopter log is not at {TEMPLATE}")


@pytest.fixture(scope="module")
def realistic_sim(tmp_path_factory):
    out = tmp_path_factory.mktemp("df") / "sim"
    res = quadfdi("sim", "--config", str(ROOT / "configs/realistic.toml"), "--out", str(out), "--workers", "1",
                  "--set", "sim.n_traj=4", "--set", "sim.ood_traj=0", "--set", "sim.duration_s=30",
                  "--set", "sim.chunk=4")
    assert res.returncode == 0, res.stderr
    return load_dataset(out / "dataset.npz")


def test_written_log_is_read_by_pymavlink_and_ingested_back(realistic_sim, tmp_path):
    ds = realistic_sim
    path = tmp_path / "flight.BIN"
    path.write_bytes(dataflash_bytes(ds.arrays, 0, TEMPLATE))
    fmt_records, _ = template_formats(TEMPLATE)
    template = TEMPLATE.read_bytes()
    assert path.read_bytes().startswith(fmt_records)
    assert all(fmt_records[k:k + 89] in template for k in range(0, len(fmt_records), 89))  # byte for byte
    cols, params, texts = load(str(path))  # pymavlink's DFReader
    assert params["FRAME_CLASS"] == 1 and texts[0].startswith("ArduCopter")
    n = len(cols["ATT"]["TimeUS"])
    assert n == pytest.approx(RATE_HZ * float(ds.arrays["time"][-1]), abs=2)
    lr, arrays = ingest(path)
    assert lr.autopilot == "ardupilot" and lr.airborne and arrays["airborne"].mean() > 0.9
    names, g = [str(c) for c in arrays["channel_names"]], arrays["time"]
    src, sn, t = ds.arrays["telemetry"][0], [str(c) for c in ds.arrays["channel_names"]], ds.arrays["time"]
    t0 = float(g[0])  # the log starts armed on the ground, a second before the flight
    # The log holds the flight's 25 Hz values at the 10 Hz sample times the writer chose; ingest
    # interpolates them linearly (no filter below 25 Hz): so the exact reference is that interpolation.
    written = np.flatnonzero(np.diff(np.floor(t * RATE_HZ), prepend=-1) > 0)
    for name in ("V_b", "I_b", "z", "vx", "roll", "pitch", "p", "r", "thr1", "thr3", "vib_ap"):
        j = names.index(name)
        ok = arrays["mask"][:, j] & (g - t0 - 1.0 >= t[written[0]]) & (g - t0 - 1.0 <= t[written[-1]])
        ref = np.interp(g[ok] - t0 - 1.0, t[written], src[written, sn.index(name)])
        err = np.abs(arrays["telemetry"][ok, j] - ref)
        tol = 1e-3 if name.startswith("thr") else 2e-5 * max(1.0, float(np.abs(ref).max()))  # PWM is whole us
        assert ok.sum() > 600 and float(err.max()) <= tol, (name, float(err.max()))


def test_a_template_without_the_messages_is_one_line(tmp_path):
    bad = tmp_path / "x.BIN"
    bad.write_bytes(b"\xa3\x95\x80" + b"\0" * 86)
    with pytest.raises(QuadfdiError, match="no FMT record"):
        template_formats(bad)
