#!/bin/bash
# fuzz/seeds.sh OUT: the seed corpus of every fuzz target, made by the programs of $BUILD (the
# normal build) from tiny inputs: OUT/KIND/ for KIND in scene fe cb rflex run. A seed is a valid
# file of its kind; libFuzzer mutates it (and keeps the inputs that reach new code).
set -eu
ROOT=$(cd "$(dirname "$0")/.." && pwd)
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
OUT=$1
export PATH="$ROOT/$BUILD/bin:$PATH" FMBD_LOG=error
mkdir -p "$OUT"/{scene,fe,cb,rflex,run}
W=$(mktemp -d) && trap 'rm -rf "$W"' EXIT
cd "$W"
# a beam body (fegen) and a coarse tet4 rod (solid: /mesh/elements and modal stress)
PYTHONPATH=$ROOT/tests/py "$PYTHON" - <<'PY'
import fegen
fegen.write("beam.fe.h5", fegen.beam(n_el=6, interfaces={"end0": [0], "end1": [6]}))
PY
mesh2fe "$ROOT/examples/geometry/rod.geo" --order 1 --size 0.03 --interface end0 --interface end1 \
  -o rod.fe.h5 -q
for b in beam rod; do
  fe2cb $b.fe.h5 --modes 4 -o $b.cb.h5 -q
  cbcheck $b.cb.h5 -o $b.rflex.h5 -q >/dev/null
  cp $b.fe.h5 $b.cb.h5 $b.rflex.h5 "$OUT"/ 2>/dev/null || true
done
mv "$OUT"/*.fe.h5 "$OUT/fe/"; mv "$OUT"/*.cb.h5 "$OUT/cb/"; mv "$OUT"/*.rflex.h5 "$OUT/rflex/"
cat >run.yaml <<'Y'
solver: {t_end: 0.002, step: 0.001}
bodies:
  - {name: rod, type: flexible, file: rod.rflex.h5, angular_velocity: [0, 0, 1]}
  - {name: p, mass: 1, inertia: [1, 1, 1], position: [1, 0, 0]}
joints:
  - {name: j, type: spherical, body1: ground, body2: p, point: [0, 0, 0]}
outputs:
  every: 0.001
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position, velocity, acceleration]}
    - {name: p, body: p, point: [0, 0, 0], quantities: [position]}
Y
fmbd-run run.yaml -o "$OUT/run/tiny.run.h5" -q
cp "$ROOT"/examples/scenes/*.yaml run.yaml "$OUT/scene/"
