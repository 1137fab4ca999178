"""firmware_ref's fwref_pair (bench/cpp_pairs.py): both precisions of a model timed in one process, taking
turns; its output's shape and order, and bad input as one line, exit 2, nothing written. No timing
assertions."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from tests.test_firmware import test_windows
from tests.test_firmware_fixtures import fw_run, host_build  # noqa: F401 (fixtures)


def pair(build: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(build / "fwref_pair"), *args], capture_output=True, text=True, timeout=300)


def test_fwref_pair_times_both_precisions_in_rounds(fw_run, host_build, tmp_path):
    x = test_windows(fw_run)[:10]
    win = tmp_path / "w.f32"
    np.ascontiguousarray(x, dtype="<f4").tofile(win)
    weights = str(fw_run / "export" / "weights.bin")
    for model in ("cnode", "gru"):
        out = tmp_path / f"{model}.f64"
        res = pair(host_build, "--weights", weights, "--model", model, "--in", str(win), "--per-round", "3",
                   "--timings", str(out))
        assert res.returncode == 0, res.stderr
        t = np.fromfile(out, dtype="<f8")
        assert t.size == 3 * 2 * 3  # 10 windows -> 3 rounds of 3 (the 10th unused), fp32 and int8
        assert np.all(t > 0) and np.all(t < 1.0)


def test_fwref_pair_bad_input_is_one_line_and_writes_nothing(fw_run, host_build, tmp_path):
    x = test_windows(fw_run)[:4]
    weights = str(fw_run / "export" / "weights.bin")
    good, short, nan = tmp_path / "good.f32", tmp_path / "short.f32", tmp_path / "nan.f32"
    np.ascontiguousarray(x, dtype="<f4").tofile(good)
    np.ascontiguousarray(x, dtype="<f4").tofile(short)
    with open(short, "ab") as f:
        f.write(b"\0\0")
    bad = np.array(x, dtype="<f4", copy=True)  # x itself stays clean: the last check compares with it
    bad[1, 5, 2] = np.nan
    bad.tofile(nan)
    out = tmp_path / "t.f64"
    cases = [(short, "4", "float32 windows"), (nan, "2", "NaN or Inf"), (good, "5", "fewer than --per-round")]
    for path, per, match in cases:
        res = pair(host_build, "--weights", weights, "--model", "cnode", "--in", str(path), "--per-round", per,
                   "--timings", str(out))
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert res.returncode == 2 and len(lines) == 1 and lines[0].startswith("fwref_pair: error: "), res.stderr
        assert match in lines[0] and not out.exists()
    res = pair(host_build, "--weights", str(good), "--model", "cnode", "--in", str(good), "--per-round", "1",
               "--timings", str(out))  # not a weights file
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and not out.exists()
    res = pair(host_build, "--weights", weights, "--model", "cnode", "--in", str(good), "--per-round", "0",
               "--timings", str(out))
    assert res.returncode == 1 and "--per-round must be a positive integer" in res.stderr and not out.exists()
    res = pair(host_build, "--weights", weights, "--model", "cnode", "--in", str(good), "--per-round", "1",
               "--timings", str(good))  # an input as the output
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert np.array_equal(np.fromfile(good, dtype="<f4"), np.ascontiguousarray(x, dtype="<f4").ravel())
