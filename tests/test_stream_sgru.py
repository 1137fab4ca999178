"""The streaming GRU on board (issue 16): its own weights file (export/sgru_weights.py), the stream
runtime stepping it once per usable sample (fwref/stream.hpp) against ONNX Runtime's one-step graph
and against the Python evaluation's prediction set, the state held over a NaN sample, and
Stream::reset() between flights. Cheap: the session's paper-config export (fault_exported), a tiny
streaming GRU (tests/test_stream_gru.py's settings), the session's host build."""

from __future__ import annotations

import hashlib
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import copy_run

from core.contracts import FP32_CPP_REL_TOL, SPLIT_TEST
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)
from tests.test_stream_gru import TINY, _cli


@pytest.fixture(scope="module")
def sgru_export(fault_exported, tmp_path_factory) -> Path:
    """A copy of the session's exported paper run with a tiny streaming GRU trained and exported."""
    run = copy_run(fault_exported, tmp_path_factory.mktemp("sgru_onboard") / "run")
    shutil.copytree(fault_exported / "export", run / "export")
    assert _cli("train", "sgru", "--run", str(run), *TINY) == 0
    assert _cli("export", "sgru", "--run", str(run)) == 0
    return run


@pytest.fixture(scope="module")
def flight(sgru_export, tmp_path_factory):
    """A test flight of the run as a stream file, its row and the on-board record."""
    from detect.streamfile import from_dataset, record_of, write_stream

    record = record_of(sgru_export / "export")
    z = np.load(sgru_export / "dataset.npz")
    row = int(np.flatnonzero((z["split"] == SPLIT_TEST) & (z["fault_class"] > 0))[0])
    path = tmp_path_factory.mktemp("sgru_streams") / "flight.bin"
    write_stream(path, from_dataset(sgru_export / "dataset.npz", row, record))
    return path, row, record


def _stream(exe: Path, weights: Path, *args: str) -> str:
    res = subprocess.run([str(exe / "fwref_stream"), "--weights", str(weights), *args], capture_output=True, text=True,
                         timeout=120, check=False)
    assert res.returncode == 0, res.stderr
    return res.stdout


def test_sgru_weights_file(sgru_export, host_build):  # noqa: F811
    """Its sections hold the checkpoint's numbers and weights.bin's record; weights.bin is untouched."""
    from core.jsonio import read_json
    from export.sgru_weights import read_sgru_weights
    from export.weights_bin import read_weights
    from train.stream_gru_run import load_stream_checkpoint

    export = sgru_export / "export"
    sw = read_sgru_weights(export / "sgru_weights.bin")
    model, _ = load_stream_checkpoint(sgru_export / "sgru_train0.pt")
    sd = {k: v.numpy() for k, v in model.state_dict().items()}
    assert sw.fp32.dims[:4] == (model.n_channels, 1, model.n_classes, model.hidden)
    np.testing.assert_array_equal(sw.fp32.tensors["gru.weight_hh"].array, sd["gru.weight_hh_l0"])
    assert sw.int8.tensors["gru.weight_hh"].array.dtype == np.int8
    wb = read_weights(export / "weights.bin")
    assert {k: t.array.tobytes() for k, t in sw.onboard.tensors.items()} == \
        {k: t.array.tobytes() for k, t in wb.onboard.tensors.items()}
    manifest = read_json(export / "manifest.json")
    rec = read_json(export / "sgru_export.json")["weights"]
    sha = hashlib.sha256((export / "weights.bin").read_bytes()).hexdigest()
    assert rec["record_from_sha256"] == sha == manifest["files"]["weights.bin"]["sha256"]
    assert rec["sha256"] == hashlib.sha256((export / "sgru_weights.bin").read_bytes()).hexdigest()
    info = _stream(host_build, export / "sgru_weights.bin", "--info")
    assert info == _stream(host_build, export / "weights.bin", "--info")  # the same record
    res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "sgru",
                          "--in", "-"], capture_output=True, text=True, check=False, input="")
    assert res.returncode == 2 and "sgru_weights.bin" in res.stderr  # weights.bin has no sgru section


def _mirror(export: Path, rs, record: dict, precision: str, hidden: int):
    """The Python statement of the on-board rules: stepped samples, decided strides, ORT logits, alarm."""
    from detect.streamref import sgru_logits, stepped_of, stream_alarm, windows_of

    sw = windows_of(rs, record)
    stepped, decided = stepped_of(sw, record["window"])
    onnx = export / ("sgru_step.int8.onnx" if precision == "int8" else "sgru_step.onnx")
    logits = sgru_logits(onnx, sw.x, stepped, hidden)[sw.ends]
    _, trace, _ = stream_alarm(record, decided, logits[decided])
    return sw, stepped, decided, logits, trace


