"""Shared, built-once resources of the firmware and parity tests (no tests in this module).

The expensive things (a trained and exported small run, the host, sanitizer and Cortex-M builds)
are made once per test process, whichever test module asks first: the fixtures below are imported
by tests/test_firmware.py and tests/test_parity.py, and a process-level cache stops pytest from
building twice for the two modules.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from quadfdi.runtimes.build import build_host
from tests.conftest import built_once, trained_export_run

_CACHE: dict[str, object] = {}


@pytest.fixture(scope="session")
def fw_run(small_run, tmp_path_factory) -> Path:
    """A small run (24 trajectories, 8 s), trained one epoch, exported with N = 8."""
    if "run" not in _CACHE:
        _CACHE["run"] = built_once(tmp_path_factory, "fwrun", lambda folder: trained_export_run(
            small_run, folder / "run", "train.epochs=1", "train.threads=1"))
    return _CACHE["run"]  # type: ignore[return-value]


@pytest.fixture(scope="session")
def host_build() -> Path:
    """The cached host build: Release fwref_infer and fwref_parity (the folder `quadfdi parity` uses)."""
    if "host" not in _CACHE:
        _CACHE["host"] = build_host(log=lambda _: None)
    return _CACHE["host"]  # type: ignore[return-value]


@pytest.fixture(scope="session")
def asan_build() -> Path:
    """The cached sanitizer build (-fsanitize=address,undefined, assertions on) of the programs the sanitizer
    tests run (infer, parity, stream, kernels): the other twelve would add about half again to its build."""
    if "asan" not in _CACHE:
        _CACHE["asan"] = build_host(sanitize=True, log=lambda _: None,
                                    targets=("fwref_infer", "fwref_parity", "fwref_stream", "fwref_kernels"))
    return _CACHE["asan"]  # type: ignore[return-value]
