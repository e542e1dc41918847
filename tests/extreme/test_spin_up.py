#!/usr/bin/python3
# tests/extreme/test_spin_up.py: the spin-up beam (Kane, Ryan and Banerjee 1987) and high-speed
# rotation: where the linear floating frame loses stiffness, and fmbd-run's warning.
# SPDX-License-Identifier: MIT
#
# WHAT COULD GO WRONG. A beam spinning about one end carries centrifugal axial forces. Their
# geometric stiffness raises every bending eigenvalue by about alpha Omega^2 (Southwell: alpha =
# 1.193 for a cantilever's first mode): out of the plane of rotation (flapwise) lambda_1 + 1.193
# Omega^2, in the plane (chordwise, where the centrifugal force on the lateral displacement
# softens by Omega^2) lambda_1 + 0.193 Omega^2. The conventional floating frame with linear
# modes has the centrifugal load but not that stiffness: flapwise lambda_1, chordwise
# lambda_1 - Omega^2, divergent past Omega^2 = lambda_1 (Kane, Ryan and Banerjee 1987).
#
# THE CASE. A beam (L = 5 m, circular section r = 20 mm, E = 70 GPa, rho = 2700: lambda_1 =
# 51.28 rad^2/s^2, 1.14 Hz, as a pair: the section is symmetric), held at end0 by a revolute
# joint about z (cbcheck --hold end0), driven at a constant speed Omega from the start (the
# spin-up's steady state; Kane et al.'s smooth spin-up profile theta(t) is not a scene function),
# struck by a smooth lateral pulse (follower loads at end1 in y and z, up and down over 0.4 s).
# The tip's deflection in the rotating frame (y: in plane, z: out of plane) rings at the first
# modes' frequencies, found as the peak of a zero-padded, Hann-windowed spectrum after the
# pulse (resolution ~1e-3 rad/s, below 0.1 % of omega^2 here).
#
# ASSERTED (the solid facts): lambda_1 from scipy on the fe matrices is the Euler-Bernoulli
# cantilever's (1e-3) and comes as a pair (1e-6); at Omega = 0 both rings are at lambda_1 (1 %:
# the reduced basis meets cbcheck's 1e-4, the integrator's period error at omega h = 0.04 is
# ~1e-4, the spectrum's peak ~1e-3); fmbd-run's spin warning appears exactly when Omega^2 >
# 0.01 lambda_1 and names the body's lowest elastic eigenvalue as held, which must be the
# cantilever's 1.1397 Hz (not the free beam's 7.25 Hz; to the 4 digits printed).
# MEASURED (printed, see docs/STABILITY.md): omega^2 at Omega = 3, 5, 6.5, 8 rad/s against the
# linear theory and against Southwell. fmbd-run follows NEITHER: its chordwise omega^2 stays
# near lambda_1 - 0.1 Omega^2 and it does not diverge at Omega^2 = 1.25 lambda_1; its flapwise
# omega^2 rises by ~0.9 Omega^2 (Southwell 1.193). The held interface's constraint modes
# (rigid rotations about end0 in the basis) with the joint's nonlinear kinematics are the
# suspects; not analysed yet. Asserted as a guard only that the results stay between the two
# models' bounds (chordwise above lambda_1 - Omega^2 and below Southwell + 1 %, flapwise from
# lambda_1 - 1 % to Southwell + 1 %), so a change of behaviour is seen.
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.linalg as sl

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "py"))
import fegen  # noqa: E402

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_spin_up")
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


L, R, E, RHO = 5.0, 0.02, 70e9, 2700.0
b = fegen.beam(n_el=20, length=L, radius=R, E=E, nu=0.3, rho=RHO, interfaces={"end0": [0], "end1": [20]})
fegen.write(os.path.join(TMP, "beam.fe.h5"), b)
run("fe2cb", "beam.fe.h5", "--modes", "12", "-o", "beam.cb.h5", "-q")
run("cbcheck", "beam.cb.h5", "--hold", "end0", "--tol", "1e-4", "-o", "beam.rflex.h5", "-q")
# lambda_1 of the beam as the scene holds it (end0 clamped in the rotating frame: the revolute
# joint and its driver fix all six dofs there), from scipy on the fe file's matrices; the
# rflex's modes span it to cbcheck's tolerance (1e-4)
K, M = fegen.read_km(os.path.join(TMP, "beam.fe.h5"))
with h5py.File(os.path.join(TMP, "beam.fe.h5"), "r") as f:
    dofs, n0 = f["dofs"][()], int(f["interfaces/end0"].attrs["node"])
held = {0, n0}  # mesh node 0 (tied: not in /dofs) and its interface node
keep = [i for i, (p, d) in enumerate(dofs) if p not in held]
lam = np.sort(sl.eigh(K.toarray()[np.ix_(keep, keep)], M.toarray()[np.ix_(keep, keep)], eigvals_only=True))
I = np.pi * R**4 / 4
lam_eb = (1.8751040687**2) ** 2 * E * I / (RHO * np.pi * R**2 * L**4)
print("first eigenvalues of the beam clamped at end0: %s rad^2/s^2 (Euler-Bernoulli %.5g)"
      % (np.array2string(lam[:4], precision=5), lam_eb))
