#!/usr/bin/env bash
# envlight against Mitsuba 3's `envmap` emitter, one thread each, on the same
# synthetic maps (issue 17's table). Run by hand, never in CI:
#
#     bash benches/peers/run_mitsuba.sh
#
# Installs, under target/peers-venv, Mitsuba 3 from PyPI and the envlight Python
# package from ./python; Mitsuba's LLVM backend needs Debian's libllvm19 (installed
# with apt-get when missing).
set -euo pipefail
cd "$(dirname "$0")/../.."

if ! dpkg -s libllvm19 >/dev/null 2>&1; then
    apt-get update -qq && apt-get install -y -qq libllvm19 >/dev/null
fi
DRJIT_LIBLLVM_PATH="$(dpkg -L libllvm19 | grep -E '/libLLVM[-.0-9]*\.so[.0-9]*$' | head -n 1)"
export DRJIT_LIBLLVM_PATH

venv=target/peers-venv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install --quiet --upgrade pip
"$venv/bin/python" -m pip install --quiet numpy "mitsuba==3.9.*"
"$venv/bin/python" -m pip install --quiet ./python

# One thread each: rayon for envlight, Dr.Jit's pool for Mitsuba (set in the script).
RAYON_NUM_THREADS=1 exec "$venv/bin/python" benches/peers/mitsuba_peer.py "$@"
