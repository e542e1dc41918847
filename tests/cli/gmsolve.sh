#!/bin/bash
# tests/cli/gmsolve.sh: gmsolve on tiny mechanisms (tests/py/fegen.py beams reduced by fe2cb):
# good runs (summary line, -q, -v, --at, -M), bad input and usage. Every failing run must exit 1
# (data) or 2 (usage), name gmsolve, the scene file and its line where one is at fault, and leave
# no output file (neither the target nor its .part).
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export PATH="$ROOT/$BUILD/bin:$PATH"
T=$ROOT/$BUILD/test-tmp/cli-gmsolve
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
bad() { echo "FAIL: $*"; fail=1; }

# --- fixtures ---------------------------------------------------------------------------------
PYTHONPATH=$ROOT/tests/py "$PYTHON" - <<'PY' || exit 1
import fegen
fegen.write("coupler.fe.h5", fegen.beam(n_el=8, length=0.4, radius=0.01, interfaces={"end0": [0], "end1": [8]}))
PY
fe2cb coupler.fe.h5 --modes 6 -o coupler.cb.h5 -q || exit 1
scene() {  # scene NAME JOINT_B_POINT EXTRA_BODY_KEYS FILE
  cat > "$1" <<YAML
title: parallelogram four-bar, flexible coupler
solver: {t_end: 0.1}
bodies:
  - {name: crank, geometry: {shape: sphere, radius: 0.02, density: 7800}, position: [0, 0.05, 0]}
  - {name: coupler, type: flexible, file: ${4:-coupler.cb.h5}, position: [0, 0.1, 0]$3}
  - {name: rocker, geometry: {shape: sphere, radius: 0.02, density: 7800}, position: [0.4, 0.05, 0]}
joints:
  - {name: O, type: revolute, body1: ground, body2: crank, point: [0, 0, 0], axis: z}
  - {name: A, type: revolute, body1: crank, body2: coupler, point: [0, 0.1, 0], axis: z, at2: {interface: end0}}
  - {name: B, type: revolute, body1: coupler, body2: rocker, point: [$2], axis: z, at1: {interface: end1}}
  - {name: C, type: revolute, body1: rocker, body2: ground, point: [0.4, 0, 0], axis: z}
drivers:
  - {name: motor, joint: O, function: {type: linear, rate: 6.283185307179586}}
YAML
}
scene good.yaml "0.4, 0.1, 0" ""
# the rocker's frame driven along x, at t = 0.5 s 0.5 m away from where the 0.1 m rocker can reach
scene far.yaml "0.4, 0.1, 0" ""
sed -i 's/{name: motor, joint: O, function: {type: linear, rate: 6.283185307179586}}/{name: push, body: rocker, coordinate: x, function: {type: linear, v0: 0.4, rate: 1}}/' far.yaml
scene notbody.yaml "0.4, 0.1, 0" "" good.gm.h5
scene missing.yaml "0.4, 0.1, 0" "" nosuch.cb.h5
scene typo.yaml "0.4, 0.1, 0" ", colour: red"
cat > clamped.yaml <<'YAML'
title: a beam clamped at both ends, no mobility
solver: {t_end: 0.1}
bodies:
  - {name: beam, type: flexible, file: coupler.cb.h5}
joints:
  - {name: c0, type: fixed, body1: ground, body2: beam, at2: {interface: end0}}
  - {name: c1, type: fixed, body1: beam, body2: ground, at1: {interface: end1}}
YAML

# expect_fail STATUS PATTERN OUTPUT -- args...: exit status, a regex the message must match
expect_fail() {
  local st=$1 pat=$2 out=$3; shift 4
  gmsolve "$@" > stdout.txt 2> stderr.txt
  local rc=$?
  [ $rc -eq "$st" ] || bad "gmsolve $*: exit $rc, expected $st ($(cat stderr.txt))"
  grep -q '^gmsolve: error: ' stderr.txt || bad "gmsolve $*: no 'gmsolve: error:' line: $(cat stderr.txt)"
  grep -Eq -e "$pat" stderr.txt || bad "gmsolve $*: message does not match /$pat/: $(cat stderr.txt)"
  [ -n "$out" ] && { [ -e "$out" ] || [ -e "$out.part" ]; } && bad "gmsolve $*: output $out left behind"
  grep '^gmsolve: error: ' stderr.txt  # the message, for the log
  return 0
}

# --- good runs ----------------------------------------------------------------------------------
gmsolve good.yaml -o good.gm.h5 --modes 4 -q 2> err.txt || bad "good run failed: $(cat err.txt)"
[ -s err.txt ] && bad "-q printed: $(cat err.txt)"
gmsolve good.yaml -o good.gm.h5 --modes 4 2> err.txt || bad "good run failed"
grep -Eq '^gmsolve: good\.gm\.h5: f = 1 rigid-reference modes, 4 flexible global modes [0-9.]+ \.\. [0-9.]+ Hz, [0-9.e-]+ s wall, [0-9.e-]+ s cpu$' err.txt \
  || bad "summary line: $(cat err.txt)"
