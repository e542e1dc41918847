#!/usr/bin/python3
# tests/extreme/test_slider_crank_dynamics.py: a dynamic closed chain: the driving torque of a
# slider-crank with masses, against an independent Lagrange solution in numpy.
# SPDX-License-Identifier: MIT
#
# A planar slider-crank (gravity -y): crank r = 0.1 m (1 kg, a uniform bar: I = m r^2 / 12 about
# its centre), connecting rod l = 0.4 m (2 kg, I = m l^2 / 12), slider 3 kg on the x axis;
# revolute joints about z at the bearing, the crank pin and the wrist pin, a prismatic guide
# along x; the crank driven at a constant 2 pi rad/s. The loop is planar in space, so three of
# its joint equations are redundant: fmbd-run removes them by its rank-revealing QR and the
# torque about z stays determined. The motor torque on the crank is minus the z component of
# the reaction of the bearing on the ground (/reactions/bearing/torque: it includes the
# driver's multiplier).
# Reference (no code of the toolchain): with theta = omega t the mechanism has one coordinate;
# tau = sum_i m_i (a_i - g) . J_i + I_i alpha_i dphi_i/dtheta, with the centres r_i(theta),
# J_i = dr_i/dtheta by the complex step (exact to round-off), a_i = d^2r_i/dtheta^2 omega^2
# (central differences of the complex-step derivative, error ~1e-9 relative) and the link
# angles' second derivatives likewise: the virtual work of the inertia and gravity forces.
# Asserted: after 0.05 s the torques agree to 1e-3 N m (amplitude 2.29 N m; a wrong inertia or
# gravity term is worth 0.1 N m and more). Error sources:
# the scheme's acceleration error O((omega h)^2) ~ 4e-7 of the inertia torques (1e-6 N m), and
# the index-3 formulation's multiplier noise: the Newton increments stop at the round-off floor
# 1e3 eps |x| (fmbd_mbs_step.c), an acceleration noise of 1e3 eps |x| / (beta h^2) ~ 4e-5 m/s^2
# at h = 1e-4 s, times the inertias' lever (6 kg x 0.1 m): ~2e-5 N m; measured 2.7e-4 N m,
# evenly over the revolution, and growing as 1/h^2 (1.2e-3 N m at h = 5e-5): round-off, not
# the method (at h = 5e-4 the truncation, 3e-3 N m, dominates instead). The first steps carry the start-up transient of the
# multipliers (the initial accelerations are not the scheme's pseudo-accelerations; it decays
# as rho_inf^n): below 1e-3 N m, measured 5.8e-4.
# Also the slider's position against the closed form (1e-9 m: kinematics, the constraint
# tolerance; measured 7e-15) and the energy balance: kinetic + potential energy change = the
# motor's work (the trapezoidal rule on 1e-3 s samples of tau omega, whose harmonics reach ~3
# omega: (3 omega dt)^2 / 12 ~ 3e-5 of the work: 1e-4; measured 1.4e-5).
import os
import subprocess
import sys

import h5py
import numpy as np

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_slider_crank_dynamics")
os.makedirs(TMP, exist_ok=True)
os.environ["PATH"] = os.path.join(ROOT, BUILD, "bin") + os.pathsep + os.environ["PATH"]
failures = []


def check(cond, msg):
    print(("ok    " if cond else "FAIL  ") + msg)
    if not cond:
        failures.append(msg)


r, l, m1, m2, m3, g, w = 0.1, 0.4, 1.0, 2.0, 3.0, 9.81, 2 * np.pi
I1, I2 = m1 * r * r / 12, m2 * l * l / 12
scene = f"""gravity: [0, {-g}, 0]
solver: {{t_end: 1, step: 1e-4}}
bodies:
  - {{name: crank, mass: {m1}, inertia: [1e-6, {I1!r}, {I1!r}], position: [{r / 2}, 0, 0]}}
  - {{name: rod, mass: {m2}, inertia: [1e-6, {I2!r}, {I2!r}], position: [{r + l / 2}, 0, 0]}}
  - {{name: slider, mass: {m3}, inertia: [1e-3, 1e-3, 1e-3], position: [{r + l}, 0, 0]}}
joints:
  - {{name: bearing, type: revolute, body1: ground, body2: crank, point: [0, 0, 0], axis: z}}
  - {{name: pin, type: revolute, body1: crank, body2: rod, point: [{r}, 0, 0], axis: z}}
  - {{name: wrist, type: revolute, body1: rod, body2: slider, point: [{r + l}, 0, 0], axis: z}}
  - {{name: guide, type: prismatic, body1: ground, body2: slider, point: [{r + l}, 0, 0], axis: x}}
drivers:
  - {{name: motor, joint: bearing, function: {{type: linear, rate: {w!r}}}}}
outputs:
  every: 1e-3
  energy: true
  points:
    - {{name: slider, body: slider, quantities: [position]}}
  reactions: [bearing]
"""
with open(os.path.join(TMP, "sc.yaml"), "w") as f:
    f.write(scene)