def _check(out: dict, sw, decided, logits, trace, precision: str) -> None:
    np.testing.assert_array_equal(out["index"], sw.ends)
    np.testing.assert_array_equal(out["status"] == "decided", decided)
    got, want = out["logits"][decided], logits[decided]
    if precision == "int8":
        np.testing.assert_array_equal(got, want)  # the C++ int8 step is ORT's, bit for bit, over every carried step
    else:
        assert np.abs(got - want).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(want).max())
    if precision == "int8":
        for key, ref in (("vote", trace.votes), ("active", trace.active), ("cls", trace.cls)):
            np.testing.assert_array_equal(out[key], ref[0], err_msg=key)


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_stream_sgru_is_onnx_runtimes_one_step_at_every_stride(sgru_export, flight, host_build, precision):  # noqa: F811
    """fwref_stream --model sgru on a test flight: every stride the ORT one-step graph's logits (int8 identical,
    fp32 within the tolerance), and (fp32) the probabilities the Python evaluation scores (its prediction set)."""
    from detect.streamfile import read_stream
    from detect.streamref import read_lines
    from train.stream_gru_run import load_stream_checkpoint

    path, row, record = flight
    model, _ = load_stream_checkpoint(sgru_export / "sgru_train0.pt")
    export = sgru_export / "export"
    text = _stream(host_build, export / "sgru_weights.bin", "--model", "sgru", "--in", str(path),
                   *(["--int8"] if precision == "int8" else []))
    out = read_lines(text, model.n_classes)
    sw, stepped, decided, logits, trace = _mirror(export, read_stream(path), record, precision, model.hidden)
    assert stepped.all() and decided.all() and f"steps={len(stepped)} " in text  # a simulated flight: every sample
    _check(out, sw, decided, logits, trace, precision)
    if precision == "fp32":  # the evaluation's set: the stream from h = 0 at take-off, read at the window ends
        pred = np.load(sgru_export / "predictions" / "sgru_sim0_train0.npz")
        mine = pred["traj"] == row
        assert mine.sum() == len(sw.ends)
        np.testing.assert_allclose(out["proba"], pred["proba"][mine], atol=1e-5)  # float32 set, torch vs C++ order


def test_stream_sgru_holds_its_state_over_a_nan_sample(sgru_export, flight, host_build, tmp_path):  # noqa: F811
    """A NaN sample is not stepped (h held), the strides whose window holds it are skipped, and the later
    strides carry the held state: the C++ stream equals the Python mirror of that rule (int8: bit for bit)."""
    from detect.streamfile import read_stream, write_stream
    from detect.streamref import read_lines

    path, _, record = flight
    rs = read_stream(path)
    lost = len(rs.time) // 2
    rs.values[lost, 3] = np.nan
    write_stream(tmp_path / "nan.bin", rs)
    replay = np.load(sgru_export / "export" / "sgru_replay.npz")
    hidden, classes = int(replay["h"].shape[1]), int(replay["logits"].shape[1])
    text = _stream(host_build, sgru_export / "export" / "sgru_weights.bin", "--model", "sgru", "--int8", "--in",
                   str(tmp_path / "nan.bin"))
    out = read_lines(text, classes)
    sw, stepped, decided, logits, trace = _mirror(sgru_export / "export", rs, record, "int8", hidden)
    assert not stepped[lost] and stepped.sum() == len(stepped) - 1 and f"steps={len(stepped) - 1} " in text
    hit = (sw.starts <= lost) & (sw.ends >= lost)
    assert hit.any() and not decided[hit].any() and decided[sw.ends > lost + record["window"]].all()
    _check(out, sw, decided, logits, trace, "int8")
    # (the later strides' logits may equal the clean flight's: the tiny GRU forgets within a window)


@pytest.mark.parametrize("model", ["cnode", "sgru"])
def test_reset_between_flights_equals_separate_runs(sgru_export, flight, host_build, model, tmp_path):  # noqa: F811
    """Stream::reset(): two flights in sequence through one stream (repeated --in) give each flight's own run,
    line for line (alarm state, hover estimate, ring and the streaming GRU's state all forgotten)."""
    from detect.streamfile import from_dataset, write_stream

    path, row, record = flight
    z = np.load(sgru_export / "dataset.npz")
    other = int(np.flatnonzero(z["split"] == SPLIT_TEST)[-1])
    assert other != row
    write_stream(tmp_path / "other.bin", from_dataset(sgru_export / "dataset.npz", other, record))
    weights = sgru_export / "export" / ("sgru_weights.bin" if model == "sgru" else "weights.bin")
    args = ("--model", model, "--int8")
    both = _stream(host_build, weights, *args, "--in", str(path), "--in", str(tmp_path / "other.bin"))
    one = _stream(host_build, weights, *args, "--in", str(path))
    two = _stream(host_build, weights, *args, "--in", str(tmp_path / "other.bin"))
    strip = lambda text: [ln for ln in text.splitlines() if not ln.startswith("# fwref_stream")]
    assert strip(both) == strip(one) + strip(two)
    assert "flight=1 " in both and sum(not ln.startswith("#") for ln in strip(two)) >= 2
