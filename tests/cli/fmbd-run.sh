#!/bin/bash
# tests/cli/fmbd-run.sh: fmbd-run on bad input: every failure exits with the documented status,
# names the file and the scene line:column (or the time and the constraint), and leaves no
# output target behind; an interrupted run keeps RUN.h5.part marked incomplete.
set -u
T=$ROOT/$BUILD/test-tmp/fmbd-run
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
PY=${PYTHON:-/usr/bin/python3}

# expect NAME STATUS REGEX -- command...: exit status, stderr matching REGEX, no out.run.h5
expect() {
  local name=$1 status=$2 re=$3
  shift 4
  rm -f out.run.h5 out.run.h5.part
  "$@" >stdout.txt 2>stderr.txt
  local st=$?
  if [ $st -ne "$status" ]; then
    echo "$name: exit $st, expected $status"; cat stderr.txt; fail=1; return
  fi
  if ! grep -Eq -- "$re" stderr.txt; then
    echo "$name: stderr does not match '$re':"; cat stderr.txt; fail=1
  fi
  if [ -e out.run.h5 ]; then echo "$name: out.run.h5 left behind"; fail=1; fi
}

head='solver: {t_end: 1}
bodies:
  - {name: p, mass: 1, inertia: [1, 1, 1], position: [1, 0, 0]}
'
# --- scene errors: file:line:column -------------------------------------------------------
printf '%sjoints:\n  - name: j1\n    type: spherical\n    body1: ground\n    body2: p\n    point: [0, 0, 0]\n    foo: 1\n' "$head" >unknown.yaml
expect unknown-key 1 "^fmbd-run: error: unknown.yaml:10:5: unknown key 'foo' in joint 'j1'$" -- fmbd-run unknown.yaml -o out.run.h5

printf '%sjoints:\n  - {name: j1, type: spherical, body1: ground, body2: q, point: [0, 0, 0]}\n' "$head" >nobody.yaml
expect missing-body 1 "nobody.yaml:5:55: body2: no body named 'q'" -- fmbd-run nobody.yaml -o out.run.h5

printf 'solver: {t_end: 1}\nbodies:\n  - {name: p, mass: 0, inertia: [1, 1, 1]}\n' >massless.yaml
expect zero-mass 1 "massless.yaml:3:21: .*mass matrix singular" -- fmbd-run massless.yaml -o out.run.h5

printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: missing.rflex.h5}\n' >nofile.yaml
expect missing-file 1 "nofile.yaml:3:39: body 'rod': missing.rflex.h5" -- fmbd-run nofile.yaml -o out.run.h5

printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: nofile.yaml}\n' >notfmbd.yaml
expect not-hdf5 1 "notfmbd.yaml:3:39: body 'rod': nofile.yaml" -- fmbd-run notfmbd.yaml -o out.run.h5

expect bad-reference 1 "^fmbd-run: error: nofile.yaml: .*HDF5" -- fmbd-run "$ROOT/examples/scenes/pendulum.yaml" -o out.run.h5 --reference nofile.yaml
expect no-scene 1 "missing.yaml: cannot open the scene" -- fmbd-run missing.yaml -o out.run.h5
expect usage 2 "no scene file given" -- fmbd-run -o out.run.h5
expect bad-t-end 2 "t-end" -- fmbd-run unknown.yaml --t-end -1 -o out.run.h5

# --- initial conditions that cannot be projected: a bar hangs from a spherical joint 0.5 m
# from its centre, and a driver asks for its centre 5 m from that joint
cat >apart.yaml <<'EOF'
solver: {t_end: 1}
bodies:
  - {name: bar, mass: 1, inertia: [0.1, 0.1, 0.1], position: [0, 0.5, 0], orientation: {axis: z, angle_deg: 90}}
joints:
  - {name: hang, type: spherical, body1: ground, body2: bar, at1: {point: [0, 0, 0]}, at2: {point: [-0.5, 0, 0]}}
drivers:
  - {name: far, body: bar, coordinate: x, function: 5}
EOF
expect no-projection 1 "apart.yaml: initial positions cannot be made consistent.*(joint 'hang'|driver 'far'|body 'bar')" -- fmbd-run apart.yaml -o out.run.h5

# --- Newton failure at the smallest step: a driver pulls the bob of a 1 m pendulum beyond
# its reach (x = 0.5 + t > 1 for t > 0.5 s): the run must stop near t = 0.5 s naming the
# time and an equation, keep the prefix as out.run.h5.part (complete = 0), and no target
cat >reach.yaml <<'EOF'
gravity: [0, -9.81, 0]
solver: {t_end: 1, first_step: 1e-3, max_step: 1e-2, min_step: 1e-7}
bodies:
  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [0.5, -0.8660254037844386, 0]}
