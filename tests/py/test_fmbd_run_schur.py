#!/usr/bin/python3
# tests/py/test_fmbd_run_schur.py: fmbd-run's two ways of solving the iteration matrix give the
# same trajectory: KLU on the whole matrix (FMBD_MBS_SCHUR=0) and the modal blocks eliminated
# by their Schur complement (FMBD_MBS_SCHUR=1, common/fmbd_mbs_schur.c).
# SPDX-License-Identifier: MIT
#
# The two paths solve the same equations (the residual is the same code); only the matrix of
# the Newton iteration differs (the Schur path leaves out the modal blocks' gyroscopic part),
# so the converged states differ by the Newton tolerance, not by the method. Scenes:
#  1. the quadruple pendulum of examples/quadpend with a 30-mode .cb.h5 rod (tet10, h = 15 mm,
#     fe2cb --modes 30: 36 modal coordinates), 0.5 s at fixed 1e-3 s steps;
#  2. a closed loop of two modal bodies, each with two interfaces: a four-bar whose coupler
#     and rocker are beams (fegen, fe2cb --modes 10: 22 modal coordinates each), driven crank,
#     0.1 s at fixed 1e-4 s; the joint between coupler and rocker couples both bodies' modes.
# Asserted for each: both runs take the same steps; the Newton iterations differ by at most
# 5 % (both paths keep and refresh their matrix by the same rule; the contraction rate changes
# by the left-out gyroscopic part, about 2 h |w| relative to Mff, < 1 %; a wrong coupling
# block shows as more iterations or failed steps); the largest distance between the two runs' output points stays below
# 2 n_steps newton_tol L (each converged step is within newton_tol of the step's exact solution
# in the position scale L, for either run; before the chain's chaos, within 0.5 s here, the
# differences add at most linearly); newton_tol = 1e-10. And -v says which path ran (the
# automatic choice takes the Schur path from 10 modes on).
import os
import subprocess
import sys

import h5py
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fegen  # noqa: E402
from harness import ROOT, check, finish, runner, tmpdir  # noqa: E402

TMP = tmpdir("test_fmbd_run_schur")
run = runner(TMP)
NEWTON_TOL = 1e-10


def fmbd_run(scene, out, schur):
    env = dict(os.environ)
    if schur is None:
        env.pop("FMBD_MBS_SCHUR", None)
    else:
        env["FMBD_MBS_SCHUR"] = schur
    p = subprocess.run(["fmbd-run", scene, "-o", out, "-v"], cwd=TMP, env=env, capture_output=True, text=True)
    if p.returncode:
        print(p.stderr)
    return p


def compare(tag, scene, points, L):
    res = {}
    for schur in ("0", "1", None):
        out = "%s_%s.run.h5" % (tag, schur or "auto")
        p = fmbd_run(scene, out, schur)
        check(p.returncode == 0, "%s: FMBD_MBS_SCHUR=%s runs" % (tag, schur))
        if p.returncode:
            return
        elim = "eliminated (Schur complement)" in p.stderr
        check(elim == (schur != "0"), "%s: FMBD_MBS_SCHUR=%s: -v says the modal blocks are %seliminated"
              % (tag, schur, "" if elim else "not "))
        with h5py.File(os.path.join(TMP, out), "r") as f:
            st = dict(f["stats"].attrs)
            pos = np.concatenate([f["outputs/%s/position" % q][()] for q in points], axis=1)
        res[schur] = (st, pos)
    (s0, p0), (s1, p1) = res["0"], res["1"]
    check(s0["steps"] == s1["steps"] and s0["rejected_steps"] == s1["rejected_steps"],
          "%s: same steps (%d, %d rejected)" % (tag, s1["steps"], s1["rejected_steps"]))
    it0, it1 = s0["newton_iterations"], s1["newton_iterations"]
    check(abs(it1 - it0) <= 0.05 * it0, "%s: Newton iterations %d (KLU) and %d (Schur), factorisations %d and %d"
          % (tag, it0, it1, s0["factorizations"], s1["factorizations"]))
    d = np.max(np.abs(p1 - p0))
    bound = 2 * s0["steps"] * NEWTON_TOL * L
    check(d <= bound, "%s: output points of the two paths within %.2g m (bound %.2g m)" % (tag, d, bound))
    da = np.max(np.abs(res[None][1] - p1))
    check(da == 0, "%s: the automatic choice is the Schur path (same output bitwise: %.2g)" % (tag, da))


