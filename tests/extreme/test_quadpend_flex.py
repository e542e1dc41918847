#!/usr/bin/python3
# tests/extreme/test_quadpend_flex.py: the quadruple pendulum's flexible link, checked where it
# moves: its point A (the node nearest the far end's top edge) over the first 0.5 s.
# SPDX-License-Identifier: MIT
#
# The chain of examples/quadpend (three rigid links, then the rod: tet10 cylinder 0.3 x 0.015 m,
# rho 7850, nu 0.285, its interface end0 0.05 m before the cylinder, spherical joints, released
# horizontal, gravity -y), the rod reduced as the example does (here h = 15 mm, fe2cb --modes
# 20, cbcheck --init 5 --range 10 --tol 1e-2), and the same rod with E x 100 (1e13 Pa).
# Reference, no code of the toolchain: the planar chain in minimal coordinates (four angles,
# Lagrange's equations, scipy DOP853, rtol 1e-11), the fourth link a rigid body with the rod
# file's own mass, first and second moments (/ffrf), so that only the elasticity differs.
# Window: 0 to 0.5 s, before the chain's chaos amplifies integration differences (the rigid
# chain's check in tests/py/test_fmbd_run.py holds to 1.5e-4 m over 1.5 s).
# Asserted (a wrong modal mass, elastic coupling or attachment offset shows as millimetres):
#  - the stiff rod's A follows the rigid reference to 2e-6 m (measured 6.3e-7 m: the
#    integration error at fixed h = 1e-4 s and the stiff rod's remaining 1 % of elasticity);
#  - the steel rod's A deviates by its elastic deflection, at least 3x the stiff rod's
#    (measured 4.5e-6 m, 7x: the elastic part falls as 1/E, 100x, down to the floor above);
#  - the steel rod's deviation stays below 1e-4 m: the rod as a cantilever under three times
#    its weight (the chain's accelerations reach about 3 g in 0.5 s) bends q L^4 / (8 E I) =
#    163 N/m x 0.35^4 / (8 x 3976 N m^2) = 7.7e-5 m at its end.
import os
import subprocess
import sys

import h5py
import numpy as np
from scipy.integrate import solve_ivp

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_quadpend_flex")
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


T_END = 0.5
SCENE = """gravity: [0, -9.806, 0]
solver: {t_end: %g, step: 1e-4}
bodies:
  - {name: link1, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [0.2, 0, 0]}
  - {name: link2, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [0.6, 0, 0]}
  - {name: link3, geometry: {shape: cylinder, length: 0.3, radius: 0.015, density: 7850, axis: x}, position: [1.0, 0, 0]}
  - {name: rod, type: flexible, file: %s, position: [1.25, 0, 0]}
joints:
  - {name: j0, type: spherical, body1: ground, body2: link1, point: [0, 0, 0]}
  - {name: j1, type: spherical, body1: link1, body2: link2, point: [0.4, 0, 0]}
  - {name: j2, type: spherical, body1: link2, body2: link3, point: [0.8, 0, 0]}
  - {name: j3, type: spherical, body1: link3, body2: rod, point: [1.2, 0, 0], at2: {interface: end0}}
outputs:
  every: 0.002
  points:
    - {name: A, body: rod, nearest: [0.3, 0.015, 0], quantities: [position]}
"""
geo = os.path.join(ROOT, "examples", "geometry", "rod.geo")
res = {}
for tag, E in (("steel", "100e9"), ("stiff", "1e13")):
    run("mesh2fe", geo, "--size", "0.015", "--E", E, "--nu", "0.285", "--rho", "7850", "--interface",
        "end0@-0.05,0,0", "-o", tag + ".fe.h5", "-q")
    run("fe2cb", tag + ".fe.h5", "--modes", "20", "-o", tag + ".cb.h5", "-q")
    run("cbcheck", tag + ".cb.h5", "--init", "5", "--range", "10", "--tol", "1e-2", "-o", tag + ".rflex.h5", "-q")
    with open(os.path.join(TMP, tag + ".yaml"), "w") as f:
        f.write(SCENE % (T_END, tag + ".rflex.h5"))
    r = run("fmbd-run", tag + ".yaml", "-o", tag + ".run.h5")
    print(r.stderr.strip())
    with h5py.File(os.path.join(TMP, tag + ".run.h5"), "r") as f:
        res[tag] = (f["time"][()], f["outputs/A/position"][()])
    with h5py.File(os.path.join(TMP, tag + ".rflex.h5"), "r") as f:
        m4, c4, J4 = f["ffrf/mass"][()], f["ffrf/first_moment"][()], f["ffrf/second_moment"][()].reshape(3, 3)
        nodes = f["mesh/nodes"][()]
