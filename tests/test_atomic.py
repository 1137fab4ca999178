"""Atomic writes: an error in the middle of a write leaves the previous file, byte for byte, and
no temp file behind; a write that succeeds replaces the file whole."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from quadfdi.core import atomic
from quadfdi.core.atomic import atomic_path, write_bytes, write_text
from quadfdi.core.npzio import read_npz, write_npz

OLD = b"the previous artifact\x00\xff, intact\n"


class Interrupted(Exception):
    pass


@pytest.fixture
def old_file(tmp_path):
    path = tmp_path / "artifact.bin"
    path.write_bytes(OLD)
    return path


def assert_untouched(path):
    assert path.read_bytes() == OLD
    assert sorted(p.name for p in path.parent.iterdir()) == [path.name]  # no .artifact.bin.*.tmp


def test_exception_inside_atomic_path_keeps_the_old_file(old_file):
    with pytest.raises(Interrupted):
        with atomic_path(old_file, "wb") as fh:
            fh.write(b"half of the new content")
            fh.flush()
            assert len(list(old_file.parent.iterdir())) == 2  # the temp file exists while writing
            raise Interrupted
    assert_untouched(old_file)


def test_keyboard_interrupt_inside_atomic_path_keeps_the_old_file(old_file):
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(old_file, "w") as fh:
            fh.write("partial")
            raise KeyboardInterrupt
    assert_untouched(old_file)


def test_failing_write_text_and_write_bytes_keep_the_old_file(old_file):
    with pytest.raises(TypeError):
        write_text(old_file, b"bytes into a text file")  # raises inside the with, in fh.write
    assert_untouched(old_file)
    with pytest.raises(TypeError):
        write_bytes(old_file, "text into a binary file")
    assert_untouched(old_file)


def test_failing_fsync_keeps_the_old_file(old_file, monkeypatch):
    """Every byte written, then the disk fails before the rename."""
    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", full_disk)
    with pytest.raises(OSError, match="No space left"):
        write_bytes(old_file, b"x" * 10_000)
    assert_untouched(old_file)


def test_write_npz_interrupted_after_some_arrays_keeps_the_old_file(old_file):
    # "a" is written into the temp zip first (keys are sorted), then "b" cannot be stored
    with pytest.raises(TypeError, match="b: object arrays would need pickle"):
        write_npz(old_file, {"a": np.arange(1000), "b": np.array([{"no": "pickle"}], dtype=object)})
    assert_untouched(old_file)


def test_interrupted_first_write_leaves_no_file(tmp_path):
    path = tmp_path / "new.txt"
    with pytest.raises(Interrupted):
        with atomic_path(path, "w") as fh:
            fh.write("never visible")
            raise Interrupted
    assert list(tmp_path.iterdir()) == []


def test_successful_writes_replace_the_whole_file(old_file, tmp_path):
    write_text(old_file, "new")
    assert old_file.read_text() == "new"
    assert stat.S_IMODE(os.stat(old_file).st_mode) == 0o644  # shared artifacts, not mkstemp's 0600
    npz = tmp_path / "arrays.npz"
    write_npz(npz, {"x": np.arange(3.0)})
    first = npz.read_bytes()
    write_npz(npz, {"x": np.arange(3.0)})
    assert npz.read_bytes() == first  # same content, same bytes
    np.testing.assert_array_equal(read_npz(npz)["x"], np.arange(3.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["arrays.npz", "artifact.bin"]
