#!/bin/bash
# tests/cli/fe2cb.sh: fe2cb on tiny bodies (tests/py/fegen.py): good runs, pipes, bad input.
# Every failing run must exit 1 (data) or 2 (usage), name fe2cb, the file and the HDF5 path or
# the dof at fault, and leave no output file (neither the target nor its .part).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export PATH="$ROOT/$BUILD/bin:$PATH"
T=$ROOT/$BUILD/test-tmp/cli-fe2cb
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }

# --- fixtures ---------------------------------------------------------------------------------
PYTHONPATH=$ROOT/tests/py "$PYTHON" - <<'PY' || exit 1
import h5py, numpy as np, fegen
b = fegen.beam(n_el=40, interfaces={"end0": [0], "end1": [40]})
a = fegen.write("good.fe.h5", b)
fegen.write("newer.fe.h5", b, format_version="2.0")
fegen.write("kind.fe.h5", b, fmt="fmbd-rflex")
K = a["K"].copy(); K.data[5] = np.nan
fegen.write("nan.fe.h5", b, K=K)
K = a["K"].tolil(); K[3, 10] = K[3, 10] + 1e6; K = K.tocsr()
fegen.write("nonsym.fe.h5", b, K=K)
# element 20 left out: nodes 21..39 float (held by nothing, end1 is not an interface here)
fl = fegen.beam(n_el=40, interfaces={"end0": [0]}, skip=(20,))
fegen.write("floating.fe.h5", fl)
small = fegen.lattice(nx=3, ny=2, nz=2, interfaces={"a": "x0"})
fegen.write("small.fe.h5", small)
# messages that used to mislead: each defect must be named as what it is
import shutil
def variant(name, edit):
    shutil.copy("good.fe.h5", name)
    with h5py.File(name, "r+") as f:
        edit(f)
variant("hugeshape.fe.h5", lambda f: f["K"].attrs.__setitem__("shape", np.array([2**40, 2**40], dtype=np.int64)))
def zero_mass(f):
    f["M/data"][...] = 0.0
variant("zeromass.fe.h5", zero_mass)
def bad_indptr(f):
    ip = f["K/indptr"][()]
    ip[5] = ip[7]
    f["K/indptr"][...] = ip
variant("indptr.fe.h5", bad_indptr)
variant("nodata.fe.h5", lambda f: f["K"].__delitem__("data"))
variant("emptyformat.fe.h5", lambda f: f.attrs.__setitem__("format", ""))
variant("ezero.fe.h5", lambda f: f["material"].attrs.__setitem__("E", 0.0))
variant("bodymass.fe.h5", lambda f: f["body"].attrs.__setitem__("mass", -1.0))
variant("inertia.fe.h5", lambda f: f["body"].attrs.__setitem__("inertia", -np.eye(3).ravel()))
PY
printf 'not an hdf5 file\n' > text.fe.h5

# expect_fail STATUS PATTERN OUTPUT -- args...: exit status, a regex the message must match
expect_fail() {
  local st=$1 pat=$2 out=$3; shift 4
  fe2cb "$@" > stdout.txt 2> stderr.txt
  local rc=$?
  [ $rc -eq "$st" ] || bad "fe2cb $*: exit $rc, expected $st ($(cat stderr.txt))"
  grep -q '^fe2cb: error: ' stderr.txt || bad "fe2cb $*: no 'fe2cb: error:' line: $(cat stderr.txt)"
  grep -Eq -e "$pat" stderr.txt || bad "fe2cb $*: message does not match /$pat/: $(cat stderr.txt)"
  [ -n "$out" ] && { [ -e "$out" ] || [ -e "$out.part" ]; } && bad "fe2cb $*: output $out left behind"
  head -n 1 stderr.txt  # the message, for the log
  return 0
}