# point A in the rod's frame, as fmbd-run picks it (nearest node)
xA = nodes[np.argmin(np.linalg.norm(nodes - [0.3, 0.015, 0], axis=1))]

# --- the rigid chain in minimal coordinates ----------------------------------------------------
g, n = 9.806, 4
mq = 7850 * np.pi * 0.015**2 * 0.3
xj = np.array([-0.05, 0.0])           # the joint in the rod's frame
mass = np.array([mq, mq, mq, m4])
rho = np.array([[0.2, 0.0], [0.2, 0.0], [0.2, 0.0], c4[:2] / m4 - xj])   # centre from the joint
Icm = np.array([mq * (3 * 0.015**2 + 0.3**2) / 12] * 3 + [J4[0, 0] + J4[1, 1] - (c4[0]**2 + c4[1]**2) / m4])
lj = 0.4                              # joint to joint, links 1-3


def u(th):
    return np.array([np.sin(th), -np.cos(th)])


def v(th):
    return np.array([np.cos(th), np.sin(th)])


def jac(th, thd):
    """J_k (2 x n) of each centre and dJ_k/dt theta'."""
    J, Jd = np.zeros((n, 2, n)), np.zeros((n, 2))
    for k in range(n):
        for j in range(k):
            J[k, :, j] = lj * v(th[j])
            Jd[k] += -lj * thd[j] ** 2 * u(th[j])
        J[k, :, k] = rho[k, 0] * v(th[k]) - rho[k, 1] * u(th[k])
        Jd[k] += thd[k] ** 2 * (-rho[k, 0] * u(th[k]) - rho[k, 1] * v(th[k]))
    return J, Jd


def rhs(_, y):
    th, thd = y[:n], y[n:]
    J, Jd = jac(th, thd)
    M = np.diag(Icm).astype(float)
    f = np.zeros(n)
    for k in range(n):
        M += mass[k] * J[k].T @ J[k]
        f -= mass[k] * J[k].T @ Jd[k]
        f -= mass[k] * g * J[k][1]
    return np.r_[thd, np.linalg.solve(M, f)]


t = res["steel"][0]
sol = solve_ivp(rhs, (0, T_END), np.r_[np.full(n, np.pi / 2), np.zeros(n)], method="DOP853", rtol=1e-11,
                atol=1e-12, t_eval=t)
th = sol.y[:n]
j3 = sum(lj * u(th[j]) for j in range(3))
A_ref = j3 + (xA[0] - xj[0]) * u(th[3]) + (xA[1] - xj[1]) * v(th[3])
dev = {}
for tag in ("steel", "stiff"):
    tt, A = res[tag]
    dev[tag] = np.max(np.linalg.norm(A[:, :2] - A_ref.T, axis=1))
    print("%s rod: point A off the rigid chain by at most %.3e m over 0..%g s (out of plane %.1e m)"
          % (tag, dev[tag], T_END, np.max(np.abs(A[:, 2] - A[0, 2]))))
check(dev["stiff"] < 2e-6, "E x 100: A follows the rigid reference to %.1e m (< 2e-6)" % dev["stiff"])
check(dev["steel"] > 3 * dev["stiff"], "steel: A's deviation %.1e m is elastic: %.0fx the stiff rod's"
      % (dev["steel"], dev["steel"] / dev["stiff"]))
check(dev["steel"] < 1e-4, "steel: A's elastic deviation below 1e-4 m (%.2e m)" % dev["steel"])
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
