#!/bin/bash
# bench/cbcheck.sh: the cost of cbcheck's error estimates against fe2cb's reduction and against
# the exact errors (--exact, a full eigensolution), and the selection loop's cost per added mode.
# Bodies: the papers' rod (tet10, one RBE2 interface at an end face), ~50 k dofs; with
# BENCH_LARGE=1 also ~200 k dofs. A side-by-side peer for the exact eigenvalues: scipy's
# shift-invert eigsh on the same K, M (50 k only). Ratios are reported, never asserted.
set -u
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/cbcheck
mkdir -p "$OUT" && cd "$OUT" || exit 1
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-2}
now() { date +%s.%N; }
sizes="0.0047:50k"
[ "${BENCH_LARGE:-0}" = 1 ] && sizes="$sizes 0.0028:200k"
printf '%-6s %8s %9s %9s %10s %9s %9s %8s %8s %10s %12s\n' body dofs fe2cb_s est_s est/fe2cb exact_s exact/est Nd iters loop_s s/mode
for spec in $sizes; do
  h=${spec%%:*}; tag=${spec##*:}
  mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$h" --E 100e9 --nu 0.285 --rho 7850 --interface end1 \
    -o rod$tag.fe.h5 -q || { echo "mesh2fe failed"; exit 1; }
  t0=$(now)
  fe2cb rod$tag.fe.h5 --modes 30 -o rod$tag.cb.h5 -q || { echo "fe2cb failed"; exit 1; }
  t_fe2cb=$(echo "$(now) - $t0" | bc -l)
  # the estimates of the 30-mode body as fe2cb wrote it (whole program: reading both files,
  # the residual blocks, the reduced solve, the report)
  t0=$(now)
  cbcheck rod$tag.cb.h5 -v > est$tag.txt 2> est$tag.err || { echo "cbcheck failed"; cat est$tag.err; exit 1; }
  t_est=$(echo "$(now) - $t0" | bc -l)
  t0=$(now)
  cbcheck rod$tag.cb.h5 --exact -v --csv exact$tag.csv > exact$tag.txt 2> exact$tag.err || { echo "cbcheck --exact failed"; exit 1; }
  t_exact=$(echo "$(now) - $t0" | bc -l)
  # the selection: E = 1e-3 on 10 modes from N0 = 5
  cbcheck rod$tag.cb.h5 --tol 1e-3 --range 10 -v -o rod$tag.rflex.h5 > sel$tag.txt 2> sel$tag.err || { echo "selection failed"; cat sel$tag.err; exit 1; }
  line=$(grep "time:" sel$tag.err)
  sel_s=$(sed -E 's/.*selection ([0-9.]+) s for ([0-9]+) iterations of which extensions ([0-9.]+) s \(([0-9]+) calls, ([0-9]+) modes\).*/\1 \2 \3 \4 \5/' <<<"$line")
  read -r t_sel iters t_ext ncall nmodes <<<"$sel_s"
  nd=$(grep -oE 'Nd = [0-9]+ meets' sel$tag.err | grep -oE '[0-9]+')
  dofs=$(grep -oE '[0-9]+ dofs' est$tag.txt | head -1 | grep -oE '[0-9]+')
  loop=$(echo "$t_sel - $t_ext" | bc -l)
  permode=$(echo "if ($nmodes > 0) $t_ext / $nmodes else 0" | bc -l)
  printf '%-6s %8s %9.2f %9.3f %9.1f%% %9.2f %8.1fx %8s %8s %10.3f %12s\n' "rod$tag" "$dofs" "$t_fe2cb" "$t_est" \
    "$(echo "100 * $t_est / $t_fe2cb" | bc -l)" "$t_exact" "$(echo "$t_exact / $t_est" | bc -l)" "$nd" "$iters" \
    "$loop" "$(printf '%.3f' "$permode")"
  echo "  rod$tag: selection loop $(printf '%.4f' "$(echo "$loop / $iters" | bc -l)") s per iteration (one rank-one downdate + reduced eigensolution), extensions $ncall calls for $nmodes modes, $(printf '%.2f' "$t_ext") s"
  grep "time:" est$tag.err | sed "s/^/  rod$tag estimate: /"
  grep "modes with exact error" exact$tag.txt | sed "s/^/  rod$tag bounds: /"
  if [ "$tag" = 50k ]; then
    # peer: scipy shift-invert Lanczos for the same number of full eigenpairs as --exact
    "$PYTHON" - rod$tag.fe.h5 "$(($(tail -n +2 exact$tag.csv | wc -l) + 6))" <<'EOF'
import sys, time, h5py, numpy as np, scipy.sparse as sp, scipy.sparse.linalg as spl
with h5py.File(sys.argv[1], "r") as f:
    csr = lambda g: sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
    K, M = csr(f["K"]), csr(f["M"])
t = time.time()
w = spl.eigsh(K.tocsc(), k=int(sys.argv[2]), M=M.tocsc(), sigma=-1e5, which="LM")[0]
print("  peer: scipy eigsh (SuperLU shift-invert) for %s eigenpairs of the full body: %.2f s" % (sys.argv[2], time.time() - t))
EOF
  fi
done