check(abs(lam[0] / lam_eb - 1) < 1e-3 and abs(lam[1] / lam[0] - 1) < 1e-6,
      "lambda_1 = %.5g is the cantilever's (%.5g) and comes as a pair" % (lam[0], lam_eb))
lam1 = lam[0]

SCENE = """solver: {t_end: %(T)g, step: 0.005}
bodies:
  - {name: beam, type: flexible, file: beam.rflex.h5, angular_velocity: [0, 0, %(W)r]}
joints:
  - {name: hub, type: revolute, body1: ground, body2: beam, at2: {interface: end0}, axis: [0, 0, 1]}
drivers:
  - {name: motor, joint: hub, function: {type: linear, rate: %(W)r}}
loads:
  - {name: up_y, type: force, body: beam, interface: end1, frame: body, direction: [0, 1, 0],
     function: {type: ramp, t0: 0, t1: 0.2, v1: %(F)r}}
  - {name: down_y, type: force, body: beam, interface: end1, frame: body, direction: [0, -1, 0],
     function: {type: ramp, t0: 0.2, t1: 0.4, v1: %(F)r}}
  - {name: up_z, type: force, body: beam, interface: end1, frame: body, direction: [0, 0, 1],
     function: {type: ramp, t0: 0, t1: 0.2, v1: %(F)r}}
  - {name: down_z, type: force, body: beam, interface: end1, frame: body, direction: [0, 0, -1],
     function: {type: ramp, t0: 0.2, t1: 0.4, v1: %(F)r}}
outputs:
  every: 0.01
  points:
    - {name: tip, body: beam, interface: end1, quantities: [position]}
"""


def spin(W, T=5.0, F=20.0):
    name = "spin%g" % W
    with open(os.path.join(TMP, name + ".yaml"), "w") as f:
        f.write(SCENE % dict(T=T, W=float(W), F=F))
    r = run("fmbd-run", name + ".yaml", "-o", name + ".run.h5")
    with h5py.File(os.path.join(TMP, name + ".run.h5"), "r") as f:
        t, x = f["time"][()], f["outputs/tip/position"][()]
    th = W * t  # the driven angle: the frame turns exactly with it (end0 is held)
    v = -np.sin(th) * x[:, 0] + np.cos(th) * x[:, 1]  # in plane, lateral
    w = x[:, 2]                                         # out of plane
    return t, v, w, r.stderr


def omega_peak(t, y):
    sel = t >= 0.5
    yy = y[sel] - y[sel].mean()
    n = 64 * len(yy)
    F = np.abs(np.fft.rfft(yy * np.hanning(len(yy)), n))
    return 2 * np.pi * np.fft.rfftfreq(n, t[1] - t[0])[np.argmax(F)]


print("%8s %8s | %12s %12s %12s | %12s %12s %12s" % ("Omega", "O^2/lam1", "in plane", "linear", "Southwell",
                                                   "out of plane", "linear", "Southwell"))
held_hz = np.sqrt(lam1) / (2 * np.pi)
for W in (0.0, 3.0, 5.0, 6.5, 8.0):
    t, v, w, err = spin(W)
    oi, oo = omega_peak(t, v) ** 2, omega_peak(t, w) ** 2
    print("%8.2f %8.3f | %12.4g %12.4g %12.4g | %12.4g %12.4g %12.4g" % (
        W, W * W / lam1, oi, lam1 - W * W, lam1 + 0.193 * W * W, oo, lam1, lam1 + 1.193 * W * W))
    if W == 0:
        check(abs(oi / lam1 - 1) < 0.01 and abs(oo / lam1 - 1) < 0.01,
              "Omega 0: both rings at lambda_1 (%.4g, %.4g vs %.4g)" % (oi, oo, lam1))
    else:
        check(lam1 - W * W < oi < 1.01 * (lam1 + 0.193 * W * W) and
              0.99 * lam1 < oo < 1.01 * (lam1 + 1.193 * W * W),
              "Omega %g: between the linear model and Southwell (guard)" % W)
    warned = [l for l in err.splitlines() if "spins at" in l and "'beam'" in l]
    check(bool(warned) == (W * W > 0.01 * lam1), "Omega %g: spin warning %s" % (W, "given" if warned else "absent"))
    if warned:
        check("(%.4g Hz)" % held_hz in warned[0], "the warning names the held eigenvalue %.4g Hz: %s" % (held_hz, warned[0]))
t, v, w, err = spin(0.5, T=1.0)
check("spins at" not in err, "Omega 0.5 (ratio %.3f): no spin warning" % (0.25 / lam1))
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
