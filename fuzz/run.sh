#!/bin/bash
# fuzz/run.sh: `make fuzz`: every target of $FUZZ_BUILD/fuzz/ for FUZZ_SECONDS seconds each
# (default 60), from the seeds (fuzz/seeds.sh), the kept regression inputs and the corpus of
# earlier runs ($FUZZ_BUILD/corpus/KIND, kept between runs). A crash, a leak, a sanitizer
# report, a timeout (10 s for one input) or an out-of-memory (2 GB) is saved as
# $FUZZ_BUILD/crashes/KIND/{crash,leak,timeout,oom}-* and fuzzing goes on (libFuzzer's fork
# mode). Each saved input is then replayed and sorted by the first stack frame in HDF5 or in
# the toolchain: inside libhdf5 (a defect of HDF5 1.10 on a corrupt file, which no
# reader of ours can prevent: listed, not failed) or in the toolchain (fails make fuzz: fix it
# and keep the input under fuzz/regress/KIND/, so that `make check` replays it,
# tests/cli/fuzz-regress.sh).
# Environment: FUZZ_BUILD (build-fuzz), BUILD (the normal build, makes the seeds),
# FUZZ_SECONDS, FUZZ_TARGETS (default: all), FUZZ_JOBS (parallel targets, default 1).
set -u
ROOT=$(cd "$(dirname "$0")/.." && pwd)
cd "$ROOT"
FB=${FUZZ_BUILD:-build-fuzz}
SECS=${FUZZ_SECONDS:-60}
TARGETS=${FUZZ_TARGETS:-$(ls fuzz/fuzz_*.c | sed 's|fuzz/fuzz_||; s|\.c$||')}
export OPENBLAS_NUM_THREADS=1 ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/tests/lsan.supp:print_suppressions=0}
if [ ! -d "$FB/seeds/fe" ]; then
  echo "fuzz: making the seeds ($FB/seeds)"
  rm -rf "$FB/seeds" && bash fuzz/seeds.sh "$FB/seeds" || { echo "fuzz: no seeds"; exit 1; }
fi
status=0
for k in $TARGETS; do
  mkdir -p "$FB/corpus/$k" "$FB/crashes/$k"
  dirs=("$FB/corpus/$k" "$FB/seeds/$k")
  [ -d "fuzz/regress/$k" ] && dirs+=("fuzz/regress/$k")
  echo "fuzz: $k for ${SECS} s"
  "$FB/fuzz/fuzz-$k" -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
    -max_total_time="$SECS" -timeout=10 -rss_limit_mb=2048 -max_len=400000 \
    -artifact_prefix="$FB/crashes/$k/" "${dirs[@]}" >"$FB/fuzz-$k.log" 2>&1
  grep -E '^#[0-9]+: cov: ' "$FB/fuzz-$k.log" | tail -1 | sed "s/^/fuzz: $k: last: /"
  for c in "$FB/crashes/$k"/*; do
    [ -f "$c" ] || continue
    [ "${c%.txt}" = "$c" ] || continue
    ASAN_OPTIONS=detect_leaks=1:fast_unwind_on_malloc=0 \
      "$FB/fuzz/fuzz-$k" -timeout=10 -rss_limit_mb=2048 "$c" >"$c.txt" 2>&1
    # the first frame in HDF5 or in the toolchain (not the sanitizer, libFuzzer or libc)
    frame=$(grep -E '^ +#[0-9]+ ' "$c.txt" | grep -E 'libhdf5|/common/|/fuzz/fuzz_' | head -1)
    if [ -z "$frame" ] && ! grep -qE 'ERROR|SUMMARY|timeout|out-of-memory' "$c.txt"; then
      echo "fuzz: $k: $(basename "$c"): no longer fails"
    elif grep -q 'LeakSanitizer' "$c.txt" && [ "$(grep -c 'leak of' "$c.txt")" = "$(awk \
      '/leak of/{r=1;h=0} r&&/ in H5Fopen /{h=1} /^$/{if(r&&h)n++; r=0} END{print n+0}' "$c.txt")" ]; then
      echo "fuzz: $k: $(basename "$c"): a leak inside a failed H5Fopen (HDF5)"
    elif grep -q 'libhdf5' <<<"$frame" && ! grep -q 'LeakSanitizer' "$c.txt"; then
      echo "fuzz: $k: $(basename "$c"): inside HDF5: $(sed -E 's/.* in ([^ ]+) .*/\1/' <<<"$frame")"
    else
      status=1
      echo "fuzz: $k: $(basename "$c"): FAILED in the toolchain: $frame (replay: $c.txt)"
    fi
  done
done
exit $status
