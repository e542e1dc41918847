#!/bin/bash
# tests/cli/mesh2fe.sh: mesh2fe on tiny inputs: the good paths (file, standard output, beams,
# default names) and every bad input of issue 2, each with its exit status (1 data, 2 usage), a
# message naming mesh2fe, the file and the option/group/element at fault, and no output left
# behind (neither the target nor its .part).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
EXE="$ROOT/$BUILD/bin/mesh2fe"
GEO="$ROOT/examples/geometry"
T="$ROOT/$BUILD/test-tmp/mesh2fe"
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }
# Under `make check SANITIZE=1`, gmsh's and OpenCASCADE's own leaks are suppressed by
# tests/lsan.supp (tests/run.sh)

# expect STATUS 'PATTERN...' -- ARGS: run mesh2fe ARGS -o out.fe.h5, check the exit status,
# that stderr starts with "mesh2fe: error:" and contains every PATTERN (fixed strings), and that
# no out.fe.h5 / out.fe.h5.part is left.
expect() {
  local status=$1; shift
  local pats=()
  while [ "$1" != -- ]; do pats+=("$1"); shift; done
  shift
  rm -f out.fe.h5 out.fe.h5.part
  "$EXE" "$@" -o out.fe.h5 >stdout.txt 2>stderr.txt
  local st=$?
  local what="mesh2fe $*"
  [ $st -eq "$status" ] || bad "$what: exit $st, expected $status ($(head -c 300 stderr.txt))"
  grep -q '^mesh2fe: error: ' stderr.txt || bad "$what: stderr lacks 'mesh2fe: error:' ($(head -c 300 stderr.txt))"
  for p in "${pats[@]}"; do
    grep -qF -- "$p" stderr.txt || bad "$what: stderr lacks '$p': $(head -c 400 stderr.txt)"
  done
  [ -e out.fe.h5 ] && bad "$what: output left behind"
  [ -e out.fe.h5.part ] && bad "$what: out.fe.h5.part left behind"
  [ $st -eq "$status" ] && echo "ok: exit $st: $(head -n 1 stderr.txt)"
}

# ---------------------------------------------------------------- tiny hand-written meshes
# Two tetrahedra sharing the face 2-3-4, gmsh MSH 2.2 (node tags 1-based), a physical curve
# "edge" (one line element 1-2) and a physical volume "body".
msh() {  # msh FILE NODES_EXTRA ELEMENTS...: write a mesh with nodes 1..5 (+ extra) and elements
  local file=$1 extra=$2; shift 2
  local nn=$((5 + $(printf '%s' "$extra" | grep -c .)))
  {
    printf '$MeshFormat\n2.2 0 8\n$EndMeshFormat\n'
    printf '$PhysicalNames\n2\n1 1 "edge"\n3 2 "body"\n$EndPhysicalNames\n'
    printf '$Nodes\n%d\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n' $nn
    [ -n "$extra" ] && printf '%s\n' "$extra"
    printf '$EndNodes\n$Elements\n%d\n' $#
    local i=1
    for e in "$@"; do printf '%d %s\n' $i "$e"; i=$((i + 1)); done
    printf '$EndElements\n'
  } >"$file"
}
EDGE='1 2 1 1 1 2'             # line2, physical 1 ("edge"), nodes 1 2
TET1='4 2 2 1 1 2 3 4'         # tet4, physical 2 ("body"), positive orientation
TET2='4 2 2 1 2 4 3 5'         # the neighbour: (2,4,3,5) is negative (det -2), (2,3,4,5) positive
TET2OK='4 2 2 1 2 3 4 5'
msh good.msh '' "$EDGE" "$TET1" "$TET2OK"
msh inverted.msh '' "$EDGE" "$TET1" "$TET2"
msh flat.msh '6 0.5 0.5 0' "$EDGE" "$TET1" "$TET2OK" '4 2 2 1 1 2 3 6'
# MSH 4.1 (nodes listed per entity): node 6 sits in the volume's node block but in no element
# (an MSH 2.2 reader drops such a node silently, so the 4.1 layout is needed to show it)
cat >orphan.msh <<'EOF'
$MeshFormat
4.1 0 8
$EndMeshFormat
$Entities
0 0 0 1
1 0 0 0 1 1 1 0 0
$EndEntities
$Nodes
1 6 1 6
3 1 0 6
1
2
3
4
5
6
0 0 0
1 0 0
0 1 0
0 0 1
1 1 1
7 7 7
$EndNodes
$Elements
1 2 1 2
3 1 4 2
1 1 2 3 4
2 2 3 4 5
$EndElements
EOF
msh surface.msh '' '2 2 0 1 1 2 3' '2 2 0 1 2 3 4'

