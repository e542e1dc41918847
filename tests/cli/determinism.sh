#!/bin/bash
# tests/cli/determinism.sh: the same inputs give the same outputs, bit for bit (docs/STABILITY.md,
# "Determinism"). The pipeline mesh2fe -> fe2cb -> cbcheck -> fmbd-run runs twice in two folders
# under the same file names, with one BLAS thread (OPENBLAS_NUM_THREADS=1, as make check runs);
# every dataset must be equal byte for byte and every attribute equal, except the ones that
# record the run's times (wall_time_s, cpu_time_s on the root, /stats timings of fmbd-run) and,
# as a consequence, the SHA-256 of an upstream file (the `inputs` hashes, /cb fe_sha256): a
# file's bytes include its times (and HDF5's object time stamps), so a file remade from the same
# inputs has the same content and another hash. The files' names in `inputs` must be equal.
# Then the same with two BLAS threads: printed (threaded BLAS may sum in another order), and
# compared with the single-thread result to the figures' round-off.
set -u
ROOT=${ROOT:-$(cd "$(dirname "$0")/../.." && pwd)}
BUILD=${BUILD:-build}
PYTHON=${PYTHON:-/usr/bin/python3}
export PATH="$ROOT/$BUILD/bin:$PATH"
T=$ROOT/$BUILD/test-tmp/cli-determinism
rm -rf "$T" && mkdir -p "$T" && cd "$T" || exit 1
fail=0
pipeline() {  # folder
  mkdir -p "$1" && cd "$1" || return 1
  cp "$ROOT/examples/geometry/rod.geo" . &&
    mesh2fe rod.geo --size 0.012 --interface end0 --interface end1 -o rod.fe.h5 -q &&
    fe2cb rod.fe.h5 --modes 12 -o rod.cb.h5 -q &&
    cbcheck rod.cb.h5 --tol 1e-3 -o rod.rflex.h5 -q >/dev/null &&
    cat >run.yaml <<'Y' &&
solver: {t_end: 0.02, first_step: 1e-5, max_step: 1e-3, tolerance: 1e-6}
gravity: [0, 0, -9.81]
bodies:
  - {name: rod, type: flexible, file: rod.rflex.h5, angular_velocity: [0, 0, 20]}
joints:
  - {name: pin, type: revolute, body1: ground, body2: rod, at2: {interface: end0}, axis: [0, 1, 0]}
outputs:
  every: 0.001
  energy: true
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position, velocity, von_mises]}
Y
    fmbd-run run.yaml -o run.run.h5 -q
  local rc=$?
  cd "$T"
  return $rc
}
OPENBLAS_NUM_THREADS=1 pipeline a || { echo "FAIL: pipeline a"; exit 1; }
OPENBLAS_NUM_THREADS=1 pipeline b || { echo "FAIL: pipeline b"; exit 1; }
OPENBLAS_NUM_THREADS=2 pipeline c || { echo "FAIL: pipeline c"; exit 1; }
"$PYTHON" - <<'PY' || fail=1
import sys
import h5py
import numpy as np

TIMES = {"wall_time_s", "cpu_time_s"}
HASHES = {"fe_sha256"}  # of an upstream file, whose bytes hold its times

def items(path):
    """{name: bytes or value} of every dataset and attribute, times left out."""
    out = {}
    with h5py.File(path, "r") as f:
        def attrs(name, obj):
            for k, v in obj.attrs.items():
                if k in TIMES or k in HASHES or (name.startswith("stats") and k.endswith("_s")):
                    continue
                if k == "inputs":  # (n, 2): names compared, hashes not (see above)
                    v = [str(r[0]) for r in np.asarray(v)]
                a = np.asarray(v)
                out["@%s:%s" % (name, k)] = repr(v) if a.dtype.kind in "OUS" else (a.dtype.str, a.tobytes())
        attrs("/", f)
        def visit(name, obj):
            attrs(name, obj)
            if isinstance(obj, h5py.Dataset):
                out[name] = (obj.dtype.str, obj.shape, obj[()].tobytes())
        f.visititems(visit)
    return out

def compare(x, y):
    a, b = items(x), items(y)
    diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return len(a), diff

bad = 0
for kind in ("fe", "cb", "rflex", "run"):
    n, diff = compare("a/rod.%s.h5" % kind if kind != "run" else "a/run.run.h5",
                      "b/rod.%s.h5" % kind if kind != "run" else "b/run.run.h5")
    print("%-5s one BLAS thread, twice: %d objects, %d differ %s" % (kind, n, len(diff), diff[:5]))
    bad |= len(diff) > 0
    n, diff = compare("a/rod.%s.h5" % kind if kind != "run" else "a/run.run.h5",
                      "c/rod.%s.h5" % kind if kind != "run" else "c/run.run.h5")
    print("%-5s one vs two BLAS threads: %d differ %s" % (kind, len(diff), diff[:5]))
with h5py.File("a/run.run.h5") as f, h5py.File("c/run.run.h5") as g:
    d = np.max(np.abs(f["outputs/tip/position"][()] - g["outputs/tip/position"][()]))
    print("tip position, one vs two BLAS threads: largest difference %.2e m" % d)
# threaded BLAS sums in another order: round-off, which the integration carries but Newton's
# tolerance bounds: 1e-6 (the scene's tolerance) x 0.3 m (the rod) = 3e-7 m (measured 4e-13 m)
bad |= not d < 3e-7
sys.exit(bad)
PY
[ $fail -eq 0 ] && echo "determinism: bitwise equal"
exit $fail
