"""fwref_stream (the streaming runtime) on a flightlog-esc export against the window path at every stride
(tests/test_stream.py's check, _check_replay): a simulated test flight and a real ingested flight.

    PYTHONPATH=.:tests python scripts/esc_stream_replay.py RUN SIM_INDEX REAL_FLIGHT.npz

RUN holds dataset.npz and export/; the C++ tools are firmware_ref/build's (``quadfdi parity`` builds
them). The real flight needs >= 5 decided windows and one skipped (before the hover freeze).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from quadfdi.detect.stream_cli import from_flight
from quadfdi.formats.stream import from_dataset, write_stream
from quadfdi.formats.export_folder import Export
from tests.test_stream import _check_replay

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> int:
    run, index, real = Path(argv[0]), int(argv[1]), argv[2]
    export, exe = run / "export", ROOT / "firmware_ref/build"
    tmp = Path(tempfile.mkdtemp(prefix="esc_stream_replay_"))
    rec = Export.open(export).onboard()
    print(f"record: profile {rec.get('profile')}, {len(rec['raw_channels'])} raw, {len(rec['channels'])} model channels")
    paths = {"sim": tmp / "sim.bin", "real": tmp / "real.bin"}
    write_stream(paths["sim"], from_dataset(run / "dataset.npz", index, rec))
    write_stream(paths["real"], from_flight(real, rec))
    for net in ("cnode", "gru"):
        for precision in ("fp32", "int8"):
            print(net, precision, "; ".join(_check_replay(export, paths, exe, tmp, net, precision)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
