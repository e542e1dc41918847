#!/usr/bin/python3
# tests/extreme/test_spin_up_transient.py: Kane, Ryan and Banerjee's (1987) transient spin-up
# of a beam, past its first bending frequency, with the scene function `spinup`.
# SPDX-License-Identifier: MIT
#
# THE CASE (Kane et al. 1987): a beam L = 10 m, rho A = 1.2 kg/m, EI = 1.4e4 N m^2, EA = 2.8e7 N
# (here A = 4e-4 m^2, I = 2e-7 m^4, E = 7e10 Pa, rho = 3000 kg/m^3),
# clamped to a rigid hub that a driven revolute joint turns about z with
#   theta(t) = (W/T) [t^2/2 + (T/2pi)^2 (cos(2 pi t/T) - 1)]  (t < T),  W (t - T/2)  (t >= T),
# W = 4 rad/s, T = 15 s. The cantilever's lambda_1 = 1.8751^4 EI / (rho A L^4) = 14.42 rad^2/s^2
# (omega_1 = 3.80 rad/s): the final speed is above it, where the conventional linear floating
# frame (in-plane eigenvalue lambda_1 - Omega^2) diverges. The beam: fegen's 3-D beam, 10
# elements, the cantilever's modes (cbcheck --hold end0).
#
# ASSERTED:
# - the run goes through (25 s, fixed step 0.01 s: omega_1 h = 0.04);
# - the hub (the driven joint's body2) follows theta(t): its angle from a point output,
#   atan2(y, x) of a hub point, to 1e-6 rad (the constraint is solved to newton_tol 1e-8 on
#   O(1) residuals; measured below 1e-9);
# - fmbd-run's spin warning comes once, naming the cantilever's lambda_1 (scipy on the fe
#   matrices, to the 4 digits printed), at the first accepted step where the FLOATING FRAME's
#   Omega^2 > 0.01 lambda_1. The frame is not the hub: the rflex's modes are M-orthogonal to the
#   rigid motions about end0, so the frame lags the hub by psi = g theta'' (g from scipy: the
#   M-projection of the quasi-static deflection on the rigid rotation), and its speed is
#   theta' + g theta''' (closed form). The step is asserted within the band the first mode's
#   ring allows (omega_1 (g / v1) v_ring, v_ring measured in the run); the band excludes the
#   hub's own crossing t* (closed form, brentq): a warning on the hub's speed would fail;
# - the tip's in-plane deflection in the hub frame, at the peak of the angular acceleration
#   (t = T/2, theta'' = 2W/T, Omega = W/2 = 2 rad/s), against an independent quasi-static
#   solution: scipy on the fe file's K and M (the beam clamped at end0) under the inertial load
#   -theta'' x (per unit mass, lateral). What separates the two: (a) the load's slowness, a
#   dynamic amplification 1/(1 - (2pi/T)^2/lambda_1) - 1 = 1.2 %; (b) the in-plane spin
#   softening fmbd-run has (test_spin_up: about -0.09 Omega^2, +2.5 % at Omega = 2); (c) the
#   reduced basis (cbcheck, 1e-4) and the step (omega_1 h = 0.04: ~1e-4), on the same K and M.
#   Asserted to 6 %: above (a) + (b), below the conventional linear model's +38 %
#   (1 / (1 - Omega^2/lambda_1)) and the sign of an error;
# - the deflection stays bounded after the spin-up (t > T, Omega^2 = 1.11 lambda_1): its peak
#   over [T, 25 s] below the peak during the spin-up (the conventional linear model grows
#   exponentially there, at rate sqrt(Omega^2 - lambda_1) = 1.26 /s: x 3e5 in 10 s);
# - out of the plane nothing moves (no load there): |w| < 1e-6 m.
# - the ring left after T (2 mm at the tip) is at the omega^2 of test_spin_up's steady-speed
#   runs, lambda_1 - 0.09 Omega^2 (3 %; a consistency check between two tests, not independent);
# MEASURED (printed; docs/STABILITY.md): the peak deflection, the quasi-static value.
# NOT VALIDATED: Kane et al.'s own curve (the geometric-stiffening model: in-plane lambda_1 +
# 0.193 Omega^2) is not reproduced by this toolchain's linear modes; the difference at T/2 is
# computed below, not asserted against the paper's figure (not read here).
import os
import re
import sys

