#!/bin/bash
# bench/mpi.sh: the distributed reduction fe2cb-mpi (PETSc/SLEPc/MUMPS) against the serial
# fe2cb side by side on tet10 rods (examples/geometry/rod.geo, one interface at each end):
#   fe2cb, 1 BLAS thread and 2 threads        (the serial path: CHOLMOD + ARPACK)
#   fe2cb-mpi on 1 process and with mpirun -np 2 (1 BLAS thread per process)
# Reports wall time, CPU time of the serial runs, peak memory (serial: GNU time; MPI: the
# largest process and process 0, from fe2cb-mpi -v), and fe2cb-mpi's measured factor and solve
# costs (MUMPS factor entries, flops, time; Krylov-Schur time and solves), the input of the
# scaling model in docs/SCALE.md. Checks that every run's eigenvalues agree (1e-10 relative).
# Environment: BUILD, PYTHON, BENCH_OUT, BENCH_SIZES="0.0047 0.0029" (element sizes, m),
# BENCH_LARGE=1 adds 0.0023 (about 380 k dofs), BENCH_MODES=20.
# BENCH_LOGVIEW=1: instead, where the time of fe2cb-mpi goes on 1 and 2 processes (PETSc's
# -log_view: MUMPS analysis and factorisations, the solves, the waits for messages) on one
# rod of BENCH_LOGVIEW_SIZE=0.0033 (about 130 k dofs), each run twice, the lower kept.
# BENCH_EXACT=1: instead, cbcheck --exact against cbcheck-mpi --exact on 1 and 2 processes on
# a rod of BENCH_EXACT_SIZE=0.0047 (about 51 k dofs; 6 rigid-body modes and 10 flexible).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
BENCH_OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}
export PATH="$ROOT/$BUILD/bin:$PATH"
if ! command -v mpirun > /dev/null || [ ! -x "$ROOT/$BUILD/bin/fe2cb-mpi" ] || [ ! -x "$ROOT/$BUILD/bin/cbcheck-mpi" ]; then
  echo "bench/mpi.sh: no mpirun or no $BUILD/bin/fe2cb-mpi (make deps && make mpi): not run"
  exit 0
fi
W=$BENCH_OUT/mpi-work
mkdir -p "$W" && cd "$W" || exit 1
SIZES=${BENCH_SIZES:-"0.0047 0.0029"}
[ "${BENCH_LARGE:-0}" = 1 ] && SIZES="$SIZES 0.0023"
N=${BENCH_MODES:-20}
MPIRUN=(mpirun --allow-run-as-root --oversubscribe)
export OMPI_MCA_btl_vader_single_copy_mechanism=none
echo "$(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg) at the start; $N modes"

run() {  # NAME THREADS CMD...: wall/cpu/rss of the command (GNU time) into globals
  local name=$1 th=$2; shift 2
  OPENBLAS_NUM_THREADS=$th OMP_NUM_THREADS=$th /usr/bin/time -f "%e %U %S %M" -o "$name.time" \
    "$@" > "$name.out" 2> "$name.err" || { echo "  $name failed: $(tail -n 3 "$name.err")"; return 1; }
  read -r wall usr sys rss < <(tail -n 1 "$name.time")
  cpu=$(printf '%.1f' "$(echo "$usr + $sys" | bc)")
  rss_mb=$((rss / 1024))
}
mpi_figures() {  # NAME: fe2cb-mpi -v figures
  sed -n 's/.*peak memory: process 0 \([0-9]*\) MB, largest process \([0-9]*\) MB.*/p0 \1 MB, largest \2 MB/p' "$1.err"
}

if [ "${BENCH_EXACT:-0}" = 1 ]; then
  # cbcheck --exact (ARPACK + CHOLMOD) against cbcheck-mpi on 1 and 2 processes (SLEPc + MUMPS)
  h=${BENCH_EXACT_SIZE:-0.0047}
  fe=rod-$h.fe.h5
  [ -f "$fe" ] || mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --interface end0 \
    --interface end1 -o "$fe" -q || exit 1
  [ -f ex-$h.cb.h5 ] || fe2cb "$fe" --modes "$N" -o ex-$h.cb.h5 -q || exit 1
  run ex-s 1 cbcheck ex-$h.cb.h5 --exact --range 10 --csv ex-s.csv -v || exit 1
  echo "  cbcheck --exact:            $wall s wall, $cpu s cpu, $rss_mb MB; exact: $(grep -o 'exact [0-9.]* s' ex-s.err | sed -n '1s/exact/wall/p;2s/exact/cpu/p' | paste -sd' ')"
  run ex-p1 1 cbcheck-mpi ex-$h.cb.h5 --exact --range 10 --csv ex-p1.csv -v || exit 1
  echo "  cbcheck-mpi, 1 process:     $wall s wall, $cpu s cpu, $rss_mb MB; exact: $(grep -o 'exact [0-9.]* s' ex-p1.err | sed -n '1s/exact/wall/p;2s/exact/cpu/p' | paste -sd' ')"
  run ex-p2 1 "${MPIRUN[@]}" -np 2 cbcheck-mpi ex-$h.cb.h5 --exact --range 10 --csv ex-p2.csv -v || exit 1
  echo "  cbcheck-mpi, 2 processes:   $wall s wall, $cpu s cpu (both), $rss_mb MB (largest); exact: $(grep -o 'exact [0-9.]* s' ex-p2.err | sed -n '1s/exact/wall/p;2s/exact/cpu/p' | paste -sd' ')"
  grep -h 'exact eigenvalues on' ex-p1.err ex-p2.err | sed 's/^cbcheck-mpi: /    /'
  "$PYTHON" - ex-s.csv ex-p1.csv ex-p2.csv <<'PY'
