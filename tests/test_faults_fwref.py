"""fwref_infer and the Cortex-M weight generator: --out never replaces a symlink, a FIFO, a device
or an input; outputs get the user's umask; --manifest checks weights.bin's sha256."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_firmware_fixtures import fw_run, host_build  # noqa: F401 (fixtures)


def infer(build: Path, *args: str, umask: int | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(build / "fwref_infer"), *args], capture_output=True, text=True, timeout=300,
                          preexec_fn=(lambda: os.umask(umask)) if umask is not None else None)


def one_line(res: subprocess.CompletedProcess, match: str) -> None:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1 and match in lines[0], res.stderr


@pytest.fixture(scope="module")
def files(fw_run, tmp_path_factory) -> dict[str, Path]:
    from quadfdi.formats.dataset import load_dataset, make_windows

    d = tmp_path_factory.mktemp("fwref_out")
    x = make_windows(load_dataset(fw_run / "dataset.npz"), "test").x[:2].astype("<f4")
    (d / "win.f32").write_bytes(x.tobytes())
    return {"weights": fw_run / "export" / "weights.bin", "manifest": fw_run / "export" / "manifest.json",
            "in": d / "win.f32"}


def base(files: dict[str, Path], weights: Path | None = None) -> list[str]:
    return ["--weights", str(weights or files["weights"]), "--model", "gru", "--in", str(files["in"])]


@pytest.mark.parametrize("kind", ["symlink", "fifo", "device", "weights", "input"])
def test_out_refuses_what_it_must_not_replace(host_build, files, tmp_path, kind):
    keep = tmp_path / "keep"
    keep.write_text("user data\n")
    weights = tmp_path / "weights.bin"
    weights.write_bytes(files["weights"].read_bytes())
    out = {"symlink": tmp_path / "link", "fifo": tmp_path / "fifo", "device": Path("/dev/null"),
           "weights": weights, "input": files["in"]}[kind]
    if kind == "symlink":
        out.symlink_to(keep)
    elif kind == "fifo":
        os.mkfifo(out)
    before = files["in"].read_bytes()
    res = infer(host_build, *base(files, weights), "--out", str(out))
    one_line(res, "refusing to write --out")
    assert keep.read_text() == "user data\n" and weights.read_bytes() == files["weights"].read_bytes()
    assert files["in"].read_bytes() == before
    assert out.is_symlink() if kind == "symlink" else True


@pytest.mark.parametrize("mask,mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_outputs_get_the_users_umask(host_build, files, tmp_path, mask, mode):
    out = tmp_path / "logits.f32"
    res = infer(host_build, *base(files), "--out", str(out), umask=mask)
    assert res.returncode == 0, res.stderr
    assert out.stat().st_mode & 0o777 == mode


def test_manifest_checks_the_weights(host_build, files, tmp_path):
    res = infer(host_build, *base(files), "--out", str(tmp_path / "a.f32"), "--manifest", str(files["manifest"]))
    assert res.returncode == 0, res.stderr
    other = tmp_path / "weights.bin"
    other.write_bytes(files["weights"].read_bytes() + b"\0")
    res = infer(host_build, *base(files, other), "--out", str(tmp_path / "b.f32"), "--manifest", str(files["manifest"]))
    one_line(res, "files.weights.bin.sha256")
    assert not (tmp_path / "b.f32").exists()


def gen(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "quadfdi.runtimes.mcu_weights_src", *args], capture_output=True,
                          text=True, timeout=300)


def test_generator_checks_the_manifest_and_its_outputs(files, tmp_path):
    other = tmp_path / "weights.bin"
    other.write_bytes(files["weights"].read_bytes()[:-1] + b"\1")
    res = gen("--weights", str(other), "--manifest", str(files["manifest"]), "--out", str(tmp_path / "g1"))
    assert res.returncode == 2 and "files.weights.bin.sha256" in res.stderr and len(res.stderr.splitlines()) == 1
    out = tmp_path / "g2"
    out.mkdir()
    (out / "fwref_limits.h").symlink_to(tmp_path / "elsewhere.h")
    res = gen("--weights", str(files["weights"]), "--manifest", str(files["manifest"]), "--out", str(out))
    assert res.returncode == 2 and "refusing to write" in res.stderr, res.stderr
    assert not (tmp_path / "elsewhere.h").exists()
