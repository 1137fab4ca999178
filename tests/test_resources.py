"""core.resources and the build cache of runtimes.build: configs by name, the per-user cache folder,
the C++ sources' hash, the copy a build is made from and the pruning of stale folders; the realism
logs a checkout names and a wheel cannot reach."""

from __future__ import annotations

import fcntl
import shutil
import os
import subprocess
import time
from pathlib import Path

import pytest

from quadfdi.core import resources
from quadfdi.core.config import load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.runtimes import build
from tests.conftest import ROOT


def test_a_bare_name_is_a_shipped_config_anything_else_a_path():
    assert resources.config_names() == ["fleet", "paper", "realistic", "realistic-mask"]
    assert resources.config_file("paper").read_bytes() == (ROOT / "configs" / "paper.toml").read_bytes()
    assert resources.config_file("paper.toml") == Path("paper.toml")  # a file in the current folder
    assert resources.config_file("./paper") == Path("paper")
    assert resources.config_file(Path("realistic")) == Path("realistic")
    with pytest.raises(QuadfdiError, match=r"no shipped config named 'papr'; shipped: fleet, paper, realistic, realistic-mask"):
        resources.config_file("papr")
    assert load_config("realistic").to_dict() == load_config(ROOT / "configs" / "realistic.toml").to_dict()
    with pytest.raises(QuadfdiError, match=r"config file nope.toml does not exist \(shipped configs, by name: fleet, paper, "):
        load_config("nope.toml")


def test_the_checkout_is_the_source_tree():
    assert resources.source_tree() == ROOT
    assert resources.firmware_sources() == ROOT / "firmware_ref"