import h5py
import numpy as np
import scipy.linalg as sl
from scipy.optimize import brentq

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "py"))
import fegen  # noqa: E402

from harness import check, finish, runner, tmpdir  # noqa: E402

TMP = tmpdir("test_spin_up_transient")
run = runner(TMP)

L, A, I, E, RHO = 10.0, 4e-4, 2e-7, 7e10, 3000.0
W, TS, TEND, H = 4.0, 15.0, 25.0, 0.01
NEL = 10
b = fegen.beam(n_el=NEL, length=L, E=E, nu=0.3, rho=RHO, section=(A, I, I, 2 * I),
               interfaces={"end0": [0], "end1": [NEL]})
fegen.write(os.path.join(TMP, "kane.fe.h5"), b)
run("fe2cb", "kane.fe.h5", "--modes", "10", "-o", "kane.cb.h5", "-q")
run("cbcheck", "kane.cb.h5", "--hold", "end0", "--tol", "1e-4", "-o", "kane.rflex.h5", "-q")

# the cantilever from the fe file (end0 clamped): lambda_1 and the quasi-static tip deflection
# per unit angular acceleration
K, M = fegen.read_km(os.path.join(TMP, "kane.fe.h5"))
with h5py.File(os.path.join(TMP, "kane.fe.h5"), "r") as f:
    dofs, n0 = f["dofs"][()], int(f["interfaces/end0"].attrs["node"])
    n1 = int(f["interfaces/end1"].attrs["node"])
    xyz = f["mesh/nodes"][()]
held = {0, n0}
keep = [i for i, (p, d) in enumerate(dofs) if p not in held]
Kd, Md = K.toarray()[np.ix_(keep, keep)], M.toarray()[np.ix_(keep, keep)]
lam = sl.eigh(Kd, Md, eigvals_only=True)
lam1 = lam[0]
lam_eb = 1.8751040687**4 * E * I / (RHO * A * L**4)
print("lambda_1 of the clamped beam %.5g rad^2/s^2 (Euler-Bernoulli %.5g), omega_1 %.4g rad/s"
      % (lam1, lam_eb, np.sqrt(lam1)))
check(abs(lam1 / lam_eb - 1) < 1e-3, "lambda_1 %.5g is the cantilever's %.5g" % (lam1, lam_eb))
# body force per unit mass in the hub frame under theta'' = 1: -x in y (the frame's angular
# acceleration about the root); the consistent load is M times that field
acc = np.zeros(len(dofs))
for i, (p, d) in enumerate(dofs):
    if d == 1:
        acc[i] = -xyz[p][0]
u = np.linalg.solve(Kd, (M.toarray() @ acc)[keep])
tip_y = [k for k, i in enumerate(keep) if dofs[i][0] == n1 and dofs[i][1] == 1][0]
v1 = u[tip_y]
print("quasi-static tip deflection per unit angular acceleration %.5g m s^2 (Euler-Bernoulli "
      "-11 rho A L^5 / (120 EI) = %.5g)" % (v1, -11 * RHO * A * L**5 / (120 * E * I)))

SCENE = """solver: {t_end: %(TEND)g, step: %(H)g}
bodies:
  - {name: hub, mass: 1, inertia: [1, 1, 1]}
  - {name: beam, type: flexible, file: kane.rflex.h5}
joints:
  - {name: motor, type: revolute, body1: ground, body2: hub, point: [0, 0, 0], axis: [0, 0, 1]}
  - {name: clamp, type: fixed, body1: hub, body2: beam, at2: {interface: end0}}
drivers:
  - {name: spin, joint: motor, function: {type: spinup, speed: %(W)r, t1: %(TS)r}}
outputs:
  every: 0.05
  points:
    - {name: mark, body: hub, point: [1, 0, 0], quantities: [position]}
    - {name: tip, body: beam, interface: end1, quantities: [position]}
"""
with open(os.path.join(TMP, "kane.yaml"), "w") as f:
    f.write(SCENE % dict(TEND=TEND, H=H, W=W, TS=TS))
r = run("fmbd-run", "kane.yaml", "-o", "kane.run.h5")
print(r.stderr.strip())
with h5py.File(os.path.join(TMP, "kane.run.h5"), "r") as f:
    t, xm, xt = f["time"][()], f["outputs/mark/position"][()], f["outputs/tip/position"][()]
