"""The C++ readers under libFuzzer (firmware_ref/fuzz): the weights.bin parser and binder with the on-board
record, the reference.bin parser, the windows file and the stream file (with the on-board loop behind it),
seeded from the session's tiny flightlog-min export, each fuzzed for FUZZ_SECONDS (default 10 s, two at a
time: about 25 s of wall time after the build) under ASan + UBSan. Any crash, leak, timeout or broken
invariant fails the test, with the harness's log lines; `make fuzz` runs the same for 600 s per harness.
The committed seeds (firmware_ref/fuzz/corpus, small) are the files ``make_seeds`` writes, and they stay
usable: the committed weights and stream run through fwref_stream."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.contracts import SPLIT_TEST
from tests.conftest import ROOT
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

FUZZ = ROOT / "firmware_ref" / "fuzz"
HARNESSES = ("fuzz_weights", "fuzz_reference", "fuzz_windows", "fuzz_stream")
SECONDS = int(os.environ.get("FUZZ_SECONDS", "10"))


def _sgru_sections(sections: list) -> list:
    """The GRU's sections relabelled as the streaming GRU's (model sgru, window 1) and the on-board record:
    the layout of sgru_weights.bin, so that the binder's streaming-GRU path has a seed that binds."""
    from quadfdi.formats.binfmt import Section

    out = []
    for s in sections:
        if s.model == "gru":
            dims = list(s.dims)
            dims[1] = 1
            out.append(Section("sgru", s.precision, tuple(dims), dict(s.tensors)))
    return out + [s for s in sections if s.model == "none"]


def _one_window_reference(sections: list) -> list:
    """reference.bin's sections cut to their first window (dims[7] = 1 on the model sections)."""
    from quadfdi.formats.binfmt import Section, Tensor

    out = []
    for s in sections:
        dims = list(s.dims)
        dims[0 if s.model == "none" else 7] = 1
        out.append(Section(s.model, s.precision, tuple(dims),
                           {k: Tensor(k, np.ascontiguousarray(t.array[:1]), t.scales, t.zero_points, t.axis)
                            for k, t in s.tensors.items()}))
    return out


def make_seeds(export: Path, out: Path, samples: int = 140) -> Path:
    """Seeds for each harness, one folder each, from a real export: its weights.bin (and an
    sgru_weights.bin made of its GRU), reference.bin cut to one window, one and two of its raw windows, a test
    flight's stream file (the first ``samples`` samples) and the same samples as the stream harness's
    body-only input (times as step counts)."""
    from quadfdi.formats.binfmt import pack, read_file
    from quadfdi.formats.stream import from_dataset, record_of, stream_bytes
    from quadfdi.formats.weights_layout import MAGIC, REFERENCE_MAGIC, REFERENCE_VERSION, VERSION

    dirs = {name: out / name for name in HARNESSES}
    for d in dirs.values():
        d.mkdir(parents=True, exist_ok=True)
    _, wsec = read_file(export / "weights.bin", MAGIC, VERSION, "weights file")
    shutil.copy(export / "weights.bin", dirs["fuzz_weights"] / "flightlog_min.bin")
    (dirs["fuzz_weights"] / "sgru_weights.bin").write_bytes(pack(MAGIC, VERSION, _sgru_sections(wsec)))
    _, rsec = read_file(export / "reference.bin", REFERENCE_MAGIC, REFERENCE_VERSION, "reference file")
    (dirs["fuzz_reference"] / "one_window.bin").write_bytes(
        pack(REFERENCE_MAGIC, REFERENCE_VERSION, _one_window_reference(rsec)))
    tel = rsec[0].tensors["telemetry"].array.astype("<f4")
    (dirs["fuzz_windows"] / "one.f32").write_bytes(tel[:1].tobytes())
    (dirs["fuzz_windows"] / "two.f32").write_bytes(tel[:2].tobytes())
    record = record_of(export)
    dataset = export.parent / "dataset.npz"
    z = np.load(dataset)
    flight = int(np.flatnonzero(z["split"] == SPLIT_TEST)[0])
    rs = from_dataset(dataset, flight, record)
    rs.time, rs.values = rs.time[:samples], rs.values[:samples]
    (dirs["fuzz_stream"] / "flight.bin").write_bytes(stream_bytes(rs))
    body = np.zeros(len(rs.time), [("steps", "<i4"), ("jitter", "i1"), ("raw", "u1"), ("pad", "u1", 2),
                                   ("v", "<f4", (rs.values.shape[1],))])
    body["steps"], body["v"] = 1, rs.values
    body["steps"][0] = 0
    (dirs["fuzz_stream"] / "body.bin").write_bytes(body.tobytes())  # no magic: the harness's body mode
    return out


def _summary(text: str) -> dict[str, dict[str, str]]:
    rows = {}
    for line in text.splitlines():
        name, _, rest = line.partition(": ")
        if name in HARNESSES:
            rows[name] = dict(kv.split("=", 1) for kv in rest.split())
    return rows


@pytest.fixture(scope="module")
def seeds(flightlog_export, tmp_path_factory) -> Path:
    return make_seeds(flightlog_export, tmp_path_factory.mktemp("fuzz_seeds"))


def test_fuzz_harnesses_find_nothing(flightlog_export, seeds, tmp_path):
    """Every harness runs FUZZ_SECONDS from the export's seeds and the committed corpus (regression inputs
    included): no crash, no sanitizer report, no timeout (a stalled push), no broken invariant."""
    if shutil.which("clang++-14") is None:
        pytest.skip("clang++-14 is not installed (`make setup` installs it: scripts/setup.sh)")
    env = dict(os.environ, FUZZ_SEEDS=str(seeds), FWREF_FUZZ_WEIGHTS=str(flightlog_export / "weights.bin"))
    res = subprocess.run(["bash", str(FUZZ / "run.sh"), str(SECONDS), str(tmp_path / "out")], env=env,
                         capture_output=True, text=True, timeout=900)
    print(res.stdout)
    rows = _summary(res.stdout)
    assert res.returncode == 0, res.stdout + res.stderr
    assert set(rows) == set(HARNESSES), res.stdout
    for name, row in rows.items():
        assert int(row["findings"]) == 0 and row["rc"] == "0", (name, row)
        assert int(row["runs"]) >= 100 and int(row["cov"]) > 100, (name, row)  # it really ran, past the headers


def test_committed_seeds_are_real_files(host_build, tmp_path):  # noqa: F811
    """The committed model and stream seeds are what the project writes: fwref_stream runs the one on the
    other (strides decided), and the committed weights parse in Python too."""
    from quadfdi.formats.weights_bin import read_weights

    weights = FUZZ / "corpus" / "fuzz_weights" / "flightlog_min.bin"
    read_weights(weights)
    res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(weights), "--model", "cnode", "--int8",
                          "--in", str(FUZZ / "corpus" / "fuzz_stream" / "flight.bin")],
                         capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    assert " decided " in res.stdout and "dropped=0 " in res.stdout
    total = sum(p.stat().st_size for p in (FUZZ / "corpus").rglob("*") if p.is_file())
    assert total <= 100 * 1024, total  # small seeds only: a long pass grows its own corpus under build-fuzz
