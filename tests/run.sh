#!/bin/bash
# tests/run.sh: run every test of `make check` and print "N passed, N failed".
#   unit tests   build/tests/tNNN-*          (C, silent when right, nonzero exit on failure)
#   cli tests    tests/cli/*.sh              (programs on tiny inputs, expected errors)
#   py tests     tests/py/test_*.py          (against scipy / closed form / CalculiX)
#   extreme      tests/extreme/*.{py,sh}     (stiff and extreme cases, docs/STABILITY.md)
# Environment: BUILD (build dir), PYTHON (/usr/bin/python3), TESTS (glob filter, optional),
# VALGRIND=1 (unit tests under valgrind memcheck).
set -u
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export BUILD PYTHON ROOT
export PATH="$ROOT/$BUILD/bin:$ROOT/$BUILD/tools:$PATH"
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$ROOT/tests/lsan.supp:print_suppressions=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
# scipy/h5py in the same process as ASan would need preloading; python tests only drive programs
LOG=$ROOT/$BUILD/test-logs
mkdir -p "$LOG"
pass=0 fail=0 skip=0 failed=()
run() {  # name, command...
  local name=$1; shift
  if [ -n "${TESTS:-}" ] && [[ $name != $TESTS ]]; then return; fi
  local t0=$SECONDS
  mkdir -p "$(dirname "$LOG/$name.log")"
  "$@" >"$LOG/$name.log" 2>&1
  local rc=$?
  if [ $rc -eq 0 ]; then
    pass=$((pass + 1)); printf 'PASS  %-40s %3ds\n' "$name" $((SECONDS - t0))
  elif [ $rc -eq 77 ]; then  # a test that cannot run here says why (exit 77, as automake's)
    skip=$((skip + 1)); printf 'SKIP  %-40s %3ds  %s\n' "$name" $((SECONDS - t0)) "$(grep -m1 SKIP "$LOG/$name.log")"
  else
    fail=$((fail + 1)); failed+=("$name"); printf 'FAIL  %-40s %3ds\n' "$name" $((SECONDS - t0))
    tail -n 20 "$LOG/$name.log" | sed 's/^/      | /'
  fi
}
# VALGRIND=1 (make check VALGRIND=1): the unit tests run under memcheck; any error or
# definite leak fails them (OpenMP/OpenBLAS thread stacks show as "possibly lost": not errors)
VG=()
if [ "${VALGRIND:-0}" = 1 ]; then
  VG=(valgrind -q --error-exitcode=99 --leak-check=full --errors-for-leak-kinds=definite)
fi
for t in "$BUILD"/tests/t*; do
  [ -f "$t" ] && [ -x "$t" ] || continue  # not tests/tools/ (tool objects)
  run "unit/$(basename "$t")" "${VG[@]}" "$t"
done
run "lint/clang-format" bash scripts/format-check.sh
for t in tests/cli/*.sh; do
  [ -f "$t" ] || continue
  run "cli/$(basename "$t" .sh)" bash "$t"
done
for t in tests/py/test_*.py; do
  [ -f "$t" ] || continue
  run "py/$(basename "$t" .py)" "$PYTHON" "$t"
done
for t in tests/extreme/*.py tests/extreme/*.sh; do
  [ -f "$t" ] || continue
  case $t in
    *.py) run "extreme/$(basename "$t" .py)" "$PYTHON" "$t" ;;
    *.sh) run "extreme/$(basename "$t" .sh)" bash "$t" ;;
  esac
done
echo
[ $fail -gt 0 ] && printf 'failed: %s (logs in %s)\n' "${failed[*]}" "$LOG"
echo "$pass passed, $fail failed$([ $skip -gt 0 ] && echo ", $skip SKIPPED")"
[ $fail -eq 0 ]
