#!/bin/bash
# tests/cli/cbcheck.sh: cbcheck on tiny bodies: the documented examples, pipes, and bad input
# (exit status, a message naming cbcheck, the file and the HDF5 path, and no output left).
set -u
T=$ROOT/$BUILD/test-tmp/cbcheck
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
err() { echo "FAIL: $*"; fail=1; }
# expect STATUS PATTERN... -- CMD...: exit status and every pattern in stderr
expect() {
  local st=$1; shift
  local pats=()
  while [ "$1" != "--" ]; do pats+=("$1"); shift; done
  shift
  "$@" >out.txt 2>err.txt
  local got=$?
  [ $got -eq "$st" ] || err "'$*': exit $got, expected $st: $(cat err.txt)"
  for p in "${pats[@]}"; do
    grep -q -- "$p" err.txt || err "'$*': stderr lacks '$p': $(cat err.txt)"
  done
}
noout() { for f in "$@"; do [ ! -e "$f" ] && [ ! -e "$f.part" ] || err "output $f left behind"; done; }

# --- a small beam body (fegen, no gmsh): 20 elements, one 6-dof end interface ----------------
"$PYTHON" - <<'EOF' || exit 1
import sys, os
sys.path.insert(0, os.path.join(os.environ["ROOT"], "tests", "py"))
import fegen
fegen.write("beam.fe.h5", fegen.beam(n_el=20, interfaces={"end": [20]}))
fegen.write("stiffer.fe.h5", fegen.beam(n_el=20, E=200e9, interfaces={"end": [20]}))
EOF
fe2cb beam.fe.h5 --modes 4 -o beam.cb.h5 -q || { echo "FAIL: fe2cb"; exit 1; }

# --- good runs -------------------------------------------------------------------------------
expect 0 -- cbcheck beam.cb.h5
grep -q "upper_next" out.txt || err "report table missing on stdout"
expect 0 "cbcheck: beam.rflex.h5: Nd = " -- cbcheck beam.cb.h5 --tol 1e-3 --range 4 --csv beam.csv --plot beam -o beam.rflex.h5
[ -f beam.rflex.h5 ] && [ -f beam.csv ] && [ -f beam-estimates.svg ] && [ -f beam-convergence.svg ] || err "outputs missing"
"$PYTHON" -c "
import xml.dom.minidom as x
for f in ('beam-estimates.svg', 'beam-convergence.svg'):
    d = x.parse(f)
    assert len(d.getElementsByTagName('path')) >= 4, f" || err "plots are not well-formed SVG with curves"
head -1 beam.csv | grep -q '^mode,frequency_hz,eigenvalue,lower,second_order,upper,exact' || err "CSV header: $(head -1 beam.csv)"
[ "$(wc -l < beam.csv)" -eq 5 ] || err "CSV rows: $(wc -l < beam.csv)"
# pipes: fe2cb | cbcheck - | file; the report goes to stderr when the rflex takes stdout
fe2cb beam.fe.h5 --modes 4 -q -o - | cbcheck - --tol 1e-2 --range 3 > piped.rflex.h5 2>piped.err || err "pipe failed: $(cat piped.err)"
grep -q "upper_next" piped.err || err "report not on stderr when the rflex goes to stdout"
"$PYTHON" -c "
import h5py, sys
f = h5py.File('piped.rflex.h5', 'r')
sys.exit(0 if f.attrs['format'] == 'fmbd-rflex' and f['modes/shapes'].shape[1] == 3 else 1)" || err "piped rflex unreadable"
# --csv - puts the CSV on stdout and the report on stderr
cbcheck beam.cb.h5 --csv - 2>csv.err > csv.out || err "--csv -"
head -1 csv.out | grep -q '^mode,' && grep -q "upper_next" csv.err || err "--csv -: streams mixed"

# the example of docs/man/cbcheck.1 and --help: the papers' rod, coarse mesh
mesh2fe "$ROOT/examples/geometry/rod.geo" --size 0.02 --E 100e9 --nu 0.285 --rho 7850 --interface end1 -o rod.fe.h5 -q \
  && fe2cb rod.fe.h5 --modes 10 -o rod.cb.h5 -q || err "rod body"
expect 0 -- cbcheck rod.cb.h5 --tol 1e-3 --range 10 -o rod.rflex.h5
[ -f rod.rflex.h5 ] || err "man page example: no rod.rflex.h5"
expect 0 -- cbcheck rod.cb.h5 --exact --range 5 --plot rod

