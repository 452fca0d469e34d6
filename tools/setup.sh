#!/usr/bin/env bash
# Idempotent set-up for a fresh machine: system packages, Python venv, CMake build.
# Every README command calls this first; nothing may rely on a hand-installed tool.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

apt_pkgs=(libcmocka-dev cmake ninja-build pkg-config gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm
          clang libclang-rt-14-dev cppcheck chromium)
missing=()
for p in "${apt_pkgs[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ "${#missing[@]}" -gt 0 ]; then
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  echo "setup: apt-get install ${missing[*]}"
  $sudo_cmd apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}" >/dev/null
fi

# The venv holds exactly host/requirements.lock (versions and hashes; refresh it with
# tools/lock_deps.sh), then the package itself, editable, built by the locked setuptools. It is
# made anew whenever the lock or host/pyproject.toml changes (the stamp holds their hash), so
# nothing resolved on another day lingers in it.
venv="$root/.venv"
stamp="$venv/.stospline-lock"
want="$(cat "$root/host/requirements.lock" "$root/host/pyproject.toml" | sha256sum | cut -d' ' -f1)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "setup: Python venv from host/requirements.lock"
  python3 -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' || {
    echo "setup: host/requirements.lock is for CPython 3.11; python3 is $(python3 -V 2>&1)" >&2
    exit 1; }
  rm -rf "$venv"
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check --require-hashes \
    --only-binary=:all: -r "$root/host/requirements.lock"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps \
    --no-build-isolation -e "$root/host"
  echo "$want" > "$stamp"
fi

cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build "$root/build" >/dev/null
