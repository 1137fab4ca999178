"""`quadfdi sim` end to end: the dataset contract, windowing, determinism, and bad input."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from quadfdi.formats.dataset import REQUIRED_KEYS, load_dataset, make_windows, window_starts
from tests.conftest import SMALL_SIM, quadfdi


def test_dataset_contract(small_run):
    path = small_run / "dataset.npz"
    with np.load(path, allow_pickle=False) as z:  # no pickle anywhere
        keys = set(z.files)
        arrays = {k: z[k] for k in z.files}
    assert set(REQUIRED_KEYS) <= keys
    n, t, c = arrays["telemetry"].shape
    assert arrays["telemetry"].dtype == np.float32 and (n, t) == (24, 200)
    assert np.allclose(arrays["time"], np.arange(t) * 0.04)
    assert list(np.bincount(arrays["fault_class"], minlength=4)) == [6, 6, 6, 6]
    fault = arrays["fault_class"] > 0
    assert np.all(arrays["fault_motor"][~fault] == -1) and np.all(np.isnan(arrays["detectable_s"][~fault]))
    assert np.all(np.isfinite(arrays["detectable_s"][fault]))
    cfg = json.loads(str(arrays["config"]))
    assert cfg["sim"]["n_traj"] == 24
    assert "runs" not in str(arrays["config"]) and str(small_run) not in str(arrays["config"])  # no paths
    # The detectable time is the first sample at or above the threshold.
    thr = float(arrays["severity_threshold"])
    for i in np.flatnonzero(fault):
        k = np.argmax(arrays["severity"][i] >= thr)
        assert arrays["severity"][i, k] >= thr and arrays["detectable_s"][i] == pytest.approx(arrays["time"][k])
        # ... at least one stride (0.4 s) before the last sample.
        assert arrays["detectable_s"][i] <= arrays["time"][-1] - 0.4 + 1e-9


def test_windowing(small_run):
    ds = load_dataset(small_run / "dataset.npz")
    w = make_windows(ds)
    starts = window_starts(200, 80, 10)
    assert list(starts[:3]) == [0, 10, 20] and starts[-1] == 120
    assert len(w) == 24 * len(starts)
    # Independent reference: a Python loop over trajectories and starts.
    thr = ds.severity_threshold
    for k in range(0, len(w), 37):
        i, s = w.traj[k], w.start[k]
        assert np.array_equal(w.x[k], ds["telemetry"][i, s:s + 80])
        assert w.t_end[k] == ds["time"][s + 79]
        expect = ds["fault_class"][i] if ds["severity"][i, s + 79] >= thr else 0
        assert w.y[k] == expect
    test = make_windows(ds, "test")
    assert set(np.unique(ds["split"][test.traj])) == {2}


def test_same_seed_same_bytes(small_run, tmp_path):
    out = tmp_path / "again"
    res = quadfdi("sim", "--out", str(out), *SMALL_SIM)
    assert res.returncode == 0, res.stderr
    digest = lambda p: hashlib.sha256(p.read_bytes()).hexdigest()  # noqa: E731
    assert digest(out / "dataset.npz") == digest(small_run / "dataset.npz")
    other = tmp_path / "other"
    assert quadfdi("sim", "--out", str(other), *SMALL_SIM, "--set", "sim.seed=1").returncode == 0
    assert digest(other / "dataset.npz") != digest(small_run / "dataset.npz")


def test_plot(small_run, tmp_path):
    out = tmp_path / "t.png"
    res = quadfdi("sim", "plot", "--run", str(small_run), "--traj", "3", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _assert_one_line_error(res, needle):
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], res.stderr


@pytest.mark.parametrize("args, needle", [
    (["--config", "configs/missing.toml"], "config file configs/missing.toml does not exist"),
    (["--set", "sim.bogus=1"], "unknown key sim.bogus; valid keys of [sim]"),
    (["--set", "sim.duration_s=-16"], "sim.duration_s must be positive"),
    (["--set", "sim.fault_ratio=1.2"], "sim.fault_ratio must be in [0, 1]"),
])
def test_bad_input_one_line_no_file(tmp_path, args, needle):
    out = tmp_path / "run"
    res = quadfdi("sim", "--out", str(out), *args)
    _assert_one_line_error(res, needle)
    assert not (out / "dataset.npz").exists()


def test_unwritable_output(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    res = quadfdi("sim", "--out", str(blocker / "run"), *SMALL_SIM)
    _assert_one_line_error(res, "cannot create output folder")


def test_truncated_dataset(small_run, tmp_path):
    from quadfdi.core.errors import QuadfdiError

    bad = tmp_path / "dataset.npz"
    bad.write_bytes((small_run / "dataset.npz").read_bytes()[:5000])
    with pytest.raises(QuadfdiError, match="not a readable .npz"):
        load_dataset(bad)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(QuadfdiError, match="missing field 'telemetry'"):
        load_dataset(foreign)


def test_nan_telemetry_rejected(small_run, tmp_path):
    from quadfdi.core.errors import QuadfdiError
    from quadfdi.formats.dataset import read_npz, write_npz

    arrays = read_npz(small_run / "dataset.npz")
    arrays["telemetry"][2, 7, 4] = np.nan
    write_npz(tmp_path / "d.npz", arrays)
    with pytest.raises(QuadfdiError, match=r"NaN or Inf \(trajectory 2, sample 7, channel 4\)"):
        load_dataset(tmp_path / "d.npz")
