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
# bases, not of the FE models: hence the second family.
# Second family (BENCH_FAMILY="chain fe", the default, runs both; "fe" or "chain" one): the
# spatial slider-crank (examples/spatial-slidercrank/) with its rod a full tet10 .fe.h5 body
# meshed at BENCH_FE_SIZES mm (default 8 6; BENCH_LARGE=1: 8 6 4 3; 2.5 and 2 take minutes and
# 4-15 GB, bench/README.md), gmsolve --modes 20 --matrices. Peer: scipy eigsh in shift-invert
# mode on the bordered pencil ([K Cq'; Cq 0], diag(M, 0)) from /linear, which needs no null
# space (SuperLU factors the bordered matrix); skipped above BENCH_FE_PEER_MAX coordinates
# (default 400000). Peak RSS of both by /usr/bin/time. build_s is the build stage's wall time,
# build_cpu_s its CPU and init_cpu_s fmbd_mbs_init's share (gmsolve -v).
set -u
family=${BENCH_FAMILY:-chain fe}
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
case " $family " in *" chain "*) ;; *) sizes="" ;; esac
[ -n "$sizes" ] && printf '%6s %7s %7s %9s %10s %9s %9s %9s %9s %8s %10s %9s\n' nb coords eqs nnz_Z gm_cpu_s null_s proj_s eig_s rss_MB peer_s peer/gm max_rel_diff
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

case " $family " in *" fe "*) ;; *) exit 0 ;; esac
EX=$ROOT/examples/spatial-slidercrank
fesizes=${BENCH_FE_SIZES:-"8 6"}
[ "${BENCH_LARGE:-0}" = 1 ] && [ -z "${BENCH_FE_SIZES:-}" ] && fesizes="8 6 4 3"
m2f=$(sed -nE 's/^ *mesh2fe: *(.*)/\1/p' "$EX/spatial-slidercrank.yaml" | sed -E 's/--size +[^ ]+//')
echo "spatial slider-crank, rod a full tet10 .fe.h5 body (mesh2fe $m2f --size H), gmsolve --modes 20"
printf '%6s %8s %4s %9s %10s %9s %11s %10s %9s %9s %9s %9s %10s %8s %9s %9s\n' h_mm coords eqs nnz_Z gm_cpu_s build_s build_cpu_s init_cpu_s null_s proj_s eig_s rss_MB peer_cpu_s peer_MB peer/gm max_rel_diff
for h in $fesizes; do
  size=$(echo "$h / 1000" | bc -l)
  fe=rod$h.fe.h5
  [ -f "$fe" ] || mesh2fe "$EX/rod.geo" $m2f --size "$size" -o "$fe" -q || { echo "mesh2fe failed (h = $h mm)"; exit 1; }
  PYTHONPATH=$EX "$PYTHON" -c "
import sys, gmtable
open('fe$h.yaml', 'w').write(gmtable.scene_variant(open('$EX/spatial-slidercrank.yaml').read(), 'file: $fe', 0.01))
" || exit 1
  /usr/bin/time -f "%M" -o rssfe$h.txt gmsolve fe$h.yaml --modes 20 --matrices -v -o fe$h.gm.h5 2> gmfe$h.err \
    || { echo "gmsolve failed (h = $h mm)"; cat gmfe$h.err; exit 1; }
  cpu=$(grep -oE '[0-9.e+-]+ s cpu' gmfe$h.err | tail -1 | cut -d' ' -f1)
  line=$(grep "time: build" gmfe$h.err)
  tbuild=$(sed -E 's/.*linearise ([0-9.e+-]+) s.*/\1/' <<<"$line")
  cbuild=$(sed -E 's/.*\(cpu ([0-9.e+-]+) s.*/\1/' <<<"$line")
  cinit=$(sed -E 's/.*fmbd_mbs_init ([0-9.e+-]+) s.*/\1/' <<<"$line")
  tnull=$(sed -E 's/.*null space ([0-9.e+-]+) s.*/\1/' <<<"$line")
  tproj=$(sed -E 's/.*projection ([0-9.e+-]+) s.*/\1/' <<<"$line")
  teig=$(sed -E 's/.*eigensolution ([0-9.e+-]+) s.*/\1/' <<<"$line")
  nz=$(grep -oE 'with [0-9]+ entries in Z' gmfe$h.err | grep -oE '[0-9]+')
  rss=$(($(tail -1 rssfe$h.txt) / 1024))
  # The peer: eigsh(A, k, B, sigma) with A = [K Cq'; Cq 0], B = diag(M, 0) (positive semi-
  # definite: shift-invert mode allows it). The multiplier rows and the constrained directions
  # are infinite eigenvalues of the pencil, which shift-invert maps to 0 and never returns; the
  # f zero (rigid-reference) eigenvalues and the 20 flexible ones are the f + 20 nearest the
  # shift sigma = -w0^2, w0 = 2 pi 10 Hz (below every flexible one, away from the zeros).
  /usr/bin/time -f "%M" -o rsspeer$h.txt "$PYTHON" - fe$h.gm.h5 "${BENCH_FE_PEER_MAX:-400000}" > peer$h.txt <<'PY' || { echo "peer failed (h = $h mm)"; exit 1; }
import sys, time, h5py, numpy as np, scipy.sparse as sp, scipy.sparse.linalg as sla
f = h5py.File(sys.argv[1], "r")
csr = lambda g: sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
M, K, C = (csr(f["linear/" + k]) for k in ("M", "K", "Cq"))
got, fz = f["global/eigenvalue"][()], int(f["global"].attrs["f"])
n, m = M.shape[0], C.shape[0]
if n > int(sys.argv[2]):
    print("%d %d - -" % (n, m)); sys.exit(0)
c = time.process_time()
# Cq scaled to K's largest diagonal entry (the same finite eigenvalues): unscaled, the bordered
# matrix mixes rows of 1 and 1e10 and SuperLU's solution lost 1e-7 of relative accuracy (6 k dofs)
C = C * (abs(K.diagonal()).max() / abs(C).max())
A = sp.bmat([[K, C.T], [C, None]], format="csc")
B = sp.bmat([[M, None], [None, sp.csr_matrix((m, m))]], format="csc")
sigma = -(2 * np.pi * 10) ** 2
# eigsh's own OPinv would be SuperLU with COLAMD (unsymmetric ordering); minimum degree on A + A'
# keeps the fill of the symmetric bordered matrix far lower: same solver, better ordering
lu = sla.splu((A - sigma * B).tocsc(), permc_spec="MMD_AT_PLUS_A")
op = sla.LinearOperator(A.shape, matvec=lu.solve, dtype=float)
w = np.sort(sla.eigsh(A, k=fz + len(got), M=B, sigma=sigma, which="LM", OPinv=op, return_eigenvectors=False))
c = time.process_time() - c
print("%d %d %.2f %.1e" % (n, m, c, np.max(np.abs(w[fz:] / got - 1))))
PY
  read -r n m pc diff < peer$h.txt
  prss=$(($(tail -1 rsspeer$h.txt) / 1024))
  [ "$pc" = - ] && prss=- ratio=- || ratio=$(echo "$pc / $cpu" | bc -l | xargs printf "%.1f")
  printf '%6s %8s %4s %9s %10s %9s %11s %10s %9s %9s %9s %9s %10s %8s %9s %9s\n' "$h" "$n" "$m" "$nz" "$cpu" "$tbuild" "$cbuild" "$cinit" "$tnull" "$tproj" \
    "$teig" "$rss" "$pc" "$prss" "$ratio" "$diff"
done
