"""The host programs' inputs and outputs as a hostile but realistic user hands them over
(fwref/read_limits.hpp, fwref/file_read.hpp, tools/host_output.hpp): /dev/zero, /dev/urandom, a FIFO that
no one writes, a folder and files past the documented maxima (sparse, so they cost nothing) are refused in
one line with exit 2, at once, with nothing allocated or written; fwref_stream reads a FIFO (a documented
pipe); fwref_hover never writes over its input (same path, another path, a hard link); and a write that a
file-size limit stops (`ulimit -f`: EFBIG, SIGXFSZ ignored) is one line, exit 2, no output, no temp file."""

from __future__ import annotations

import os
import resource
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

from tests.test_firmware_fixtures import host_build  # noqa: F401 (fixture)

ONE_LINE_TIMEOUT = 20  # s: a refusal is immediate; an unbounded reader would block on a FIFO or allocate 34 GB


def _run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=ONE_LINE_TIMEOUT, **kw)


def _refused(res: subprocess.CompletedProcess, program: str, match: str) -> None:
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1, (res.returncode, res.stderr)
    assert lines[0].startswith(program) and match in lines[0], (match, lines[0])


@pytest.fixture()
def fifo(tmp_path) -> Path:
    path = tmp_path / "fifo"
    os.mkfifo(path)
    return path


@pytest.fixture()
def sparse(tmp_path):
    def make(name: str, size: int) -> Path:
        path = tmp_path / name
        with open(path, "wb") as fh:
            fh.truncate(size)
        return path
    return make


def _commands(build: Path, export: Path, bad: Path, out: Path) -> dict[str, tuple[list, str]]:
    """Every reader of every program with ``bad`` in its place, and the program's name."""
    w, ref = export / "weights.bin", export / "reference.bin"
    infer = [build / "fwref_infer", "--model", "cnode", "--out", out]
    return {
        "infer --weights": (infer + ["--weights", bad, "--in", ref], "fwref_infer"),
        "infer --in": (infer + ["--weights", w, "--in", bad], "fwref_infer"),
        "infer --manifest": (infer + ["--weights", w, "--in", ref, "--manifest", bad], "fwref_infer"),
        "pair --in": ([build / "fwref_pair", "--weights", w, "--model", "gru", "--in", bad, "--per-round", 1,
                       "--timings", out], "fwref_pair"),
        "parity --weights": ([build / "fwref_parity", "--weights", bad, "--reference", ref], "fwref_parity"),
        "parity --reference": ([build / "fwref_parity", "--weights", w, "--reference", bad], "fwref_parity"),
        "stream --weights": ([build / "fwref_stream", "--weights", bad, "--info"], "fwref_stream"),
        "stream --in": ([build / "fwref_stream", "--weights", w, "--model", "cnode", "--in", bad], "fwref_stream"),
        "activations --in": ([build / "fwref_activations", "--in", bad, "--out", out], "fwref_activations"),
        "hover --in": ([build / "fwref_hover", "--in", bad, "--samples", 10, "--out", out], "fwref_hover"),
        "alarm --in": ([build / "fwref_alarm", "--in", bad, "--out", out, "--windows", 3, "--classes", 4], "fwref_alarm"),
    }


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "folder", "fifo"])
def test_non_regular_inputs_are_refused_at_once(flightlog_export, host_build, tmp_path, fifo, device):  # noqa: F811
    bad = {"folder": tmp_path, "fifo": fifo}.get(device, Path(device))
    out = tmp_path / "out.bin"
    for name, (cmd, program) in _commands(host_build, flightlog_export, bad, out).items():
        if name == "stream --in" and device == "fifo":
            continue  # a stream may come through a FIFO: test_stream_reads_a_fifo
        kind = {"folder": "a folder", "fifo": "a FIFO"}.get(device, "a character device")
        _refused(_run(cmd), program, f"is {kind}, not a regular file")
        assert not out.exists(), name
    res = _run([host_build / "fwref_sgru", bad, out])
    assert res.returncode == 1 and "not a regular file" in res.stderr and not out.exists()  # its documented exit 1


def test_inputs_past_their_maximum_are_refused_before_reading(flightlog_export, host_build, tmp_path, sparse):  # noqa: F811
    """Sparse files one byte past fwref/read_limits.hpp's maxima: refused from their size alone."""
    export, out = flightlog_export, tmp_path / "out.bin"
    mib = 1 << 20
    cases = [
        ([host_build / "fwref_infer", "--weights", sparse("w.bin", 64 * mib + 1), "--model", "cnode", "--in",
          export / "reference.bin", "--out", out], "fwref_infer", "more than the 64 MiB"),
        ([host_build / "fwref_infer", "--weights", export / "weights.bin", "--model", "cnode",
          "--in", sparse("x.f32", 1024 * mib + 4), "--out", out], "fwref_infer", "more than the 1024 MiB"),
        ([host_build / "fwref_infer", "--weights", export / "weights.bin", "--model", "cnode", "--in",
          export / "reference.bin", "--out", out, "--manifest", sparse("m.json", 16 * mib + 1)], "fwref_infer",
         "more than the 16 MiB"),
        ([host_build / "fwref_parity", "--weights", export / "weights.bin", "--reference", sparse("r.bin", 256 * mib + 1)],
         "fwref_parity", "more than the 256 MiB"),
        ([host_build / "fwref_activations", "--in", sparse("a.f32", 1024 * mib + 4), "--out", out], "fwref_activations",
         "more than the 1024 MiB"),
    ]
    for cmd, program, match in cases:
        res = _run(cmd, preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30)))
        _refused(res, program, match)
        assert not out.exists()