# ---------------------------------------------------------------- good paths
"$EXE" good.msh -o good.fe.h5 -q 2>err.txt || bad "good.msh: exit $? ($(cat err.txt))"
[ -s err.txt ] && bad "-q printed: $(cat err.txt)"
h5ls good.fe.h5/mesh/elements >ls.txt 2>&1 && grep -q 'tet4 .*{2, 4}' ls.txt || bad "good.msh: /mesh/elements: $(cat ls.txt)"
h5ls good.fe.h5/mesh/groups | grep -q edge || bad "good.msh: group edge missing"
[ -e good.fe.h5.part ] && bad "good.msh: .part left"
# --order 2 on a tet4 .msh: mid-edge nodes added (5 nodes + 9 edges)
"$EXE" good.msh --order 2 -o good2.fe.h5 -q || bad "good.msh --order 2: exit $?"
h5ls good2.fe.h5/mesh/nodes | grep -q '{14, 3}' || bad "good.msh --order 2: $(h5ls good2.fe.h5/mesh/nodes)"
# the group "edge" (nodes 1-2) gains the mid-edge node of its edge
h5ls good2.fe.h5/mesh/groups/edge | grep -q '{3}' || bad "good.msh --order 2: group edge: $(h5ls good2.fe.h5/mesh/groups/edge)"
# --order 1 on a tet10 .msh keeps the corners only (the end groups lose their mid-edge nodes)
printf 'Merge "%s";\nMesh.MeshSizeMax = 0.01;\n' "$GEO/rod.geo" >rod10.geo
if gmsh -3 -order 2 rod10.geo -o rod10.msh >gmsh.log 2>&1; then
  "$EXE" rod10.msh -o r10.fe.h5 -v 2>err10.txt || bad "rod10.msh: exit $?"
  "$EXE" rod10.msh --order 1 -o r4.fe.h5 -v 2>err4.txt || bad "rod10.msh --order 1: exit $?"
  n10=$(sed -n 's/.*msh: \([0-9]*\) nodes, \([0-9]*\) tet10.*/\2/p' err10.txt)
  n4=$(sed -n 's/.*msh: \([0-9]*\) nodes, \([0-9]*\) tet4.*/\2/p' err4.txt)
  [ -n "$n10" ] && [ "$n10" = "$n4" ] || bad "rod10.msh: tet10 count '$n10' vs tet4 count '$n4'"
  h5ls r4.fe.h5/mesh/elements | grep -q 'tet4 ' || bad "rod10.msh --order 1: no tet4"
else
  bad "gmsh -3 -order 2 failed: $(tail -3 gmsh.log)"
