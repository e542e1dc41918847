#!/usr/bin/python3
# tests/extreme/test_tumbling.py: a genuinely tumbling rigid body (the intermediate-axis, or
# Dzhanibekov, flip): momentum and energy conserved, the flip period and the motion against
# Euler's equations solved by scipy and the elliptic-function closed form.
# SPDX-License-Identifier: MIT
#
# A free rigid body (no gravity, no joint), principal inertia (1, 2, 3) kg m^2 about its centre
# of mass at the body origin, spinning at 2 rad/s about its intermediate axis (y) with a small
# disturbance of 0.02 rad/s about x and z: the spin axis flips over and back, periodically.
# References (nobody here wrote them):
#  - scipy.integrate.solve_ivp (DOP853, rtol 1e-12) of Euler's equations I w' = (I w) x w with
#    the attitude A' = A [w]x (the body point p is at A p in the world);
#  - the period of w(t), T = 4 K(k) / lambda (Landau and Lifshitz, Mechanics, section 37):
#    with L^2 > 2 E I2, lambda = sqrt((I3 - I2)(L^2 - 2 E I1) / (I1 I2 I3)) and
#    k^2 = (I2 - I1)(2 E I3 - L^2) / ((I3 - I2)(L^2 - 2 E I1)); L^2 < 2 E I2 swaps I1 and I3.
# Runs: fixed steps h = 1e-3, 5e-4, 2.5e-4 s (newton_tol 1e-13: the Newton leftovers far
# below the truncation error), 20 s: about 2.5 periods of w, 5 flips of the y axis.
# Asserted:
#  - closed form and scipy agree on the period (1e-6 relative: the zero crossings of w_y found
#    by linear interpolation in 1e-3 s samples of a 1e-12 solution; measured 1e-9);
#  - the angular momentum about the world origin and the kinetic energy are invariants of the
#    equations; the scheme keeps them to its truncation error: the drifts must fall as h^2
#    (ratio 4 +- 0.5 for the momentum per halving; 2.5..5.5 for the energy, whose drift also
#    holds the numerical damping of rho_inf = 0.9); measured 4.9e-6, 1.2e-6, 3.0e-7 (momentum)
#    and 1.4e-6, 3.4e-7, 1.2e-7 (energy); at h = 2.5e-4 both below 1e-6. A wrong gyroscopic
#    term breaks conservation at O(1) and does not converge;
#  - the flip period of fmbd-run's finest run (zero crossings of the body's y axis along L)
#    equals scipy's and the closed form's to 1e-4 (measured 5.7e-6);
#  - the body's y axis in the world follows scipy's to 1e-3 (unit vector) over the 20 s.
#    Measured 5.2e-5, 7.6e-5, 2.2e-4 at h = 1e-3, 5e-4, 2.5e-4: this error does NOT fall with h.
#    It depends on rho_inf (2.2e-4 at 0.9, 1.6e-4 at 0.5, 1.3e-5 at 0.99 for h = 2.5e-4): near
#    the separatrix the flip time is sensitive to the orbit's energy, which the numerical
#    damping shifts. Reported in docs/STABILITY.md; not analysed further.
import os
import subprocess
import sys

import h5py
import numpy as np
from scipy.integrate import solve_ivp
from scipy.special import ellipk

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_tumbling")
os.makedirs(TMP, exist_ok=True)
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


I = np.array([1.0, 2.0, 3.0])
w0 = np.array([0.1, 4.0, 0.1])
T_END = 20.0
SCENE = """solver: {t_end: %g, step: %s, newton_tol: 1e-13}
bodies:
  - {name: top, mass: 1, inertia: [1, 2, 3], angular_velocity: [%r, %r, %r]}
outputs:
  every: 0.001
  energy: true
  momentum: true
  points:
    - {name: ay, body: top, point: [0, 1, 0]}
"""
runs = {}
for h in ("1e-3", "5e-4", "2.5e-4"):
    with open(os.path.join(TMP, "top%s.yaml" % h), "w") as f:
        f.write(SCENE % (T_END, h, *w0))
    r = subprocess.run(["fmbd-run", "top%s.yaml" % h, "-o", "top%s.run.h5" % h], cwd=TMP, capture_output=True,
                       text=True)
    print(r.stderr.strip())
    if r.returncode != 0:
        sys.exit("fmbd-run failed")
    with h5py.File(os.path.join(TMP, "top%s.run.h5" % h), "r") as f:
        runs[h] = (f["time"][()], f["outputs/ay/position"][()], f["momentum/angular"][()], f["energy/kinetic"][()])