gmsolve good.yaml -o v.gm.h5 --modes 4 -v 2> err.txt || bad "-v run failed"
grep -q 'null space' err.txt && grep -q 'eigensolution' err.txt && grep -q 'GMc basis' err.txt \
  || bad "-v breakdown missing: $(cat err.txt)"
gmsolve good.yaml -o fmax.gm.h5 --fmax 1000 -q || bad "--fmax failed"
gmsolve clamped.yaml -o clamped.gm.h5 --modes 3 2> err.txt || bad "clamped (f = 0) failed: $(cat err.txt)"
grep -q 'f = 0 rigid-reference modes' err.txt || bad "clamped: does not say f = 0: $(cat err.txt)"
# --at: the crank driven an eighth of a turn (pi/4 about z): the coupler's frame (at the crank's
# tip) goes to 0.1 (-sin 45, cos 45, 0). (A quarter turn flattens the parallelogram: a singular
# configuration with two zero modes, which gmsolve refuses against the mobility 1.)
gmsolve good.yaml -o at.gm.h5 --modes 2 --at 0.125 --matrices -q || bad "--at failed"
expect_fail 1 'good\.yaml: 2 zero-frequency modes found.*mobility of the mechanism is 1' flat.gm.h5 -- good.yaml -o flat.gm.h5 --modes 2 --at 0.25
"$PYTHON" - <<'PY' || bad "--at: the rigid-reference configuration is not the driven one"
import h5py, numpy as np
f = h5py.File("at.gm.h5", "r")
x, c, g = f["linear/x"][()], f["global/coordinates"][()], f["global"].attrs
R = x[(c[:, 0] == 1) & (c[:, 1] < 3)]
q = x[(c[:, 0] == 1) & (c[:, 1] >= 7)]
assert g["time"] == 0.125, g["time"]
# the projection stops at 1e-12 of the mechanism's size: 1e-10
s = 0.1 * np.sqrt(0.5)
assert np.allclose(R, [-s, s, 0.0], atol=1e-10), R
assert np.all(q == 0.0), q
with h5py.File("fmax.gm.h5", "r") as h:
    fr = h["global/frequency_hz"][()]
    assert len(fr) >= 1 and fr[-1] <= 1000, fr
PY
gmsolve good.yaml -o plot.gm.h5 --modes 2 --plot pl -q || bad "--plot failed"
{ grep -q '<svg' pl-mode1.svg && grep -q 'global mode 2' pl-mode2.svg && [ ! -e pl-mode3.svg ]; } \
  || bad "--plot: pl-mode1.svg, pl-mode2.svg expected (and no third)"
gmsolve -M good.yaml > rules.mk 2> err.txt || bad "-M failed: $(cat err.txt)"
grep -q '^good\.gm\.h5: good\.yaml' rules.mk && grep -q 'coupler\.cb\.h5' rules.mk || bad "-M rules: $(cat rules.mk)"

# --- bad input (exit 1) ---------------------------------------------------------------------------
gmsolve far.yaml -o far.gm.h5 --modes 2 -q || bad "far.yaml at t = 0 (reachable) failed"
expect_fail 1 "far\.yaml.*cannot be satisfied at t = 0\.5 s.*far\.yaml:[0-9]+: (joint|driver) '[A-Za-z]+'" out1.gm.h5 -- far.yaml -o out1.gm.h5 --at 0.5
expect_fail 1 'good\.yaml.*50 flexible modes asked for; the mechanism has 9' out2.gm.h5 -- good.yaml -o out2.gm.h5 --modes 50
expect_fail 1 'fourbar\.yaml.*no flexible mode.*f = 1' out3.gm.h5 -- "$ROOT/examples/scenes/fourbar.yaml" -o out3.gm.h5
expect_fail 1 'notbody\.yaml:5:.*good\.gm\.h5 is a fmbd-gm file' out4.gm.h5 -- notbody.yaml -o out4.gm.h5
expect_fail 1 'missing\.yaml:5:.*nosuch\.cb\.h5' out5.gm.h5 -- missing.yaml -o out5.gm.h5
expect_fail 1 "typo\.yaml:5:.*unknown key 'colour'" out6.gm.h5 -- typo.yaml -o out6.gm.h5
expect_fail 1 'no flexible mode below the bound' out7.gm.h5 -- good.yaml -o out7.gm.h5 --fmax 1

# --- usage (exit 2) -------------------------------------------------------------------------------
expect_fail 2 'unknown option' u1.gm.h5 -- good.yaml -o u1.gm.h5 --bogus
expect_fail 2 'exclusive' u2.gm.h5 -- good.yaml -o u2.gm.h5 --modes 3 --fmax 100
expect_fail 2 "option --modes: '0' must be >= 1" u3.gm.h5 -- good.yaml -o u3.gm.h5 --modes 0
expect_fail 2 'no SCENE' u4.gm.h5 --
expect_fail 2 'rank-tol' u5.gm.h5 -- good.yaml -o u5.gm.h5 --rank-tol 2
exit $fail