joints:
  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], at2: {point: [-0.5, 0.8660254037844386, 0]}, axis: z}
drivers:
  - {name: pull, body: bob, coordinate: x, function: {type: linear, v0: 0.5, rate: 1}}
outputs:
  points: [{name: bob, body: bob}]
EOF
expect newton 1 "t = 0\.(4[5-9]|5[0-2])[0-9]* s.*(joint 'pivot'|driver 'pull'|body 'bob')" -- fmbd-run reach.yaml -o out.run.h5
if [ -f out.run.h5.part ]; then
  "$PY" - <<'EOF' || fail=1
import h5py, sys
with h5py.File("out.run.h5.part", "r") as f:
    c, n, t = f["stats"].attrs["complete"], f["time"].shape[0], f["time"][-1]
    # the prefix: at least the initial row, the last row before the failure near 0.5 s
    if c != 0 or n < 2 or not (0.3 < t < 0.53):
        sys.exit(f"newton: prefix complete={c} rows={n} t_last={t}")
EOF
else
  echo "newton: no out.run.h5.part kept"; fail=1
fi

# --- interruption: SIGINT keeps a valid prefix marked incomplete, exit 1, no target
cat >long.yaml <<'EOF'
gravity: [0, -9.81, 0]
solver: {t_end: 100000, step: 1e-4}
bodies:
  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}
joints:
  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}
outputs:
  points: [{name: bob, body: bob}]
EOF
rm -f out.run.h5 out.run.h5.part
fmbd-run long.yaml -o out.run.h5 2>stderr.txt &
pid=$!
for _ in $(seq 50); do [ -f out.run.h5.part ] && break; sleep 0.1; done
sleep 1
kill -INT $pid
wait $pid
st=$?
[ $st -eq 1 ] || { echo "sigint: exit $st, expected 1"; cat stderr.txt; fail=1; }
grep -q "interrupted by signal 2" stderr.txt || { echo "sigint: message"; cat stderr.txt; fail=1; }
[ -e out.run.h5 ] && { echo "sigint: target left"; fail=1; }
if [ -f out.run.h5.part ]; then
  "$PY" - <<'EOF' || fail=1
import h5py, sys
with h5py.File("out.run.h5.part", "r") as f:
    c, n = f["stats"].attrs["complete"], f["time"].shape[0]
    m = f["outputs/bob/position"].shape[0]
    if c != 0 or n < 10 or m != n:
        sys.exit(f"sigint: prefix complete={c} time rows={n} position rows={m}")
EOF
else
  echo "sigint: no out.run.h5.part"; fail=1
fi

# --- the examples of the man page (docs/man/fmbd-run.1) run as written ---------------------
ex=$ROOT/examples
( cd "$T" && mkdir -p man && cd man &&
  fmbd-run "$ex/scenes/pendulum.yaml" -o pendulum.run.h5 --plot pend- -q &&
  [ -f pend-bob-trajectory.svg ] &&
  fmbd-run -M "$ex/quadpend/quadpend.yaml" --body-dir out | grep -q "^out/rod.rflex.h5: out/rod.cb.h5 out/rod.fe.h5 $ex/quadpend/quadpend.yaml\$" &&
  fmbd-run "$ex/scenes/pendulum.yaml" -o coarse.run.h5 --reference pendulum.run.h5 2>ref.err &&
  grep -Eq "^fmbd-run: +bob +position +0\.0000e\+00 +0\.0000e\+00 " ref.err ) || { echo "man page examples failed"; fail=1; }

# --- a load of absurd magnitude overflows: said as such (was "singular iteration matrix")
cat >overflow.yaml <<'EOF'
solver: {t_end: 0.1}
bodies:
  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}
joints:
  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}
loads:
  - {name: push, type: force, body: bob, point: [0, 0, 0], direction: [0, 1, 0], function: {type: ramp, t1: 0.01, v1: 1e300}}
EOF
expect overflow 1 "^fmbd-run: error: overflow.yaml: t = .* s: the equations are not finite \(overflow" -- fmbd-run overflow.yaml -o out.run.h5
rm -f out.run.h5.part