check(abs(t[-1] - TEND) < 1e-9, "the run reaches t = %g s" % t[-1])


def theta(tt):
    tt = np.asarray(tt, float)
    c = TS / (2 * np.pi)
    return np.where(tt < TS, W / TS * (tt**2 / 2 + c * c * (np.cos(tt / c) - 1)), W * (tt - TS / 2))


def speed(tt):
    c = TS / (2 * np.pi)
    return W / TS * (tt - c * np.sin(tt / c)) if tt < TS else W


phi = np.unwrap(np.arctan2(xm[:, 1], xm[:, 0]))
err = np.max(np.abs(phi - theta(t)))
check(err < 1e-6, "the hub follows theta(t): max |phi - theta| = %.2g rad" % err)

# the warning: at the first accepted step where theta'^2 > 0.01 lambda_1
warn = [l for l in r.stderr.splitlines() if "spins at" in l and "'beam'" in l]
check(len(warn) == 1, "one spin warning for the beam")
if warn:
    m = re.search(r"t = ([0-9.eE+-]+) s: .* spins at ([0-9.eE+-]+) rad/s.*\(([0-9.eE+-]+) Hz\)", warn[0])
    tw, hz = float(m.group(1)), float(m.group(3))
    check("%.4g" % hz == "%.4g" % (np.sqrt(lam1) / (2 * np.pi)),
          "the warning's held eigenvalue %.4g Hz is the cantilever's %.4g Hz" % (hz, np.sqrt(lam1) / (2 * np.pi)))
    lw = (2 * np.pi * hz) ** 2
    ts_ = brentq(lambda s: speed(s) ** 2 - 0.01 * lw, 1e-6, TS)
    print("Omega^2 = 0.01 lambda_1 at t* = %.6g s (closed form); the warning at t = %.6g s" % (ts_, tw))
    # the warning measures the floating frame's Omega, not the hub's: the rflex's frame (modes
    # M-orthogonal to the rigid motions about end0) turns with the hub plus psi, the M-projection
    # of the clamped beam's deflection on the rigid rotation about end0 (z); quasi-statically
    # psi = g theta'', so the frame's speed is theta' + g theta'''. On top of that rides the
    # ring of the first mode: psi_ring = (g / v1) v_ring, its speed omega_1 psi_ring, v_ring the
    # tip's largest departure from amp v1 theta'' in the run up to a period after the warning;
    # with the 2 % dynamic amplification of the lag (1.2 % computed), that is the tolerance on the
    # frame's speed, and the warning must come within the steps that tolerance allows
    ufull = np.zeros(len(dofs))
    ufull[keep] = u
    Rg = np.zeros((len(dofs), 6))
    for i, (p, d) in enumerate(dofs):
        if d < 3:
            Rg[i, d] = 1
            for a in range(3):
                Rg[i, 3 + a] = np.cross(np.eye(3)[a], xyz[p])[d]
        else:
            Rg[i, d] = 1
    Mf = M.toarray()
    g = np.linalg.solve(Rg.T @ Mf @ Rg, Rg.T @ Mf @ ufull)[5]
    c = TS / (2 * np.pi)
    accel = lambda s: W / TS * (1 - np.cos(s / c)) if s < TS else 0.0  # noqa: E731
    jerk = lambda s: W / TS * np.sin(s / c) / c if s < TS else 0.0  # noqa: E731
    fspeed = lambda s: speed(s) + jerk(s) * g  # noqa: E731
    phi_ = np.unwrap(np.arctan2(xm[:, 1], xm[:, 0]))
    v_ = -np.sin(phi_) * xt[:, 0] + np.cos(phi_) * xt[:, 1]
    amp = 1 / (1 - (2 * np.pi / TS) ** 2 / lam1)  # the quasi-static response's amplification
    sel = t <= tw + 1  # up to the warning and a period beyond: Omega^2 < 0.02 lambda_1 there
    v_ring = np.max(np.abs(v_[sel] - amp * v1 * np.array([accel(s) for s in t[sel]])))
    tol = np.sqrt(lam1) * abs(g / v1) * v_ring + 0.02 * abs(g * jerk(tw))
    steps = np.arange(1, int(round(TEND / H)) + 1) * H
    t_lo = steps[np.argmax([(fspeed(s) + tol) ** 2 > 0.01 * lw for s in steps])]
    t_hi = steps[np.argmax([(fspeed(s) - tol) ** 2 > 0.01 * lw for s in steps])]
    print("the frame's rotation per unit angular acceleration g = %.5g rad s^2 (quasi-static); "
          "the ring at the tip %.3g m, %.2g rad/s in the frame's speed; at t = %.4g s hub %.5g rad/s, "
          "frame %.5g rad/s, printed %s" % (g, v_ring, tol, tw, speed(tw), fspeed(tw), m.group(2)))
    check(t_lo - 1e-9 <= tw <= t_hi + 1e-9 and tw > ts_,
          "the warning at the first step where the frame's Omega^2 > 0.01 lambda_1: t = %.4g s in "
          "[%.4g, %.4g] (the hub's closed form t* = %.5g s; the frame lags)" % (tw, t_lo, t_hi, ts_))
    check(abs(float(m.group(2)) - fspeed(tw)) < tol + 5e-5,
          "the warning's speed %s rad/s is the frame's %.5g to %.2g (hub %.5g)"
          % (m.group(2), fspeed(tw), tol + 5e-5, speed(tw)))

