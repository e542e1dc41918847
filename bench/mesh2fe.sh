#!/bin/bash
# bench/mesh2fe.sh: mesh2fe assembly time and peak memory for tet10 bodies of ~100 k dofs (and
# ~1 M dofs with BENCH_LARGE=1), beside the size of the two CSR matrices, and side by side with
# a peer in the same run.
#
# Body: the rod of examples/geometry/rod.geo (L = 0.3 m, R = 15 mm), tet10, free-free.
# Meshing is measured apart from assembly: gmsh (its own command line) meshes to a .msh first,
# then `mesh2fe rod.msh -v` reads it (its "meshing" line is then the .msh read), assembles K and
# M ("assembly" line) and writes the file ("writing" line); /usr/bin/time -v gives its peak
# resident memory (max RSS), compared with the bytes of the two CSR matrices
# (2 x (nnz x (8 + 8) + (ndof + 1) x 8)). Aims (issue 2): 1 M dofs assembled in < 10 s on one
# core, peak memory < 2.5 x the CSR size.
#
# Peer: scipy. The same element matrices (tet10, isoparametric, 4-point stiffness rule,
# 14-point degree-5 mass rule, written here independently in numpy, vectorised over elements in
# chunks of 20 000) assembled by scipy.sparse coo -> csr, the usual way to assemble in Python.
# It does the same arithmetic as mesh2fe's assembly on the same mesh (and its K and M are
# checked against mesh2fe's, so the comparison is of equal work). ccx would be a peer too, but
# its assembly cannot be timed apart from its solver; gmsh's meshing time is printed as the
# reference for the meshing step.
#
# Measured 2026-11-22 (2-core machine shared with other jobs: CPU seconds are the reliable
# figures; BUILD=build-mesh2fe BENCH_LARGE=1 bash bench/mesh2fe.sh):
#   dofs     nnz(K)  CSR MB | gmsh mesh | .msh read | assembly cpu (wall) | max RSS     | scipy cpu, RSS
#   105684   8.27 M   254   |   2.6 s   |  0.2 s    |  1.0 s (1.6 s)      | 348 MB 1.37x | 6.0 s, 1.2 GB
#   946464  78.2 M   2402   |  26.6 s   |  3.5 s    | 12.1 s (25.9 s)     | 2.78 GB 1.15x | 53.4 s, 5.6 GB
# mesh2fe assembles in 0.17-0.23 of scipy's CPU time with a third (100 k) to a half (1 M) of its
# memory; K and M agree with scipy's to 5e-11 of max|K|. The 1 M-dof assembly is 12 s of CPU
# against the 10 s aim; the memory aim (< 2.5x CSR) is met.
# 2026-11-24, after M shares K's pattern (bench/README.md has the runs): 946464 dofs assembled
# in 8.7-10.3 s cpu (the 11-22 binary 11.1-11.9 s in the same runs), max RSS 2184 MB = 0.91x;
# 105684 dofs 0.47 s cpu, 285 MB = 1.12x; scipy 53.2 s cpu (1 M) and 4.9 s cpu (100 k).
# 2026-11-24, after the set-wise element loop (bench/README.md, "The element loop set by set"):
# 946464 dofs 5.4-9.7 s cpu in 11 runs, mean 7.7 (main 8.7-11.8 s, mean 10.3, same runs), 0.91x.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
EXE="$ROOT/$BUILD/bin/mesh2fe"
W="${BENCH_OUT:-$ROOT/$BUILD/bench}/mesh2fe"
mkdir -p "$W" && cd "$W" || exit 1
export OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1
[ -x "$EXE" ] || { echo "no $EXE (make BUILD=$BUILD first)"; exit 1; }

# size label, element size h (m): 3.6 mm gives ~100 k dofs, 1.65 mm ~1 M dofs
cases=("100k 0.0036")
[ "${BENCH_LARGE:-0}" = 1 ] && cases+=("1M 0.00165")

