#!/bin/bash
# bench/reports.sh: the error-against-run-time reports of the papers' three benchmarks at full
# size (make bench; alone: make reports). Each writes $BENCH_OUT/reports/NAME/report.{md,csv,svg}
# through examples/report.mk (driver: examples/report.py). Minutes: the quadruple pendulum's
# reference keeps 1.5 x the 0.1 % tolerance's Nd fixed-interface modes, run over 7 s twice
# (the window before separation needs a second, finer reference).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/reports
export OPENBLAS_NUM_THREADS=1
cd "$ROOT" || exit 1
rc=0
for r in report-slidercrank report-spatial-slidercrank report-quadpend; do
  echo "== $r"
  make --no-print-directory -f examples/report.mk BUILD="$BUILD" PYTHON="$PYTHON" RP_OUT="$OUT" "$r" || rc=1
  n=${r#report-}
  [ -f "$OUT/$n/report.md" ] && cat "$OUT/$n/report.md"
done
exit $rc