def test_cache_root_follows_quadfdi_cache_then_xdg_then_home(monkeypatch, tmp_path):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("QUADFDI_CACHE", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    assert resources.cache_root() == tmp_path / "home" / ".cache" / "quadfdi"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/ignored")  # the XDG rule: only absolute paths count
    assert resources.cache_root() == tmp_path / "home" / ".cache" / "quadfdi"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert resources.cache_root() == tmp_path / "xdg" / "quadfdi"
    monkeypatch.setenv("QUADFDI_CACHE", str(tmp_path / "own"))
    assert resources.cache_root() == tmp_path / "own"


def test_the_sources_hash_covers_every_shipped_file_its_bytes_and_its_name(tmp_path):
    files = resources.firmware_files()
    assert {"CMakeLists.txt", "mcu/CMakeLists.txt", "mcu/mps2.ld", "mcu/startup.c", "mcu/toolchain-arm-none-eabi.cmake",
            "include/fwref/contracts_gen.hpp", "src/cnode.cpp", "tools/fwref_infer.cpp",
            "tools/host_files.hpp"} <= set(files)
    assert not [f for f in files if f.endswith(".py") or f.startswith("build")]
    digest = resources.firmware_digest(files)
    changed = dict(files, **{"src/cnode.cpp": files["src/cnode.cpp"] + b"\n"})
    renamed = {("src/cnode2.cpp" if k == "src/cnode.cpp" else k): v for k, v in files.items()}
    digests = {digest, resources.firmware_digest(changed), resources.firmware_digest(dict(sorted(renamed.items())))}
    assert len(digests) == 3


def _aged(folder: Path, days: float) -> Path:
    folder.mkdir(parents=True)
    (folder / build.LAST_USED).touch()
    t = time.time() - days * 86400
    os.utime(folder / build.LAST_USED, (t, t))
    return folder


def test_first_use_copies_the_sources_and_prunes_stale_folders(monkeypatch, tmp_path):
    monkeypatch.setenv("QUADFDI_CACHE", str(tmp_path))
    stale, recent, busy = (_aged(tmp_path / f"fwref-{n}", d) for n, d in (("old", 30), ("new", 2), ("busy", 30)))
    with open(busy / build.LOCK, "a") as fh:  # another process setting it up right now
        fcntl.flock(fh, fcntl.LOCK_EX)
        home = build.fwref_home()
    assert home.name == f"fwref-{resources.firmware_digest()[:16]}"
    assert resources.firmware_files(home / "src") == resources.firmware_files()
    assert not stale.exists() and recent.is_dir() and busy.is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([home.name, recent.name, busy.name])
    (home / "src" / "CMakeLists.txt").write_text("# edited by hand\n")  # a second use takes the copy as it is
    assert build.fwref_home() == home and (home / "src" / "CMakeLists.txt").read_text() == "# edited by hand\n"
    assert build.mcu_build_dir("cortex-m7") == home / "build-mcu-m7"
    assert build.host_build_dir(True) == home / "build-asan"


def test_an_unwritable_cache_is_one_line(monkeypatch, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    monkeypatch.setenv("QUADFDI_CACHE", str(blocker / "cache"))
    with pytest.raises(QuadfdiError, match=r"cannot use the build cache .*QUADFDI_CACHE names another folder"):
        build.fwref_home()


def test_realism_logs_relative_to_a_checkout_are_skipped_from_a_wheel(monkeypatch):
    from quadfdi.realism.cli import listed_logs

    listed = ("../shared/data/flightlogs/a.ulg", "/abs/b.ulg")
    assert listed_logs(listed) == ([str((ROOT / listed[0]).resolve()), "/abs/b.ulg"], None)
    monkeypatch.setattr(resources, "source_tree", lambda: None)  # as from an installed wheel
    logs, why = listed_logs(listed)
    assert logs == ["/abs/b.ulg"] and why.startswith("1 of 2 logs skipped: [run] realism_logs names logs relative")
    logs, why = listed_logs(listed[:1])
    assert logs == [] and why.startswith("skipped: ") and "--set 'run.realism_logs=[\"/path/flight.ulg\"]'" in why


def test_a_build_folder_configured_from_another_copy_of_the_sources_is_configured_afresh(tmp_path):
    """A caller's own build folder kept while the sources changed (a new cache folder, a new src/):
    CMake refuses another source folder for an existing build, so it is configured anew."""
    if shutil.which("cmake") is None:
        pytest.skip("cmake not installed")
    out = tmp_path / "build"
    for name in ("a", "b"):
        src = tmp_path / name
        src.mkdir()
        (src / "CMakeLists.txt").write_text("cmake_minimum_required(VERSION 3.20)\nproject(p NONE)\n"
                                            f"add_custom_target(t ALL COMMAND ${{CMAKE_COMMAND}} -E touch {name}.txt)\n")
        out.mkdir(exist_ok=True)
        build.configure_and_build(src, out, {"X": "1"}, f"project {name}")
        assert (out / f"{name}.txt").is_file()
    assert f"CMAKE_HOME_DIRECTORY:INTERNAL={tmp_path / 'b'}" in (out / "CMakeCache.txt").read_text()


def _ccache_hits(ccache_dir: Path) -> int:
    out = subprocess.run(["ccache", "--print-stats"], env=dict(os.environ, CCACHE_DIR=str(ccache_dir)),
                         capture_output=True, text=True, check=True).stdout
    stats = dict(line.split("\t", 1) for line in out.splitlines() if "\t" in line)
    return int(stats.get("direct_cache_hit", 0)) + int(stats.get("preprocessed_cache_hit", 0))


def test_a_copy_of_the_sources_elsewhere_reads_its_objects_back_from_ccache(tmp_path, monkeypatch):
    """Two cache folders of the same sources at different depths (a checkout's and a wheel's): the second
    build compiles nothing (ccache, paths relative to each folder); QUADFDI_CCACHE=0 configures without it."""
    if shutil.which("cmake") is None or shutil.which("c++") is None or shutil.which("ccache") is None:
        pytest.skip("cmake, c++ or ccache not installed")
    monkeypatch.setenv("CCACHE_DIR", str(tmp_path / "ccache"))
    monkeypatch.delenv("QUADFDI_CCACHE", raising=False)
    for i, home in enumerate((tmp_path / "a" / "fwref-x", tmp_path / "b" / "deeper" / "fwref-x")):
        (home / "src").mkdir(parents=True)
        (home / "build").mkdir()
        (home / "src" / "CMakeLists.txt").write_text("cmake_minimum_required(VERSION 3.20)\nproject(p CXX)\n"
                                                     "add_executable(prog prog.cpp)\n")
        (home / "src" / "prog.cpp").write_text('#include "prog.hpp"\nint main() { return answer() - 42; }\n')
        (home / "src" / "prog.hpp").write_text("inline int answer() { return 42; }\n")
        build.configure_and_build(home / "src", home / "build", {}, "project p")
        assert subprocess.run([str(home / "build" / "prog")]).returncode == 0
        assert _ccache_hits(tmp_path / "ccache") == i  # the first compiles, the second reads back
    assert f"CMAKE_CXX_COMPILER_LAUNCHER:UNINITIALIZED={shutil.which('ccache')}" in \
        (home / "build" / "CMakeCache.txt").read_text()
    monkeypatch.setenv("QUADFDI_CCACHE", "0")
    build.configure_and_build(home / "src", home / "build", {}, "project p")  # configured again, without it
    assert "CMAKE_CXX_COMPILER_LAUNCHER:UNINITIALIZED=\n" in (home / "build" / "CMakeCache.txt").read_text()


def test_the_pipeline_skips_realism_with_one_line_from_a_wheel(monkeypatch, capsys, tmp_path):
    from quadfdi import pipeline
    from quadfdi.core.rundir import RunDir

    cfg = load_config("paper")
    assert cfg.run.realism_logs and not any(Path(p).is_absolute() for p in cfg.run.realism_logs)
    monkeypatch.setattr(resources, "source_tree", lambda: None)  # as from an installed wheel
    pipeline._realism(RunDir(tmp_path), cfg)  # would fail on the missing dataset if it compared anything
    assert capsys.readouterr().out.startswith("realism: skipped: [run] realism_logs names logs relative to a "
                                              "quadfdi checkout, and this quadfdi is installed from a wheel")
    assert not (tmp_path / "realism").exists()
