#!/bin/bash
# bench/fe2cb.sh: fe2cb on tet10 rods of ~50 k and ~200 k dofs (1 M with BENCH_LARGE=1) and
# 20/100/300 fixed-interface modes, side by side in the same run with
#   (a) scipy: eigsh(Ks, M=Ms, sigma=0, which='LM') + constraint modes with splu (bench/fe2cb_scipy.py)
#   (b) CalculiX *FREQUENCY for the same number of modes on the same mesh, interfaces clamped.
# Reports wall time, CPU time and peak RSS (GNU time) and the ratios, and fe2cb's breakdown
# (-v). fe2cb runs with its Sturm check (the default) and once with --no-sturm.
# Environment: BUILD, PYTHON, BENCH_OUT, BENCH_LARGE=1, BENCH_MODES="20 100 300",
# BENCH_SIZES="0.0047 0.0029" (element sizes in m), BENCH_CCX=0 to skip CalculiX,
# BENCH_CCX_MODES="20" to run CalculiX only for those mode counts (it takes 15 min and more for
# 300 modes), BENCH_ARPACK=1 to run fe2cb once more with the single-vector ARPACK path
# (FMBD_EIG_BLOCK=1) where the default takes the block method (60 modes and more).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
BENCH_OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}
export PATH="$ROOT/$BUILD/bin:$PATH"
W=$BENCH_OUT/fe2cb-work
mkdir -p "$W" && cd "$W" || exit 1
SIZES=${BENCH_SIZES:-"0.0047 0.0029"}
[ "${BENCH_LARGE:-0}" = 1 ] && SIZES="$SIZES 0.0017"
MODES=${BENCH_MODES:-"20 100 300"}
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-2} OMP_NUM_THREADS=${OMP_NUM_THREADS:-2}
echo "threads: OPENBLAS_NUM_THREADS=$OPENBLAS_NUM_THREADS OMP_NUM_THREADS=$OMP_NUM_THREADS; $(nproc) cores"

# measure NAME CMD...: wall, cpu (user+sys) and peak RSS of a command into $NAME.time
measure() {
  local name=$1; shift
  /usr/bin/time -f "%e %U %S %M" -o "$name.time" "$@" > "$name.out" 2> "$name.err"
  local rc=$?
  read -r wall usr sys rss < <(tail -n 1 "$name.time")
  cpu=$(echo "$usr + $sys" | bc)
  cpu=$(printf '%.1f' "$cpu")
  rss_mb=$((rss / 1024))
  return $rc
}

echo "columns: wall s / cpu s / peak RSS MB of fe2cb, fe2cb --no-sturm, scipy (eigsh + splu), ccx;"
echo "ratios fe2cb/scipy and fe2cb/ccx of wall, cpu and RSS (the machine may be shared: cpu is the steadier)"
printf '%-7s %7s %5s | %-17s| %-17s| %-17s| %-17s| %s\n' h dofs modes "fe2cb" "fe2cb --no-sturm" "scipy" "ccx" \
  "ratios wall cpu RSS: /scipy ; /ccx"
for h in $SIZES; do
  fe=rod-$h.fe.h5
  [ -f "$fe" ] || mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --interface end0 --interface end1 -o "$fe" -q || exit 1
  ndof=$("$PYTHON" -c "import h5py; print(h5py.File('$fe','r')['dofs'].shape[0])")
  for n in $MODES; do
    measure fe2cb-$h-$n fe2cb "$fe" --modes "$n" -o cb-$h-$n.cb.h5 -v
    rc=$?; fw=$wall; fc=$cpu; fr=$rss_mb
    [ $rc -eq 0 ] || { echo "fe2cb failed: $(tail -n 3 fe2cb-$h-$n.err)"; continue; }
    measure fe2cbns-$h-$n fe2cb "$fe" --modes "$n" -o cbns-$h-$n.cb.h5 --no-sturm -q
    nw=$wall; nc=$cpu; nr=$rss_mb
    measure scipy-$h-$n "$PYTHON" "$ROOT/bench/fe2cb_scipy.py" "$fe" cb-$h-$n.cb.h5 "$n"
    sw=$wall; sc=$cpu; sr=$rss_mb
    cw=; cc=; cr=
    if [ "${BENCH_ARPACK:-0}" = 1 ] && [ "$n" -ge 60 ]; then
      FMBD_EIG_BLOCK=1 measure fe2cb1-$h-$n fe2cb "$fe" --modes "$n" -o cb1-$h-$n.cb.h5 -v &&
        echo "    fe2cb single-vector (FMBD_EIG_BLOCK=1): $wall s wall / $cpu s cpu / $rss_mb MB; $(grep -o 'Lanczos [^)]*)' fe2cb1-$h-$n.err)"
    fi
    ccx_here=1
    if [ -n "${BENCH_CCX_MODES:-}" ]; then
      case " $BENCH_CCX_MODES " in *" $n "*) ;; *) ccx_here=0 ;; esac
    fi
    if [ "${BENCH_CCX:-1}" != 0 ] && [ $ccx_here = 1 ]; then
      PYTHONPATH=$ROOT/tests/py "$PYTHON" -c "import fegen; fegen.write_ccx_deck('$fe', 'ccx-$h-$n.inp', $n, ['end0', 'end1'])"
      measure ccx-$h-$n ccx -i ccx-$h-$n && { cw=$wall; cc=$cpu; cr=$rss_mb; }
    fi
    r() { [ -n "$2" ] && echo "scale=2; $1 / $2" | bc | sed 's/^\./0./' || echo -; }
    printf '%-7s %7s %5s | %5s %5s %5s | %5s %5s %5s | %5s %5s %5s | %5s %5s %5s | %s %s %s ; %s %s %s\n' \
      "$h" "$ndof" "$n" "$fw" "$fc" "$fr" "$nw" "$nc" "$nr" "$sw" "$sc" "$sr" "${cw:--}" "${cc:--}" "${cr:--}" \
      "$(r "$fw" "$sw")" "$(r "$fc" "$sc")" "$(r "$fr" "$sr")" "$(r "$fw" "$cw")" "$(r "$fc" "$cc")" "$(r "$fr" "$cr")"
    grep -E 'time:' fe2cb-$h-$n.err | sed 's/^/    fe2cb /'
    grep -E '^scipy:' scipy-$h-$n.out | sed 's/^/    /'
  done
done