p = subprocess.run(["fmbd-run", "sc.yaml", "-o", "sc.run.h5"], cwd=TMP, capture_output=True, text=True)
print(p.stderr.strip())
if p.returncode != 0:
    sys.exit("fmbd-run failed")
with h5py.File(os.path.join(TMP, "sc.run.h5"), "r") as f:
    t = f["time"][()]
    tau_run = -f["reactions/bearing/torque"][()][:, 2]
    xs_run = f["outputs/slider/position"][()][:, 0]
    e = f["energy/kinetic"][()] + f["energy/potential"][()]
    nred = int(f["stats"].attrs["redundant_equations"])
check(nred == 3, "3 redundant joint equations removed (%d)" % nred)


def config(th):
    """Centres (3 x 2) and link angles (3) as functions of the crank angle (complex-safe)."""
    P = r * np.array([np.cos(th), np.sin(th)])
    phi = np.arcsin(-r * np.sin(th) / l)
    xs = r * np.cos(th) + l * np.cos(phi)
    S = np.array([xs, 0 * th])
    return [P / 2, (P + S) / 2, S], [th, phi, 0 * th]


def d1(th):
    hc = 1e-30
    c, a = config(th + 1j * hc)
    return [np.imag(x) / hc for x in c], [np.imag(x) / hc for x in a]


def torque(th):
    h = 1e-5
    Jp, Ap = d1(th + h)
    Jm, Am = d1(th - h)
    J, A = d1(th)
    tau = 0.0
    for mi, Ii, Ji, Ai, Jpi, Jmi, Api, Ami in zip((m1, m2, m3), (I1, I2, 0.0), J, A, Jp, Jm, Ap, Am):
        acc = (Jpi - Jmi) / (2 * h) * w * w   # theta'' = 0
        alpha = (Api - Ami) / (2 * h) * w * w
        tau += mi * np.dot(acc - np.array([0, -g]), Ji) + Ii * alpha * Ai
    return tau


th = w * t
tau_ref = np.array([torque(x) for x in th])
xs_ref = np.array([np.real(config(x)[0][2][0]) for x in th])
amp = np.max(np.abs(tau_ref))
late = t >= 0.05
dd = np.abs(tau_run - tau_ref)
print("largest |difference| per 0.1 s (1e-6 N m):", np.round([dd[(t >= a) & (t < a + 0.1)].max() * 1e6 for a in np.arange(0, 1, 0.1)], 1))
d0 = np.max(np.abs(tau_run - tau_ref)[~late])
d = np.max(np.abs(tau_run - tau_ref)[late])
print("driving torque: amplitude %.4f N m; largest difference %.2e N m in the first 0.05 s (the start-up "
      "transient), %.2e N m after (%.1e of the amplitude)" % (amp, d0, d, d / amp))
check(d < 1e-3, "driving torque against the Lagrange solution after 0.05 s: %.1e N m (< 1e-3)" % d)
check(d0 < 1e-3, "start-up transient of the torque below 1e-3 N m (%.1e)" % d0)
dx = np.max(np.abs(xs_run - xs_ref))
check(dx < 1e-9, "slider position against the closed form (%.1e m)" % dx)
work = np.concatenate([[0], np.cumsum(0.5 * (tau_run[1:] + tau_run[:-1]) * np.diff(th))])
scale = np.max(np.abs(work))
db = np.max(np.abs((e - e[0]) - work))
check(db < 1e-4 * scale, "energy change = motor work (%.1e of %.3f J)" % (db / scale, scale))
if failures:
    print("%d failure(s)" % len(failures))
    sys.exit(1)