# --- 1. quadruple pendulum, 30-mode rod --------------------------------------------------------
geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
run("mesh2fe", geo, "--size", "0.015", "--E", "100e9", "--nu", "0.285", "--rho", "7850", "--interface",
    "end0@-0.05,0,0", "-o", "rod.fe.h5", "-q")
run("fe2cb", "rod.fe.h5", "--modes", "30", "-o", "rod.cb.h5", "-q")
with open(os.path.join(TMP, "quad.yaml"), "w") as f:
    f.write("""gravity: [0, -9.806, 0]
solver: {t_end: 0.5, step: 1e-3, newton_tol: %g, rho_inf: 0.9}
bodies:
  - {name: link1, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [0.2, 0, 0]}
  - {name: link2, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [0.6, 0, 0]}
  - {name: link3, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [1.0, 0, 0]}
  - {name: rod, type: flexible, file: rod.cb.h5, position: [1.25, 0, 0]}
joints:
  - {name: j0, type: spherical, body1: ground, body2: link1, point: [0, 0, 0]}
  - {name: j1, type: spherical, body1: link1, body2: link2, point: [0.4, 0, 0]}
  - {name: j2, type: spherical, body1: link2, body2: link3, point: [0.8, 0, 0]}
  - {name: j3, type: spherical, body1: link3, body2: rod, point: [1.2, 0, 0], at2: {interface: end0}}
outputs:
  every: 0.005
  points:
    - {name: A, body: rod, nearest: [0.3, 0.015, 0], quantities: [position]}
""" % NEWTON_TOL)
# L: the position scale of newton_tol, the system's size (fmbd_mbs.h: L_ref, about 1.55 m here)
compare("quadpend", "quad.yaml", ["A"], 1.6)

# --- 2. four-bar with a flexible coupler and a flexible rocker (closed loop) -------------------
fegen.write(os.path.join(TMP, "coupler.fe.h5"),
            fegen.beam(n_el=8, length=0.4, radius=0.006, interfaces={"end0": [0], "end1": [8]}))
fegen.write(os.path.join(TMP, "rocker.fe.h5"),
            fegen.beam(n_el=8, path=[(0, 0, 0), (0, -0.1, 0)], radius=0.006, interfaces={"end0": [0], "end1": [8]}))
run("fe2cb", "coupler.fe.h5", "--modes", "10", "-o", "coupler.cb.h5", "-q")
run("fe2cb", "rocker.fe.h5", "--modes", "10", "-o", "rocker.cb.h5", "-q")
with open(os.path.join(TMP, "fourbar.yaml"), "w") as f:
    f.write("""gravity: [0, -9.81, 0]
solver: {t_end: 0.1, step: 1e-4, newton_tol: %g}
bodies:
  - {name: crank, geometry: {shape: sphere, radius: 0.02, density: 7800}, position: [0, 0.05, 0]}
  - {name: coupler, type: flexible, file: coupler.cb.h5, position: [0, 0.1, 0]}
  - {name: rocker, type: flexible, file: rocker.cb.h5, position: [0.4, 0.1, 0]}
joints:
  - {name: O, type: revolute, body1: ground, body2: crank, point: [0, 0, 0], axis: z}
  - {name: A, type: revolute, body1: crank, body2: coupler, point: [0, 0.1, 0], axis: z, at2: {interface: end0}}
  - {name: B, type: revolute, body1: coupler, body2: rocker, point: [0.4, 0.1, 0], axis: z, at1: {interface: end1}, at2: {interface: end0}}
  - {name: C, type: revolute, body1: rocker, body2: ground, point: [0.4, 0, 0], axis: z, at1: {interface: end1}}
drivers:
  - {name: motor, joint: O, function: {type: linear, rate: 6.283185307179586}}
outputs:
  every: 0.001
  points:
    - {name: cmid, body: coupler, node: 4, quantities: [position]}
    - {name: rmid, body: rocker, node: 4, quantities: [position]}
""" % NEWTON_TOL)
compare("four-bar", "fourbar.yaml", ["cmid", "rmid"], 0.5)
finish()
