#!/bin/sh
# Fuzz the C decoder with libFuzzer for a bounded time and report.
#
# usage: clients/c/fuzz/run_fuzz.sh [SECONDS]        (default 60)
#   CC       clang with libFuzzer (default: clang, then clang-14..19)
#   OUT      work directory (default: clients/c/build/fuzz)
#
# Seeds the corpus with the shared vectors, runs with ASan + UBSan, prints the
# libFuzzer summary and exits 0 if no crash was found, 1 if one was (the
# reproducer is under $OUT/crashes/; those of the run before move to
# $OUT/crashes.prev/) or the harness does not build, 77 if no libFuzzer-capable
# clang exists.
set -eu

secs=${1:-60}
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../../.." && pwd)
out=${OUT:-$root/clients/c/build/fuzz}

if [ -z "${CC:-}" ]; then
    for c in clang clang-19 clang-18 clang-17 clang-16 clang-15 clang-14; do
        if command -v "$c" >/dev/null 2>&1; then CC=$c; break; fi
    done
fi
if [ -z "${CC:-}" ]; then
    echo "run_fuzz: no clang found (apt-get install clang); libFuzzer needs clang" >&2
    exit 77
fi

# The corpus grows from run to run, but crashes/ holds only this run's
# reproducers: the previous run's move to crashes.prev/ (replacing older ones),
# so a fixed crash is not counted again.
if [ -d "$out/crashes" ] && [ -n "$(ls -A "$out/crashes")" ]; then
    rm -rf "$out/crashes.prev"
    mv "$out/crashes" "$out/crashes.prev"
    echo "run_fuzz: the previous run's reproducers are now in $out/crashes.prev/"
fi
mkdir -p "$out/corpus" "$out/crashes"
sanitize="-fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined"
# Whether $CC can build a fuzzer at all (77, skip) is asked of an empty target first, so that a harness or
# decoder that does not compile fails the run (1) instead of passing for a missing libFuzzer.
printf '#include <stddef.h>\n#include <stdint.h>\n%s\n' \
    'int LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; (void)n; return 0; }' >"$out/probe.c"
# shellcheck disable=SC2086
if ! "$CC" $sanitize "$out/probe.c" -o "$out/probe" >"$out/build.log" 2>&1; then
    echo "run_fuzz: $CC cannot build with -fsanitize=fuzzer (see $out/build.log)" >&2
    exit 77
fi
# shellcheck disable=SC2086
if ! "$CC" -g -O1 -std=c99 $sanitize -I"$root/clients/c" "$root/clients/c/ghjoints.c" "$here/fuzz_ghjoints.c" \
        -o "$out/fuzz_ghjoints" 2>"$out/build.log"; then
    cat "$out/build.log" >&2
    echo "run_fuzz: FAILED, the harness does not build with $CC (see $out/build.log)" >&2
    exit 1
fi
cp "$root"/tests/vectors/joint_stream/*.bin "$out/corpus/"

echo "run_fuzz: $CC, ${secs}s, corpus $out/corpus"
set +e
"$out/fuzz_ghjoints" -max_total_time="$secs" -print_final_stats=1 -max_len=4096 \
    -artifact_prefix="$out/crashes/" "$out/corpus" >"$out/fuzz.log" 2>&1
rc=$?
set -e

runs=$(grep -E '^stat::number_of_executed_units' "$out/fuzz.log" | awk '{print $2}')
cov=$(grep -E '^#[0-9]+' "$out/fuzz.log" | tail -1 | sed -n 's/.*cov: \([0-9]*\).*/\1/p')
crashes=$(find "$out/crashes" -type f | wc -l)
echo "run_fuzz: executions=${runs:-?} coverage_edges=${cov:-?} corpus=$(ls "$out/corpus" | wc -l) crashes=$crashes exit=$rc"
if [ "$rc" -ne 0 ] || [ "$crashes" -ne 0 ]; then
    tail -30 "$out/fuzz.log"
    echo "run_fuzz: FAILED, reproducers in $out/crashes/" >&2
    exit 1
fi
echo "run_fuzz: OK"
