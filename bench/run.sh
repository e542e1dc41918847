#!/bin/bash
# bench/run.sh: run every benchmark script bench/<name>.sh (make bench).
# Benchmarks report ratios against a peer run side by side in the same run (scipy, CalculiX),
# never timed assertions. Results go to stdout and to $BENCH_OUT (default build/bench/).
# BENCH_ONLY=name runs one; BENCH_LARGE=1 adds the largest sizes (long).
set -u
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
BENCH_OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}
export ROOT BUILD PYTHON BENCH_OUT
export PATH="$ROOT/$BUILD/bin:$ROOT/$BUILD/tools:$PATH"
mkdir -p "$BENCH_OUT"
status=0
for b in bench/*.sh; do
  name=$(basename "$b" .sh)
  [ "$name" = run ] && continue
  if [ -n "${BENCH_ONLY:-}" ] && [ "$name" != "$BENCH_ONLY" ]; then continue; fi
  echo "=== bench: $name ==="
  bash "$b" 2>&1 | tee "$BENCH_OUT/$name.txt" || status=1
done
exit $status