t = runs["1e-3"][0]


def rhs(_, y):
    w, A = y[:3], y[3:].reshape(3, 3)
    dw = np.cross(I * w, w) / I
    W = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    return np.r_[dw, (A @ W).ravel()]


sol = solve_ivp(rhs, (0, T_END), np.r_[w0, np.eye(3).ravel()], method="DOP853", rtol=1e-12, atol=1e-12,
                t_eval=t, dense_output=False)
w_ref = sol.y[:3].T
ay_ref = np.array([y[3:].reshape(3, 3) @ [0, 1, 0] for y in sol.y.T])
# (every run's output instants are t: outputs every 1 ms, steps dividing it)


def crossings(tt, y):
    k = np.nonzero(np.sign(y[1:]) != np.sign(y[:-1]))[0]
    return tt[k] - y[k] * (tt[k + 1] - tt[k]) / (y[k + 1] - y[k])


E = 0.5 * np.sum(I * w0**2)
L2 = np.sum((I * w0) ** 2)
I1, I2, I3 = I if L2 > 2 * E * I[1] else I[::-1]
lam = np.sqrt((I3 - I2) * (L2 - 2 * E * I1) / (I1 * I2 * I3))
k2 = (I2 - I1) * (2 * E * I3 - L2) / ((I3 - I2) * (L2 - 2 * E * I1))
T_cf = 4 * ellipk(k2) / lam
c = crossings(t, w_ref[:, 1])
T_sp = 2 * np.mean(np.diff(c))  # w_y changes sign twice a period
check(abs(T_sp / T_cf - 1) < 1e-6, "period of w: closed form %.8f s, scipy %.8f s" % (T_cf, T_sp))

err = {}
for hh, (tt, ay, H, ek) in runs.items():
    dH = np.max(np.linalg.norm(H - H[0], axis=1)) / np.linalg.norm(H[0])
    dE = np.max(np.abs(ek - ek[0])) / ek[0]
    d = np.max(np.linalg.norm(ay - ay_ref, axis=1))
    err[hh] = (dH, dE, d)
    print("h = %-7s |H| drift %.2e, energy drift %.2e, y axis off scipy's by %.2e (relative, over %g s)"
          % (hh, dH, dE, d, T_END))
for a_, b_ in (("1e-3", "5e-4"), ("5e-4", "2.5e-4")):
    q = [err[a_][i] / err[b_][i] for i in range(2)]
    check(3.5 < q[0] < 4.5 and 2.5 < q[1] < 5.5,
          "h %s -> %s: momentum and energy errors fall %.2f and %.2f times (second order: 4)" % (a_, b_, *q))
check(err["2.5e-4"][0] < 1e-6 and err["2.5e-4"][1] < 1e-6, "h = 2.5e-4: momentum and energy to 1e-6")
tt, ay, H, ek = runs["2.5e-4"]
h = H[0] / np.linalg.norm(H[0])
cf = crossings(tt, ay @ h)
cr = crossings(t, ay_ref @ h)
n = min(len(cf), len(cr))
check(n >= 4, "%d flips of the body's y axis in %g s" % (n, T_END))
Tf, Tr = 2 * np.mean(np.diff(cf[:n])), 2 * np.mean(np.diff(cr[:n]))
check(abs(Tf / Tr - 1) < 1e-4 and abs(Tr / T_cf - 1) < 1e-4,
      "flip period: fmbd-run %.6f s, scipy %.6f s, closed form %.6f s" % (Tf, Tr, T_cf))
check(err["2.5e-4"][2] < 1e-3, "the body's y axis follows scipy's to %.1e over %g s" % (err["2.5e-4"][2], T_END))
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
