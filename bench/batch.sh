#!/bin/bash
# bench/batch.sh: the batch example (examples/batch, 32 brackets) from scratch under make -j1
# and make -j2, side by side in the same run: wall time of each, speed-up, and the peak memory
# per job (the largest /usr/bin/time -v maximum resident set of any step of any body, from the
# per-step NAME.STEP.time files the example writes). The peer of -j2 is -j1 on the same bodies.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/batch
cd "$ROOT" || exit 1
rm -rf "$OUT" && mkdir -p "$OUT" || exit 1
for j in 1 2; do
  o=$OUT/j$j
  t0=$(date +%s.%N)
  /usr/bin/time -v -o "$OUT/j$j.time" make --no-print-directory -f examples/batch/Makefile \
    -j$j -k BUILD="$BUILD" OUT="$o" PYTHON="$PYTHON" > "$OUT/j$j.log" 2>&1 || {
    echo "batch -j$j failed: $(tail -5 "$OUT/j$j.log")"
    exit 1
  }
  t1=$(date +%s.%N)
  wall=$(echo "$t1 - $t0" | bc)
  cpu=$(awk -F': ' '/User time/ {u = $2} /System time/ {s = $2} END {print u + s}' "$OUT/j$j.time")
  peak=$(cat "$o"/*.*.time | awk '{if ($2 > m) m = $2} END {print m / 1024}')
  n=$(ls "$o"/*.rflex.h5 | wc -l)
  printf 'make -j%d: %d bodies, wall %.1f s, CPU %.1f s, peak memory of one job %.0f MB\n' \
    "$j" "$n" "$wall" "$cpu" "$peak"
  grep '^summary:' "$OUT/j$j.log" | head -1
  eval "wall$j=$wall"
done
printf 'speed-up -j2 / -j1: %.2f (2 cores; 1 BLAS thread per job under -j2, 2 under -j1)\n' \
  "$(echo "$wall1 / $wall2" | bc -l)"
# per step: the largest peak memory and the summed wall time over the 32 bodies (-j1 run)
for s in mesh2fe fe2cb cbcheck; do
  cat "$OUT"/j1/*."$s".time | awk -v s="$s" '{w += $1; if ($2 > m) m = $2} END {printf "  %-8s summed wall %.1f s, largest peak %.0f MB\n", s, w, m / 1024}'
done
