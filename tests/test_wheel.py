"""A wheel that runs anywhere: ``pip wheel`` of the sources holds the one package ``quadfdi`` with its
configs and firmware_ref's C++ sources and no build folder; installed into a fresh venv (its
dependencies reached through a plain .pth naming this interpreter's site-packages, so no editable
finder of the checkout is active), its ``quadfdi`` command runs from an empty folder: a tiny realistic
pipeline (sim, train, export, parity) whose first C++ use builds firmware_ref into an empty per-user cache,
and ``detect --runtime cpp`` on a real flight with that model. (The bench's C++ probes ship in the wheel,
checked below; the bench itself runs in tests/test_pipeline.py and tests/test_bench_report.py.)"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import sysconfig
import tomllib
import zipfile
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

import pytest

from quadfdi.core.jobcache import code_version
from quadfdi.core.resources import firmware_digest, firmware_files
from tests.conftest import FLIGHTLOG_TINY, FLIGHTLOG_TRAIN, ROOT, SHARED_DATA

pytestmark = pytest.mark.slow

MISSION = SHARED_DATA / "flightlogs" / "px4_quad_6s_uavcan_mission.ulg"
# build folders a checkout may hold beside the sources: planted in the copy, they must stay out of the wheel
PACKAGES = ("quadfdi", "sim", "train", "bench")  # a sweep's job: the app layer, two stages, the C++ sources
PLANTED = ("firmware_ref/build/CMakeCache.txt", "firmware_ref/build-mcu-m4/fwref_mcu_parity.elf",
           "firmware_ref/build-asan/fwref_infer")


def _sources(dst: Path) -> Path:
    """The files the wheel is built from (pyproject.toml, README.md, every mapped package folder), copied
    so that the build writes nothing into the checkout, plus the planted build folders."""
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, dst / name)
    def skip(folder: str, names: list[str]) -> set[str]:  # caches and build folders, not build.py
        return {n for n in names if n == "__pycache__" or n.endswith(".egg-info")
                or (n.startswith("build") and (Path(folder) / n).is_dir())}

    for folder in sorted(set(_package_dirs().values())):
        shutil.copytree(ROOT / folder, dst / folder, ignore=skip)
    for rel in PLANTED:
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        (dst / rel).write_text("a build product\n")
    return dst


def _package_dirs() -> dict[str, str]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]


def _can_build_offline() -> bool:
    """setuptools here writes wheels by itself (>= 70.1) or with the `wheel` package: no index needed."""
    try:
        major, minor = (int(x) for x in version("setuptools").split(".")[:2])
    except (PackageNotFoundError, ValueError):
        return False
    return (major, minor) >= (70, 1) or importlib.util.find_spec("wheel") is not None


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    src = _sources(tmp_path_factory.mktemp("wheel_src"))
    out = tmp_path_factory.mktemp("wheel_out")
    isolation = ["--no-build-isolation"] if _can_build_offline() else []  # else pip fetches setuptools>=68
    cmd = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", *isolation, "-w", str(out), str(src)]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    (whl,) = out.glob("quadfdi-*.whl")
    return whl


def test_the_wheel_holds_quadfdi_its_configs_and_cpp_sources_and_no_build(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        info = next(n.split("/")[0] for n in names if n.endswith(".dist-info/RECORD"))
        assert z.read(f"{info}/top_level.txt").decode().split() == ["quadfdi"]
        record = [line.split(",")[0] for line in z.read(f"{info}/RECORD").decode().splitlines() if line]
        assert {r.split("/")[0] for r in record} == {"quadfdi", info}
        assert not [n for n in names if n.startswith("quadfdi/firmware_ref/build")]  # PLANTED left out
        shipped = {n.removeprefix("quadfdi/firmware_ref/"): z.read(n) for n in names
                   if n.startswith("quadfdi/firmware_ref/") and not n.endswith("__init__.py")}
        # what a build reads (core.resources.FWREF_PATTERNS) is what pyproject.toml's package-data ships
        assert shipped == firmware_files(ROOT / "firmware_ref")
        assert z.read("quadfdi/configs/paper.toml") == (ROOT / "configs" / "paper.toml").read_bytes()
        assert {n for n in names if n.startswith("quadfdi/configs/")} == \
            {"quadfdi/configs/__init__.py", "quadfdi/configs/paper.toml", "quadfdi/configs/realistic.toml",
             "quadfdi/configs/realistic-mask.toml", "quadfdi/configs/fleet.toml"}
        modules = {f"{pkg.replace('.', '/')}/{f.relative_to(ROOT / folder).as_posix()}"
                   for pkg, folder in _package_dirs().items() for f in (ROOT / folder).rglob("*.py")
                   if "__pycache__" not in f.parts and (f.parent / "__init__.py").is_file()}  # not tools/*.py
        assert modules <= set(names), sorted(modules - set(names))[:5]
        assert "quadfdi/runtimes/mcu_weights_src.py" in names and "quadfdi/bench/cpp/l2bw.cpp" in names


@pytest.fixture(scope="module")
def venv(wheel, tmp_path_factory) -> Path:
    """A fresh venv with the wheel installed; the dependencies through a .pth naming this interpreter's
    site-packages folders (a .pth line adds a folder; the .pth files inside it, such as the checkout's
    editable finder, are not run)."""
    new = tmp_path_factory.mktemp("venv") / "v"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(new)], check=True, timeout=300)
    py = new / "bin" / "python"
    purelib = Path(subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                  capture_output=True, text=True, check=True).stdout.strip())
    deps = [p for p in sys.path if Path(p).name in ("site-packages", "dist-packages") and Path(p).is_dir()]
    assert sysconfig.get_paths()["purelib"] in deps
    (purelib / "zz_checkout_deps.pth").write_text("".join(f"{p}\n" for p in deps))
    res = subprocess.run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    return new


def _env(cache: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["QUADFDI_CACHE"] = str(cache)
    return env


def _quadfdi(venv: Path, cwd: Path, cache: Path, *args: str, timeout: float = 1800) -> subprocess.CompletedProcess:
    res = subprocess.run([str(venv / "bin" / "quadfdi"), *args], cwd=cwd, env=_env(cache), capture_output=True,
                         text=True, timeout=timeout)
    assert res.returncode == 0, f"quadfdi {' '.join(args)}: " + res.stderr[-3000:]
    return res


def _sets(values: list[str]) -> list[str]:
    return [a for v in values for a in ("--set", v)]


@pytest.fixture(scope="module")
def place(tmp_path_factory) -> tuple[Path, Path]:
    """(an empty working folder, an empty cache folder), shared by the two pipelines below."""
    return tmp_path_factory.mktemp("empty"), tmp_path_factory.mktemp("cache") / "quadfdi"


def test_installed_quadfdi_is_the_wheel_and_names_configs(venv, place):
    cwd, cache = place
    probe = ("import json, sys, quadfdi; from quadfdi.core import jobcache, resources; "
             "print(json.dumps({'file': quadfdi.__file__, 'tree': str(resources.source_tree()), "
             "'editable': [repr(f) for f in sys.meta_path if 'Editable' in repr(f)], "
             f"'code': jobcache.code_version({PACKAGES!r})}}))")
    res = subprocess.run([str(venv / "bin" / "python"), "-c", probe], cwd=cwd, env=_env(cache), capture_output=True,
                         text=True, timeout=120, check=True)
    out = json.loads(res.stdout)
    assert Path(out["file"]).resolve().is_relative_to(venv.resolve()) and out["editable"] == []
    assert out["tree"] == "None"  # no source tree: relative realism logs are skipped, not guessed
    assert out["code"] == code_version(PACKAGES)  # the same sources give the same job keys as in the checkout
    res = subprocess.run([str(venv / "bin" / "quadfdi"), "sim", "--config", "paperr", "--out", "x"], cwd=cwd,
                         env=_env(cache), capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and res.stderr.strip().splitlines() == [
        "quadfdi sim: error: no shipped config named 'paperr'; shipped: fleet, paper, realistic, realistic-mask "
        "(a file needs a path: a '/' or the .toml suffix)"]
    assert not (cwd / "x").exists()


@pytest.fixture(scope="module")
def pipeline(venv, place) -> Path:
    """A flightlog-min model (a profile a real log can feed; tests/conftest.py's tiny realistic run) made by the
    installed command from the empty folder: sim, train, export and parity, whose first C++ use builds the
    sources into the empty cache. The realism refusal in between: the shipped configs' real logs lie beside a
    checkout (../shared); from a wheel, the user names them."""
    cwd, cache = place
    assert not cache.exists()
    _quadfdi(venv, cwd, cache, "sim", "--config", "realistic", "--out", "flightlog", "--workers", "1",
             *_sets(FLIGHTLOG_TINY))
    res = subprocess.run([str(venv / "bin" / "quadfdi"), "realism", "--run", "flightlog"], cwd=cwd, env=_env(cache),
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert res.stderr.startswith("quadfdi realism: error: no real logs to compare with: name them with --logs LOG... "
                                 "(skipped: [run] realism_logs names logs relative to a quadfdi checkout")
    _quadfdi(venv, cwd, cache, "train", "--run", "flightlog", *_sets(FLIGHTLOG_TRAIN))
    _quadfdi(venv, cwd, cache, "export", "--run", "flightlog")
    _quadfdi(venv, cwd, cache, "parity", "--run", "flightlog", "--no-mcu")
    return cwd / "flightlog"


def test_a_pipeline_from_an_empty_folder_builds_the_cpp_into_the_cache(venv, place, pipeline):
    cwd, cache = place
    # the first C++ use built the sources the wheel ships, in the folder their hash names
    home = cache / f"fwref-{firmware_digest(firmware_files(ROOT / 'firmware_ref'))[:16]}"
    assert [p.name for p in cache.iterdir()] == [home.name]
    assert (home / "build" / "fwref_infer").is_file() and (home / "build" / "fwref_parity").is_file()
    assert firmware_files(home / "src") == firmware_files(ROOT / "firmware_ref")
    parity = json.loads((pipeline / "parity" / "parity.json").read_text())
    assert parity["passed"] and Path(parity["firmware"]["build_dir"]).resolve() == (home / "build").resolve()
    # nothing beside the run folder in the working folder (detect below writes later), no build inside the package
    assert [p.name for p in cwd.iterdir()] == [pipeline.name]
    package = next((venv / "lib").glob("python3*/site-packages/quadfdi"))
    assert not list((package / "firmware_ref").glob("build*"))


@pytest.mark.skipif(not MISSION.is_file(), reason=f"the shared real flight logs are not here ({MISSION})")
def test_detect_with_the_cpp_runtime_on_a_real_flight(venv, place, pipeline):
    """The pipeline's model, on a real flight through the same cached build."""
    cwd, cache = place
    _quadfdi(venv, cwd, cache, "detect", "--model", str(pipeline / "export"), str(MISSION), "--runtime", "cpp",
             "--out", "detect")
    rec = json.loads((cwd / "detect" / "alarms.json").read_text())
    assert rec["profile"] == "flightlog-min" and 0 < rec["decided_windows"] <= rec["windows"]
    assert len(list(cache.glob("fwref-*"))) == 1  # the same build served detect
