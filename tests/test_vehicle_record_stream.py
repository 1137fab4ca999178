"""The stream runtime with a vehicle record: the flightlog-ref and flightlog-phys exports of tests/conftest.py (a
tiny fleet trained through the CLI, each flight with its vehicle's record; flightlog-phys adds the channels its
recursions carry from the flight's first sample) replaying streams written by `quadfdi stream-file --vehicle`
through fwref_stream as the Python window path decides them (int8 bit-identical to ONNX Runtime), `--vehicle
RECORD.bin` against the stream's own record, and the refusals."""

from __future__ import annotations

import dataclasses
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.channels import PROFILE_BY_NAME
from quadfdi.formats.vehicle_record_bin import write_record
from quadfdi.models.inputs import profile_of
from tests.conftest import quadfdi
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)


@pytest.fixture(scope="module", params=["reference_export", "physics_export"])
def ref_case(request, tmp_path_factory) -> tuple[Path, dict[str, Path]]:
    """A reference profile's export and three test flights after their vehicle's reference flights (a fault
    among them) written by `quadfdi stream-file --vehicle` with their vehicle's reference."""
    from quadfdi.core.contracts import SPLIT_TEST
    from quadfdi.formats.dataset import load_dataset, vehicle_columns
    from quadfdi.formats.vehicle import write_vehicle
    from quadfdi.train.vehicle_ref import learn_references

    reference_export = request.getfixturevalue(request.param)
    run, out = reference_export.parent, tmp_path_factory.mktemp("ref_streams")
    ds = load_dataset(run / "dataset.npz")
    cols = vehicle_columns(ds.arrays)
    refs, vid = learn_references(ds.arrays, "fleet"), cols["vehicle_id"]
    rows = np.flatnonzero((ds["split"] == SPLIT_TEST) & ~np.asarray(cols["reference_flight"], bool))[:3].tolist()
    assert len(rows) == 3 and ds["fault_class"][rows].any(), rows
    paths = {}
    for row in rows:
        write_vehicle(out / f"v{row}.json", refs[int(vid[row])])
        paths[f"sim{row}"] = out / f"sim{row}.bin"
        res = quadfdi("stream-file", "--model", str(reference_export), "--dataset", str(run / "dataset.npz"), "--flight",
                      str(row), "--vehicle", str(out / f"v{row}.json"), "--out", str(paths[f"sim{row}"]))
        assert res.returncode == 0 and "vehicle record" in res.stdout, res.stderr
    return reference_export, paths


@pytest.mark.parametrize("net, precision", [("cnode", "int8"), ("gru", "int8"), ("cnode", "fp32")])
def test_stream_with_a_record_gives_the_window_path(ref_case, host_build, tmp_path, net, precision):  # noqa: F811
    """fwref_stream loads each stream's record at reset: the Python window path's status, logits (int8: the same
    bits, fp32: within the parity tolerance) and alarm at every stride (tests/test_stream.py's check)."""
    from quadfdi.formats.stream import read_stream
    from tests.test_stream import _check_replay

    reference_export, ref_streams = ref_case
    for name, path in ref_streams.items():
        assert read_stream(path).vehicle is not None
        print(name, _check_replay(reference_export, {"sim": path}, host_build, tmp_path, net, precision))


def _fwref_stream(exe: Path, export: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(exe / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "cnode",
                           "--int8", *args], capture_output=True, text=True)


def test_vehicle_flag_is_the_streams_own_record_and_refusals(ref_case, host_build, tmp_path):  # noqa: F811
    """A version 2 stream with --vehicle gives the version 3 stream's lines; without a record the decisions
    differ (the reference channels at their fills); a record for another profile, a truncated one, or
    --vehicle beside a stream carrying its own: one line, exit 2."""
    from quadfdi.formats.stream import read_stream, write_stream
    from quadfdi.runtimes.fwref import stream_lines

    reference_export, ref_streams = ref_case
    profile = profile_of(json.loads((reference_export / "manifest.json").read_text()))
    path = next(iter(ref_streams.values()))
    rs = read_stream(path)
    write_stream(tmp_path / "v2.bin", dataclasses.replace(rs, vehicle=None))
    write_record(tmp_path / "r.bin", rs.vehicle, profile)
    own, flag, none = (_fwref_stream(host_build, reference_export, *a) for a in
                       (("--in", str(path)), ("--in", str(tmp_path / "v2.bin"), "--vehicle", str(tmp_path / "r.bin")),
                        ("--in", str(tmp_path / "v2.bin"))))
    assert own.returncode == flag.returncode == none.returncode == 0, (own.stderr, flag.stderr, none.stderr)
    assert "vehicle=stream" in own.stdout and "vehicle=file" in flag.stdout and "vehicle=none" in none.stdout
    k = len(json.loads((reference_export / "manifest.json").read_text())["class_names"])
    a, b, c = (stream_lines(r.stdout, k) for r in (own, flag, none))
    np.testing.assert_array_equal(a["logits"].view(np.uint32), b["logits"].view(np.uint32))
    decided = a["status"] == "decided"
    assert decided.sum() >= 5 and (a["logits"][decided] != c["logits"][decided]).any()
    data = (tmp_path / "r.bin").read_bytes()
    (tmp_path / "trunc.bin").write_bytes(data[:60])
    mask = data[:12] + PROFILE_BY_NAME["flightlog-mask"].id.to_bytes(4, "little") + data[16:]
    (tmp_path / "mask.bin").write_bytes(mask)
    for args, why in (((str(path), str(tmp_path / "r.bin")), "carries its vehicle record: --vehicle is for streams "
                                                              "without one"),
                      ((str(tmp_path / "v2.bin"), str(tmp_path / "trunc.bin")), "holds 60 bytes"),
                      ((str(tmp_path / "v2.bin"), str(tmp_path / "mask.bin")), "is for profile 'flightlog-mask'")):
        res = _fwref_stream(host_build, reference_export, "--in", args[0], "--vehicle", args[1])
        assert res.returncode == 2 and why in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
