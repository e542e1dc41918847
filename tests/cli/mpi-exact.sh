#!/bin/bash
# tests/cli/mpi-exact.sh: cbcheck-mpi, cbcheck with the --exact eigensolution on MPI processes
# (SLEPc Krylov-Schur, MUMPS factor and inertia), against the serial cbcheck --exact and scipy on
# a small free tet10 bracket (examples/batch/bracket.geo, about 3,500 dofs, 6 rigid-body modes):
# under `mpirun -np 2` and on one process without mpirun the report is cbcheck's, the CSV equal
# to the serial one but for the exact column, whose eigenvalues agree to 1e-10 relative; the
# bracket clamped (shift 0, no rigid-body modes) to the round-off of its stiffer pencil.
# Exit 77 (SKIP, loudly) only where MPI or PETSc/SLEPc is absent (make check installs them).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export PATH="$ROOT/$BUILD/bin:$PATH"
if ! command -v mpirun > /dev/null || [ ! -x "$ROOT/$BUILD/bin/cbcheck-mpi" ]; then
  echo "SKIP: no mpirun or no $BUILD/bin/cbcheck-mpi (PETSc/SLEPc/OpenMPI not installed: run make deps)"
  exit 77
fi
T=$ROOT/$BUILD/test-tmp/cli-mpi-exact
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }
MPIRUN=(mpirun --allow-run-as-root --oversubscribe)
export ASAN_OPTIONS=${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_leaks=0  # OpenMPI's allocations at exit
export OMPI_MCA_btl_vader_single_copy_mechanism=none

ldd "$ROOT/$BUILD/bin/cbcheck" | grep -q 'libmpi' && bad "cbcheck links MPI"
ldd "$ROOT/$BUILD/bin/cbcheck-mpi" | grep -q 'libmpi' || bad "cbcheck-mpi does not link MPI"

# the body of tests/cli/mpi.sh: free (two interfaces, no clamp), not symmetric
{ echo 'L = 0.05; W = 0.02; H = 0.03; T = 0.004; R = 0.004; h = 0.008;'
  cat "$ROOT/examples/batch/bracket.geo"; } > br.geo
mesh2fe br.geo -q --interface hole:rbe2 --interface top:rbe3 -o br.fe.h5 || { echo "FAIL: mesh2fe"; exit 1; }
fe2cb br.fe.h5 -q --modes 12 -o br.cb.h5 || { echo "FAIL: fe2cb"; exit 1; }
cbcheck br.cb.h5 --exact --range 8 --csv s.csv > s.txt 2> s.err || bad "serial cbcheck --exact: $(cat s.err)"
"${MPIRUN[@]}" -np 2 cbcheck-mpi br.cb.h5 --exact --range 8 --csv p2.csv -v > p2.txt 2> p2.err \
  || bad "mpirun -np 2 cbcheck-mpi --exact failed: $(tail -5 p2.err)"
cbcheck-mpi br.cb.h5 --exact --range 8 --csv p1.csv > p1.txt 2> p1.err \
  || bad "cbcheck-mpi on one process (no mpirun) failed: $(tail -5 p1.err)"
grep -q 'cbcheck-mpi: exact eigenvalues on 2 processes: 14 pairs, .* Sturm count 14 below' p2.err \
  || bad "no Sturm count of the 14 pairs (6 rigid + 8 flexible) on 2 processes: $(cat p2.err)"
grep -q '^cbcheck-mpi: br.cb.h5: estimates of 8 flexible modes at Nd = 12, .* s wall' p2.err \
  || bad "no summary line of cbcheck-mpi: $(cat p2.err)"
[ "$(grep -c 'estimates of 8 flexible modes' p2.err)" -eq 1 ] || bad "the summary printed by more than process 0"
# the report (standard output) is cbcheck's, to the character: the exact column is printed
# with 4 digits, far coarser than the agreement of the eigenvalues checked below
cmp -s s.txt p2.txt || bad "report of -np 2 differs from cbcheck's: $(diff s.txt p2.txt | head)"
cmp -s s.txt p1.txt || bad "report of one process differs from cbcheck's: $(diff s.txt p1.txt | head)"

"$PYTHON" - s.csv p2.csv p1.csv br.fe.h5 br.cb.h5 <<'PY' || fail=1
import csv, sys
import h5py, numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
ok = True
def check(c, msg):
    global ok
    print(("ok   " if c else "FAIL ") + msg)
    ok = ok and bool(c)
rows = lambda f: list(csv.DictReader(open(f)))
s = rows(sys.argv[1])
fe = h5py.File(sys.argv[4], "r")
def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
K, M = csr(fe["K"]), csr(fe["M"])
nrig = int(h5py.File(sys.argv[5], "r")["cb"].attrs["n_rigid"])
# chi from the CSV: exact = chibar / chi - 1, chibar = the eigenvalue column (both %.10e: the
# recovered chi carries 5e-11 relative of printing, hence the 2e-10 against scipy below)
chi = lambda r: np.array([float(x["eigenvalue"]) / (1 + float(x["exact"])) for x in r])
# scipy, independent of both: shift-invert Lanczos (ARPACK) at a negative shift below the
# rigid-body modes, to machine precision (tol 0)
lam = np.sort(sla.eigsh(K.tocsc(), k=nrig + len(s), M=M.tocsc(), sigma=-0.5 * chi(s)[0],
                        which="LM", tol=0)[0])[nrig:]
# why 1e-10 is a fair figure: each pair converges to a relative residual r (both programs
# check r <= 1e-6; here ~1e-9 and below), and the Rayleigh quotient's error is of order r^2
# (symmetric pencil), far below 1e-10; what remains is round-off, whose worst case, eps times
# the pencil's condition max_i K_ii/M_ii over the first flexible eigenvalue, is printed: a bound
# for an eigenvector concentrated on one dof, where the smooth low modes of a structure spread
# over thousands of dofs and average the round-off out (observed 1e-11 on this body)
cond = (K.diagonal() / M.diagonal()).max() / lam[0]
print(f"worst-case round-off eps cond = {np.finfo(float).eps * cond:.2e} (pencil condition {cond:.3g})")
e = np.max(np.abs(chi(s) - lam) / lam)
check(e <= 2e-10, f"serial cbcheck --exact against scipy: {e:.2e} relative (<= 2e-10)")
for name in sys.argv[2:4]:
    p = rows(name)
    check(len(p) == len(s), f"{name}: {len(p)} modes")
    same = all(a[k] == b[k] for a, b in zip(s, p) for k in a if k != "exact")
    check(same, f"{name}: every column but exact equal to the serial CSV")
    # exact = chibar/chi - 1 in both: a relative difference d of chi moves it by (1 + exact) d;
    # the 11 printed digits of exact add |exact| 1e-10 at most
    d = max(abs(float(a["exact"]) - float(b["exact"])) / (1 + float(a["exact"]))
            - 1e-10 * abs(float(a["exact"])) for a, b in zip(s, p))
    check(d <= 1e-10, f"{name}: eigenvalues equal to the serial ones to {max(d, 0):.2e} relative (<= 1e-10)")
    e = np.max(np.abs(chi(p) - lam) / lam)
    check(e <= 2e-10, f"{name}: against scipy {e:.2e} relative (<= 2e-10)")
sys.exit(0 if ok else 1)
PY

# --- the same bracket clamped at its bore: no rigid-body mode, so the shift is 0 (K positive
# definite) and no first pass; a stiffer pencil (condition ~7e6), whose eigenvalues no solver
# gets to 1e-10: scipy's eigsh and LAPACK's dense eigh differ by 4.5e-10 on it ---
mesh2fe br.geo -q --clamp hole --interface top:rbe3 -o cl.fe.h5 || { echo "FAIL: mesh2fe clamped"; exit 1; }
fe2cb cl.fe.h5 -q --modes 12 -o cl.cb.h5 || { echo "FAIL: fe2cb clamped"; exit 1; }
cbcheck cl.cb.h5 --exact --range 6 --csv cls.csv > cls.txt 2> cls.err || bad "serial cbcheck --exact, clamped: $(cat cls.err)"
"${MPIRUN[@]}" -np 2 cbcheck-mpi cl.cb.h5 --exact --range 6 --csv clp.csv -v > clp.txt 2> clp.err \
  || bad "mpirun -np 2 cbcheck-mpi --exact, clamped: $(tail -5 clp.err)"
grep -q 'exact eigenvalues on 2 processes: 6 pairs, shift 0, .* Sturm count 6 below' clp.err \
  || bad "clamped: no shift 0 and Sturm count 6: $(grep exact clp.err)"
cmp -s cls.txt clp.txt || bad "clamped: report differs from cbcheck's: $(diff cls.txt clp.txt | head)"
"$PYTHON" - cls.csv clp.csv cl.fe.h5 <<'PY' || fail=1
import csv, sys
import h5py, numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
fe = h5py.File(sys.argv[3], "r")
def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))
K, M = csr(fe["K"]), csr(fe["M"])
chi = lambda f: np.array([float(x["eigenvalue"]) / (1 + float(x["exact"])) for x in csv.DictReader(open(f))])
s, p = chi(sys.argv[1]), chi(sys.argv[2])
lam = np.sort(sla.eigsh(K.tocsc(), k=len(s), M=M.tocsc(), sigma=0, which="LM", tol=0)[0])
# the round-off scale of this pencil (see above): eps max_i K_ii/M_ii / chi_1, here 1.5e-9
tol = np.finfo(float).eps * (K.diagonal() / M.diagonal()).max() / lam[0]
e, es = np.max(np.abs(p - s) / s), np.max(np.abs(p - lam) / lam)
print(f"clamped: eigenvalues to {e:.2e} of the serial ones, {es:.2e} of scipy's (<= eps cond = {tol:.2e})")
sys.exit(0 if e <= tol and es <= tol else 1)
PY

# --- cbcheck's errors, one message from process 0, and cbcheck-mpi's help and name ---
"${MPIRUN[@]}" -np 2 cbcheck-mpi missing.cb.h5 --exact > out.txt 2>&1
[ $? -ne 0 ] || bad "missing input: exit 0"
[ "$(grep -c 'cbcheck-mpi: error: .*missing.cb.h5' out.txt)" -eq 1 ] || bad "missing input: not one message naming it: $(cat out.txt)"
cbcheck-mpi --help | grep -q 'cbcheck-mpi: --exact on MPI processes' || bad "--help does not say what cbcheck-mpi is"
cbcheck-mpi --no-such-option > /dev/null 2>&1
[ $? -eq 2 ] || bad "--no-such-option: not exit 2"
exit $fail
