#!/usr/bin/env bash
# envlight against Mitsuba 3's `envmap` emitter, one thread each, on the same
# synthetic maps, both envlight densities (issue 17's table, issue 34's targets).
# Run by hand, never in CI:
#
#     bash benches/peers/run_mitsuba.sh [--densities D,D] [--sizes WxH,...] [--repeat N]
#
# Installs, under target/peers-venv, Mitsuba 3 from PyPI and the envlight Python
# package; Mitsuba's LLVM backend needs Debian's libllvm19 (installed with apt-get
# when missing).
#
# envlight is built from the committed HEAD (a `git archive` under
# target/peers-src/<commit>), not from the working tree, so that the table names the
# code it measured even while others have edits in progress in this checkout.
# ENVLIGHT_PEER_SOURCE=worktree builds ./python as it stands instead.
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

if [ "${ENVLIGHT_PEER_SOURCE:-head}" = worktree ]; then
    ENVLIGHT_PEER_BUILT="working tree on $(git rev-parse --short HEAD)"
    if [ -n "$(git status --porcelain -- crates python Cargo.toml Cargo.lock)" ]; then
        ENVLIGHT_PEER_BUILT="$ENVLIGHT_PEER_BUILT, with uncommitted changes"
    fi
    "$venv/bin/python" -m pip install --quiet --force-reinstall --no-deps ./python
else
    commit="$(git rev-parse HEAD)"
    src="target/peers-src/$commit"
    if [ ! -d "$src" ]; then
        mkdir -p "$src.partial"
        git archive "$commit" | tar -x -C "$src.partial"
        mv "$src.partial" "$src"
    fi
    ENVLIGHT_PEER_BUILT="commit $(git rev-parse --short HEAD)"
    # One target directory for every snapshot: a new commit recompiles only what changed.
    CARGO_TARGET_DIR="$PWD/target/peers-target" "$venv/bin/python" -m pip install --quiet --force-reinstall --no-deps "./$src/python"
fi
export ENVLIGHT_PEER_BUILT

# One thread each: rayon for envlight, Dr.Jit's pool for Mitsuba (set in the script).
RAYON_NUM_THREADS=1 exec "$venv/bin/python" benches/peers/mitsuba_peer.py "$@"
