#!/bin/bash
# tests/cli/fuzz-regress.sh: the inputs kept under fuzz/regress/KIND/ (crashes once found and
# fixed, and inputs of the fuzzer's corpus that reach the readers' error paths) replayed through
# each reader as the fuzz targets call it (BUILD/fuzz/replay-KIND, gcc; under SANITIZE=1 with
# ASan and UBSan). Passes when every input goes through without a crash, a sanitizer report or
# a leak; the readers' answers (mostly errors) are not judged here (tests/cli/badinput.sh is).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
T=$ROOT/$BUILD/test-tmp/fuzz-regress
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
n=0
for d in "$ROOT"/fuzz/regress/*/; do
  k=$(basename "$d")
  r=$ROOT/$BUILD/fuzz/replay-$k
  [ -x "$r" ] || { echo "FAIL: $r missing (make check-build)"; fail=1; continue; }
  TMPDIR=$T "$r" "$d" >out.txt 2>err.txt
  rc=$?
  echo "$k: $(cat out.txt) exit $rc"
  [ $rc -eq 0 ] || { echo "FAIL: $k: $(tail -5 err.txt)"; fail=1; }
  n=$((n + 1))
done
[ $n -ge 5 ] || { echo "FAIL: only $n kinds under fuzz/regress"; fail=1; }
exit $fail
