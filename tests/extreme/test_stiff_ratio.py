#!/usr/bin/python3
# tests/extreme/test_stiff_ratio.py: a stiffness ratio of 1e6 between bodies, and retained modal
# frequencies 1e7 times the mechanism's lowest (docs/STABILITY.md).
# SPDX-License-Identifier: MIT
#
# A double pendulum of two flexible rods (rod.geo, tet4, h = 15 mm, 10 fixed-interface modes):
# the first of steel (E = 1e11 Pa, held at both ends: cbcheck --hold end0 --hold end1), hinged to
# the ground; the second hinged to its far end, either the same steel rod ("soft-soft") or one
# with E = 1e17 Pa ("soft-hard": 1e6 times stiffer, its modes from 1.27 MHz to 38 MHz, while
# the pendulum swings at about 1 Hz). Released horizontal, gravity -y, 0.5 s, variable steps
# (tolerance 1e-5), rho_inf 0.9. What could go wrong: the step controller chasing the stiff
# body's modes (steps of 1e-8 s), or energy growth from modes the steps cannot resolve.
# Asserted:
#  - the stiff rod's frequencies are 1000 times the steel rod's (sqrt of the stiffness ratio;
#    1e-9: the same mesh and matrices scaled);
#  - the stiff body costs no steps: soft-hard needs at most 1.2 times soft-soft's steps (the
#    controller is driven by the steel rods' kHz modes; measured 16334 vs 16801);
#  - the energy (kinetic + potential + strain) never rises above its start (1e-12 J of round-off)
#    and loses less than 1e-5 J (m g L ~ 1 J; measured 3.0e-7 and 3.4e-7 J: the scheme's damping);
#  - the tips end within 1e-5 m of each other (the second rod's elastic deflection, all that
#    differs; measured 8e-7 m).
import os
import subprocess
import sys

import h5py
import numpy as np

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_stiff_ratio")
os.makedirs(TMP, exist_ok=True)
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


def run(*cmd):
    r = subprocess.run(list(cmd), cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("command failed (%d): %s" % (r.returncode, " ".join(cmd)))
    return r


geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
for tag, E in (("soft", "1e11"), ("hard", "1e17")):
    run("mesh2fe", geo, "--order", "1", "--size", "0.015", "--E", E, "--interface", "end0", "--interface", "end1",
        "-o", tag + ".fe.h5", "-q")
    run("fe2cb", tag + ".fe.h5", "--modes", "10", "-o", tag + ".cb.h5", "-q")
run("cbcheck", "soft.cb.h5", "--hold", "end0", "--hold", "end1", "--range", "6", "-o", "soft1.rflex.h5", "-q")
run("cbcheck", "soft.cb.h5", "--hold", "end0", "-o", "soft2.rflex.h5", "-q")
run("cbcheck", "hard.cb.h5", "--hold", "end0", "-o", "hard2.rflex.h5", "-q")
with h5py.File(os.path.join(TMP, "soft2.rflex.h5"), "r") as f, h5py.File(os.path.join(TMP, "hard2.rflex.h5"), "r") as g:
    fs, fh = f["modes/frequency_hz"][()], g["modes/frequency_hz"][()]
check(np.max(np.abs(fh / fs / 1000 - 1)) < 1e-9,
      "the stiff rod's modes (%.3g .. %.3g Hz) are 1000x the steel rod's" % (fh[0], fh[-1]))
SCENE = """gravity: [0, -9.81, 0]
solver: {t_end: 0.5, tolerance: 1e-5, max_step: 1e-2}
bodies:
  - {name: first, type: flexible, file: soft1.rflex.h5}
  - {name: second, type: flexible, file: %s, position: [0.3, 0, 0]}
joints:
  - {name: pivot, type: revolute, body1: ground, body2: first, at2: {interface: end0}, axis: z}
  - {name: hinge, type: revolute, body1: first, body2: second, at1: {interface: end1}, at2: {interface: end0}, axis: z}
outputs:
  every: 0.01
  energy: true
  points:
    - {name: tip, body: second, interface: end1}
"""
out = {}
for tag, f2 in (("soft-soft", "soft2.rflex.h5"), ("soft-hard", "hard2.rflex.h5")):
    with open(os.path.join(TMP, tag + ".yaml"), "w") as f:
        f.write(SCENE % f2)
    r = run("fmbd-run", tag + ".yaml", "-o", tag + ".run.h5")
    print(r.stderr.strip().splitlines()[-1])
    with h5py.File(os.path.join(TMP, tag + ".run.h5"), "r") as f:
        e = f["energy/kinetic"][()] + f["energy/potential"][()] + f["energy/strain"][()]
        out[tag] = (int(f["stats"].attrs["steps"]), e, f["outputs/tip/position"][()])
    check(e.max() - e[0] <= 1e-12 and e[0] - e[-1] < 1e-5,
          "%s: energy never above its start (%+.1e J), lost %.1e J" % (tag, e.max() - e[0], e[0] - e[-1]))
ss, sh = out["soft-soft"][0], out["soft-hard"][0]
check(sh <= 1.2 * ss, "the 1e6x stiffer body costs no steps: %d vs %d" % (sh, ss))
d = np.max(np.abs(out["soft-soft"][2][-1] - out["soft-hard"][2][-1]))
check(d < 1e-5, "the tips end %.1e m apart (the second rod's elasticity)" % d)
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
