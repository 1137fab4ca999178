"""The streaming CNODE in the window-free stream (``fwref_stream --model scnode``): on a test flight of the
session's exported paper run, every stride's logits are ONNX Runtime's one-step graph stepped on the samples
the stream steps (int8 bit for bit), the fp32 probabilities those of the prediction set the evaluation scores,
and a NaN sample is not stepped (state and previous sample held)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from quadfdi.core.contracts import FP32_CPP_REL_TOL, SPLIT_TEST
from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)
from tests.test_stream_cnode import _cli

TINY = ["--epochs", "2", "--latent", "6", "--hidden", "8", "--segment", "120", "--tbptt", "40", "--warmup", "10",
        "--batch", "6"]


@pytest.fixture(scope="module")
def scnode_onboard(fault_exported, tmp_path_factory) -> Path:
    """A copy of the session's exported paper run (its published stages: parity reads them) with a tiny streaming
    CNODE trained and exported."""
    run = tmp_path_factory.mktemp("scnode_onboard") / "run"
    shutil.copytree(fault_exported, run, ignore=shutil.ignore_patterns(".lock"))
    assert _cli("train", "scnode", "--run", str(run), *TINY) == 0
    assert _cli("export", "scnode", "--run", str(run)) == 0
    return run


@pytest.fixture(scope="module")
def flight(scnode_onboard, tmp_path_factory):
    from quadfdi.formats.export_folder import Export
    from quadfdi.formats.stream import from_dataset, write_stream

    record = Export.open(scnode_onboard / "export").onboard()
    z = np.load(scnode_onboard / "dataset.npz")
    row = int(np.flatnonzero((z["split"] == SPLIT_TEST) & (z["fault_class"] > 0))[0])
    path = tmp_path_factory.mktemp("scnode_streams") / "flight.bin"
    write_stream(path, from_dataset(scnode_onboard / "dataset.npz", row, record))
    return path, row, record


def _stream(host_build, export: Path, precision: str, stream: Path, check: bool = True):  # noqa: F811
    step = export / ("scnode_weights_i8.bin" if precision == "int8" else "scnode_weights.bin")
    res = subprocess.run([str(host_build / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "scnode",
                          "--step-weights", str(step), "--in", str(stream), *(["--int8"] if precision == "int8" else [])],
                         capture_output=True, text=True, timeout=120, check=False)
    assert not check or res.returncode == 0, res.stderr
    return res


def _mirror(export: Path, rs, record: dict, precision: str):
    """ONNX Runtime's one-step graph on the samples the stream steps (detect/streamref.py's rules), z = 0 at the
    first, the previous stepped sample as ``prev`` (the first: itself): logits at each stride's end sample."""
    from quadfdi.detect.streamref import stepped_of, windows_of
    from quadfdi.runtimes.ort import session

    sw = windows_of(rs, record)
    stepped, decided = stepped_of(sw, record["window"])
    sess = session(str(export / ("scnode_step.int8.onnx" if precision == "int8" else "scnode_step.onnx")))
    z = np.zeros((1, int(np.load(export / "scnode_replay.npz")["z"].shape[1])), np.float32)
    logits, prev = None, None
    for t in np.flatnonzero(stepped):
        x = np.ascontiguousarray(sw.x[t:t + 1], np.float32)
        lg, _, z = sess.run(["logits", "proba", "z_new"], {"z": z, "prev": x if prev is None else prev, "sample": x})
        logits = np.full((len(sw.x), lg.shape[1]), np.nan, np.float32) if logits is None else logits
        logits[t], prev = lg[0], x
    return sw, stepped, decided, logits[sw.ends]