def test_a_windows_file_that_is_not_whole_windows_is_refused_from_its_size(flightlog_export, host_build, tmp_path,  # noqa: F811
                                                                           sparse):
    """34 GB of nothing (the size /dev/zero once made fwref_infer allocate): refused from fstat, under a 1 GB
    address-space limit, without a read."""
    res = _run([host_build / "fwref_infer", "--weights", flightlog_export / "weights.bin", "--model", "gru", "--in",
                sparse("big.f32", 34 * 10 ** 9), "--out", tmp_path / "o.f32"],
               preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (1 << 30, 1 << 30)))
    _refused(res, "fwref_infer", "more than the 1024 MiB")


def test_stream_reads_a_fifo(flightlog_export, host_build, tmp_path, fifo):  # noqa: F811
    """fwref_stream --in <FIFO>: it waits for the writer (the first open does not block) and gives the
    lines of the same stream read from a regular file."""
    src = Path(__file__).resolve().parents[1] / "firmware_ref" / "fuzz" / "corpus" / "fuzz_stream" / "flight.bin"
    cmd = [host_build / "fwref_stream", "--weights", flightlog_export / "weights.bin", "--model", "gru", "--in"]
    want = _run(cmd + [src])
    assert want.returncode == 0, want.stderr
    writer = threading.Thread(target=lambda: fifo.write_bytes(src.read_bytes()))
    writer.start()
    got = _run(cmd + [fifo])
    writer.join()
    assert got.returncode == 0, got.stderr
    assert got.stdout.replace(str(fifo), "") == want.stdout.replace(str(src), "")


def test_hover_never_writes_over_its_input(host_build, tmp_path):  # noqa: F811
    data = np.zeros((1, 10, 9), np.float32)
    src = tmp_path / "in.f32"
    data.tofile(src)
    (tmp_path / "sub").mkdir()
    os.link(src, tmp_path / "hard.f32")
    for out in (src, tmp_path / "sub" / ".." / "in.f32", tmp_path / "hard.f32"):
        res = _run([host_build / "fwref_hover", "--in", src, "--samples", 10, "--out", out])
        _refused(res, "fwref_hover", "it is the --in file")
        assert src.read_bytes() == data.tobytes()
    res = _run([host_build / "fwref_hover", "--in", src, "--samples", 10, "--out", tmp_path / "est.bin"])
    assert res.returncode == 0 and (tmp_path / "est.bin").stat().st_size == 12, res.stderr


def _fsize_limit(limit: int):
    return lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))


def test_a_write_past_a_file_size_limit_leaves_nothing(flightlog_export, host_build, tmp_path):  # noqa: F811
    """`ulimit -f`: SIGXFSZ would kill the program with its temp file left; it is ignored, the write fails
    with EFBIG, the temp file is removed, one line, exit 2 -- for fwref_stream's streamed outputs (the
    lines, --timings, stdout redirected to a file) and fwref_infer's whole-file output."""
    src = Path(__file__).resolve().parents[1] / "firmware_ref" / "fuzz" / "corpus" / "fuzz_stream" / "flight.bin"
    stream = [host_build / "fwref_stream", "--weights", flightlog_export / "weights.bin", "--model", "cnode", "--in", src]
    np.zeros((200, 40, 15), np.float32).tofile(tmp_path / "x.f32")  # 200 x 5 logits: 4000 bytes out
    infer = [host_build / "fwref_infer", "--weights", flightlog_export / "weights.bin", "--model", "cnode",
             "--in", tmp_path / "x.f32"]
    cases = [(stream + ["--out", tmp_path / "lines.txt"], "fwref_stream", tmp_path / "lines.txt"),  # ~1.4 kB
             (stream + ["--timings", tmp_path / "t.f64"], "fwref_stream", tmp_path / "t.f64"),  # 140 x 8 bytes
             (infer + ["--out", tmp_path / "y.f32"], "fwref_infer", tmp_path / "y.f32")]
    for cmd, program, out in cases:
        res = _run(cmd, preexec_fn=_fsize_limit(800))
        _refused(res, program, "File too large")
        assert not out.exists() and not list(tmp_path.glob("*.tmp.*")), sorted(p.name for p in tmp_path.iterdir())
    with open(tmp_path / "stdout.txt", "w") as fh:
        res = subprocess.run([str(c) for c in stream], stdout=fh, stderr=subprocess.PIPE, text=True,
                             timeout=ONE_LINE_TIMEOUT, preexec_fn=_fsize_limit(800))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "cannot write stdout: File too large" in res.stderr, res.stderr


def test_an_allocation_the_machine_refuses_is_one_line(flightlog_export, host_build, tmp_path, sparse):  # noqa: F811
    """A windows file within the maximum (600 MB of whole windows) under a 400 MB address-space limit:
    std::bad_alloc does not escape main (it aborted with a multi-line message); one line, exit 2, no output."""
    out = tmp_path / "y.f32"
    res = _run([host_build / "fwref_infer", "--weights", flightlog_export / "weights.bin", "--model", "cnode", "--in",
                sparse("x.f32", 2400 * 250_000), "--out", out],
               preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (400 << 20, 400 << 20)))
    _refused(res, "fwref_infer", "out of memory")
    assert not out.exists()
