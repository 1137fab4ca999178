"""One top-level name: every package folder is installed as ``quadfdi.<folder>``, and no module of the
project can end up imported under a bare folder name (``core``, ``sim``, ...). In a checkout both names
would load the same file as two modules, and an error raised through one escapes an ``except``
written with the other."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib

from tests.conftest import ROOT


def _package_dirs() -> dict[str, str]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]


def test_every_package_folder_is_mapped_under_quadfdi():
    mapped = _package_dirs()
    on_disk = {p.parent.name for p in ROOT.glob("*/__init__.py")}
    assert set(mapped.values()) == on_disk, f"package-dir misses {on_disk - set(mapped.values())}"
    assert all(name == "quadfdi" or name.startswith("quadfdi.") for name in mapped)
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    assert set(mapped) <= listed


# Imports every module of every package from an empty folder (no checkout on sys.path), then lists
# what reached sys.modules under a bare folder name.
_PROBE = """
import importlib, json, pkgutil, sys
bare = set(json.loads(sys.argv[1]))
import quadfdi
failed = []
for name in sorted(json.loads(sys.argv[2])):
    pkg = importlib.import_module(name)
    for info in pkgutil.walk_packages(pkg.__path__, name + "."):
        if info.name.endswith("__main__"):
            continue
        try:
            importlib.import_module(info.name)
        except Exception as exc:  # noqa: BLE001 - reported below
            failed.append(f"{info.name}: {type(exc).__name__}: {exc}")
print(json.dumps({"bare": sorted(m for m in sys.modules if m.split(".")[0] in bare), "failed": failed,
                  "quadfdi": quadfdi.__file__}))
"""


def test_no_bare_stage_module_from_an_empty_folder(tmp_path):
    mapped = _package_dirs()
    bare = [folder for folder in mapped.values() if folder != "quadfdi"]
    res = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(bare), json.dumps(sorted(mapped))],
                         cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["failed"] == []
    assert out["bare"] == [], f"modules imported under a bare folder name: {out['bare']}"
