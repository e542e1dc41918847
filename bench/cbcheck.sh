#!/bin/bash
# bench/cbcheck.sh: the cost of cbcheck's error estimates against fe2cb's reduction and against
# the exact errors (--exact, a full eigensolution), and the selection loop's cost per added mode.
# Bodies: the papers' rod (tet10, one RBE2 interface at an end face), ~50 k dofs; with
# BENCH_LARGE=1 also ~200 k dofs. Side-by-side peer for the exact eigenvalues: scipy's
# shift-invert eigsh on the same K, M (50 k only). Ratios are reported, never asserted.
# CPU seconds (all threads) as the programs report them: wall times on a shared machine mean
# little; both are in the logs under $BENCH_OUT/cbcheck. BENCH_SIZES="H:TAG ..." picks sizes.
set -u
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/cbcheck
mkdir -p "$OUT" && cd "$OUT" || exit 1
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-2}
sizes=${BENCH_SIZES:-"0.0047:50k"}
[ "${BENCH_LARGE:-0}" = 1 ] && [ -z "${BENCH_SIZES:-}" ] && sizes="$sizes 0.0028:200k"
cpu() { grep -oE '[0-9.e+-]+ s cpu' "$1" | tail -1 | cut -d' ' -f1; }     # summary line
vcpu() { grep "cpu: " "$1" | sed -E "s/.*$2 ([0-9.]+) s.*/\1/"; }           # -v cpu line
r() { echo "$1" | bc -l | xargs printf "%.${2:-3}f"; }
echo "CPU seconds; est = the whole cbcheck run without --exact (reading both files, residual blocks,"
echo "reduced eigensolution, report); num = est less reading the fe file; plain = est with --plain (cb file alone)"
printf '%-7s %7s %9s %8s %8s %8s %7s %9s %9s %9s %4s %5s %10s %10s\n' body dofs fe2cb est est/fe2cb num plain \
  exact exact/est exact/num Nd iter s/iter s/ext.mode
for spec in $sizes; do
  h=${spec%%:*}; tag=rod${spec##*:}
  mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --E 100e9 --nu 0.285 --rho 7850 --interface end1 \
    -o $tag.fe.h5 -q || { echo "mesh2fe failed"; exit 1; }
  fe2cb $tag.fe.h5 --modes 30 -o $tag.cb.h5 2> $tag.fe2cb.err || { echo "fe2cb failed"; cat $tag.fe2cb.err; exit 1; }
  cbcheck $tag.cb.h5 -v > $tag.est.txt 2> $tag.est.err || { echo "cbcheck failed"; cat $tag.est.err; exit 1; }
  cbcheck $tag.cb.h5 --plain -v > $tag.plain.txt 2> $tag.plain.err || { echo "cbcheck (plain) failed"; exit 1; }
  cbcheck $tag.cb.h5 --exact -v --csv $tag.exact.csv > $tag.exact.txt 2> $tag.exact.err || { echo "--exact failed"; exit 1; }
  cbcheck $tag.cb.h5 --tol 1e-3 --range 10 -v -o $tag.rflex.h5 > $tag.sel.txt 2> $tag.sel.err || { echo "selection failed"; cat $tag.sel.err; exit 1; }
  dofs=$(grep -oE '[0-9]+ dofs' $tag.est.txt | head -1 | cut -d' ' -f1)
  c_fe2cb=$(cpu $tag.fe2cb.err); c_est=$(cpu $tag.est.err); c_plain=$(cpu $tag.plain.err)
  c_read=$(vcpu $tag.est.err "reading the fe file"); c_num=$(r "$c_est - $c_read")
  c_exact=$(vcpu $tag.exact.err exact)
  c_sel=$(vcpu $tag.sel.err selection)
  line=$(grep "time:" $tag.sel.err)
  iters=$(sed -E 's/.* for ([0-9]+) iterations.*/\1/' <<<"$line")
  t_ext=$(sed -E 's/.*extensions ([0-9.]+) s.*/\1/' <<<"$line")
  nmodes=$(sed -E 's/.*calls, ([0-9]+) modes.*/\1/' <<<"$line")
  t_sel=$(sed -E 's/.*selection ([0-9.]+) s.*/\1/' <<<"$line")
  nd=$(grep -oE 'Nd = [0-9]+ meets' $tag.sel.err | grep -oE '[0-9]+')
  # the loop's own cost per iteration (wall: it is single-threaded dense algebra) and the
  # extension's cost per added mode (wall: a refactorisation and Lanczos run of fmbd_cb_extend)
  periter=$(r "($t_sel - $t_ext) / $iters" 4)
  permode=$(r "if ($nmodes > 0) $t_ext / $nmodes else 0" 3)
  printf '%-7s %7s %9.2f %8.2f %7.1f%% %8.2f %7.2f %9.2f %8.1fx %8.1fx %4s %5s %10s %10s\n' $tag "$dofs" "$c_fe2cb" \
    "$c_est" "$(r "100 * $c_est / $c_fe2cb")" "$c_num" "$c_plain" "$c_exact" "$(r "$c_exact / $c_est")" \
    "$(r "$c_exact / $c_num")" "$nd" "$iters" "$periter" "$permode"
  grep "modes with exact error" $tag.exact.txt | sed "s/^/  $tag bounds at Nd = 30: /"
  grep -E "time:|cpu:" $tag.sel.err | sed "s/^/  $tag selection: /"
  if [ "${spec##*:}" = 50k ]; then
    # peer: scipy shift-invert Lanczos (SuperLU) for the same full eigenpairs as --exact
    "$PYTHON" - $tag.fe.h5 "$(($(tail -n +2 $tag.exact.csv | wc -l) + 6))" <<'EOF'
import sys, time, h5py, numpy as np, scipy.sparse as sp, scipy.sparse.linalg as spl
with h5py.File(sys.argv[1], "r") as f:
    csr = lambda g: sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
    K, M = csr(f["K"]), csr(f["M"])
t, c = time.time(), time.process_time()
w = spl.eigsh(K.tocsc(), k=int(sys.argv[2]), M=M.tocsc(), sigma=-1e5, which="LM")[0]
print("  peer: scipy eigsh (SuperLU shift-invert), %s eigenpairs of the full body: %.2f s cpu, %.2f s wall"
      % (sys.argv[2], time.process_time() - c, time.time() - t))
EOF
  fi
done