def _check(text: str, sw, decided, logits, precision: str) -> dict:
    from quadfdi.detect.streamref import read_lines

    out = read_lines(text, logits.shape[1])
    np.testing.assert_array_equal(out["index"], sw.ends)
    np.testing.assert_array_equal(out["status"] == "decided", decided)
    got, want = out["logits"][decided], logits[decided]
    if precision == "int8":
        np.testing.assert_array_equal(got, want)  # the C++ int8 step is ORT's, bit for bit, over every carried step
    else:
        assert np.abs(got - want).max() <= FP32_CPP_REL_TOL * max(1.0, np.abs(want).max())
    return out


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_stream_scnode_is_onnx_runtimes_step_at_every_stride(scnode_onboard, flight, host_build, precision):  # noqa: F811
    from quadfdi.core.jsonio import read_json
    from quadfdi.formats.stream import read_stream

    path, row, record = flight
    export = scnode_onboard / "export"
    assert read_json(export / "scnode_export.json")["onboard"] == {"record": True}
    res = _stream(host_build, export, precision, path)
    sw, stepped, decided, logits = _mirror(export, read_stream(path), record, precision)
    assert stepped.all() and decided.all() and f"steps={len(stepped)} " in res.stdout  # a simulated flight
    out = _check(res.stdout, sw, decided, logits, precision)
    if precision == "fp32":  # the evaluation's set: the stream from z = 0 at take-off, read at the window ends
        pred = np.load(scnode_onboard / "predictions" / "scnode_sim0_train0.npz")
        mine = pred["traj"] == row
        np.testing.assert_allclose(out["proba"], pred["proba"][mine], atol=1e-5)


def test_stream_scnode_holds_state_and_previous_sample_over_a_nan(scnode_onboard, flight, host_build, tmp_path):  # noqa: F811
    from quadfdi.formats.stream import read_stream, write_stream

    path, _, record = flight
    rs = read_stream(path)
    lost = len(rs.time) // 2
    rs.values[lost, 3] = np.nan
    write_stream(tmp_path / "nan.bin", rs)
    res = _stream(host_build, scnode_onboard / "export", "int8", tmp_path / "nan.bin")
    sw, stepped, decided, logits = _mirror(scnode_onboard / "export", rs, record, "int8")
    assert not stepped[lost] and f"steps={len(stepped) - 1} " in res.stdout and not decided.all()
    _check(res.stdout, sw, decided, logits, "int8")


def test_stream_scnode_refuses_a_missing_or_wrong_step_file(scnode_onboard, flight, host_build):  # noqa: F811
    export = scnode_onboard / "export"
    path = flight[0]
    base = [str(host_build / "fwref_stream"), "--weights", str(export / "weights.bin"), "--model", "scnode", "--in", str(path)]
    for extra, why in (([], "--step-weights"), (["--step-weights", str(export / "scnode_weights.bin"), "--int8"], "int8"),
                       (["--step-weights", str(export / "weights.bin")], "not a usable streaming CNODE file")):
        res = subprocess.run(base + extra, capture_output=True, text=True, timeout=60, check=False)
        assert res.returncode == 2 and why in res.stderr and res.stderr.count("\n") == 1, res.stderr


def test_cortex_m_stream_image_runs_the_scnode_as_the_host(scnode_onboard):
    """quadfdi parity --mcu: the stream image carries the streaming CNODE beside the other models; every stride on
    both cores as the host's fwref_stream --model scnode (int8 logits bit-identical), M4 cycles per push traced."""
    from quadfdi.core.jsonio import read_json
    from quadfdi.runtimes.mcu import tools_missing

    missing = tools_missing()
    if missing:
        pytest.skip(missing)
    assert _cli("parity", "--run", str(scnode_onboard), "--mcu") == 0
    r = read_json(scnode_onboard / "parity" / "mcu_stream.json")
    assert r["passed"], r["problems"]
    for cpu, core in r["cores"].items():
        for prec in ("fp32", "int8"):
            assert core["host_check"][f"scnode_{prec}"]["strides"] > 0, (cpu, prec)
            m = core["models"][f"scnode_{prec}"]
            assert m["decisions"] > 0 and m["duty"] < 0.01
            assert ("cycles" in m) == (cpu == "cortex-m4")
