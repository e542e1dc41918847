#!/usr/bin/python3
# tests/py/test_fmbd_run_inertia.py: the scene key `inertia_coupling` of a modal body (full or
# partial: docs/SCENE.md, docs/THEORY.md section 4c) through fmbd-run. The physics of the partial
# model (its own energy conserved, its distance from the full model bounded) is checked in
# tests/unit/t512-mbs-modal-inertia.c; here the key's way from the scene to the body:
#  1. a flexible beam pendulum (fegen beam, fe2cb --modes 10) swinging under gravity, 0.3 s at
#     fixed 1e-3 s steps: `inertia_coupling: full` gives the default's output bit for bit;
#     `partial` runs, -v names the body's partial coupling, and its tip differs from the full
#     model's (the flag reaches the body), by far less than the tip's travel;
#  2. refused, naming the scene line, nothing written: an unknown value, the key on a rigid
#     body, `partial` on a full-model (.fe.h5) body.
import os
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402
from harness import check, finish, runner, tmpdir  # noqa: E402

TMP = tmpdir("test_fmbd_run_inertia")
run = runner(TMP)
fegen.write(os.path.join(TMP, "beam.fe.h5"),
            fegen.beam(n_el=8, length=0.5, radius=0.006, interfaces={"end0": [0], "end1": [8]}))
run("fe2cb", "beam.fe.h5", "--modes", "10", "-o", "beam.cb.h5", "-q")

SCENE = """gravity: [0, -9.81, 0]
solver: {t_end: 0.3, step: 1e-3, newton_tol: 1e-10}
bodies:
  - {name: beam, type: flexible, file: FILE, position: [0, 0, 0]KEY}
  - {name: bob, geometry: {shape: sphere, radius: 0.02, density: 7800}, position: [0.5, 0, 0]RKEY}
joints:
  - {name: pin, type: spherical, body1: ground, body2: beam, point: [0, 0, 0], at2: {interface: end0}}
  - {name: hold, type: spherical, body1: beam, body2: bob, point: [0.5, 0, 0], at1: {interface: end1}}
outputs:
  every: 0.01
  energy: true
  points:
    - {name: tip, body: beam, interface: end1, quantities: [position]}
"""


def scene(name, key="", rkey="", file="beam.cb.h5"):
    with open(os.path.join(TMP, name), "w") as f:
        f.write(SCENE.replace("FILE", file).replace("RKEY", rkey).replace("KEY", key))


def fmbd_run(name, out):
    if os.path.exists(os.path.join(TMP, out)):
        os.remove(os.path.join(TMP, out))
    return subprocess.run(["fmbd-run", name, "-o", out, "-v"], cwd=TMP, capture_output=True, text=True)


def tip(out):
    with h5py.File(os.path.join(TMP, out), "r") as f:
        return f["outputs/tip/position"][()], f["energy/kinetic"][()]


# --- 1. full (default and explicit) and partial -----------------------------------------------
res = {}
for tag, key in (("default", ""), ("full", ", inertia_coupling: full"), ("partial", ", inertia_coupling: partial")):
    scene(tag + ".yaml", key)
    p = fmbd_run(tag + ".yaml", tag + ".run.h5")
    check(p.returncode == 0, "%s: runs (%s)" % (tag, p.stderr[-300:]))
    if p.returncode:
        finish()
    said = "partial inertia coupling" in p.stderr
    check(said == (tag == "partial"), "%s: -v %s the partial coupling" % (tag, "names" if said else "does not name"))
    res[tag] = tip(tag + ".run.h5")
check(np.array_equal(res["default"][0], res["full"][0]) and np.array_equal(res["default"][1], res["full"][1]),
      "inertia_coupling: full is the default (the same output bit for bit)")
# the flag reaches the body: the runs differ. The size of the difference is bounded and derived in
# t512 (the inertia forces of the deformation's relative motion); here only a sanity scale: far
# below the tip's travel (1e-3 of it), the deformation being a small part of the motion
pf, pp = res["full"][0], res["partial"][0]
travel = np.max(np.linalg.norm(pf - pf[0], axis=1))
d = np.max(np.linalg.norm(pp - pf, axis=1))
check(0 < d < 1e-3 * travel, "partial vs full: the tip %.3g m apart (travel %.3g m)" % (d, travel))
print("partial vs full: tip %.3g m apart over 0.3 s; tip travel %.3g m" % (d, travel))

# --- 2. refused --------------------------------------------------------------------------------
for tag, key, rkey, file, want in (
        ("bad_value", ", inertia_coupling: half", "", "beam.cb.h5", "full or partial"),
        ("bad_rigid", "", ", inertia_coupling: partial", "beam.cb.h5", "is for flexible bodies"),
        ("bad_fe", ", inertia_coupling: partial", "", "beam.fe.h5", "is for modal bodies")):
    scene(tag + ".yaml", key, rkey, file)
    p = fmbd_run(tag + ".yaml", tag + ".run.h5")
    check(p.returncode != 0 and want in p.stderr and (tag + ".yaml:") in p.stderr
          and not os.path.exists(os.path.join(TMP, tag + ".run.h5")),
          "%s: refused naming the line (rc %d: %s)" % (tag, p.returncode, p.stderr.strip()[-200:]))
finish()