fi
# standard output when -o is absent and stdout is not a terminal; the summary names (stdout)
"$EXE" "$GEO/rodbeam.geo" --circle 0.015 --clamp end0 >beam.h5 2>err.txt || bad "rodbeam.geo > file: exit $? ($(cat err.txt))"
grep -q '^mesh2fe: (stdout): 21 nodes, 20 beam2, 0 interfaces, 120 dofs' err.txt || bad "rodbeam summary: $(cat err.txt)"
h5ls beam.h5/mesh/elements | grep -q beam2 || bad "rodbeam to stdout: no /mesh/elements/beam2"
# the --help example: the rod, two interfaces
"$EXE" "$GEO/rod.geo" --size 0.01 --order 1 --interface end0 --interface end1:rbe3@0.3,0,0 -o rod.fe.h5 2>err.txt || bad "rod.geo: exit $? ($(cat err.txt))"
grep -Eq '^mesh2fe: rod.fe.h5: [0-9]+ nodes, [0-9]+ tet4, 2 interfaces, [0-9]+ dofs, mass 1\.[0-9]+ kg, .* s wall, .* s cpu$' err.txt || bad "rod summary: $(cat err.txt)"
h5dump -a /interfaces/end1/kind rod.fe.h5 | grep -q rbe3 || bad "rod: /interfaces/end1 kind"
h5dump -a /interfaces/end1/point rod.fe.h5 | grep -q '0.3, 0, 0' || bad "rod: /interfaces/end1 point: $(h5dump -a /interfaces/end1/point rod.fe.h5)"
# STEP and BREP (exported from rod.geo by gmsh's command line; they carry no physical groups,
# so the end face is named by a box) and a .msh of 3-node lines (each split into two beams)
if gmsh "$GEO/rod.geo" -0 -o rod.step >gmsh.log 2>&1 && gmsh "$GEO/rod.geo" -0 -o rod.brep >>gmsh.log 2>&1; then
  "$EXE" rod.step --size 0.01 --group end0:-1,-1,-1,0,1,1 --clamp end0 -o step.fe.h5 2>err.txt || bad "rod.step: exit $? ($(cat err.txt))"
  h5ls step.fe.h5/clamped | grep -q end0 || bad "rod.step: no /clamped/end0"
  "$EXE" rod.brep --size 0.01 -o brep.fe.h5 2>err.txt || bad "rod.brep: exit $? ($(cat err.txt))"
  grep -q 'tet10' err.txt || bad "rod.brep: not tet10: $(cat err.txt)"
else
  bad "gmsh could not export rod.step/rod.brep: $(tail -3 gmsh.log)"
fi
if gmsh -1 -order 2 "$GEO/rodbeam.geo" -o line3.msh >gmsh.log 2>&1; then
  "$EXE" line3.msh --circle 0.015 -o line3.fe.h5 2>err.txt || bad "line3.msh: exit $? ($(cat err.txt))"
  grep -q ' 41 nodes, 40 beam2' err.txt || bad "line3.msh: 20 line3 should give 40 beams: $(cat err.txt)"
else
  bad "gmsh -1 -order 2 rodbeam.geo failed: $(tail -3 gmsh.log)"
fi
# default output name beside the input's name in the current folder, when stdout is a terminal:
# only testable with a terminal (script(1), which make check installs; a failure without it)
if command -v script >/dev/null 2>&1; then
  cp "$GEO/rodbeam.geo" named.geo
  script -qec "'$EXE' named.geo --circle 0.015 -q" /dev/null >/dev/null 2>&1
  [ -f named.fe.h5 ] || bad "named.geo with a terminal on stdout: no named.fe.h5"
else
  bad "script(1) missing (bsdutils, installed by make check): the terminal case cannot run"
fi

# every example command of the man page and of --help, as written there (run from the top of
# the tree, output redirected into the scratch folder)
n=0
while IFS= read -r cmd; do
  n=$((n + 1))
  # shellcheck disable=SC2086
  (cd "$ROOT" && $cmd -o "$T/example$n.fe.h5" -q) || bad "example '$cmd': exit $?"
  [ -s "$T/example$n.fe.h5" ] || bad "example '$cmd': no output"
done < <({ sed -n 's/\\-/-/g; s/^mesh2fe examples/mesh2fe examples/p' "$ROOT/docs/man/mesh2fe.1"
           "$EXE" --help | sed -n 's/^  mesh2fe /mesh2fe /p'; } | sed "s|^mesh2fe |$EXE |")
[ $n -ge 5 ] || bad "only $n examples found in the man page and --help"
echo "ok: $n documented examples run"

# the h5dump -H sample of docs/FORMAT.md: same command, same shapes
(cd "$ROOT" && "$EXE" examples/geometry/rodbeam.geo --circle 0.015 --size 0.1 --interface end1 \
  --clamp end0 -o "$T/rodbeam.fe.h5" -q) || bad "FORMAT.md sample command: exit $?"
