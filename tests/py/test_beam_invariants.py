#!/usr/bin/python3
"""tests/py/test_beam_invariants.py: the FFRF invariants of a beam body are the M-projection.

The rod of rodbeam.geo as 8 beam elements (mesh2fe, consistent mass, RBE2 interfaces end0 and
end1), free-free normal modes, ALL 48 flexible modes kept (fe2cb --method nm, cbcheck). With
the modes M-orthonormal (Mff = I), the rigid-flexible coupling of the reduced body must be the
projection on the same consistent M the modes come from (docs/THEORY.md section 9):
  (1) S1 = T'MS and M_wf(q = 0) = R'MS (T, R the rigid translation and rotation fields of the
      active dofs), so that sum_k S1[a,k]^2 <= m (Bessel's inequality); the lumped nodal
      masses used before gave sum_k S1^2 of several kg per direction for a 1.66 kg rod;
  (2) the body's 6+nm mass matrix at q = 0 (fmbd_mbs.h EQUATIONS: M_RR, M_Rw, M_Rf, M_ww,
      M_wf, Mff from the file's invariants) equals [T R S]'M[T R S] and is positive definite;
  (3) the rod hinged at end0 under gravity (fmbd-run, a short run) runs; with the lumped
      coupling Newton failed at t = 2e-3 s.
"""
import os
import subprocess
import sys

import h5py
import numpy as np
import scipy.sparse as sp

