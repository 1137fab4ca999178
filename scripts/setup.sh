#!/usr/bin/env bash
# Sets up everything quadfdi needs on a fresh Debian machine, idempotently:
#   1. Debian packages (Eigen, CMake, g++, ccache, the arm-none-eabi toolchain, QEMU) if missing;
#   2. a virtualenv in .venv with torch==2.13.0 installed FIRST (the CPU build on this disk;
#      otherwise pip resolves a multi-GB CUDA build), then the project and its test deps.
set -euo pipefail
cd "$(dirname "$0")/.."

DEB_PKGS=(cmake g++ make libeigen3-dev gcc-arm-none-eabi libnewlib-arm-none-eabi
          libstdc++-arm-none-eabi-newlib qemu-system-arm binutils-arm-none-eabi
          ccache time valgrind util-linux clang-14 libfuzzer-14-dev libclang-rt-14-dev chromium chromium-driver)
missing=()
for p in "${DEB_PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
stamp=.venv/.quadfdi-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q "torch==2.13.0"
  .venv/bin/pip install -q -e ".[test]"
  touch "$stamp"
fi
echo "setup: ready (.venv)"
