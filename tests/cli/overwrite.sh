#!/bin/bash
# tests/cli/overwrite.sh: no program may overwrite a file it reads (issue: `fmbd-run p.yaml -o
# p.yaml` turned the scene into HDF5, `fe2cb x.fe.h5 -o x.fe.h5` replaced its input, and both
# said success). Each case must exit 2, name the program and the file, and leave the input
# byte for byte as it was, also when -o reaches it through another path or a symbolic link.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
export PATH="$ROOT/$BUILD/bin:$PATH"
T=$ROOT/$BUILD/test-tmp/cli-overwrite
rm -rf "$T" && mkdir -p "$T/sub" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }

cp "$ROOT/examples/geometry/rod.geo" "$ROOT/examples/scenes/pendulum.yaml" .
mesh2fe rod.geo --size 0.02 --order 1 --interface end0 -o rod.fe.h5 -q || bad "fixture mesh2fe"
fe2cb rod.fe.h5 --modes 6 -o rod.cb.h5 -q || bad "fixture fe2cb"
cbcheck rod.cb.h5 --tol 0.5 --range 2 -o rod.rflex.h5 -q || bad "fixture cbcheck"
fmbd-run pendulum.yaml -o pendulum.run.h5 -q || bad "fixture fmbd-run"
ln -s ../rod.cb.h5 sub/link.cb.h5

# refuse PROG FILE ARGS...: the run must exit 2, name PROG and refuse, and FILE must not change
refuse() {
  local prog=$1 file=$2; shift 2
  local before; before=$(sha256sum "$file")
  "$prog" "$@" > out.txt 2> err.txt
  local rc=$?
  [ $rc -eq 2 ] || bad "$prog $*: exit $rc, expected 2 ($(cat err.txt))"
  grep -q "^$prog: error: .*refusing to overwrite" err.txt || bad "$prog $*: message: $(cat err.txt)"
  [ "$(sha256sum "$file")" = "$before" ] || bad "$prog $*: $file changed"
  [ ! -e "$file.part" ] || bad "$prog $*: $file.part left"
}
refuse mesh2fe rod.geo rod.geo --size 0.02 -o rod.geo
refuse fe2cb rod.fe.h5 rod.fe.h5 --modes 4 -o rod.fe.h5
refuse fe2cb rod.fe.h5 rod.fe.h5 --modes 4 -o ./sub/../rod.fe.h5
refuse cbcheck rod.cb.h5 rod.cb.h5 --tol 0.5 --range 2 -o rod.cb.h5
refuse cbcheck rod.cb.h5 rod.cb.h5 --tol 0.5 --range 2 -o sub/link.cb.h5
refuse cbcheck rod.fe.h5 rod.cb.h5 --fe rod.fe.h5 --tol 0.5 --range 2 -o rod.fe.h5
refuse cbcheck rod.cb.h5 rod.cb.h5 --csv rod.cb.h5
refuse fmbd-run pendulum.yaml pendulum.yaml -o pendulum.yaml
refuse fmbd-run pendulum.run.h5 pendulum.yaml --reference pendulum.run.h5 -o pendulum.run.h5

[ $fail -eq 0 ] && echo "overwrite.sh: all passed"
exit $fail