# the tip in the hub frame
v = -np.sin(phi) * xt[:, 0] + np.cos(phi) * xt[:, 1]
w = xt[:, 2]
during, after = t <= TS, t > TS
k = np.argmin(np.abs(t - TS / 2))
v_qs = v1 * 2 * W / TS
ratio = v[k] / v_qs
print("tip in-plane deflection at T/2: %.5g m, quasi-static %.5g m (ratio %.4f); conventional "
      "linear model's quasi-static %.5g m, Southwell-stiffened %.5g m"
      % (v[k], v_qs, ratio, v_qs / (1 - (W / 2) ** 2 / lam1), v_qs / (1 + 0.193 * (W / 2) ** 2 / lam1)))
check(abs(ratio - 1) < 0.06, "at T/2 the deflection is the quasi-static one to 6 %% (ratio %.4f)" % ratio)
ip = np.argmax(np.abs(v))
pk_during, pk_after = np.max(np.abs(v[during])), np.max(np.abs(v[after]))
print("peak |v| %.5g m at t = %.4g s; over [T, %g s] %.4g m" % (abs(v[ip]), t[ip], TEND, pk_after))
check(pk_after < pk_during, "bounded after the spin-up: peak %.3g m after T < %.3g m during" % (pk_after, pk_during))
check(np.max(np.abs(w)) < 1e-6, "out of plane: max |w| = %.2g m" % np.max(np.abs(w)))

# the residual ring after T, at the steady speed W: its omega^2 from the upward zero crossings
# (linear interpolation between output rows: the ring is nearly linear over 0.05 s at a
# crossing, 0.18 rad of phase; the mean removed over whole periods), against test_spin_up's
# steady-speed in-plane shift (-0.086 to -0.094 Omega^2 measured there on another beam). The
# conventional linear model has no ring here (lambda_1 - Omega^2 < 0). Asserted to 3 %: the
# spread of test_spin_up's coefficient is 0.008 Omega^2 = 0.9 %, the crossings' timing
# (0.18 rad steps, a 2 mm ring on a mean of its own size) about 1 %.
ta, va = t[after], v[after]


def up_crossings(tt, yy):
    i = np.nonzero((yy[:-1] < 0) & (yy[1:] >= 0))[0]
    return tt[i] - yy[i] * (tt[i + 1] - tt[i]) / (yy[i + 1] - yy[i])


tz = up_crossings(ta, va - va.mean())
sel = (ta >= tz[0]) & (ta < tz[-1]) if len(tz) >= 2 else np.ones(len(ta), bool)
tz = up_crossings(ta, va - va[sel].mean())  # mean over whole periods
om2 = (2 * np.pi / np.mean(np.diff(tz))) ** 2 if len(tz) >= 3 else float("nan")
pred = lam1 - 0.09 * W * W
print("after T: ring amplitude %.3g m, %d periods, omega^2 %.4g rad^2/s^2 (test_spin_up's lambda_1 - "
      "0.09 Omega^2 = %.4g; conventional linear %.4g, no ring)"
      % (np.max(np.abs(va - va[sel].mean())), len(tz) - 1, om2, pred, lam1 - W * W))
check(abs(om2 / pred - 1) < 0.03, "the ring after T at omega^2 %.4g, test_spin_up's steady-speed %.4g (3 %%)"
      % (om2, pred))
finish()
