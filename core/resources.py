"""Where quadfdi's own files are: the shipped configs, firmware_ref's C++ sources, the per-user cache,
and the source tree when quadfdi runs from one.

One code path for a git checkout (installed editable) and an installed wheel: the configs and the C++
sources are the package data of ``quadfdi.configs`` and ``quadfdi.firmware_ref`` (pyproject.toml maps
the top-level folders ``configs/`` and ``firmware_ref/`` there), found through the import system,
never from a module's ``__file__`` and its parents. What only a checkout has (the tracked files that
the wheel leaves out, relative paths such as the default real logs ``../shared/...``) goes through
``source_tree()``, which is None for an installed wheel.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
from pathlib import Path

from quadfdi.core.errors import QuadfdiError

CONFIGS = "quadfdi.configs"
FIRMWARE = "quadfdi.firmware_ref"
# firmware_ref's files that a build reads: what the wheel ships (pyproject.toml's package-data lists
# the same patterns; tests/test_wheel.py holds the two together) and what names a build folder.
# firmware_ref/tools/*.py are measurement helpers that no build runs.
FWREF_PATTERNS = ("CMakeLists.txt", "include/**/*", "src/**/*", "mcu/**/*", "tools/*.cpp", "tools/*.hpp")
_CONFIG_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")  # a bare word; anything else is a path


def package_folder(module: str) -> Path:
    """The folder of the installed package ``module`` (e.g. ``quadfdi.sim``), wherever it is installed."""
    try:
        spec = importlib.util.find_spec(module)
    except ModuleNotFoundError:
        spec = None
    if spec is None or not spec.submodule_search_locations:
        raise QuadfdiError(f"package {module} is not installed (reinstall quadfdi: pip install <checkout or wheel>)")
    return Path(list(spec.submodule_search_locations)[0]).resolve()


def source_tree() -> Path | None:
    """The source tree quadfdi runs from (a checkout installed editable: the folder of pyproject.toml
    and configs/), or None for an installed wheel, whose package data lies inside site-packages."""
    configs = package_folder(CONFIGS)
    root = configs.parent
    return root if configs.name == "configs" and (root / "pyproject.toml").is_file() else None


# ------------------------------------------------------------------------------------------ configs


def config_names() -> list[str]:
    """The shipped configs, by name (``paper``, ``realistic``): the stems of configs/*.toml."""
    return sorted(p.stem for p in package_folder(CONFIGS).glob("*.toml"))


def config_file(value: str | os.PathLike) -> Path:
    """A ``--config`` value as a file: a bare name (``paper``) is the shipped config of that name, anything
    else (``configs/paper.toml``, ``./mine.toml``, a ``Path``) a path, read as given."""
    if isinstance(value, os.PathLike) or not _CONFIG_NAME.fullmatch(str(value)):
        return Path(value)
    path = package_folder(CONFIGS) / f"{value}.toml"
    if not path.is_file():
        raise QuadfdiError(f"no shipped config named {value!r}; shipped: {', '.join(config_names())} "
                           "(a file needs a path: a '/' or the .toml suffix)")
    return path


# --------------------------------------------------------------------------------- firmware sources


def firmware_sources() -> Path:
    """firmware_ref's folder: the tracked firmware_ref/ in a checkout, quadfdi/firmware_ref in a wheel.
    Builds never write here (runtimes.build copies the sources into the cache); the generated
    headers (``python -m quadfdi.core.contracts --header``) do."""
    return package_folder(FIRMWARE)


def firmware_files(root: Path | None = None) -> dict[str, bytes]:
    """{relative path: bytes} of the sources a build reads (``FWREF_PATTERNS``), sorted by path."""
    root = root or firmware_sources()
    out = {}
    for pattern in FWREF_PATTERNS:
        for p in root.glob(pattern):
            if p.is_file() and "__pycache__" not in p.parts:
                out[p.relative_to(root).as_posix()] = p.read_bytes()
    if "CMakeLists.txt" not in out:
        raise QuadfdiError(f"{root} holds no firmware_ref sources (CMakeLists.txt missing): reinstall quadfdi")
    return dict(sorted(out.items()))


def firmware_digest(files: dict[str, bytes] | None = None) -> str:
    """sha256 (hex) of the C++ sources: every file's relative path, length and bytes, in path order."""
    h = hashlib.sha256()
    for rel, data in (files if files is not None else firmware_files()).items():
        h.update(f"{rel}\0{len(data)}\0".encode())
        h.update(data)
    return h.hexdigest()


# -------------------------------------------------------------------------------------------- cache


def cache_root() -> Path:
    """The per-user cache: ``$QUADFDI_CACHE``, else ``$XDG_CACHE_HOME/quadfdi``, else ``~/.cache/quadfdi``
    (the XDG base-directory rule: a relative ``XDG_CACHE_HOME`` is ignored)."""
    own = os.environ.get("QUADFDI_CACHE")
    if own:
        return Path(own).expanduser().absolute()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg and Path(xdg).is_absolute() else Path.home() / ".cache"
    return base / "quadfdi"