# --- misleading messages, now named for what they are ------------------------------------------
expect_fail 1 'hugeshape\.fe\.h5:/K: shape \(1099511627776, 1099511627776\) does not match indptr' out11.cb.h5 -- hugeshape.fe.h5 -o out11.cb.h5
expect_fail 1 'zeromass\.fe\.h5:/M: the mass matrix is zero' out12.cb.h5 -- zeromass.fe.h5 -o out12.cb.h5
expect_fail 1 'indptr\.fe\.h5:/K: indptr: not monotone: entry 6' out13.cb.h5 -- indptr.fe.h5 -o out13.cb.h5
expect_fail 1 'nodata\.fe\.h5:/K/data: missing dataset' out14.cb.h5 -- nodata.fe.h5 -o out14.cb.h5
expect_fail 1 "emptyformat\.fe\.h5: the 'format' attribute is empty, expected fmbd-fe" out15.cb.h5 -- emptyformat.fe.h5 -o out15.cb.h5
expect_fail 1 'ezero\.fe\.h5:/material: E = 0 must be positive' out16.cb.h5 -- ezero.fe.h5 -o out16.cb.h5
expect_fail 1 'bodymass\.fe\.h5:/body: mass = -1 must be positive' out17.cb.h5 -- bodymass.fe.h5 -o out17.cb.h5
expect_fail 1 'inertia\.fe\.h5:/body: inertia is not physical' out18.cb.h5 -- inertia.fe.h5 -o out18.cb.h5

# --- good runs ----------------------------------------------------------------------------------
fe2cb good.fe.h5 -o good.cb.h5 --modes 6 -q 2> err.txt || bad "good run failed: $(cat err.txt)"
[ -s err.txt ] && bad "-q printed: $(cat err.txt)"
fe2cb good.fe.h5 -o good.cb.h5 --modes 6 2> err.txt || bad "good run failed"
grep -Eq '^fe2cb: good\.cb\.h5: 6 fixed-interface \+ 12 constraint modes, [0-9.]+ s wall, [0-9.]+ s cpu$' err.txt \
  || bad "summary line: $(cat err.txt)"
fe2cb good.fe.h5 -o v.cb.h5 --modes 6 -v 2> err.txt || bad "-v run failed"
grep -q 'ordering' err.txt && grep -q 'factorisation' err.txt && grep -q 'Lanczos' err.txt \
  && grep -q 'constraint modes' err.txt && grep -q 'projections' err.txt || bad "-v breakdown missing: $(cat err.txt)"
# the man page's example name rule: BODY.fe.h5 -> BODY.cb.h5 (stdout is a file here, so give -o)
# pipe: standard input to standard output
cat good.fe.h5 | fe2cb - --modes 4 -q > piped.cb.h5 || bad "pipe run failed"
"$PYTHON" -c "
import h5py, sys
f = h5py.File('piped.cb.h5', 'r')
assert f.attrs['format'] in ('fmbd-cb', b'fmbd-cb'), f.attrs['format']
assert f['cb/kappa'].shape == (4,) and f['reduced/M'].shape == (16, 16)
assert 'mesh' in f and 'dofs' in f and 'interfaces' in f and 'K' not in f
" || bad "piped output is not a valid fmbd-cb file with the description copied"
fe2cb good.fe.h5 -o nm.cb.h5 --method nm --modes 5 -q || bad "--method nm failed"

# --- bad input (exit 1) ---------------------------------------------------------------------------
expect_fail 1 'kind\.fe\.h5.*(fmbd-rflex|expected fmbd-fe)' out1.cb.h5 -- kind.fe.h5 -o out1.cb.h5
expect_fail 1 'text\.fe\.h5' out2.cb.h5 -- text.fe.h5 -o out2.cb.h5
expect_fail 1 'newer\.fe\.h5.*(version|2\.0)' out3.cb.h5 -- newer.fe.h5 -o out3.cb.h5
expect_fail 1 'nan\.fe\.h5:/K' out4.cb.h5 -- nan.fe.h5 -o out4.cb.h5
expect_fail 1 'nonsym\.fe\.h5:/K: .*not symmetric.*node' out5.cb.h5 -- nonsym.fe.h5 -o out5.cb.h5
expect_fail 1 'floating\.fe\.h5:/K: .*singular at dof [0-9]+ \(node (2[1-9]|3[0-9]|40), ' out6.cb.h5 -- floating.fe.h5 -o out6.cb.h5
expect_fail 1 'small\.fe\.h5.*1000 modes.*only [0-9]+ interior dofs' out7.cb.h5 -- small.fe.h5 -o out7.cb.h5 --modes 1000
expect_fail 1 'good\.fe\.h5.*--fmax 1 Hz lies below the first fixed-interface mode' out8.cb.h5 -- good.fe.h5 -o out8.cb.h5 --fmax 1
expect_fail 1 'missing\.fe\.h5' out9.cb.h5 -- missing.fe.h5 -o out9.cb.h5
expect_fail 1 'good\.fe\.h5.*--boundary nosuch' out10.cb.h5 -- good.fe.h5 -o out10.cb.h5 --boundary nosuch

