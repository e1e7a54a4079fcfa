#!/bin/sh
# Compare ghj_dump's output on every shared vector with the vector's expected
# JSON (tests/vectors/joint_stream/NAME.json: events one per line, then stats),
# feeding it 1, 7 and 4096 bytes at a time. Fails if ghj_dump exits non-zero
# or prints anything else. POSIX sh + sed + cmp; used by `make check`.
#
# usage: tools/check_vectors.sh GHJ_DUMP VECTOR_DIR
set -u

dump=$1
dir=$2
tmp=$(mktemp -d)
# A signal ends the script (its EXIT trap removes $tmp): trapping INT/TERM with the rm alone went on with the
# loop after the directory was gone, reporting a FAIL for every remaining run.
trap 'rm -rf "$tmp"' EXIT
trap 'exit 130' INT
trap 'exit 143' TERM
fail=0
n=0

# The expected output from NAME.json, in ghj_dump's format: each event line
# without its indent and separating comma, then the stats object without spaces.
expected() {
    sed -n '
/^ "events": \[$/,/^ \]$/{
  /^ "events": \[$/d
  /^ \]$/d
  /^$/d
  s/^  //
  s/,$//
  p
}' "$1"
    sed -n 's/^ "stats": \(.*\),$/{"stats":\1}/p' "$1" | tr -d ' '
}

for bin in "$dir"/*.bin; do
    json=${bin%.bin}.json
    name=$(basename "$bin" .bin)
    if [ ! -f "$json" ]; then
        echo "FAIL $name: no $json"
        fail=1
        continue
    fi
    expected "$json" >"$tmp/expected"
    if ! grep -q '^{"stats":' "$tmp/expected"; then
        echo "FAIL $name: no stats line in $json"
        fail=1
        continue
    fi
    for chunk in 1 7 4096; do
        n=$((n + 1))
        rc=0
        "$dump" -c "$chunk" "$bin" >"$tmp/actual" || rc=$?
        if [ "$rc" -ne 0 ]; then
            echo "FAIL $name (chunk $chunk): $dump exited with status $rc"
            fail=1
        elif ! cmp -s "$tmp/expected" "$tmp/actual"; then
            echo "FAIL $name (chunk $chunk): output differs from $json"
            diff "$tmp/expected" "$tmp/actual" | cut -c1-160 | head -6
            fail=1
        fi
    done
done
if [ "$n" -eq 0 ]; then
    echo "FAIL: no vectors in $dir"
    exit 1
fi
if [ "$fail" -ne 0 ]; then
    echo "check_vectors: FAILED"
    exit 1
fi
echo "check_vectors: $n runs ($((n / 3)) vectors x chunks 1, 7, 4096) match their expected JSON"