import csv, sys
rows = [list(csv.DictReader(open(f))) for f in sys.argv[1:]]
chi = lambda r: [float(x["eigenvalue"]) / (1 + float(x["exact"])) for x in r]
s = chi(rows[0])
e = max(abs(a - b) / b for r in rows[1:] for a, b in zip(chi(r), s))
print(f"    exact eigenvalues of the three runs agree to {e:.1e} relative")
PY
  echo "load average $(cut -d' ' -f1-3 /proc/loadavg) at the end"
  exit 0
fi
if [ "${BENCH_LOGVIEW:-0}" = 1 ]; then
  h=${BENCH_LOGVIEW_SIZE:-0.0033}
  fe=rod-$h.fe.h5
  [ -f "$fe" ] || mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --interface end0 \
    --interface end1 -o "$fe" -q || exit 1
  for rep in 1 2; do
    for np in 1 2; do
      PETSC_OPTIONS="-log_view :lv-np$np-r$rep.log" run lv-np$np-r$rep 1 "${MPIRUN[@]}" -np $np \
        fe2cb-mpi "$fe" --modes "$N" -o lv-np$np-r$rep.cb.h5 -v || exit 1
      echo "  np $np, run $rep: $wall s wall, load $(cut -d' ' -f1-3 /proc/loadavg)"
    done
  done
  "$PYTHON" - "$fe" <<'PY'
import re, sys, h5py
n = h5py.File(sys.argv[1], "r")["dofs"].shape[0]
def events(f):  # event -> (count, max time over the processes)
    e = {}
    for line in open(f):
        m = re.match(r"^(\w+)\s+(\d+)\s+[\d.]+\s+([\d.e+-]+)\s", line)
        if m: e[m.group(1)] = (int(m.group(2)), float(m.group(3)))
        m = re.match(r"^Time \(sec\):\s+([\d.e+-]+)", line)
        if m: e["total"] = (1, float(m.group(1)))
    return e
print(f"fe2cb-mpi, {n} dofs, -log_view (seconds, slowest process; the lower total of two runs)")
print(f"{'':4} {'total':>7} {'analysis':>9} {'numeric':>8} {'solves':>14} {'waits':>7} {'Krylov-Schur':>13}")
for np in (1, 2):
    runs = [events(f"lv-np{np}-r{r}.log") for r in (1, 2)]
    e = min(runs, key=lambda x: x["total"][1])
    g = lambda k: e.get(k, (0, 0.0))
    print(f"np {np} {g('total')[1]:7.1f} {g('MatCholFctrSym')[1]:9.1f} {g('MatCholFctrNum')[1]:8.1f} "
          f"{g('MatSolve')[1]:7.1f} ({g('MatSolve')[0]:3d}) {g('VecScatterEnd')[1]:7.1f} {g('EPSSolve')[1]:13.1f}")
print("analysis, numeric: MatCholFctrSym/Num (the Cholesky of Ks and the Sturm LDL'); solves:")
print("MatSolve (count); waits: VecScatterEnd (messages of the mat-vecs and gathers)")
PY
  echo "load average $(cut -d' ' -f1-3 /proc/loadavg) at the end"
  exit 0
fi

printf '%-7s %8s | %-22s | %-22s | %-30s | %-30s\n' h dofs "fe2cb 1 thread" "fe2cb 2 threads" \
  "fe2cb-mpi 1 process" "fe2cb-mpi -np 2"
printf '%-7s %8s | %-22s | %-22s | %-30s | %-30s\n' "" "" "wall cpu RSS(MB)" "wall cpu RSS(MB)" \
  "wall, peak per process" "wall, peak per process"
for h in $SIZES; do
  fe=rod-$h.fe.h5
  [ -f "$fe" ] || mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --interface end0 \
    --interface end1 -o "$fe" -q || exit 1
  ndof=$("$PYTHON" -c "import h5py; print(h5py.File('$fe','r')['dofs'].shape[0])")
  run s1-$h 1 fe2cb "$fe" --modes "$N" -o s1-$h.cb.h5 -v || continue
  a="$wall $cpu $rss_mb"
  run s2-$h 2 fe2cb "$fe" --modes "$N" -o s2-$h.cb.h5 -v || continue
  b="$wall $cpu $rss_mb"
  run p1-$h 1 fe2cb-mpi "$fe" --modes "$N" -o p1-$h.cb.h5 -v || continue
  c="$wall s, cpu $cpu, $(mpi_figures p1-$h)"
  run p2-$h 1 "${MPIRUN[@]}" -np 2 fe2cb-mpi "$fe" --modes "$N" -o p2-$h.cb.h5 -v || continue
  d="$wall s, cpu $cpu, $(mpi_figures p2-$h)"
  printf '%-7s %8s | %-22s | %-22s | %-30s | %-30s\n' "$h" "$ndof" "$a" "$b" "$c" "$d"
  for p in p1 p2; do
    grep -E 'MUMPS factor of Ks|time:' $p-$h.err | sed "s/^fe2cb-mpi: /    $p: /"
  done
  grep -E 'time:' s1-$h.err | sed 's/^fe2cb: /    s1: /'
  "$PYTHON" - s1-$h.cb.h5 s2-$h.cb.h5 p1-$h.cb.h5 p2-$h.cb.h5 <<'PY'
import sys, h5py, numpy as np
k = [h5py.File(f, "r")["cb/kappa"][()] for f in sys.argv[1:]]
e = max(np.max(np.abs(x - k[0]) / k[0]) for x in k[1:])
print(f"    eigenvalues of the four runs agree to {e:.1e} relative" + ("" if e <= 1e-10 else "  ** ABOVE 1e-10 **"))
PY
done
echo "load average $(cut -d' ' -f1-3 /proc/loadavg) at the end"