# --- usage (exit 2) -------------------------------------------------------------------------------
expect_fail 2 'unknown option' u1.cb.h5 -- good.fe.h5 -o u1.cb.h5 --bogus
expect_fail 2 'exclusive' u2.cb.h5 -- good.fe.h5 -o u2.cb.h5 --modes 3 --fmax 100
expect_fail 2 '--modes: .-1. must be >= 0' u3.cb.h5 -- good.fe.h5 -o u3.cb.h5 --modes -1
expect_fail 2 'no BODY' u4.cb.h5 --
expect_fail 2 'cb or nm' u5.cb.h5 -- good.fe.h5 -o u5.cb.h5 --method xx
expect_fail 2 '--hold needs' u6.cb.h5 -- good.fe.h5 -o u6.cb.h5 --hold

# --- the examples of docs/man/fe2cb.1, as written there --------------------------------------
cp "$ROOT/examples/geometry/rod.geo" .
mesh2fe rod.geo --size 0.008 --interface end0 --interface end1 -o rod.fe.h5 -q || bad "example: mesh2fe"
fe2cb rod.fe.h5 --modes 24 -o rod.cb.h5 -q || bad "example: fe2cb --modes 24"
fe2cb rod.fe.h5 --fmax 5000 -o rod.cb.h5 -v 2> ex.err || bad "example: fe2cb --fmax 5000: $(cat ex.err)"
fe2cb rod.fe.h5 --method nm --modes 10 -o rod.nm.h5 -q || bad "example: fe2cb --method nm"
if command -v cbcheck > /dev/null; then
  mesh2fe rod.geo --interface end0 | fe2cb - | cbcheck - -o rod.rflex.h5 2> ex.err \
    || bad "example: mesh2fe | fe2cb | cbcheck: $(cat ex.err)"
  [ -s rod.rflex.h5 ] || bad "example pipe: no rod.rflex.h5"
else
  bad "cbcheck not built: the pipe example of fe2cb.1 cannot run"
fi

# --modes 0 on a free body: the Guyan reduction of one interface is rigid motion only, its
# reduced eigenvalues round-off; all six must be flagged rigid (they were not: cbcheck then
# reported six "flexible" 0 Hz modes); with two interfaces six rigid and six flexible
fe2cb good.fe.h5 --modes 0 --boundary end0 -o m0.cb.h5 -q 2> m0.err || bad "--modes 0: $(cat m0.err)"
mesh2fe rod.geo --size 0.015 --interface end0 -o rod1.fe.h5 -q || bad "mesh2fe rod1"
fe2cb rod1.fe.h5 --modes 0 -o rod1.cb.h5 -q 2> m0.err || bad "--modes 0 rod1: $(cat m0.err)"
"$PYTHON" - <<'PY' || bad "--modes 0: rigid-body modes not flagged"
import h5py, sys
ok = True
with h5py.File("rod1.cb.h5") as f:
    r = f["reduced/rigid"][()]
    ok &= bool(r.all()) and len(r) == 6 and int(f["cb"].attrs["n_rigid"]) == 6
with h5py.File("m0.cb.h5") as f:
    r, fr = f["reduced/rigid"][()], f["reduced/frequency_hz"][()]
    # good.fe.h5: free beam, boundary end0 + end1 = 12 dofs: 6 rigid, 6 flexible above 1 Hz
    ok &= int(r.sum()) == 6 and bool(r[:6].all()) and bool((fr[6:] > 1.0).all())
sys.exit(0 if ok else 1)
PY
if command -v cbcheck > /dev/null; then
  cbcheck rod1.cb.h5 > m0.out 2>&1 || bad "cbcheck on a --modes 0 body: $(cat m0.out)"
  grep -q "6 rigid-body modes" m0.out || bad "cbcheck on a --modes 0 body: not 6 rigid ($(cat m0.out))"
fi

[ $fail -eq 0 ] && echo "fe2cb.sh: all passed"
exit $fail
