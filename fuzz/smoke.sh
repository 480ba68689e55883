#!/usr/bin/env bash
# The fuzz smoke run (CI calls it from .ci/run): every target of `cargo fuzz list`
# for SECONDS_PER_TARGET seconds (default 5), starting from a temporary copy of its
# committed seeds, fuzz/seeds/<target>/ (libFuzzer writes new inputs into the corpus
# it is given; the committed folders stay as generated). Fails when a target has no
# seeds, when a target fails, or when a regression input fails.
#
# Regression inputs: fuzz/regressions/<target>/ is replayed through the target's
# binary here unless crates/envlight/tests/fuzz_regressions.rs replays that folder
# already (it does `distribution` and `load`, the loader targets' shared folder, on
# every `cargo test`).
#
# Memory: every libFuzzer run (timed and replay) gets -rss_limit_mb=1024
# -malloc_limit_mb=1024, so an input that makes the loader take 2 GB fails the run
# as an out-of-memory. The 612-byte EXR in fuzz/regressions/load/ (issue 49) took
# 1.9 GB before 728337f and passed under the old -rss_limit_mb=4096; replayed
# through load_any under 1024, the code before the fix stops with "ERROR: libFuzzer:
# out-of-memory (used: 1067Mb; limit: 1024Mb)" (this script leaves that folder to
# `cargo test`, where crates/envlight/tests/memory_bound.rs holds every input to a
# much tighter bound with a counting allocator). The RSS limit is the one that acts:
# libFuzzer checks the peak RSS once a second, so a block that is reserved and
# written counts, a reservation never written does not. -malloc_limit_mb is
# accepted but needs a sanitizer's malloc hooks, which a --sanitizer none build
# lacks; it is passed so that a sanitizer build keeps the same limit per allocation.
#
# Needs cargo-fuzz (`cargo install cargo-fuzz --locked`); runs without sanitizers,
# so stable Rust is enough. A crash leaves its input in fuzz/artifacts/<target>/.
set -euo pipefail
cd "$(dirname "$0")"

seconds=${SECONDS_PER_TARGET:-5}
case "$seconds" in
    '' | *[!0-9]* | 0)
        # libFuzzer reads a malformed -max_total_time as 0, which means no limit.
        echo "SECONDS_PER_TARGET must be a positive whole number of seconds, not '$seconds'" >&2
        exit 2
        ;;
esac

# See the header: 1024 MB, so a 2 GB allocation fails the run.
memory_limits=(-rss_limit_mb=1024 -malloc_limit_mb=1024)

targets=$(cargo fuzz list)
if [ -z "$targets" ]; then
    echo "cargo fuzz list found no targets" >&2
    exit 1
fi

missing=""
for target in $targets; do
    if [ -z "$(ls -A "seeds/$target" 2>/dev/null)" ]; then
        missing="$missing $target"
    fi
done
if [ -n "$missing" ]; then
    echo "no seeds in fuzz/seeds/<target>/ for:$missing" >&2
    echo "add the target's seeds to crates/envlight/examples/fuzz_seeds.rs and run" >&2
    echo "  cargo run --release -p envlight --example fuzz_seeds -- fuzz/seeds" >&2
    exit 1
fi

# All targets at once, so a build error stops here rather than inside the first run.
cargo fuzz build --sanitizer none -O

work=$(mktemp -d "${TMPDIR:-/tmp}/envlight-fuzz-smoke.XXXXXX")
trap 'rm -rf "$work"' EXIT

# Runs one `cargo fuzz run` with its output in $work/$1.log. Prints libFuzzer's
# summary when it passes; the error, the backtrace's functions and the command
# that reproduces it when it fails.
run() {
    local name=$1 log="$work/$1.log"
    shift
    if cargo fuzz run --sanitizer none -O "$@" >"$log" 2>&1; then
        grep -E '^#[0-9]+[[:space:]]+DONE|^Done [0-9]+ runs|^Executed ' "$log" | tail -n 3 ||
            tail -n 2 "$log"
    else
        local details
        details=$(sed -n '/panicked at\|memory allocation of\|ERROR: libFuzzer/,$p' "$log" |
            grep -v '^ *at ' | head -n 40 || true)
        if [ -n "$details" ]; then
            echo "$details"
            sed -n '/^Reproduce with:/,+2p' "$log"
        else
            tail -n 40 "$log"
        fi
        echo "FAILED: $name"
        failed="$failed $name"
    fi
}

failed=""
for target in $targets; do
    corpus="$work/corpus-$target"
    cp -R "seeds/$target" "$corpus"
    echo "==> $target: ${seconds}s from $(find "$corpus" -type f | wc -l) seeds"
    run "$target" "$target" "$corpus" -- -max_total_time="$seconds" "${memory_limits[@]}"

    if [ -d "regressions/$target" ] &&
        ! grep -qF "inputs(\"$target\")" ../crates/envlight/tests/fuzz_regressions.rs; then
        mapfile -t inputs < <(find "regressions/$target" -type f | sort)
        if [ "${#inputs[@]}" -gt 0 ]; then
            echo "==> $target: replaying ${#inputs[@]} regression inputs"
            run "$target-regressions" "$target" "${inputs[@]}" -- "${memory_limits[@]}"
        fi
    fi
done

if [ -n "$failed" ]; then
    echo "fuzz smoke failed:$failed" >&2
    exit 1
fi
echo "fuzz smoke passed: $(wc -w <<<"$targets") targets, ${seconds}s each"