# --- bad input --------------------------------------------------------------------------------
# non-positive tolerances: usage errors (2) naming the file and the option
expect 2 "cbcheck: error" "beam.cb.h5" "--tol" -- cbcheck beam.cb.h5 --tol 0 -o bad.rflex.h5
expect 2 "cbcheck: error" "beam.cb.h5" "--tol" -- cbcheck beam.cb.h5 --tol -1e-3 -o bad.rflex.h5
noout bad.rflex.h5
# --range beyond the modes the body can have (ndof - rigid-body modes)
expect 1 "cbcheck: error" "beam.cb.h5:/dofs" "flexible modes" -- cbcheck beam.cb.h5 --tol 1e-3 --range 100000 -o bad.rflex.h5
noout bad.rflex.h5
expect 1 "cbcheck: error" "beam.cb.h5:/cb/interior_dofs" "--init" -- cbcheck beam.cb.h5 --tol 1e-3 --init 100000 -o bad.rflex.h5
noout bad.rflex.h5
# without --tol, --range beyond the reduced body's modes
expect 1 "cbcheck: error" "beam.cb.h5:/reduced/eigenvalues" -- cbcheck beam.cb.h5 --range 50
# an unreachable tolerance (the pool capped): the best reached is reported, exit 1, no rflex
expect 1 "cbcheck: error" "beam.cb.h5:/cb/kappa" "not reached" "best reached" -- cbcheck beam.cb.h5 --tol 1e-10 --range 2 --max-modes 6 -o bad.rflex.h5 --csv bad.csv --plot bad
grep -q "first_failing" out.txt || err "unreachable tolerance: no iteration log in the report"
grep -q "upper_next" out.txt || err "unreachable tolerance: no table of the best Nd in the report"
noout bad.rflex.h5 bad.csv bad-estimates.svg bad-convergence.svg
# the same with a cap on Nd
expect 1 "not reached" "max-modes" -- cbcheck beam.cb.h5 --tol 1e-9 --range 4 --max-modes 8 -o bad.rflex.h5
noout bad.rflex.h5
# the source fe file missing when more modes are needed (looked up as recorded, relative to
# the working directory, then beside the cb file: neither exists from inside moved/)
mkdir -p moved && cp beam.cb.h5 moved/
cd moved
expect 1 "cbcheck: error" "beam.cb.h5:/cb" "beam.fe.h5" "cannot be read" -- cbcheck beam.cb.h5 --tol 1e-6 --range 4 -o bad.rflex.h5
noout bad.rflex.h5
expect 1 "cbcheck: error" "beam.cb.h5:/cb" -- cbcheck beam.cb.h5 --exact
# changed since fe2cb read it (SHA-256)
cp ../stiffer.fe.h5 beam.fe.h5
expect 1 "cbcheck: error" "beam.cb.h5:/cb" "changed" "SHA-256" -- cbcheck beam.cb.h5 --tol 1e-6 --range 4 -o bad.rflex.h5
noout bad.rflex.h5
expect 1 "changed" -- cbcheck beam.cb.h5 --exact --fe ../stiffer.fe.h5
cd ..
# an explicit --fe that cannot be read, is of another kind or changed is an error, not a warning
# with a quiet fallback to the cb file alone (even when nothing else needs the fe file)
printf 'not hdf5\n' > text.fe.h5
expect 1 "cbcheck: error" "nothere.fe.h5" "given with --fe" -- cbcheck beam.cb.h5 --fe nothere.fe.h5 --tol 1e-2 --range 2 -o bad.rflex.h5
noout bad.rflex.h5
expect 1 "cbcheck: error" "text.fe.h5" -- cbcheck beam.cb.h5 --fe text.fe.h5
expect 1 "cbcheck: error" "beam.cb.h5" "fmbd-cb" -- cbcheck beam.cb.h5 --fe beam.cb.h5
expect 1 "cbcheck: error" "stiffer.fe.h5" "changed" -- cbcheck beam.cb.h5 --fe stiffer.fe.h5
# a corrupt count is named where it is read (was a negative "at most -1099511627528 modes")
"$PYTHON" -c "
import h5py, shutil, numpy as np
shutil.copy('beam.cb.h5', 'nrigid.cb.h5')
with h5py.File('nrigid.cb.h5', 'r+') as f:
    f['cb'].attrs['n_rigid'] = np.int64(2**40)"
expect 1 "cbcheck: error: nrigid.cb.h5:/cb: attribute n_rigid = 1099511627776, but /reduced/rigid flags" -- cbcheck nrigid.cb.h5 --range 2
# not a cb file, missing file, usage
expect 1 "cbcheck: error" "beam.fe.h5" "fmbd-fe" -- cbcheck beam.fe.h5
expect 1 "cbcheck: error" "nothere.cb.h5" -- cbcheck nothere.cb.h5
expect 2 "cbcheck: error" -- cbcheck beam.cb.h5 --csv - -o -
expect 2 "cbcheck: error" -- cbcheck
expect 2 "--estimator" -- cbcheck beam.cb.h5 --estimator best
# a tolerance below what double precision resolves is refused (it was "met" by estimates of
# 1e-21 on a small body, or chased forever by adding modes on a larger one)
expect 2 "cbcheck: error" "--tol 1e-16" "at least 1e-10" -- cbcheck beam.cb.h5 --tol 1e-16 -o bad.rflex.h5
noout bad.rflex.h5
exit $fail