cat >peer.py <<'EOF'
"""scipy peer: tet10 K and M from /mesh of an fmbd-fe file, assembled with coo -> csr."""
import sys, time
import h5py, numpy as np, scipy.sparse as sp
f = h5py.File(sys.argv[1], "r")
X = f["mesh/nodes"][()]
T = f["mesh/elements/tet10"][()]
E, nu, rho = (f["material"].attrs[k] for k in ("E", "nu", "rho"))
t0, c0 = time.perf_counter(), time.process_time()
lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
D = np.zeros((6, 6)); D[:3, :3] = lam; D[range(3), range(3)] += 2 * mu; D[range(3, 6), range(3, 6)] = mu
edges = [(0, 1), (1, 2), (0, 2), (0, 3), (2, 3), (1, 3)]
dL = np.array([[-1, -1, -1], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
def shape(p):
    L = np.array([1 - sum(p), *p]); N = np.zeros(10); dN = np.zeros((10, 3))
    for a in range(4): N[a] = L[a] * (2 * L[a] - 1); dN[a] = (4 * L[a] - 1) * dL[a]
    for e, (a, b) in enumerate(edges): N[4 + e] = 4 * L[a] * L[b]; dN[4 + e] = 4 * (dL[a] * L[b] + L[a] * dL[b])
    return N, dN
a, b = 0.1381966011250105, 0.5854101966249685
q2 = [((a, a, a), 1 / 24), ((b, a, a), 1 / 24), ((a, b, a), 1 / 24), ((a, a, b), 1 / 24)]
# Keast-type degree-5 rule with 14 points (weights sum to 1/6)
a1, w1 = 0.0927352503108912, 0.01224884051939366
a2, w2 = 0.3108859192633006, 0.01878132095300264
b3, w3 = 0.0455037041256496, 0.007091003462846911
q5 = []
for aa, ww in ((a1, w1), (a2, w2)):
    c = 1 - 3 * aa
    q5 += [((aa, aa, aa), ww), ((c, aa, aa), ww), ((aa, c, aa), ww), ((aa, aa, c), ww)]
d3 = 0.5 - b3
q5 += [(p, w3) for p in ((b3, d3, d3), (d3, b3, d3), (d3, d3, b3), (b3, b3, d3), (b3, d3, b3), (d3, b3, b3))]
S2 = [(w, *shape(np.array(p))) for p, w in q2]
S5 = [(w, *shape(np.array(p))) for p, w in q5]
nd = 3 * X.shape[0]
K = sp.csr_matrix((nd, nd)); M = sp.csr_matrix((nd, nd))
for s0 in range(0, len(T), 20000):
    Tc = T[s0:s0 + 20000]; ne = len(Tc); xe = X[Tc]
    Ke = np.zeros((ne, 30, 30)); Me = np.zeros((ne, 10, 10))
    for w, N, dN in S2:
        J = np.einsum("ak,eaj->ekj", dN, xe)
        g = np.einsum("ejk,ak->eaj", np.linalg.inv(J), dN)
        B = np.zeros((ne, 6, 30))
        B[:, 0, 0::3] = g[:, :, 0]; B[:, 1, 1::3] = g[:, :, 1]; B[:, 2, 2::3] = g[:, :, 2]
        B[:, 3, 0::3] = g[:, :, 1]; B[:, 3, 1::3] = g[:, :, 0]
        B[:, 4, 1::3] = g[:, :, 2]; B[:, 4, 2::3] = g[:, :, 1]
        B[:, 5, 2::3] = g[:, :, 0]; B[:, 5, 0::3] = g[:, :, 2]
        DB = np.einsum("ij,ejb->eib", D, B)
        Ke += np.einsum("e,eia,eib->eab", w * np.linalg.det(J), B, DB)
    for w, N, dN in S5:
        J = np.einsum("ak,eaj->ekj", dN, xe)
        Me += np.einsum("e,a,b->eab", w * rho * np.linalg.det(J), N, N)
    dofs = (3 * Tc[:, :, None] + np.arange(3)).reshape(ne, 30)
    r = np.repeat(dofs, 30, axis=1).ravel(); c = np.tile(dofs, (1, 30)).ravel()
    K = K + sp.coo_matrix((Ke.ravel(), (r, c)), shape=(nd, nd)).tocsr()
    M3 = np.einsum("eab,ij->eaibj", Me, np.eye(3)).reshape(ne, 30, 30)
    M = M + sp.coo_matrix((M3.ravel(), (r, c)), shape=(nd, nd)).tocsr()
t, tc = time.perf_counter() - t0, time.process_time() - c0
def csr(g): return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
Kf, Mf = csr(f["K"]), csr(f["M"])
dk = abs(Kf - K).max() / abs(K).max() if Kf.shape == K.shape else float("nan")
dm = abs(Mf - M).max() / abs(M).max() if Mf.shape == M.shape else float("nan")
print("scipy assembly %.3f s wall, %.3f s cpu  nnz(K) %d  max|K_mesh2fe - K_scipy|/max|K| %.1e  (M: %.1e)" % (t, tc, K.nnz, dk, dm))
EOF

printf '%-5s %8s %9s %7s | %7s %7s %7s %7s %7s | %8s %7s | %7s %7s %8s | %6s\n' \
  case dofs nnz CSR_MB gmsh_s read_s asm_s asm_cpu write_s maxRSS_MB RSS/CSR sp_s sp_cpu sp_MB cpu/sp
for c in "${cases[@]}"; do
  read -r label h <<<"$c"
  printf 'Merge "%s";\nMesh.MeshSizeMin = %s;\nMesh.MeshSizeMax = %s;\n' "$ROOT/examples/geometry/rod.geo" "$h" "$h" >rod_$label.geo
  t0=$(date +%s.%N)
  gmsh -3 -order 2 -format msh4 rod_$label.geo -o rod_$label.msh >gmsh_$label.log 2>&1 || { echo "gmsh failed"; exit 1; }
  t_gmsh=$(echo "$(date +%s.%N) - $t0" | bc)
  /usr/bin/time -v "$EXE" rod_$label.msh -v -o rod_$label.fe.h5 >/dev/null 2>m2f_$label.log || { cat m2f_$label.log; exit 1; }
  t_read=$(sed -n 's/.*groups, meshing \([0-9.]*\) s wall.*/\1/p' m2f_$label.log)
  t_asm=$(sed -n 's/.*assembly \([0-9.]*\) s wall.*/\1/p' m2f_$label.log)
  c_asm=$(sed -n 's/.*assembly .* s wall, \([0-9.]*\) s cpu.*/\1/p' m2f_$label.log)
  ndof=$(sed -n 's/.*assembly .* s cpu: \([0-9]*\) dofs.*/\1/p' m2f_$label.log)
  nnz=$(sed -n 's/.*nnz(K) \([0-9]*\),.*/\1/p' m2f_$label.log)
  t_write=$(sed -n 's/.*writing \([0-9.]*\) s wall.*/\1/p' m2f_$label.log)
  rss_kb=$(sed -n 's/.*Maximum resident set size (kbytes): //p' m2f_$label.log)
  csr_mb=$(echo "scale=1; 2 * ($nnz * 16 + ($ndof + 1) * 8) / 1048576" | bc)
  rss_mb=$(echo "scale=1; $rss_kb / 1024" | bc)
  ratio=$(echo "scale=2; $rss_mb / $csr_mb" | bc)
  /usr/bin/time -v "$PYTHON" peer.py rod_$label.fe.h5 >peer_$label.log 2>peer_$label.time || { cat peer_$label.log peer_$label.time; exit 1; }
  t_sp=$(sed -n 's/^scipy assembly \([0-9.]*\) s wall.*/\1/p' peer_$label.log)
  c_sp=$(sed -n 's/^scipy assembly .* s wall, \([0-9.]*\) s cpu.*/\1/p' peer_$label.log)
  sp_mb=$(echo "scale=1; $(sed -n 's/.*Maximum resident set size (kbytes): //p' peer_$label.time) / 1024" | bc)
  speed=$(echo "scale=3; $c_asm / $c_sp" | bc)
  printf '%-5s %8s %9s %7s | %7.2f %7s %7s %7s %7s | %8s %7s | %7s %7s %8s | %6.3f\n' \
    "$label" "$ndof" "$nnz" "$csr_mb" "$t_gmsh" "$t_read" "$t_asm" "$c_asm" "$t_write" "$rss_mb" "$ratio" "$t_sp" "$c_sp" "$sp_mb" "$speed"
  sed 's/^/      peer: /' peer_$label.log
  grep '^mesh2fe: rod' m2f_$label.log | sed 's/^/      /'
  rm -f rod_$label.fe.h5
done
echo "columns: gmsh_s = gmsh -3 -order 2 meshing (its command line, wall); read_s = mesh2fe reading the"
echo ".msh (wall); asm_s / asm_cpu = mesh2fe assembly of K and M (+ dof map, expand, body properties),"
echo "wall and CPU seconds; write_s = writing the file (wall); maxRSS = mesh2fe peak memory (read +"
echo "assembly + write); CSR_MB = both matrices; sp_* = the scipy peer; cpu/sp = mesh2fe assembly CPU"
echo "time / scipy assembly CPU time (CPU, not wall: the machine may be shared)"
