#!/bin/bash
# bench/gmsolve.sh: the cost of gmsolve's global eigensolution against the size of the
# mechanism, with scipy side by side on the same matrices as the peer.
# Mechanism: a planar chain of nb flexible beams (tests/py/fegen.py, 8 Euler-Bernoulli elements,
# 0.2 m, radius 0.02 m,
# reduced by fe2cb --modes 6: 12 flexible modes each) on revolute joints about z, the first to
# ground: n = 19 nb coordinates, m = 6 nb equations (5 per joint, 1 normalisation per body),
# null space 13 nb, mobility nb. gmsolve --modes 20 --matrices; the peer reads /linear (M, K, Cq)
# and solves the same constrained problem densely: scipy.linalg.null_space (SVD) + eigh of the
# projected pencil (all eigenvalues: the dense way scipy offers). Reported: CPU seconds (the
# summary line), gmsolve's stages (-v), peak RSS (/usr/bin/time), the peer's CPU, and the
# largest relative difference of the 20 flexible eigenvalues. Ratios are reported, never asserted.
# BENCH_SIZES="nb ..." picks the chain lengths (default 4 8 16 32; BENCH_LARGE=1 adds 48). Longer
# chains (64 links) have a first bending mode below 1e-11 of the stiffest element's, which gmsolve
# cannot tell from the spurious zero of a singular configuration (and refuses): this mechanism
# family cannot grow further, and with modal bodies the mechanism's size is that of its modal
# bases, not of the FE models (full .fe.h5 bodies are not in the multibody core yet).
set -u
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/gmsolve
mkdir -p "$OUT" && cd "$OUT" || exit 1
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
sizes=${BENCH_SIZES:-"4 8 16 32"}
[ "${BENCH_LARGE:-0}" = 1 ] && [ -z "${BENCH_SIZES:-}" ] && sizes="$sizes 48"
PYTHONPATH=$ROOT/tests/py "$PYTHON" -c "
import fegen
fegen.write('beam.fe.h5', fegen.beam(n_el=8, length=0.2, radius=0.02, interfaces={'end0': [0], 'end1': [8]}))
" || exit 1
fe2cb beam.fe.h5 --modes 6 -o beam.cb.h5 -q || exit 1
printf '%6s %7s %7s %9s %10s %9s %9s %9s %9s %8s %10s %9s\n' nb coords eqs nnz_Z gm_cpu_s null_s proj_s eig_s rss_MB peer_s peer/gm max_rel_diff
for nb in $sizes; do
  "$PYTHON" - "$nb" <<'PY' > chain$nb.yaml
import sys
nb = int(sys.argv[1])
print("title: chain of %d flexible beams\nsolver: {t_end: 0.01}\nbodies:" % nb)
for i in range(nb):
    print("  - {name: b%d, type: flexible, file: beam.cb.h5, position: [%g, 0, 0]}" % (i, 0.2 * i))
print("joints:\n  - {name: j0, type: revolute, body1: ground, body2: b0, point: [0, 0, 0], axis: z, at2: {interface: end0}}")
for i in range(1, nb):
    print("  - {name: j%d, type: revolute, body1: b%d, body2: b%d, point: [%g, 0, 0], axis: z, "
          "at1: {interface: end1}, at2: {interface: end0}}" % (i, i - 1, i, 0.2 * i))
PY
  /usr/bin/time -f "%M" -o rss$nb.txt gmsolve chain$nb.yaml --modes 20 --matrices -v -o chain$nb.gm.h5 2> gm$nb.err \
    || { echo "gmsolve failed (nb = $nb)"; cat gm$nb.err; exit 1; }
  cpu=$(grep -oE '[0-9.e+-]+ s cpu' gm$nb.err | tail -1 | cut -d' ' -f1)
  line=$(grep "time: build" gm$nb.err)
  tnull=$(sed -E 's/.*null space ([0-9.e+-]+) s.*/\1/' <<<"$line")
  tproj=$(sed -E 's/.*projection ([0-9.e+-]+) s.*/\1/' <<<"$line")
  teig=$(sed -E 's/.*eigensolution ([0-9.e+-]+) s.*/\1/' <<<"$line")
  nz=$(grep -oE 'with [0-9]+ entries in Z' gm$nb.err | grep -oE '[0-9]+')
  rss=$(($(tail -1 rss$nb.txt) / 1024))
  peer=$("$PYTHON" - chain$nb.gm.h5 "$nb" <<'PY'
import sys, time, h5py, numpy as np, scipy.linalg as sl, scipy.sparse as sp
f = h5py.File(sys.argv[1], "r")
csr = lambda g: sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
M, K, C = (csr(f["linear/" + k]) for k in ("M", "K", "Cq"))
got, fz = f["global/eigenvalue"][()], int(f["global"].attrs["f"])
n, m = M.shape[0], C.shape[0]
if int(sys.argv[2]) > 128:
    print("%d %d - - -" % (n, m)); sys.exit(0)
c = time.process_time()
N = sl.null_space(C.toarray())
w = sl.eigh(N.T @ (K @ N), N.T @ (M @ N), eigvals_only=True)
c = time.process_time() - c
print("%d %d %.3f %.1e" % (n, m, c, np.max(np.abs(w[fz:fz + len(got)] / got - 1))))
PY
)
  read -r n m pc diff <<<"$peer"
  ratio=$( [ "$pc" = - ] && echo - || echo "$pc / $cpu" | bc -l | xargs printf "%.1f")
  printf '%6s %7s %7s %9s %10s %9s %9s %9s %9s %8s %10s %9s\n' "$nb" "$n" "$m" "$nz" "$cpu" "$tnull" "$tproj" "$teig" \
    "$rss" "$pc" "$ratio" "$diff"
done
