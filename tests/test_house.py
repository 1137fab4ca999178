"""The installed package list names every stage package: ``pip install -e .`` maps only the listed
ones, so a stage missing there imports from the checkout's root and nowhere else (``quadfdi
evaluate`` and ``quadfdi detect`` failed outside the repository before this test)."""

from __future__ import annotations

import tomllib

from tests.conftest import ROOT


def test_pyproject_lists_every_package():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    on_disk = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    assert listed == on_disk, f"pyproject.toml [tool.setuptools] packages: missing {on_disk - listed}, extra {listed - on_disk}"