# --- a runaway run is announced before the work (it was silent while writing 25 MB/s)
printf 'solver: {t_end: 1000, step: 1e-12}\nbodies:\n  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}\njoints:\n  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}\noutputs:\n  points:\n    - {name: bob, body: bob, point: [0, 0, 0], quantities: [position]}\n' >runaway.yaml
timeout 2 fmbd-run runaway.yaml -o runaway.run.h5 2>runaway.err
grep -q "warning: runaway.yaml: fixed step: 1e+15 steps" runaway.err || { echo "runaway: no step-count warning"; cat runaway.err; fail=1; }
grep -q "output rows" runaway.err || { echo "runaway: no output-size warning"; fail=1; }
[ -e runaway.run.h5 ] && { echo "runaway: complete target after a kill"; fail=1; }
rm -f runaway.run.h5.part

# --- a fixed step that does not divide outputs.every is named (each interval would end with a
# shorter step: bench/README.md, "Fixed steps and the output interval"); a divisor is not
for ev in 0.014:warn 0.015:quiet; do
  printf 'solver: {t_end: 0.03, step: 1.5e-3}\nbodies:\n  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}\njoints:\n  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}\noutputs:\n  every: %s\n' "${ev%%:*}" >every.yaml
  fmbd-run every.yaml -o every.run.h5 2>every.err || { echo "every ${ev%%:*}: run failed"; cat every.err; fail=1; }
  if [ "${ev##*:}" = warn ]; then
    grep -q "warning: every.yaml: the fixed step 0.0015 s does not divide outputs.every 0.014 s: each output interval ends with a step of 0.0005 s" every.err || { echo "every 0.014: no warning"; cat every.err; fail=1; }
  else
    grep -q "does not divide" every.err && { echo "every 0.015: a warning for a divisor"; cat every.err; fail=1; }
  fi
done

# --- a driver is never dropped as redundant (it was, with a warning, and the run exited 0 far
# from the prescribed motion): at a singular position, and fighting a locked chain
printf 'solver: {t_end: 0.5}\nbodies:\n  - {name: bob, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}\njoints:\n  - {name: pivot, type: revolute, body1: ground, body2: bob, point: [0, 0, 0], axis: z}\ndrivers:\n  - {name: pushx, body: bob, coordinate: x, function: {type: linear, v0: 1, rate: 1}}\n' >drvsing.yaml
expect driver-singular 1 "^fmbd-run: error: drvsing.yaml: t = 0 s: the driver 'pushx' .* depends on the joint equations" -- fmbd-run drvsing.yaml -o out.run.h5
printf 'solver: {t_end: 0.5}\nbodies:\n  - {name: a, mass: 1, inertia: [1e-3, 1e-3, 1e-3], position: [1, 0, 0]}\njoints:\n  - {name: pivot, type: revolute, body1: ground, body2: a, point: [0, 0, 0], axis: z}\n  - {name: lock, type: fixed, body1: ground, body2: a, point: [1, 0, 0]}\ndrivers:\n  - {name: motor, joint: pivot, function: {type: linear, rate: 1}}\n' >drvlock.yaml
expect driver-locked 1 "^fmbd-run: error: drvlock.yaml: t = 0 s: the driver 'motor' .* depends on the joint equations" -- fmbd-run drvlock.yaml -o out.run.h5

# --- a reference must be a complete run with a finite, strictly increasing /time ------------
if [ -f man/pendulum.run.h5 ]; then
  "$PY" - <<'PYEOF' || { echo "reference fixtures failed"; fail=1; }
import shutil, h5py, numpy as np
for name in ("incomplete", "constant", "backwards"):
    shutil.copy("man/pendulum.run.h5", name + ".run.h5")
with h5py.File("incomplete.run.h5", "r+") as f:
    f["stats"].attrs["complete"] = np.int64(0)
with h5py.File("constant.run.h5", "r+") as f:
    f["time"][...] = 0.5
with h5py.File("backwards.run.h5", "r+") as f:
    t = f["time"][()]
    t[7] = t[3]
    f["time"][...] = t
PYEOF
  pend=$ex/scenes/pendulum.yaml
  expect ref-incomplete 1 "^fmbd-run: error: incomplete.run.h5:/stats: attribute complete = 0: the reference is an interrupted run" -- fmbd-run "$pend" -o out.run.h5 --reference incomplete.run.h5
  expect ref-constant 1 "^fmbd-run: error: constant.run.h5:/time: not strictly increasing at instant 1" -- fmbd-run "$pend" -o out.run.h5 --reference constant.run.h5
  expect ref-backwards 1 "^fmbd-run: error: backwards.run.h5:/time: not strictly increasing at instant 7" -- fmbd-run "$pend" -o out.run.h5 --reference backwards.run.h5
fi

