#!/usr/bin/env bash
# Engine bench of two commits on this machine, run alternately (old, new, old, new, ...), so
# that their engine/baseline ratios and set-up times can be compared in one session: the
# machine's speed varies from day to day and from one machine to the next, a ratio measured
# beside its own baseline much less, and alternation spreads the noise over both.
#
#   bench/compare_commits.sh OLD [NEW] [ROUNDS]     (NEW: the working tree; ROUNDS: 2)
#
# Environment: TOPOMECH_BENCH_MODELS (default cloth,mass_tensor,corotational) and
# TOPOMECH_BENCH_SIZES (default 1e5), as for `make bench`; one thread. OLD (and NEW when given)
# is built in a worktree under target/compare/ with its own target folder.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
old=${1:?usage: bench/compare_commits.sh OLD [NEW] [ROUNDS]}
new=${2:-}
rounds=${3:-2}
build() { # commit -> path of its engine bench binary
    local rev=$1 dir=target/compare/$1
    if [ ! -d "$dir" ]; then git worktree add -q --detach "$dir" "$rev"; fi
    (cd "$dir" && CARGO_TARGET_DIR="$PWD/target" cargo bench -q -p topomech-physics --bench engine --no-run 2>/dev/null)
    ls -t "$dir"/target/release/deps/engine-* | grep -v '\.d$' | head -1
}
old_bin=$(build "$old")
if [ -n "$new" ]; then
    new_bin=$(build "$new")
else
    cargo bench -q -p topomech-physics --bench engine --no-run 2>/dev/null
    new_bin=$(ls -t target/release/deps/engine-* | grep -v '\.d$' | head -1)
    new=working-tree
fi
export TOPOMECH_BENCH_MODELS=${TOPOMECH_BENCH_MODELS:-cloth,mass_tensor,corotational}
export TOPOMECH_BENCH_SIZES=${TOPOMECH_BENCH_SIZES:-1e5}
export TOPOMECH_BENCH_THREADS=1
for i in $(seq "$rounds"); do
    for side in old new; do
        if [ $side = old ]; then bin=$old_bin; rev=$old; else bin=$new_bin; rev=$new; fi
        TOPOMECH_BENCH_OUT=$(mktemp -d) "$bin" --bench 2>&1 \
            | grep -E '^\s+(cloth|mass_tensor|corotational)\s+[0-9]' | sed "s/^/$rev round $i:/"
    done
done
