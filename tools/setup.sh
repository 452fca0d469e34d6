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

# The venv holds exactly the lock of python3's version, host/requirements-py3.X.lock (versions
# and hashes; refresh them with tools/lock_deps.sh), then the package itself, editable, built by
# the locked setuptools. It is made anew whenever that lock or host/pyproject.toml changes (the
# stamp holds their hash), so nothing resolved on another day lingers in it.
venv="$root/.venv"
stamp="$venv/.stospline-lock"
# "3.X" for CPython; other implementations get no lock (the locks hold CPython wheels).
minor="$(python3 -c 'import sys; print("%d.%d" % sys.version_info[:2]
                                       if sys.implementation.name == "cpython" else "none")')"
lock="$root/host/requirements-py$minor.lock"
if [ ! -f "$lock" ]; then
  supported=""  # the versions there are locks for: "3.11, 3.12 or 3.13"
  for f in "$root"/host/requirements-py*.lock; do
    v="${f##*-py}"; supported+="${supported:+, }${v%.lock}"
  done
  supported="${supported%, *} or ${supported##*, }"
  echo "setup: needs CPython $supported as python3 (host/requirements-py<version>.lock);" \
       "python3 is $(python3 -c 'import platform; print(platform.python_implementation(),
                                                       platform.python_version())' 2>&1)" >&2
  exit 1
fi
want="$(cat "$lock" "$root/host/pyproject.toml" | sha256sum | cut -d' ' -f1)"

# The CMake build (no Python in it; its configuration only looks for .venv/bin/python, made
# first) runs while pip installs the venv, which waits mostly on downloads and unpacking.
build() {
  cmake -S "$root" -B "$root/build" -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null &&
    cmake --build "$root/build" >/dev/null
}
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "setup: Python venv from host/requirements-py$minor.lock"
  rm -rf "$venv"
  python3 -m venv "$venv"
  build &
  build_pid=$!
  pip_status=0
  { "$venv/bin/python" -m pip install -q --disable-pip-version-check --require-hashes \
      --only-binary=:all: -r "$lock" &&
    "$venv/bin/python" -m pip install -q --disable-pip-version-check --no-deps \
      --no-build-isolation -e "$root/host"; } || pip_status=$?
  build_status=0
  wait "$build_pid" || build_status=$?
  [ "$pip_status" -eq 0 ] || { echo "setup: pip install failed" >&2; exit 1; }
  [ "$build_status" -eq 0 ] || { echo "setup: the CMake build failed" >&2; exit 1; }
  echo "$want" > "$stamp"
else
  build
fi