ROOT = os.environ.get("ROOT", os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..")))
BUILD = os.environ.get("BUILD", "build")
TMP = os.path.join(ROOT, BUILD, "test-tmp", "test_beam_invariants")
os.makedirs(TMP, exist_ok=True)
BIN = os.path.join(ROOT, BUILD, "bin")
fails = []


def check(ok, what):
    print(("ok    " if ok else "FAIL  ") + what)
    if not ok:
        fails.append(what)


def run(*cmd):
    r = subprocess.run([os.path.join(BIN, cmd[0]), *cmd[1:]], cwd=TMP, capture_output=True, text=True)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("%s: exit %d" % (" ".join(cmd), r.returncode))
    return r


def csr(g):
    return sp.csr_matrix((g["data"][()], g["indices"][()], g["indptr"][()]), shape=tuple(g.attrs["shape"]))


geo = os.path.join(ROOT, "examples", "geometry", "rodbeam.geo")
run("mesh2fe", geo, "--circle", "0.015", "--size", "0.0375", "--interface", "end0", "--interface", "end1",
    "-o", "b.fe.h5", "-q")
run("fe2cb", "b.fe.h5", "--method", "nm", "--modes", "48", "-o", "b.cb.h5", "-q")
run("cbcheck", "b.cb.h5", "-o", "b.rflex.h5", "-q")

with h5py.File(os.path.join(TMP, "b.fe.h5"), "r") as fe, h5py.File(os.path.join(TMP, "b.rflex.h5"), "r") as rf:
    M = csr(fe["M"]).toarray()
    dofs = fe["dofs"][()]
    x = fe["mesh/nodes"][()]
    S = rf["modes/shapes"][()]
    S1 = rf["ffrf/S1"][()]
    XS = rf["ffrf/XS"][()]
    Mff = rf["ffrf/Mff"][()]
    m = float(rf["ffrf/mass"][()])
    c0 = rf["ffrf/first_moment"][()]
    J0 = rf["ffrf/second_moment"][()]
n, nm = S.shape
check(nm == 48 and n == 54, f"all {nm} flexible modes of the {n}-dof free-free beam kept")

# rigid fields of the active dofs: T_a unit translation a, R_a rotation about axis a through
# the origin (e_a x x0 at the translations, e_a at the rotations)
T = np.zeros((n, 3))
R = np.zeros((n, 3))
eye = np.eye(3)
for i, (p, d) in enumerate(dofs):
    if d < 3:
        T[i, d] = 1.0
        for a in range(3):
            R[i, a] = np.cross(eye[a], x[p])[d]
    else:
        R[i, d - 3] = 1.0
eps = np.zeros((3, 3, 3))
eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
I0 = np.trace(J0) * eye - J0
Mwf = np.einsum("abc,bck->ak", eps, XS)

# --- (1) Bessel and the coupling from M ---
ssq = (S1**2).sum(axis=1)
check(np.all(ssq <= m * (1 + 1e-12)), f"sum_k S1[a,k]^2 = {ssq.max():.2e} kg <= m = {m:.4f} kg")
# free-free modes are M-orthogonal to rigid motion: both sides are round-off, so the scale of
# the comparison is the bound of each entry, |S1[a,k]| <= sqrt(m), |Mwf[a,k]| <= sqrt(I0_aa)
eS1 = np.abs(S1 - T.T @ M @ S).max() / np.sqrt(m)
eWf = np.abs(Mwf - R.T @ M @ S).max() / np.sqrt(np.trace(I0))
check(eS1 < 1e-12, f"S1 = T'MS to {eS1:.1e} of sqrt(m)")
check(eWf < 1e-12, f"eps_abc XS_bc = R'MS to {eWf:.1e} of sqrt(tr I0)")
# the rigid-body terms are /body: Hermitian beams carry the exact translational mass, and
# /body's inertia is R'MR itself
eT = np.abs(T.T @ M @ T - m * eye).max() / m
eR = np.abs(R.T @ M @ R - I0).max() / np.abs(I0).max()
cx = np.array([[0, -c0[2], c0[1]], [c0[2], 0, -c0[0]], [-c0[1], c0[0], 0]])
eC = np.abs(T.T @ M @ R + cx).max() / np.abs(c0).max()
check(eT < 1e-12 and eR < 1e-12 and eC < 1e-12,
      f"T'MT = m 1 ({eT:.1e}), R'MR = I0 ({eR:.1e}), T'MR = -c0~ ({eC:.1e})")

# --- (2) the 6+nm mass matrix at q = 0 ---
Mb = np.block([[m * eye, -cx, S1], [cx, I0, Mwf], [S1.T, Mwf.T, Mff]])
B = np.hstack([T, R, S])
Mp = B.T @ M @ B
eM = np.abs(Mb - Mp).max() / np.abs(Mp).max()
check(eM < 1e-12, f"body mass matrix at q = 0 = [T R S]'M[T R S] to {eM:.1e}")
w = np.linalg.eigvalsh(0.5 * (Mb + Mb.T))
check(w.min() > 1e-8 * w.max(), f"body mass matrix positive definite (eigenvalues {w.min():.2e} .. {w.max():.2e})")

# --- (3) the hinged beam pendulum runs ---
scene = os.path.join(TMP, "pend.yaml")
with open(scene, "w") as f:
    f.write("""title: hinged flexible beam pendulum, all 48 modes
gravity: [0, -9.81, 0]
solver: {t_end: 0.02, first_step: 1e-5, max_step: 1e-4}
bodies:
  - name: rod
    type: flexible
    file: %s
    damping_ratio: 0.05
joints:
  - {name: hinge, type: revolute, body1: ground, body2: rod, point: [0, 0, 0], axis: z, at2: {interface: end0}}
outputs:
  every: 0.001
  points:
    - {name: tip, body: rod, interface: end1, quantities: [position]}
""" % os.path.join(TMP, "b.rflex.h5"))
out = os.path.join(TMP, "pend.run.h5")
r = subprocess.run([os.path.join(BIN, "fmbd-run"), scene, "-o", out], cwd=TMP, capture_output=True, text=True)
check(r.returncode == 0, "hinged beam pendulum with all modes runs to t = 0.02 s")
if r.returncode:
    print(r.stderr)
else:
    with h5py.File(out, "r") as f:
        t = f["time"][()]
    check(abs(t[-1] - 0.02) < 1e-9, f"the run reached t_end (last row t = {t[-1]:g} s)")

if fails:
    print("test_beam_invariants: %d failure(s)" % len(fails))
    sys.exit(1)
print("test_beam_invariants: all checks passed")
