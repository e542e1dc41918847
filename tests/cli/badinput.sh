#!/bin/bash
# tests/cli/badinput.sh: every reader on bad files (docs/STABILITY.md, "Bad input"): empty,
# truncated, plain text, a foreign HDF5 file, a toolchain file of another kind, for each program
# that reads each kind (fe2cb: fe; cbcheck and fmbd-run: cb; fmbd-run: rflex and --reference);
# then the cb-file defects that used to pass or blame the wrong thing: overlapping or
# out-of-range dof lists, dof lists that do not cover /dofs, a lost /mesh/elements (all-zero
# modal stress before). Each failure: exit 1, "PROG: error:" naming the file (and the dataset
# where there is one), no output left behind.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export PATH="$ROOT/$BUILD/bin:$PATH"
T=$ROOT/$BUILD/test-tmp/cli-badinput
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }

# expect PROG STATUS REGEX OUT -- args...: the exit status, a "PROG: error:" line matching REGEX,
# and OUT (and OUT.part) absent afterwards
expect() {
  local prog=$1 st=$2 re=$3 out=$4; shift 5
  rm -f "$out" "$out.part"
  "$prog" "$@" >stdout.txt 2>stderr.txt
  local rc=$?
  [ $rc -eq "$st" ] || { bad "$prog $*: exit $rc, expected $st: $(cat stderr.txt)"; return; }
  grep -Eq -- "^$prog: error: .*$re" stderr.txt || bad "$prog $*: no error matching /$re/: $(cat stderr.txt)"
  { [ -e "$out" ] || [ -e "$out.part" ]; } && bad "$prog $*: $out left behind"
  head -n 1 stderr.txt
}

# --- fixtures: a small tet4 rod through the whole pipeline ----------------------------------
mesh2fe "$ROOT/examples/geometry/rod.geo" --order 1 --size 0.03 --interface end0 --interface end1 \
  -o rod.fe.h5 -q || { echo "mesh2fe failed"; exit 1; }
fe2cb rod.fe.h5 --modes 4 -o rod.cb.h5 -q || { echo "fe2cb failed"; exit 1; }
cbcheck rod.cb.h5 -o rod.rflex.h5 -q >/dev/null || { echo "cbcheck failed"; exit 1; }
cat >run.yaml <<'Y'
solver: {t_end: 0.002, step: 0.001}
bodies:
  - {name: rod, type: flexible, file: rod.rflex.h5}