# --- flexible bodies: need a reduced body from the toolchain ------------------------------
if mesh2fe "$ROOT/examples/geometry/rodbeam.geo" --circle 0.015 --interface end0 --interface end1 -o rod.fe.h5 -q 2>mesh.err &&
  fe2cb rod.fe.h5 --modes 10 -o rod.cb.h5 -q 2>cb.err &&
  cbcheck rod.cb.h5 --fe rod.fe.h5 -o rod.rflex.h5 -q >/dev/null 2>check.err; then
  # (a .fe.h5 is a full-model body, tests/py/test_fm.py; a run file is of no body kind)
  fmbd-run "$pend" -o wk.run.h5 -q
  printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: wk.run.h5}\n' >wrongkind.yaml
  expect wrong-kind 1 "wrongkind.yaml:3:39: body 'rod': wk.run.h5 is a fmbd-run file" -- fmbd-run wrongkind.yaml -o out.run.h5
  printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: rod.rflex.h5}\njoints:\n  - {name: j, type: spherical, body1: ground, body2: rod, point: [0.1, 0.02, 0]}\n' >offbody.yaml
  expect off-body 1 "offbody.yaml:5:66: joint 'j': the point \(0.1, 0.02, 0\) \(body frame\) is not on body 'rod'" -- fmbd-run offbody.yaml -o out.run.h5
  printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: rod.rflex.h5}\njoints:\n  - {name: j, type: fixed, body1: ground, body2: rod, at2: {interface: middle}}\n' >noif.yaml
  expect no-interface 1 "noif.yaml:5:72: joint 'j': body 'rod' .* has no interface 'middle' \(it has: end0, end1\)" -- fmbd-run noif.yaml -o out.run.h5
  printf 'solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: rod.rflex.h5, modes: 500}\n' >toomany.yaml
  expect too-many-modes 1 "toomany.yaml:3:39: body 'rod' asks for 500 modes" -- fmbd-run toomany.yaml -o out.run.h5
  # physical data checked where it is read (it surfaced as "Newton did not converge", or not at all)
  "$PY" - <<'PYEOF' || { echo "physical-data fixtures failed"; fail=1; }
import shutil, h5py, numpy as np
def bad(name, edit):
    shutil.copy("rod.rflex.h5", name + ".rflex.h5")
    with h5py.File(name + ".rflex.h5", "r+") as f:
        edit(f)
    with open(name + ".yaml", "w") as y:
        y.write("solver: {t_end: 1}\nbodies:\n  - {name: rod, type: flexible, file: %s.rflex.h5}\n" % name)
bad("mass0", lambda f: f["ffrf/mass"].__setitem__((), 0.0))
bad("massneg", lambda f: f["ffrf/mass"].__setitem__((), -1.0))
def neg_inertia(f):
    J = f["ffrf/second_moment"][()]
    J[0, 0] = 10 * (J[1, 1] + J[2, 2])   # a principal moment above the sum of the others
    f["ffrf/second_moment"][...] = J
bad("inertia", neg_inertia)
def asym_k(f):
    K = f["ffrf/Kff"][()]
    K[0, 1] = 0.5 * K[0, 0]
    f["ffrf/Kff"][...] = K
bad("asymk", asym_k)
def neg_k(f):
    K = f["ffrf/Kff"][()]
    K[1, 1] = -K[1, 1]
    f["ffrf/Kff"][...] = K
bad("negk", neg_k)
def eig_k(f):
    e = f["modes/eigenvalue"][()]
    e[2] *= 1.5
    f["modes/eigenvalue"][...] = e
bad("eigk", eig_k)
PYEOF
  expect phys-mass0 1 "mass0.rflex.h5:/ffrf/mass: mass 0 must be positive" -- fmbd-run mass0.yaml -o out.run.h5
  expect phys-massneg 1 "massneg.rflex.h5:/ffrf/mass: mass -1 must be positive" -- fmbd-run massneg.yaml -o out.run.h5
  expect phys-inertia 1 "inertia.rflex.h5:/ffrf/second_moment: .*not physical" -- fmbd-run inertia.yaml -o out.run.h5
  expect phys-asymk 1 "asymk.rflex.h5:/ffrf/Kff: not symmetric" -- fmbd-run asymk.yaml -o out.run.h5
  expect phys-negk 1 "negk.rflex.h5:/ffrf/Kff: diagonal entry 1 .* negative" -- fmbd-run negk.yaml -o out.run.h5
  expect phys-eigk 1 "eigk.rflex.h5:/ffrf/Kff: diagonal entry 2 .* /modes/eigenvalue says" -- fmbd-run eigk.yaml -o out.run.h5
else
  echo "flexible-body cases: the toolchain could not make rod.rflex.h5:"; cat mesh.err cb.err check.err 2>/dev/null
  fail=1
fi
exit $fail