h5ls -r rodbeam.fe.h5 >ls.txt 2>&1
for want in '^/dofs +Dataset \{18, 2\}' '^/K/data +Dataset \{252\}' '^/mesh/nodes +Dataset \{5, 3\}' \
  '^/mesh/elements/beam2 +Dataset \{3, 2\}' '^/mesh/beam2_orientation +Dataset \{3, 3\}' \
  '^/clamped/end0 +Dataset \{1\}' '^/interfaces/end1/nodes +Dataset \{1\}' '^/expand/data +Dataset \{24\}'; do
  grep -Eq "$want" ls.txt || bad "FORMAT.md sample: no '$want' in h5ls -r"
done
echo "ok: docs/FORMAT.md h5dump sample reproduced"

# ---------------------------------------------------------------- bad inputs
expect 1 'nosuch.geo' 'cannot open' -- nosuch.geo
mkdir -p adir.geo
expect 1 'adir.geo' 'not a regular file' -- adir.geo
cp good.msh unreadable.msh && chmod 000 unreadable.msh
if [ "$(id -u)" != 0 ]; then
  expect 1 'unreadable.msh' 'cannot open' -- unreadable.msh
elif command -v setpriv >/dev/null 2>&1; then
  # root reads anything: the case runs as nobody (util-linux's setpriv, installed by make check)
  chmod 755 . && chmod 644 good.msh
  HOME=/tmp setpriv --reuid=65534 --regid=65534 --clear-groups "$EXE" unreadable.msh -o /tmp/unreadable-$$.fe.h5 >stdout.txt 2>stderr.txt
  st=$?
  [ $st -eq 1 ] && grep -q "unreadable.msh.*cannot open" stderr.txt \
    || bad "unreadable file (as nobody): exit $st, $(cat stderr.txt)"
  rm -f /tmp/unreadable-$$.fe.h5
else
  bad "setpriv missing (util-linux): the unreadable-file case cannot run as root"
