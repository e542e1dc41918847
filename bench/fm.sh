#!/bin/bash
# bench/fm.sh: cost of a full FE body in fmbd-run (make bench BENCH_ONLY=fm)
# The quadruple pendulum of examples/quadpend with its flexible rod as the full model (FM: the
# rod's .fe.h5, every FE dof in the floating frame, docs/THEORY.md section 4b), tet10 meshes of
# three sizes (--size 0.015, 0.01 and the demo's 0.0075: about 3 k, 6.7 k and 14.7 k dofs),
# over a short span (0.05 s): fixed 5e-4 s steps (Newton and solve cost, few factorisations) and
# the example's variable steps (tolerance 1e-2: refactorisations when h changes). Side by side,
# the peer: the same scene with the demo's reduced rod (.cb.h5, first 30 flexible modes of the
# CB reduction with 110 fixed-interface modes) on the largest mesh. Per size: dofs, steps,
# Newton iterations, factorisations, CPU time per step and per Newton iteration, and the CPU
# time the demo's 7 s would take at the variable-step rate. Results on stdout and in $BENCH_OUT.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
OUT=${BENCH_OUT:-$ROOT/$BUILD/bench}/fm
mkdir -p "$OUT"
export PATH="$ROOT/$BUILD/bin:$PATH" OPENBLAS_NUM_THREADS=1
cd "$OUT" || exit 1
SIZES=${FM_SIZES:-"0.015 0.01 0.0075"}
for s in $SIZES; do
  [ -f "rod$s.fe.h5" ] || mesh2fe "$ROOT/examples/geometry/rod.geo" --size "$s" --E 100e9 --nu 0.285 \
    --rho 7850 --interface 'end0@-0.05,0,0' -o "rod$s.fe.h5" -q || exit 1
done
last=${SIZES##* }
[ -f rod.cb.h5 ] || fe2cb "rod$last.fe.h5" --modes 110 -o rod.cb.h5 -q || exit 1

"$PYTHON" - "$ROOT" $SIZES <<'EOF'
import re, subprocess, sys
import h5py
import numpy as np

ROOT, sizes = sys.argv[1], sys.argv[2:]
scene = open(f"{ROOT}/examples/quadpend/quadpend.yaml").read()
scene = re.sub(r"    make:\n(      .*\n)+", "", scene).replace("t_end: 7", "t_end: 0.05")
fixed = re.sub(r"first_step:.*\n", "step: 5e-4\n", scene)
fixed = re.sub(r" *max_step:.*\n", "", re.sub(r" *tolerance:.*\n( *#.*\n)*", "", fixed))


def run(name, text):
    open(name + ".yaml", "w").write(text)
    p = subprocess.run(["fmbd-run", name + ".yaml", "-o", name + ".run.h5", "-q"], capture_output=True, text=True)
    if p.returncode:
        print(p.stderr)
        return None
    with h5py.File(name + ".run.h5", "r") as f:
        return dict(f["stats"].attrs)


print(f"{'rod body':30s} {'coords':>7s} {'steps':>6s} {'rej':>4s} {'Newton':>7s} {'fact':>5s} "
      f"{'cpu s':>7s} {'ms/step':>8s} {'ms/iter':>8s} {'7 s demo':>9s}")
rows = []
for s in sizes:
    for mode, text in (("fixed 5e-4", fixed), ("variable", scene)):
        st = run(f"fm{s}-{mode[:3]}", text.replace("file: rod.rflex.h5", f"file: rod{s}.fe.h5"))
        if not st:
            continue
        cpu = st["run_cpu_time_s"]
        est = cpu / st["t_reached"] * 7 / 60
        print(f"{'FM ' + s + ' ' + mode:30s} {st['coordinates']:7d} {st['steps']:6d} {st['rejected_steps']:4d} "
              f"{st['newton_iterations']:7d} {st['factorizations']:5d} {cpu:7.3g} "
              f"{1e3 * cpu / st['steps']:8.1f} {1e3 * cpu / st['newton_iterations']:8.2f} {est:7.1f} min")
        rows.append((s, mode, st))
for mode, text in (("fixed 5e-4", fixed), ("variable", scene)):
    st = run(f"cb30-{mode[:3]}", text.replace("file: rod.rflex.h5", "file: rod.cb.h5\n    modes: 30"))
    if st:
        cpu = st["run_cpu_time_s"]
        print(f"{'CB 30 modes (' + sizes[-1] + ') ' + mode:30s} {st['coordinates']:7d} {st['steps']:6d} "
              f"{st['rejected_steps']:4d} {st['newton_iterations']:7d} {st['factorizations']:5d} {cpu:7.3g} "
              f"{1e3 * cpu / st['steps']:8.1f} {1e3 * cpu / st['newton_iterations']:8.2f} "
              f"{cpu / st['t_reached'] * 7 / 60:7.1f} min")
# the variable-step rate past the first step-size ramp (from first_step 1e-6 s): the smallest
# mesh over 0.5 s
st = run(f"fm{sizes[0]}-var-long", scene.replace("t_end: 0.05", "t_end: 0.5")
         .replace("file: rod.rflex.h5", f"file: rod{sizes[0]}.fe.h5"))
if st:
    cpu = st["run_cpu_time_s"]
    print(f"{'FM ' + sizes[0] + ' variable, 0.5 s':30s} {st['coordinates']:7d} {st['steps']:6d} "
          f"{st['rejected_steps']:4d} {st['newton_iterations']:7d} {st['factorizations']:5d} {cpu:7.3g} "
          f"{1e3 * cpu / st['steps']:8.1f} {1e3 * cpu / st['newton_iterations']:8.2f} "
          f"{cpu / st['t_reached'] * 7 / 60:7.1f} min")
fx = [(r[2]["coordinates"], r[2]["run_cpu_time_s"] / r[2]["newton_iterations"]) for r in rows if r[1] == "fixed 5e-4"]
if len(fx) >= 2:
    a = np.polyfit(np.log([x[0] for x in fx]), np.log([x[1] for x in fx]), 1)[0]
    print(f"cost per Newton iteration (fixed steps) grows as dofs^{a:.2f}")
EOF