outputs:
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position]}
Y
fmbd-run run.yaml -o ref.run.h5 -q || { echo "fmbd-run failed"; exit 1; }
"$PYTHON" - <<'PY' || exit 1
import h5py, numpy as np, shutil
for k in ("fe", "cb", "rflex"):
    src = "rod.%s.h5" % k
    data = open(src, "rb").read()
    open("empty.%s.h5" % k, "wb").close()
    open("trunc.%s.h5" % k, "wb").write(data[: len(data) // 2])
    open("text.%s.h5" % k, "w").write("format: fmbd-%s\n" % k)
    with h5py.File("foreign.%s.h5" % k, "w") as f:  # HDF5, but no toolchain file
        f["x"] = np.arange(3.0)
    with h5py.File("newer.%s.h5" % k, "w") as f:
        f.attrs["format"] = "fmbd-" + k
        f.attrs["format_version"] = "9.0"
data = open("ref.run.h5", "rb").read()
open("trunc.run.h5", "wb").write(data[: len(data) // 2])
# cb defects
def variant(name, edit):
    shutil.copy("rod.cb.h5", name)
    with h5py.File(name, "r+") as f:
        edit(f)
def setds(path, val):
    def fn(f):
        del f[path]
        f[path] = val
    return fn
with h5py.File("rod.cb.h5") as f:
    bd, idf = f["cb/boundary_dofs"][()], f["cb/interior_dofs"][()]
b2 = bd.copy(); b2[0] = 10**6
variant("range.cb.h5", setds("cb/boundary_dofs", b2))
i2 = idf.copy(); i2[0] = bd[0]
variant("overlap.cb.h5", setds("cb/interior_dofs", i2))
variant("short.cb.h5", setds("cb/interior_dofs", idf[:-1]))
variant("noelem.cb.h5", lambda f: f["mesh"].__delitem__("elements"))
variant("nodes.cb.h5", lambda f: f["mesh"].__delitem__("nodes"))
PY

# --- every reader on empty, truncated, text, foreign, newer files ------------------------------
for c in empty trunc text foreign; do
  expect fe2cb 1 "$c\.fe\.h5: (empty|not an HDF5 file|not a toolchain file)" o.cb.h5 -- $c.fe.h5 -o o.cb.h5
  expect cbcheck 1 "$c\.cb\.h5: (empty|not an HDF5 file|not a toolchain file)" o.rflex.h5 -- $c.cb.h5 -o o.rflex.h5
  for k in cb rflex; do
    sed "s/rod.rflex.h5/$c.$k.h5/" run.yaml >b.yaml
    expect fmbd-run 1 "body 'rod': $c\.$k\.h5" o.run.h5 -- b.yaml -o o.run.h5
  done
done
expect fe2cb 1 "newer\.fe\.h5.*9\.0" o.cb.h5 -- newer.fe.h5 -o o.cb.h5
expect cbcheck 1 "newer\.cb\.h5.*9\.0" o.rflex.h5 -- newer.cb.h5 -o o.rflex.h5
sed "s/rod.rflex.h5/newer.rflex.h5/" run.yaml >b.yaml
expect fmbd-run 1 "newer\.rflex\.h5.*9\.0" o.run.h5 -- b.yaml -o o.run.h5
# a file of another kind where one is expected
expect fe2cb 1 "rod\.cb\.h5.*fmbd-cb.*expected fmbd-fe" o.cb.h5 -- rod.cb.h5 -o o.cb.h5
expect cbcheck 1 "rod\.fe\.h5.*fmbd-fe.*expected fmbd-cb" o.rflex.h5 -- rod.fe.h5 -o o.rflex.h5
sed "s/rod.rflex.h5/ref.run.h5/" run.yaml >b.yaml
expect fmbd-run 1 "ref\.run\.h5 is a fmbd-run file" o.run.h5 -- b.yaml -o o.run.h5
for c in trunc foreign; do
  r=$c.run.h5; [ $c = foreign ] && r=foreign.fe.h5
  expect fmbd-run 1 "$r" o.run.h5 -- run.yaml -o o.run.h5 --reference $r
done
expect fmbd-run 1 "rod\.rflex\.h5.*expected fmbd-run" o.run.h5 -- run.yaml -o o.run.h5 --reference rod.rflex.h5

# --- cb files whose dof lists are inconsistent: the cb file is named, never the fe file -------
for p in cbcheck fmbd-run; do
  for v in range overlap short; do
    case $v in
      range) re="$v\.cb\.h5:/cb/boundary_dofs: entry 0 = 1000000 out of range 0\.\.[0-9]+" ;;
      overlap) re="$v\.cb\.h5:/cb/boundary_dofs: entry 0: dof [0-9]+ is also in /cb/interior_dofs" ;;
      short) re="$v\.cb\.h5:/cb: [0-9]+ interior \+ [0-9]+ boundary \+ 0 held dofs, but /dofs has [0-9]+ rows" ;;
    esac
    if [ $p = cbcheck ]; then
      expect cbcheck 1 "$re" o.rflex.h5 -- $v.cb.h5 -o o.rflex.h5
      expect cbcheck 1 "$re" o.rflex.h5 -- $v.cb.h5 --fe rod.fe.h5 -o o.rflex.h5
    else
      sed "s/rod.rflex.h5/$v.cb.h5/" run.yaml >b.yaml
      expect fmbd-run 1 "$re" o.run.h5 -- b.yaml -o o.run.h5
    fi
  done
done
expect cbcheck 1 "nodes\.cb\.h5:/mesh/nodes: missing dataset" o.rflex.h5 -- nodes.cb.h5 --fe rod.fe.h5 -o o.rflex.h5

# --- a lost /mesh/elements: no all-zero modal stress -------------------------------------------
cbcheck noelem.cb.h5 -o noelem.rflex.h5 >/dev/null 2>stderr.txt || bad "cbcheck noelem: $(cat stderr.txt)"
grep -q "^cbcheck: warning: noelem\.cb\.h5: no solid elements (/mesh/elements/tet4 or tet10): no modal stress written" stderr.txt ||
  bad "cbcheck noelem: no warning naming the file: $(cat stderr.txt)"
"$PYTHON" -c "
import h5py, sys
with h5py.File('noelem.rflex.h5') as f: sys.exit('modes/stress' in f)
" || bad "noelem.rflex.h5 has a /modes/stress"
sed "s/rod.rflex.h5/noelem.cb.h5/; s/quantities: \[position\]/quantities: [von_mises]/" run.yaml >b.yaml
expect fmbd-run 1 "output 'tip' asks for stress or strain, but noelem\.cb\.h5 has no modal stress \(it is recovered from solid elements" \
  o.run.h5 -- b.yaml -o o.run.h5
sed "s/rod.rflex.h5/noelem.rflex.h5/; s/quantities: \[position\]/quantities: [von_mises]/" run.yaml >b.yaml
expect fmbd-run 1 "noelem\.rflex\.h5 has no modal stress \(no /modes/stress" o.run.h5 -- b.yaml -o o.run.h5
# the cb body without stress outputs still runs (the elements are needed for stress only)
sed "s/rod.rflex.h5/noelem.cb.h5/" run.yaml >b.yaml
fmbd-run b.yaml -o o.run.h5 -q 2>stderr.txt || bad "noelem.cb.h5 without stress outputs: $(cat stderr.txt)"

# --- provenance: an input remade since a file was made is named (docs/FORMAT.md) -------------
fmbd-run run.yaml -o o.run.h5 2>stderr.txt || bad "run before the change: $(cat stderr.txt)"
grep -q warning stderr.txt && bad "a warning with unchanged inputs: $(cat stderr.txt)"
mesh2fe "$ROOT/examples/geometry/rod.geo" --order 1 --size 0.025 --interface end0 --interface end1 \
  -o rod.fe.h5 -q || bad "mesh2fe again"
fmbd-run run.yaml -o o.run.h5 2>stderr.txt || bad "run after the change: $(cat stderr.txt)"
grep -q "^fmbd-run: warning: rod\.rflex\.h5: its input rod\.fe\.h5 changed since it was made (SHA-256 .*): remake rod\.rflex\.h5" \
  stderr.txt || bad "fmbd-run: no changed-input warning: $(cat stderr.txt)"
fe2cb rod.fe.h5 -o rod.cb.h5 --modes 4 2>stderr.txt || bad "fe2cb again"
grep -q warning stderr.txt && bad "fe2cb: a warning on a fresh fe file: $(cat stderr.txt)"
cp rod.fe.h5 keep.fe.h5 && mv text.fe.h5 rod.fe.h5  # the cb file's fe file replaced
cbcheck rod.cb.h5 -o o.rflex.h5 2>stderr.txt >/dev/null
grep -q "^cbcheck: warning: rod\.cb\.h5: its input rod\.fe\.h5 changed since it was made" stderr.txt ||
  bad "cbcheck: no changed-input warning: $(cat stderr.txt)"

[ $fail -eq 0 ] && echo "badinput: all cases as expected"
exit $fail
