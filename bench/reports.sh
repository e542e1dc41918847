#!/bin/bash
# bench/reports.sh: the error-against-run-time reports of the papers' three benchmarks at full
# size (make bench; alone: make reports), and the demo's body whole against made for its scene
# (file size, load time). Each writes $BENCH_OUT/reports/NAME/report.{md,csv,svg}
# through examples/report.mk (driver: examples/report.py). The reference of each is the full FE
# model of the rod in the same scene, on the mesh and over the time report.mk sets (QP_ARGS,
# SC_ARGS, SSC_ARGS: the FM's cost); about 8 min of CPU in all for the runs (the three FMs 57,
# 272 and 41 s, the quadruple pendulum's 316-mode CB body 30 s twice), plus the bodies' making
# (cbcheck at 0.1 % on the pendulum's rod: 13 s of CPU).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/reports
export OPENBLAS_NUM_THREADS=1
cd "$ROOT" || exit 1
rc=0

# --- the demo's body whole and made for its scene (cbcheck --for-scene): file size, load time --
# The quadruple pendulum's rod as make demo builds it (the scene's mesh2fe, fe2cb and cbcheck
# options); fmbd-run's time before its first step (CPU of the whole run minus the
# integration's, over a run of one output interval), the median of 5 runs.
D="$OUT/subset"
mkdir -p "$D"
(
  export PATH="$ROOT/$BUILD/bin:$PATH"
  S="$ROOT/examples/quadpend/quadpend.yaml"
  cd "$D" || exit 1
  [ -f rod.cb.h5 ] || { mesh2fe "$ROOT/examples/geometry/rod.geo" --size 0.0075 --E 100e9 --nu 0.285 \
    --rho 7850 --interface 'end0@-0.05,0,0' -o rod.fe.h5 -q && fe2cb rod.fe.h5 --modes 60 -o rod.cb.h5 -q; } || exit 1
  cbcheck rod.cb.h5 --fe rod.fe.h5 --init 5 --range 30 --tol 1e-2 -o whole.rflex.h5 -q || exit 1
  cbcheck rod.cb.h5 --fe rod.fe.h5 --init 5 --range 30 --tol 1e-2 --for-scene "$S:rod" -o subset.rflex.h5 -q || exit 1
  "$PYTHON" - "$S" <<'PYEOF'
import os, subprocess, sys
import h5py
import numpy as np
scene = open(sys.argv[1]).read()
print("the demo's rod (quadruple pendulum), whole and made for its scene:")
print(f"  {'body':8s} {'file_MB':>8s} {'nodes_held':>10s} {'dofs':>7s} {'load_cpu_s':>10s} {'load_wall_s':>11s}")
runs = {}
for b in ("whole", "subset"):
    open(b + ".yaml", "w").write(scene.replace("file: rod.rflex.h5", f"file: {b}.rflex.h5"))
    cpu, wall = [], []
    for i in range(5):
        subprocess.run(["fmbd-run", b + ".yaml", "-o", b + ".run.h5", "--t-end", "0.014", "-q"], check=True)
        with h5py.File(b + ".run.h5") as f:
            s = f["stats"].attrs
            cpu.append(s["cpu_time_s"] - s["run_cpu_time_s"])
            wall.append(s["wall_time_s"] - s["run_wall_time_s"])
    with h5py.File(b + ".rflex.h5") as f:
        held = f["subset/nodes"].shape[0] if "subset" in f else f["mesh/nodes"].shape[0]
        nd = f["dofs"].shape[0]
    runs[b] = os.path.getsize(b + ".rflex.h5")
    print(f"  {b:8s} {runs[b] / 1e6:8.2f} {held:10d} {nd:7d} {np.median(cpu):10.3f} {np.median(wall):11.3f}")
with h5py.File("whole.run.h5") as w, h5py.File("subset.run.h5") as s:
    same = all(np.array_equal(w["outputs/A/" + q][()], s["outputs/A/" + q][()]) for q in ("position", "von_mises"))
print(f"  file {runs['whole'] / runs['subset']:.0f}x smaller; node A's run identical bitwise: {same}")
PYEOF
) || rc=1
[ "${REPORTS_SUBSET_ONLY:-0}" = 1 ] && exit $rc  # the measurement above alone

for r in report-slidercrank report-spatial-slidercrank report-quadpend; do
  echo "== $r"
  make --no-print-directory -f examples/report.mk BUILD="$BUILD" PYTHON="$PYTHON" RP_OUT="$OUT" "$r" || rc=1
  n=${r#report-}
  [ -f "$OUT/$n/report.md" ] && cat "$OUT/$n/report.md"
done
exit $rc