fi
echo 'solid x' >part.igs
expect 2 'part.igs' "unknown geometry type '.igs'" -- part.igs
echo 'Point(1) = {0, 0, 0' >syntax.geo
expect 1 'syntax.geo' 'gmsh cannot read the file' -- syntax.geo
printf 'SetFactory("OpenCASCADE");\nRectangle(1) = {0, 0, 0, 1, 1};\n' >flat.geo
expect 1 'flat.geo' 'surfaces but no volume' -- flat.geo
expect 1 'surface.msh' 'no volume (tetrahedron) or beam (line) elements' -- surface.msh
expect 1 'inverted.msh' 'element 1 (gmsh element tag 3) is inverted' 'Jacobian determinant -2' -- inverted.msh
expect 1 'flat.msh' 'element 2 (gmsh element tag 4) is degenerate' 'Jacobian determinant 0' -- flat.msh
expect 1 'orphan.msh' 'node tag 6' 'attached to no element' -- orphan.msh
expect 1 'good.msh' "--interface nosuch" "physical group 'nosuch' not found (groups: edge, body)" -- good.msh --interface nosuch
expect 1 'good.msh' "--clamp nosuch" "physical group 'nosuch' not found" -- good.msh --clamp nosuch
expect 1 'good.msh' "RBE3 interface 'edge' cannot carry rotation" 'collinear' -- good.msh --interface edge:rbe3
expect 1 'rodbeam.geo' "RBE3 interface 'end0' cannot carry rotation" 'one point' -- "$GEO/rodbeam.geo" --circle 0.01 --interface end0:rbe3
expect 2 '--E' 'must be > 0' -- good.msh --E 0
expect 2 '--E' 'must be > 0' -- good.msh --E -2e11
expect 2 '--rho' 'must be > 0' -- good.msh --rho 0
expect 2 '--nu' 'outside (-1, 0.5)' -- good.msh --nu 0.5
expect 2 '--nu' 'outside (-1, 0.5)' -- good.msh --nu -1
expect 2 '--E' -- good.msh --E abc
expect 2 '--order' -- good.msh --order 3
expect 2 '--size' -- good.msh --size 0
expect 2 '--mass' "'diagonal'" -- good.msh --mass diagonal
expect 2 '--interface' "'rbe9'" -- good.msh --interface body:rbe9
expect 2 '--interface' 'list of 3 numbers' -- good.msh --interface body@1,2
expect 2 '--group' -- good.msh --group nobox
expect 2 '--group' 'min 1 > max 0' -- good.msh --group g:1,0,0,0,1,1
expect 1 'good.msh' "--group far" "holds no node" -- good.msh --group far:5,5,5,6,6,6
expect 1 'good.msh' "--group edge" "exists already" -- good.msh --group edge:0,0,0,1,1,1
expect 2 'rodbeam.geo' 'beam elements' '--section' -- "$GEO/rodbeam.geo"
expect 2 '--section' -- "$GEO/rodbeam.geo" --section 1,2,3
expect 2 'exclusive' -- "$GEO/rodbeam.geo" --section 1,1,1,1 --circle 0.01
expect 2 'unknown option' -- good.msh --frobnicate
expect 2 'one GEOMETRY expected' -- good.msh good.msh
expect 2 'standard input' -- -
# an open surface: the faceted rod without its first triangle
awk 'NR == 2 { skip = 7 } skip > 0 { skip--; next } { print }' "$GEO/rod_faceted.stl" >open.stl
expect 1 'open.stl' 'not closed' -- open.stl
printf 'OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 9\n' >badindex.off
expect 1 'badindex.off' 'line 7' 'vertex index 9 out of range' -- badindex.off
# unwritable output: the folder does not exist
rm -f stderr.txt
"$EXE" good.msh -o /nonexistent/x.fe.h5 2>stderr.txt
st=$?
[ $st -eq 1 ] || bad "-o /nonexistent/x.fe.h5: exit $st, expected 1"
grep -q '^mesh2fe: error: .*/nonexistent/x.fe.h5' stderr.txt || bad "-o /nonexistent: message: $(cat stderr.txt)"
[ -e /nonexistent/x.fe.h5.part ] && bad "-o /nonexistent: .part left"
echo "ok: exit $st: $(head -n 1 stderr.txt)"
# --- millimetre-scale geometry meshes with tet10 (reported: "inverted tet10 element" for the
# rod scaled by 1e-3 while tet4 worked); the element checks are relative to each element's
# size. The same rod at scales 1 and 1e-3 with the same relative element size: frequencies scale
# as 1/s; tolerance 1e-3 relative (the two gmsh meshes differ slightly: 1e-4 measured; a
# length-unit defect would be off by powers of ten).
sed 's/^L = 0.3;/L = 0.0003;/; s/^R = 0.015;/R = 0.000015;/; s/^e = 1e-6;/e = R \/ 10;/' \
  "$ROOT/examples/geometry/rod.geo" > rodmm.geo
mesh2fe "$ROOT/examples/geometry/rod.geo" --size 0.01 --interface end0 -o scale1.fe.h5 -q \
  || bad "rod at scale 1 did not mesh"
mesh2fe rodmm.geo --size 0.00001 --interface end0 -o scale3.fe.h5 -q 2> mm.err \
  || bad "millimetre-scale rod (tet10) did not mesh: $(cat mm.err)"
fe2cb scale1.fe.h5 --method nm --modes 6 -o scale1.nm.h5 -q && fe2cb scale3.fe.h5 --method nm --modes 6 -o scale3.nm.h5 -q \
  || bad "fe2cb on the scaled rods"
"$PYTHON" -c "
import h5py, numpy as np, sys
a = h5py.File('scale1.nm.h5')['cb/kappa'][()]; b = h5py.File('scale3.nm.h5')['cb/kappa'][()]
r = np.abs(np.sqrt(a) / np.sqrt(b) * 1e3 - 1).max()
print('frequency ratio (scale 1e-3) / 1e3 - 1: %.1e' % r)
sys.exit(0 if r < 1e-3 else 1)" || bad "millimetre-scale rod: frequencies do not scale as 1/s"

# no stray outputs from the failing runs
ls ./*.part 2>/dev/null && bad ".part files left: $(ls ./*.part)"
exit $fail
